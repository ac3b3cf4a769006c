//! Converting Python arguments to Rust values, with errors that name the argument and the
//! expected type or shape.
//!
//! Scalar arguments (numbers, flags, names, paths, grids) are converted by [`arg`] (or
//! [`index`] for indices), named in the signature as `#[pyo3(from_py_with = arg)]`: the Rust
//! type of the parameter picks the conversion ([`Arg`], one implementation per concept), and
//! the parameter keeps its Python default. A wrong type raises `InputTypeError`, a value the
//! parameter cannot take (a negative count, a non-finite number) `ConfigError` (`InputError`
//! for an index). pyo3 reports which argument failed, and the exception classes fold that
//! name into the message (`errors::BASE_METHODS`): `max_sweeps: expected an integer >= 0,
//! got int -1`. Arrays are converted in the function bodies ([`vector`], [`matrix`],
//! [`one_or_batch`]), whose errors name the argument themselves.

use std::path::PathBuf;
use std::str::FromStr;

use fuzzyq_core::options::UnknownName;
use fuzzyq_sim::learn::samples::Transitions;
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyInt, PyString};

use crate::errors::{Kind, config_error, error};

/// A Python argument as a Rust value of this type, or a typed error (see the module docs).
pub(crate) trait Arg<'a, 'py>: Sized {
    fn from_arg(obj: &'a Bound<'py, PyAny>) -> PyResult<Self>;
}

/// Converts an argument: `#[pyo3(from_py_with = arg)]`.
pub(crate) fn arg<'a, 'py, T: Arg<'a, 'py>>(obj: &'a Bound<'py, PyAny>) -> PyResult<T> {
    T::from_arg(obj)
}

/// Converts an index argument (an `InputError` when negative, as when too large):
/// `#[pyo3(from_py_with = crate::convert::index)]` (the full path: the parameter is usually
/// named `index` too).
pub(crate) fn index(obj: &Bound<'_, PyAny>) -> PyResult<usize> {
    integer(obj, usize::MAX as u64, Kind::Input).map(|v| v as usize)
}

/// `obj`'s type and a short `repr`, for messages: `str '0.9'`.
pub(crate) fn describe(obj: &Bound<'_, PyAny>) -> String {
    let ty = obj
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_else(|_| "?".into());
    let repr = obj
        .repr()
        .map(|r| r.to_string())
        .unwrap_or_else(|_| "?".into());
    let short: String = repr.chars().take(40).collect();
    let dots = if short.len() < repr.len() { "..." } else { "" };
    if repr.starts_with('<') {
        ty
    } else {
        format!("{ty} {short}{dots}")
    }
}

/// An `InputTypeError`: `expected {expected}, got {obj}`.
pub(crate) fn wrong_type(obj: &Bound<'_, PyAny>, expected: &str) -> PyErr {
    error(
        obj.py(),
        Kind::InputType,
        format!("expected {expected}, got {}", describe(obj)),
    )
}

/// A non-negative integer up to `max` (Python ints and numpy integers, not bools or floats);
/// a value out of range is an error of `kind`.
fn integer(obj: &Bound<'_, PyAny>, max: u64, kind: Kind) -> PyResult<u64> {
    let py = obj.py();
    if obj.is_instance_of::<PyBool>() {
        return Err(wrong_type(obj, "an integer"));
    }
    let out_of_range = |expected: String| {
        error(
            py,
            kind,
            format!("expected {expected}, got {}", describe(obj)),
        )
    };
    match obj.extract::<u64>() {
        Ok(v) if v <= max => Ok(v),
        Ok(_) => Err(out_of_range(format!("an integer of at most {max}"))),
        Err(e) if e.is_instance_of::<PyTypeError>(py) => Err(wrong_type(obj, "an integer")),
        // An integer, but negative or too large for 64 bits.
        Err(_) if obj.lt(0).unwrap_or(false) => Err(out_of_range("an integer >= 0".into())),
        Err(_) => Err(out_of_range(format!("an integer of at most {max}"))),
    }
}

