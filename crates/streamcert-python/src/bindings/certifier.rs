//! `Certifier`, `Evidence` and `Reasons`: the live certifier and its records.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use streamcert_certificate::{EvidenceRow, NotCertified};

use super::{PyConfig, to_py};
use crate::{Error, EvidenceColumns, FLOAT_COLUMNS, GATES, ReasonColumn, Run, WINDOW_COLUMNS};

/// A streaming certifier with the command line's configuration, summary and checkpoints.
#[pyclass(module = "streamcert._native", name = "Certifier", subclass)]
pub(crate) struct PyCertifier {
    run: Run,
    config: PyConfig,
    y: Vec<f64>,
    u: Vec<f64>,
}

/// Read one sample's values from a float (one value), a 1-D float64 array or a sequence.
fn values_into(v: &Bound<'_, PyAny>, out: &mut Vec<f64>) -> PyResult<()> {
    out.clear();
    if let Ok(x) = v.extract::<f64>() {
        out.push(x);
    } else if let Ok(a) = v.cast::<PyArray1<f64>>() {
        out.extend(a.readonly().as_array().iter());
    } else {
        out.extend(v.extract::<Vec<f64>>()?);
    }
    Ok(())
}

/// A 2-D float64 array's values, row-major, and its shape.
fn matrix<'a>(py: Python<'_>, a: &'a PyReadonlyArray2<'_, f64>, what: &str) -> PyResult<&'a [f64]> {
    a.as_slice().map_err(|_| {
        to_py(py, Error::Shape(format!("{what}: a C-contiguous float64 array is needed")))
    })
}

#[pymethods]
impl PyCertifier {
    #[new]
    fn new(py: Python<'_>, config: PyRef<'_, PyConfig>) -> PyResult<Self> {
        let config = config.clone();
        let run = Run::new(config.inner.config.clone()).map_err(|e| to_py(py, e))?;
        Ok(Self { run, config, y: Vec::new(), u: Vec::new() })
    }

    /// Certify one sample: `y` and `u` are floats (one output or input) or 1-D sequences.
    fn update(
        &mut self,
        py: Python<'_>,
        t: f64,
        y: &Bound<'_, PyAny>,
        u: &Bound<'_, PyAny>,
    ) -> PyResult<PyEvidence> {
        values_into(y, &mut self.y)?;
        values_into(u, &mut self.u)?;
        let (p, m) = self.run.dims();
        if self.y.len() != p || self.u.len() != m {
            let msg = format!(
                "one sample needs {p} outputs and {m} inputs, got {} and {}",
                self.y.len(),
                self.u.len()
            );
            return Err(to_py(py, Error::Shape(msg)));
        }
        let ev = self.run.push(t, &self.y, &self.u).map_err(|e| to_py(py, e))?;
        let reasons =
            [ev.gaussian.reason, ev.wasserstein.reason, ev.calibrated.reason, ev.nonlinear.reason];
        Ok(PyEvidence { row: EvidenceRow::from(&ev), reasons })
    }

