//! Converting Python arguments to Rust values, with errors that name the expected shape.

use numpy::{PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{Kind, error};

/// Shape as written in messages: `(8,)`, `(B, 4)`.
fn fmt_shape(shape: &[Option<usize>]) -> String {
    let parts: Vec<String> = shape
        .iter()
        .map(|d| d.map_or_else(|| "n".into(), |v| v.to_string()))
        .collect();
    if parts.len() == 1 {
        format!("({},)", parts[0])
    } else {
        format!("({})", parts.join(", "))
    }
}

/// `obj` as a float64 numpy array (any array-like), or an `InputTypeError`.
fn as_f64_array<'py>(
    obj: &Bound<'py, PyAny>,
    what: &str,
    expected: &[Option<usize>],
) -> PyResult<PyReadonlyArrayDyn<'py, f64>> {
    let py = obj.py();
    let bad_type = || {
        let ty = obj
            .get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_else(|_| "?".into());
        error(
            py,
            Kind::InputType,
            format!(
                "{what}: expected an array of numbers of shape {}, got {ty}",
                fmt_shape(expected)
            ),
        )
    };
    if obj.is_none() || obj.is_instance_of::<pyo3::types::PyString>() {
        return Err(bad_type());
    }
    let kwargs = PyDict::new(py);
    kwargs.set_item("dtype", "float64")?;
    let arr = py
        .import("numpy")?
        .getattr("asarray")?
        .call((obj,), Some(&kwargs))
        .map_err(|_| bad_type())?;
    arr.extract::<PyReadonlyArrayDyn<'py, f64>>()
        .map_err(|_| bad_type())
}

/// Checks the shape against `expected` (`None`: any length).
fn check_shape(
    py: Python<'_>,
    what: &str,
    shape: &[usize],
    expected: &[Option<usize>],
) -> PyResult<()> {
    let ok = shape.len() == expected.len()
        && shape
            .iter()
            .zip(expected)
            .all(|(s, e)| e.is_none_or(|e| e == *s));
    if ok {
        Ok(())
    } else {
        let got: Vec<Option<usize>> = shape.iter().map(|&s| Some(s)).collect();
        Err(error(
            py,
            Kind::Input,
            format!(
                "{what}: expected shape {}, got {}",
                fmt_shape(expected),
                fmt_shape(&got)
            ),
        ))
    }
}

/// Checks that every value is finite.
pub(crate) fn check_finite(py: Python<'_>, what: &str, values: &[f64]) -> PyResult<()> {
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(i) => Err(error(
            py,
            Kind::Input,
            format!("{what}: element {i} is not a finite number"),
        )),
    }
}

/// A 1-D array of `len` floats (any length if `None`).
pub(crate) fn vector(obj: &Bound<'_, PyAny>, what: &str, len: Option<usize>) -> PyResult<Vec<f64>> {
    let expected = [len];
    let arr = as_f64_array(obj, what, &expected)?;
    check_shape(obj.py(), what, arr.shape(), &expected)?;
    Ok(arr.as_array().iter().copied().collect())
}

/// A finite 1-D array of `len` floats: a state or an action.
pub(crate) fn finite_vector(
    obj: &Bound<'_, PyAny>,
    what: &str,
    len: Option<usize>,
) -> PyResult<Vec<f64>> {
    let v = vector(obj, what, len)?;
    check_finite(obj.py(), what, &v)?;
    Ok(v)
}

/// A 2-D array with `cols` columns: `(rows, values row-major)`.
pub(crate) fn matrix(
    obj: &Bound<'_, PyAny>,
    what: &str,
    rows: Option<usize>,
    cols: Option<usize>,
) -> PyResult<(usize, usize, Vec<f64>)> {
    let expected = [rows, cols];
    let arr = as_f64_array(obj, what, &expected)?;
    check_shape(obj.py(), what, arr.shape(), &expected)?;
    let (r, c) = (arr.shape()[0], arr.shape()[1]);
    Ok((r, c, arr.as_array().iter().copied().collect()))
}

/// One state `(E,)` or a batch `(B, E)`: `(values, batch size or None)`.
pub(crate) fn one_or_batch(
    obj: &Bound<'_, PyAny>,
    what: &str,
    cols: usize,
) -> PyResult<(Vec<f64>, Option<usize>)> {
    let arr = as_f64_array(obj, what, &[None, Some(cols)])?;
    let shape = arr.shape().to_vec();
    let values: Vec<f64> = arr.as_array().iter().copied().collect();
    check_finite(obj.py(), what, &values)?;
    match shape.as_slice() {
        [n] if *n == cols => Ok((values, None)),
        [b, n] if *n == cols => Ok((values, Some(*b))),
        _ => {
            let got: Vec<Option<usize>> = shape.iter().map(|&s| Some(s)).collect();
            Err(error(
                obj.py(),
                Kind::Input,
                format!(
                    "{what}: expected shape ({cols},) or (n, {cols}), got {}",
                    fmt_shape(&got)
                ),
            ))
        }
    }
}