impl Arg<'_, '_> for usize {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        integer(obj, usize::MAX as u64, Kind::Config).map(|v| v as usize)
    }
}

impl Arg<'_, '_> for u64 {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        integer(obj, u64::MAX, Kind::Config)
    }
}

/// A finite number: ints, floats and numpy scalars (not bools or strings).
impl Arg<'_, '_> for f64 {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        if obj.is_instance_of::<PyBool>() || obj.is_instance_of::<PyString>() {
            return Err(wrong_type(obj, "a number"));
        }
        match obj.extract::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            // Non-finite, or an integer too large for a float.
            Ok(_) => Err(not_finite(obj)),
            Err(_) if obj.is_instance_of::<PyInt>() => Err(not_finite(obj)),
            Err(_) => Err(wrong_type(obj, "a number")),
        }
    }
}

/// A `ConfigError`: `expected a finite number, got {obj}`.
fn not_finite(obj: &Bound<'_, PyAny>) -> PyErr {
    error(
        obj.py(),
        Kind::Config,
        format!("expected a finite number, got {}", describe(obj)),
    )
}

/// `True` or `False` (or a numpy bool).
impl Arg<'_, '_> for bool {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        obj.extract::<bool>()
            .map_err(|_| wrong_type(obj, "True or False"))
    }
}

/// A string (a name: a setting, a preset, a policy kind).
impl<'a> Arg<'a, '_> for &'a str {
    fn from_arg(obj: &'a Bound<'_, PyAny>) -> PyResult<Self> {
        let s = obj
            .cast::<PyString>()
            .map_err(|_| wrong_type(obj, "a string"))?;
        s.to_str().map_err(|_| {
            error(
                obj.py(),
                Kind::Config,
                format!("expected a valid Unicode string, got {}", describe(obj)),
            )
        })
    }
}

/// A file system path: a string or an `os.PathLike`.
impl Arg<'_, '_> for PathBuf {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        obj.extract::<PathBuf>()
            .map_err(|_| wrong_type(obj, "a path (a string or an os.PathLike)"))
    }
}

/// A sequence of indices (per-agent action indices).
impl Arg<'_, '_> for Vec<usize> {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        let items = sequence(obj, "a sequence of integers")?;
        items.iter().map(|item| index(item)).collect()
    }
}

/// A friction patch: `((x, y), radius, eta)`.
pub(crate) type Patch = ((f64, f64), f64, f64);

/// A sequence of friction patches.
impl Arg<'_, '_> for Vec<Patch> {
    fn from_arg(obj: &Bound<'_, PyAny>) -> PyResult<Self> {
        const EXPECTED: &str = "a sequence of ((x, y), radius, eta)";
        let items = sequence(obj, EXPECTED)?;
        items
            .iter()
            .map(|item| {
                let p: Patch = item.extract().map_err(|_| wrong_type(item, EXPECTED))?;
                let ((x, y), r, eta) = p;
                if [x, y, r, eta].iter().all(|v| v.is_finite()) {
                    Ok(p)
                } else {
                    Err(error(
                        obj.py(),
                        Kind::Config,
                        format!("expected finite numbers, got {}", describe(item)),
                    ))
                }
            })
            .collect()
    }
}

/// `None`, or the argument converted.
impl<'a, 'py, T: Arg<'a, 'py>> Arg<'a, 'py> for Option<T> {
    fn from_arg(obj: &'a Bound<'py, PyAny>) -> PyResult<Self> {
        if obj.is_none() {
            Ok(None)
        } else {
            T::from_arg(obj).map(Some)
        }
    }
}

/// The items of a sequence (not a string or a mapping).
fn sequence<'py>(obj: &Bound<'py, PyAny>, expected: &str) -> PyResult<Vec<Bound<'py, PyAny>>> {
    if obj.is_instance_of::<PyString>() || obj.is_instance_of::<PyDict>() {
        return Err(wrong_type(obj, expected));
    }
    let items = obj.try_iter().map_err(|_| wrong_type(obj, expected))?;
    items.collect()
}

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