    /// Certify a block: `t` (n), `y` (n × p), `u` (n × m), all C-contiguous float64. Returns
    /// a dict of arrays (the CSV's columns) and the reasons. The GIL is released meanwhile.
    fn update_block<'py>(
        &mut self,
        py: Python<'py>,
        t: PyReadonlyArray1<'py, f64>,
        y: PyReadonlyArray2<'py, f64>,
        u: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyDict>, PyReasons)> {
        let (p, m) = self.run.dims();
        if y.shape()[1] != p || u.shape()[1] != m {
            let msg = format!(
                "y must have {p} columns and u {m} (the configuration's outputs {:?} and inputs \
                 {:?}), got {} and {}",
                self.config.inner.config.columns.outputs,
                self.config.inner.config.columns.inputs,
                y.shape()[1],
                u.shape()[1]
            );
            return Err(to_py(py, Error::Shape(msg)));
        }
        let t = t.as_slice().map_err(|_| to_py(py, Error::Shape("t: not contiguous".into())))?;
        let (ys, us) = (matrix(py, &y, "y")?, matrix(py, &u, "u")?);
        let run = &mut self.run;
        let mut cols = run.columns(t.len());
        py.detach(|| run.push_block(t, ys, us, &mut cols)).map_err(|e| to_py(py, e))?;
        columns_to_py(py, cols)
    }

    /// Every gate's state after the last sample: `{gate: {"open", "streak", "opened_at",
    /// "first_opened_at"}}` (`opened_at`: when the current opening began; `first_opened_at`:
    /// the first opening of the run, the deployment decision).
    fn gates<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        use streamcert_certificate::CertificateKind as K;
        let d = PyDict::new(py);
        let kinds = [K::Gaussian, K::Wasserstein, K::Calibrated, K::Nonlinear];
        for (gate, kind) in GATES.iter().zip(kinds) {
            let g = self.run.certifier().gate(kind);
            let e = PyDict::new(py);
            e.set_item("open", g.open)?;
            e.set_item("streak", g.streak)?;
            e.set_item("opened_at", g.opened_at)?;
            e.set_item("first_opened_at", g.first_opened_at)?;
            d.set_item(*gate, e)?;
        }
        Ok(d)
    }

    /// The summary so far as JSON (`certify --summary FILE`'s object).
    fn summary_json(&self) -> String {
        let c = &self.config.inner.config;
        self.run.summary().json(&c.certifier, &c.columns.outputs).to_string()
    }

    /// The summary's text (`certify`'s stderr), whose first line is the verdict.
    fn summary_text(&self) -> String {
        let c = &self.config.inner.config;
        self.run.summary().text(&c.certifier, &c.columns.outputs)
    }

    /// Whether the verdict gate (calibrated; the Gaussian one in the paper-only mode) is open
    /// after the last sample.
    #[getter]
    fn certified(&self) -> bool {
        self.run.summary().certified_at_end(&self.config.inner.config.certifier)
    }

    /// The configuration.
    #[getter]
    fn config(&self) -> PyConfig {
        self.config.clone()
    }

    /// The region columns' names (as in the CSV's header).
    #[getter]
    fn region_names(&self) -> Vec<String> {
        self.run.region_names().to_vec()
    }

    /// The region values of the last sample: `(lo, hi)` per region channel (NaN when none).
    fn region(&self) -> Vec<(f64, f64)> {
        self.run
            .last_region()
            .iter()
            .map(|r| if r.is_proper() { (r.lo, r.hi) } else { (f64::NAN, f64::NAN) })
            .collect()
    }

    /// The sealed checkpoint (the command line's `--checkpoint` format), as bytes.
    fn checkpoint<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let bytes = self.run.checkpoint().map_err(|e| to_py(py, e))?;
        Ok(PyBytes::new(py, &bytes))
    }

    /// Replace this certifier's state by the checkpoint `data` (for its own configuration),
    /// refused as `certify --resume` refuses: damaged, foreign, another configuration.
    fn load(&mut self, py: Python<'_>, data: &[u8]) -> PyResult<()> {
        self.run =
            Run::restore(data, self.config.inner.config.clone()).map_err(|e| to_py(py, e))?;
        Ok(())
    }

    /// A certifier resumed from `data` for `config`, refused as `certify --resume` refuses.
    #[staticmethod]
    fn restore(py: Python<'_>, data: &[u8], config: PyRef<'_, PyConfig>) -> PyResult<Self> {
        let config = config.clone();
        let run = Run::restore(data, config.inner.config.clone()).map_err(|e| to_py(py, e))?;
        Ok(Self { run, config, y: Vec::new(), u: Vec::new() })
    }
}

fn columns_to_py(py: Python<'_>, c: EvidenceColumns) -> PyResult<(Bound<'_, PyDict>, PyReasons)> {
    let d = PyDict::new(py);
    for (name, v) in FLOAT_COLUMNS.iter().zip(c.floats) {
        d.set_item(*name, PyArray1::from_vec(py, v))?;
    }
    let [r0, r1, r2, r3] = c.reasons;
    let mut reasons = [r0, r1, r2, r3];
    for ((gate, open), reason) in GATES.iter().zip(c.open).zip(&mut reasons) {
        d.set_item(format!("{gate}_open"), PyArray1::from_vec(py, open))?;
        let codes = std::mem::take(&mut reason.codes);
        d.set_item(format!("reason_code_{gate}"), PyArray1::from_vec(py, codes))?;
    }
    for (name, v) in WINDOW_COLUMNS.iter().zip(c.windows) {
        d.set_item(*name, PyArray1::from_vec(py, v))?;
    }
    for (name, v) in c.region_names.iter().zip(c.regions) {
        d.set_item(name, PyArray1::from_vec(py, v))?;
    }
    Ok((d, PyReasons { reasons }))
}

/// The reasons of a block, kept as values until their texts are asked for.
#[pyclass(module = "streamcert._native", name = "Reasons", frozen)]
pub(crate) struct PyReasons {
    /// The reasons (their codes moved out into the result's arrays).
    reasons: [ReasonColumn; 4],
}

#[pymethods]
impl PyReasons {
    /// The texts of gate `gate` (`"gauss"`, `"wass"`, `"calibrated"`, `"nonlinear"`): the
    /// CSV's `reason_<gate>` fields, `""` where the gate is open.
    fn texts(&self, py: Python<'_>, gate: &str) -> PyResult<Vec<String>> {
        let g = GATES.iter().position(|g| *g == gate).ok_or_else(|| {
            to_py(py, Error::Config(format!("no gate `{gate}`; the gates are {GATES:?}")))
        })?;
        Ok(self.reasons[g].texts())
    }

    fn __len__(&self) -> usize {
        self.reasons[0].len()
    }
}

