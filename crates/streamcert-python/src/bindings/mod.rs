//! The extension module `streamcert._native` (pyo3). The Python package wraps it
//! (`python/streamcert`): conversions of numpy and pandas inputs, result objects, stubs.
//!
//! Exceptions are the Python package's classes (`streamcert._errors`), raised from here by
//! name so that they can inherit from both `StreamcertError` and the builtin a Python user
//! catches (`ValueError`).

mod certifier;
mod network;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::Error;
use crate::config::{ConfigText, from_json_over_defaults, from_toml, with_columns};

/// The Python exception for `e`: `ConfigError`, `InputDataError` (with `row` and `column`),
/// `ShapeError`, `CheckpointError` or `ComposeError` from `streamcert._errors`.
pub(crate) fn to_py(py: Python<'_>, e: Error) -> PyErr {
    let (class, row, column) = match &e {
        Error::Config(_) => ("ConfigError", None, None),
        Error::Data { row, column, .. } => ("InputDataError", Some(*row), column.clone()),
        Error::Shape(_) => ("ShapeError", None, None),
        Error::Checkpoint(_) => ("CheckpointError", None, None),
        Error::Compose(_) => ("ComposeError", None, None),
    };
    let raise = || -> PyResult<PyErr> {
        let cls = py.import("streamcert._errors")?.getattr(class)?;
        let obj = cls.call1((e.to_string(),))?;
        obj.setattr("row", row)?;
        obj.setattr("column", column)?;
        Ok(PyErr::from_value(obj))
    };
    raise().unwrap_or_else(|err| err)
}

/// A validated `certify` configuration and its TOML text.
#[pyclass(module = "streamcert._native", name = "Config", frozen, subclass)]
#[derive(Debug, Clone)]
pub(crate) struct PyConfig {
    pub(crate) inner: ConfigText,
}

#[pymethods]
impl PyConfig {
    /// Read a configuration file's text as `streamcert certify --config` does.
    #[staticmethod]
    #[pyo3(signature = (text, name = "configuration"))]
    fn from_toml(py: Python<'_>, text: &str, name: &str) -> PyResult<Self> {
        from_toml(text, name).map(|inner| Self { inner }).map_err(|e| to_py(py, e))
    }

    /// A JSON object of sections laid over the command line's defaults.
    #[staticmethod]
    fn from_json(py: Python<'_>, json: &str) -> PyResult<Self> {
        from_json_over_defaults(json).map(|inner| Self { inner }).map_err(|e| to_py(py, e))
    }

    /// This configuration with its columns renamed (`None` keeps a name).
    #[pyo3(signature = (time = None, outputs = None, inputs = None))]
    fn with_columns(
        &self,
        py: Python<'_>,
        time: Option<String>,
        outputs: Option<Vec<String>>,
        inputs: Option<Vec<String>>,
    ) -> PyResult<Self> {
        with_columns(&self.inner, time, outputs, inputs)
            .map(|inner| Self { inner })
            .map_err(|e| to_py(py, e))
    }

    /// The TOML text (what `certify --config` would read to get this configuration).
    #[getter]
    fn toml(&self) -> &str {
        &self.inner.text
    }

    /// The output column names (`[columns] outputs`).
    #[getter]
    fn outputs(&self) -> Vec<String> {
        self.inner.config.columns.outputs.clone()
    }

    /// The input column names (`[columns] inputs`).
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.inner.config.columns.inputs.clone()
    }

    /// The time column's name.
    #[getter]
    fn time(&self) -> &str {
        &self.inner.config.columns.time
    }

    /// Whether this is the paper-only mode (no calibrated certificate: no stated risk).
    #[getter]
    fn paper_only(&self) -> bool {
        self.inner.config.certifier.calibration.is_none()
    }

    /// The deployment margin.
    #[getter]
    fn margin(&self) -> f64 {
        self.inner.config.certifier.margin
    }

    /// The loop model's order, `[regression] order`: 1 the paper's first-order model, 2 or 3
    /// a closed loop of that order read through one output.
    #[getter]
    fn order(&self) -> usize {
        self.inner.config.certifier.regression.order.order()
    }
}

/// Compose rates `β_i` with coupling triplets `(rows[k], cols[k], gains[k])`: a dict of the
/// network rate, weights, symmetric bound, critical scale, participation and the limiting
/// subsystem and coupling.
#[pyfunction]
#[pyo3(signature = (rates, rows, cols, gains, dense = None))]
fn compose<'py>(
    py: Python<'py>,
    rates: PyReadonlyArray1<'py, f64>,
    rows: PyReadonlyArray1<'py, i64>,
    cols: PyReadonlyArray1<'py, i64>,
    gains: PyReadonlyArray1<'py, f64>,
    dense: Option<bool>,
) -> PyResult<Bound<'py, PyDict>> {
    let shape = |m: String| to_py(py, Error::Shape(m));
    let (rows, cols, gains) = (rows.as_array(), cols.as_array(), gains.as_array());
    if rows.len() != cols.len() || rows.len() != gains.len() {
        return Err(shape("rows, cols and gains must have the same length".into()));
    }
    let mut edges = Vec::with_capacity(rows.len());
    for k in 0..rows.len() {
        let (i, j) = (rows[k], cols[k]);
        if i < 0 || j < 0 {
            return Err(shape(format!("coupling {k}: negative index ({i}, {j})")));
        }
        edges.push((i as usize, j as usize, gains[k]));
    }
    let rates = rates.as_array().to_vec();
    let c =
        py.detach(|| crate::compose::compose(&rates, &edges, dense)).map_err(|e| to_py(py, e))?;
    let d = PyDict::new(py);
    d.set_item("rate", c.rate)?;
    d.set_item("contracting", c.rate > 0.0)?;
    d.set_item("weights", PyArray1::from_vec(py, c.weights))?;
    d.set_item("symmetric_rate", c.symmetric_rate)?;
    d.set_item("critical_scale", c.critical_scale)?;
    d.set_item("participation", PyArray1::from_vec(py, c.participation))?;
    d.set_item("limiting_subsystem", c.limiting_subsystem)?;
    d.set_item("limiting_coupling", c.limiting_coupling)?;
    d.set_item("method", c.method)?;
    Ok(d)
}

