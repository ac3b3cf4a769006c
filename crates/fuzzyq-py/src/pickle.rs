//! Pickling: every grid, model, solution and policy reduces to a call of the module's
//! `_restore(kind, data)` (defined at the crate's root, which knows every class) with plain
//! data: a policy file's bytes for solutions of built-in models and learned policies, JSON for
//! the point-mass and robot models, arrays and the `CallableModel` (whose function pickles by
//! reference) for a solution of a `CallableModel`. So `pickle`, `copy`, `joblib` and process
//! pools move them between processes.

use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyTuple};

/// `(_restore, (kind, data))`: what a `__reduce__` returns.
pub(crate) fn reduce<'py>(
    py: Python<'py>,
    kind: &str,
    data: Bound<'py, PyAny>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
    let restore = py.import("fuzzyq._fuzzyq")?.getattr("_restore")?;
    let args = PyTuple::new(py, [kind.into_pyobject(py)?.into_any(), data])?;
    Ok((restore, args))
}

/// The bytes of `data` (a pickled payload).
pub(crate) fn bytes(data: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    Ok(data.cast::<PyBytes>()?.as_bytes().to_vec())
}