/// One sample's evidence (the CSV row's fields).
#[pyclass(module = "streamcert._native", name = "Evidence", frozen)]
pub(crate) struct PyEvidence {
    row: EvidenceRow,
    reasons: [Option<NotCertified>; 4],
}

#[pymethods]
impl PyEvidence {
    /// Sample time.
    #[getter]
    fn t(&self) -> f64 {
        self.row.t
    }
    /// `β̂` (eq. betahat), `None` while warming up.
    #[getter]
    fn beta_hat(&self) -> Option<f64> {
        self.row.beta_hat
    }
    /// `ρ` (eq. rho).
    #[getter]
    fn rho(&self) -> Option<f64> {
        self.row.rho
    }
    /// `ε(t)` (eq. eps_est).
    #[getter]
    fn eps(&self) -> Option<f64> {
        self.row.eps
    }
    /// The Gaussian certificate `β̂ − ρ`.
    #[getter]
    fn cert_gauss(&self) -> Option<f64> {
        self.row.cert_gauss
    }
    /// The Wasserstein certificate `β̂ − ρ(1 + 2ε)` (eq. wass_cert).
    #[getter]
    fn cert_wass(&self) -> Option<f64> {
        self.row.cert_wass
    }
    /// The calibrated certificate `β̂_w − ρ_w`.
    #[getter]
    fn cert_calibrated(&self) -> Option<f64> {
        self.row.cert_calibrated
    }
    /// `ρ_w` of the calibrated certificate's window.
    #[getter]
    fn rho_calibrated(&self) -> Option<f64> {
        self.row.rho_calibrated
    }
    /// The calibrated look's window `M_w`.
    #[getter]
    fn calibrated_window(&self) -> Option<usize> {
        self.row.calibrated_window
    }
    /// The calibrated look's horizon `h` (with `horizon = "auto"`, the standing horizon's).
    #[getter]
    fn calibrated_horizon(&self) -> Option<usize> {
        self.row.calibrated_horizon
    }
    /// The calibrated look's model order `n` (with `order = "auto"`, the standing order's).
    #[getter]
    fn calibrated_order(&self) -> Option<usize> {
        self.row.calibrated_order
    }
    /// The nonlinear certificate.
    #[getter]
    fn cert_nonlinear(&self) -> Option<f64> {
        self.row.cert_nonlinear
    }
    /// The Gaussian gate.
    #[getter]
    fn gauss_open(&self) -> bool {
        self.row.gauss_open == 1
    }
    /// The Wasserstein gate.
    #[getter]
    fn wass_open(&self) -> bool {
        self.row.wass_open == 1
    }
    /// The calibrated gate (the verdict).
    #[getter]
    fn calibrated_open(&self) -> bool {
        self.row.calibrated_open == 1
    }
    /// The nonlinear gate.
    #[getter]
    fn nonlinear_open(&self) -> bool {
        self.row.nonlinear_open == 1
    }
    /// Why gate `gate` is closed: `(code, text)`, or `None` when it is open.
    fn reason(&self, py: Python<'_>, gate: &str) -> PyResult<Option<(u8, String)>> {
        let g = GATES.iter().position(|g| *g == gate).ok_or_else(|| {
            to_py(py, Error::Config(format!("no gate `{gate}`; the gates are {GATES:?}")))
        })?;
        Ok(self.reasons[g].map(|r| (r.code(), r.to_string())))
    }
    /// Every field as a dict (the CSV row's columns; reasons as text and code).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let r = &self.row;
        let d = PyDict::new(py);
        let floats = crate::columns::float_values(r);
        for (name, v) in FLOAT_COLUMNS.iter().zip(floats) {
            d.set_item(*name, v)?;
        }
        let open = [r.gauss_open, r.wass_open, r.calibrated_open, r.nonlinear_open];
        for ((gate, o), reason) in GATES.iter().zip(open).zip(self.reasons) {
            d.set_item(format!("{gate}_open"), o == 1)?;
            d.set_item(format!("reason_code_{gate}"), reason.map_or(0, |r| r.code()))?;
            d.set_item(format!("reason_{gate}"), reason.map(|r| r.to_string()))?;
        }
        d.set_item("calibrated_window", r.calibrated_window)?;
        d.set_item("calibrated_horizon", r.calibrated_horizon)?;
        d.set_item("calibrated_order", r.calibrated_order)?;
        d.set_item("nonlinear_window", r.nonlinear_window)?;
        Ok(d)
    }
    fn __repr__(&self) -> String {
        format!(
            "Evidence(t={}, beta_hat={}, cert_calibrated={}, calibrated_open={})",
            self.row.t,
            py_repr(self.row.beta_hat),
            py_repr(self.row.cert_calibrated),
            if self.row.calibrated_open == 1 { "True" } else { "False" }
        )
    }
}

/// A Python-style text of an optional float (`None` or the shortest round trip).
fn py_repr(v: Option<f64>) -> String {
    v.map_or_else(|| "None".into(), |x| format!("{x:?}"))
}
