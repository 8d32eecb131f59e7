//! `NetworkCertifier`: many subsystems, epoch reports out.

use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;

use super::to_py;
use crate::config::{network_from_json, network_from_toml};
use crate::{Error, NetworkRun};

/// The command line's `network` fed by subsystem; reports come out as JSON texts.
#[pyclass(module = "streamcert._native", name = "NetworkCertifier", subclass)]
pub(crate) struct PyNetwork {
    run: NetworkRun,
    text: String,
}

#[pymethods]
impl PyNetwork {
    /// From a `network` configuration's TOML text.
    #[staticmethod]
    #[pyo3(signature = (text, name = "configuration"))]
    fn from_toml(py: Python<'_>, text: &str, name: &str) -> PyResult<Self> {
        let cfg = network_from_toml(text, name).map_err(|e| to_py(py, e))?;
        let run = NetworkRun::new(cfg).map_err(|e| to_py(py, e))?;
        Ok(Self { run, text: text.to_string() })
    }

    /// From a JSON object with the TOML file's keys.
    #[staticmethod]
    fn from_json(py: Python<'_>, json: &str) -> PyResult<Self> {
        let (cfg, text) = network_from_json(json).map_err(|e| to_py(py, e))?;
        let run = NetworkRun::new(cfg).map_err(|e| to_py(py, e))?;
        Ok(Self { run, text })
    }

    /// The configuration's TOML text.
    #[getter]
    fn toml(&self) -> &str {
        &self.text
    }

    /// The subsystems' names.
    #[getter]
    fn subsystems(&self) -> Vec<String> {
        self.run.names().to_vec()
    }

    /// `(outputs, inputs)` of each subsystem.
    #[getter]
    fn dims(&self) -> Vec<(usize, usize)> {
        self.run.dims().to_vec()
    }

    /// The index of subsystem `name`.
    fn index(&self, py: Python<'_>, name: &str) -> PyResult<usize> {
        self.run.index(name).map_err(|e| to_py(py, e))
    }

    /// Feed subsystem `i` a block (`t` n, `y` n × p, `u` n × m, C-contiguous float64): the
    /// JSON list of the epochs composed meanwhile. The GIL is released.
    fn update_block<'py>(
        &mut self,
        py: Python<'py>,
        i: usize,
        t: PyReadonlyArray1<'py, f64>,
        y: PyReadonlyArray2<'py, f64>,
        u: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<String> {
        let shape = |m: &str| to_py(py, Error::Shape(m.into()));
        let _ = (y.shape(), u.shape());
        let t = t.as_slice().map_err(|_| shape("t: not contiguous"))?;
        let y = y.as_slice().map_err(|_| shape("y: not contiguous"))?;
        let u = u.as_slice().map_err(|_| shape("u: not contiguous"))?;
        let run = &mut self.run;
        let mut reports = Vec::new();
        py.detach(|| run.push(i, t, y, u, &mut reports)).map_err(|e| to_py(py, e))?;
        serde_json::to_string(&reports).map_err(|e| to_py(py, Error::Shape(e.to_string())))
    }

    /// Compose every epoch up to `t`: the JSON list of the epochs composed.
    fn advance(&mut self, py: Python<'_>, t: f64) -> PyResult<String> {
        let mut reports = Vec::new();
        self.run.advance(t, &mut reports).map_err(|e| to_py(py, e))?;
        serde_json::to_string(&reports).map_err(|e| to_py(py, Error::Shape(e.to_string())))
    }
}