/// Refuses repeated rows among `values` (rows of `dim` components, `-0.0` equal to `0.0`): two
/// equal actions would be two names for one action, and ties between them arbitrary. The
/// `ConfigError` names `what` and both rows (`{item} 2 ([0.0]) repeats {item} 0`).
pub(crate) fn distinct(
    py: Python<'_>,
    what: &str,
    item: &str,
    values: &[f64],
    dim: usize,
) -> PyResult<()> {
    if dim == 0 {
        return Ok(());
    }
    let rows: Vec<&[f64]> = values.chunks_exact(dim).collect();
    let key = |r: &[f64]| -> Vec<u64> { r.iter().map(|v| (v + 0.0).to_bits()).collect() };
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.sort_by_key(|&i| (key(rows[i]), i));
    match order
        .windows(2)
        .filter(|w| key(rows[w[0]]) == key(rows[w[1]]))
        .map(|w| (w[0], w[1]))
        .min_by_key(|&(_, later)| later)
    {
        None => Ok(()),
        Some((first, later)) => Err(error(
            py,
            Kind::Config,
            format!(
                "{what}: {item} {later} ({:?}) repeats {item} {first}; every {item} must be \
                 distinct",
                rows[later]
            ),
        )),
    }
}

/// The option named `got`, or a `ConfigError` naming `field` and the accepted names.
pub(crate) fn parse_option<T: FromStr<Err = UnknownName>>(
    py: Python<'_>,
    field: &str,
    got: &str,
) -> PyResult<T> {
    got.parse()
        .map_err(|e: UnknownName| error(py, Kind::Config, format!("{field}: {e}, got {got:?}")))
}

/// The transitions of `obj` (a mapping with `states`, `actions`, `next_states` and
/// `rewards`, as `collect` returns them) for states of `e` and joint action
/// vectors of `d` values.
pub(crate) fn transitions_of(obj: &Bound<'_, PyAny>, e: usize, d: usize) -> PyResult<Transitions> {
    let py = obj.py();
    let field = |name: &str| -> PyResult<Bound<'_, PyAny>> {
        obj.get_item(name).map_err(|_| {
            error(
                py,
                Kind::InputType,
                format!(
                    "transitions: expected a mapping with states, actions, next_states and \
                     rewards (as fuzzyq.collect returns); {name} is missing"
                ),
            )
        })
    };
    let (n, _, x) = matrix(&field("states")?, "transitions.states", None, Some(e))?;
    let (_, _, u) = matrix(&field("actions")?, "transitions.actions", Some(n), Some(d))?;
    let (_, _, next) = matrix(
        &field("next_states")?,
        "transitions.next_states",
        Some(n),
        Some(e),
    )?;
    let r = finite_vector(&field("rewards")?, "transitions.rewards", Some(n))?;
    Transitions::from_columns(e, d, x, u, next, r).map_err(|err| config_error(py, &err))
}

/// `data` as the dict `collect` returns: `states`, `actions`, `next_states`, `rewards`.
pub(crate) fn transitions_dict<'py>(
    py: Python<'py>,
    data: &Transitions,
) -> PyResult<Bound<'py, PyDict>> {
    let (x, u, next, r) = data.columns();
    let (n, e, a) = (data.len(), data.state_dim(), data.action_dim());
    let rows = |v: &[f64], k: usize| {
        PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((n, k), v.to_vec()).expect("rows"),
        )
    };
    let d = PyDict::new(py);
    d.set_item("states", rows(x, e))?;
    d.set_item("actions", rows(u, a))?;
    d.set_item("next_states", rows(next, e))?;
    d.set_item("rewards", PyArray1::from_slice(py, r))?;
    Ok(d)
}

/// Pairs `(a, b)` as a new `(n, 2)` array.
pub(crate) fn pairs_array<'py>(py: Python<'py>, pairs: &[(f64, f64)]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
    PyArray2::from_owned_array(
        py,
        Array2::from_shape_vec((pairs.len(), 2), flat).expect("pairs"),
    )
}
