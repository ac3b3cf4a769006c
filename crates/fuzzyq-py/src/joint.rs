//! A model's joint actions as every model class exposes them: the vector of a joint action,
//! and joint indices to and from per-agent indices (agent 0 most significant).

use fuzzyq_core::JointActions;
use numpy::PyArray1;
use pyo3::prelude::*;

use crate::errors::{Kind, error, eval_error};

/// The joint action vector of joint action `index`.
pub(crate) fn vector<'py>(
    py: Python<'py>,
    joint: &JointActions<'_, f64>,
    index: usize,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let mut u = vec![0.0; joint.dim()];
    joint
        .vector(index, &mut u)
        .map_err(|e| eval_error(py, &e))?;
    Ok(PyArray1::from_vec(py, u))
}

/// The joint action index of per-agent action indices.
pub(crate) fn index(
    py: Python<'_>,
    joint: &JointActions<'_, f64>,
    per_agent: &[usize],
) -> PyResult<usize> {
    joint
        .compose(per_agent)
        .map_err(|e| error(py, Kind::Input, format!("per_agent: {e}")))
}

/// The per-agent action indices of joint action `index`.
pub(crate) fn per_agent(
    py: Python<'_>,
    joint: &JointActions<'_, f64>,
    index: usize,
) -> PyResult<Vec<usize>> {
    let mut out = vec![0; joint.n_agents()];
    joint
        .decompose(index, &mut out)
        .map_err(|e| eval_error(py, &e))?;
    Ok(out)
}