/// Lemma 1 (eq. beta_net): `β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ²)`.
#[pyfunction]
fn lemma1(py: Python<'_>, beta_a: f64, beta_b: f64, gamma: f64) -> PyResult<f64> {
    streamcert_compose::lemma1_rate(beta_a, beta_b, gamma)
        .map_err(|e| to_py(py, Error::Compose(e.to_string())))
}

/// The warning gain `γ_warn = √(β_A β_B)`: Lemma 1's rate is positive iff `γ < γ_warn`.
#[pyfunction]
fn warning_gain(py: Python<'_>, beta_a: f64, beta_b: f64) -> PyResult<f64> {
    streamcert_compose::warning_gain(beta_a, beta_b)
        .map_err(|e| to_py(py, Error::Compose(e.to_string())))
}

/// The command line's `compose --json` on the texts of a rates file and a gains file
/// (`triplets`: `i,j,gamma` lines; otherwise a dense matrix).
#[pyfunction]
fn cli_compose_json(py: Python<'_>, rates: &str, gains: &str, triplets: bool) -> PyResult<String> {
    use streamcert_pipeline::compose::{GainsFormat, Method, Render, run};
    let format = if triplets { GainsFormat::Triplets } else { GainsFormat::Dense };
    run(rates, "rates", gains, "gains", format, Method::Auto, Render::Json)
        .map_err(|e| to_py(py, e.into()))
}

/// Run `seed` of the paper's G5 experiment `experiment` (1 or 2): a dict of arrays `t`
/// (n), `y`, `u`, `beta_true` (n × 2) and `x` (n × 5).
#[pyfunction]
#[pyo3(signature = (experiment, seed, steps = None, gamma = None, bidirectional = false))]
fn simulate_g5<'py>(
    py: Python<'py>,
    experiment: u8,
    seed: u64,
    steps: Option<usize>,
    gamma: Option<f64>,
    bidirectional: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let run = py
        .detach(|| crate::simulate::simulate_g5(experiment, seed, steps, gamma, bidirectional))
        .map_err(|e| to_py(py, e))?;
    let n = run.t.len();
    let d = PyDict::new(py);
    d.set_item("t", PyArray1::from_vec(py, run.t))?;
    for (name, v, w) in [("y", run.y, 2), ("u", run.u, 2), ("x", run.x, 5)] {
        d.set_item(name, PyArray1::from_vec(py, v).reshape([n, w])?)?;
    }
    d.set_item("beta_true", PyArray1::from_vec(py, run.beta_true).reshape([n, 2])?)?;
    Ok(d)
}

/// The names of the reasons, index `code − 1` (`NotCertified::KINDS`).
#[pyfunction]
fn reason_kinds<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
    PyTuple::new(py, streamcert_certificate::NotCertified::KINDS)
}

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("DEFAULT_CONFIG", streamcert_pipeline::config::DEFAULT_CONFIG)?;
    m.add("G5_NODE_B_CONFIG", streamcert_pipeline::config::g5_node_b())?;
    m.add("NETWORK_EXAMPLE_CONFIG", streamcert_pipeline::network::EXAMPLE_CONFIG)?;
    m.add("EVIDENCE_COLUMNS", streamcert_certificate::EVIDENCE_COLUMNS.to_vec())?;
    m.add("FLOAT_COLUMNS", crate::FLOAT_COLUMNS.to_vec())?;
    m.add("GATES", crate::GATES.to_vec())?;
    m.add("WINDOW_COLUMNS", crate::WINDOW_COLUMNS.to_vec())?;
    m.add("VERSION", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyConfig>()?;
    m.add_class::<certifier::PyCertifier>()?;
    m.add_class::<certifier::PyEvidence>()?;
    m.add_class::<certifier::PyReasons>()?;
    m.add_class::<network::PyNetwork>()?;
    m.add_function(wrap_pyfunction!(compose, m)?)?;
    m.add_function(wrap_pyfunction!(lemma1, m)?)?;
    m.add_function(wrap_pyfunction!(warning_gain, m)?)?;
    m.add_function(wrap_pyfunction!(cli_compose_json, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_g5, m)?)?;
    m.add_function(wrap_pyfunction!(reason_kinds, m)?)?;
    Ok(())
}
