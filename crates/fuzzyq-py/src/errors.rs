//! The exception hierarchy and the mapping of Rust errors onto it.
//!
//! ```text
//! FuzzyqError(Exception)
//! ├── ConfigError(FuzzyqError, ValueError)      invalid settings, grids, models
//! ├── InputError(FuzzyqError, ValueError)       arrays of the wrong shape or with bad values
//! ├── InputTypeError(FuzzyqError, TypeError)    arguments of the wrong type or dtype
//! ├── ModelError(FuzzyqError, ValueError)       a model returned unusable data
//! ├── PolicyFileError(FuzzyqError, OSError)     policy files that cannot be read or written
//! └── SolverError(FuzzyqError, RuntimeError)    anything else the solver refuses
//! ```
//!
//! The classes are created at import with `type(name, bases, ...)`, since an exception with
//! two bases cannot be declared with `create_exception!`.

use fuzzyq_core::EvalError;
use fuzzyq_core::solver::SolveError;
use fuzzyq_sim::{ConfigError, PolicyFileError, SimError};
use pyo3::exceptions::{PyException, PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

/// The exception classes, created once.
struct Classes {
    base: Py<PyType>,
    config: Py<PyType>,
    input: Py<PyType>,
    input_type: Py<PyType>,
    model: Py<PyType>,
    policy_file: Py<PyType>,
    solver: Py<PyType>,
}

static CLASSES: PyOnceLock<Classes> = PyOnceLock::new();

/// The kinds of error this crate raises.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Kind {
    Config,
    Input,
    InputType,
    Model,
    PolicyFile,
    Solver,
}

fn make(py: Python<'_>, name: &str, bases: &[Bound<'_, PyAny>], doc: &str) -> PyResult<Py<PyType>> {
    let dict = PyDict::new(py);
    dict.set_item("__doc__", doc)?;
    dict.set_item("__module__", "fuzzyq")?;
    let ty = py
        .get_type::<PyType>()
        .call1((name, PyTuple::new(py, bases)?, dict))?;
    Ok(ty.cast_into::<PyType>()?.unbind())
}

fn classes(py: Python<'_>) -> PyResult<&Classes> {
    CLASSES.get_or_try_init(py, || {
        let base = make(
            py,
            "FuzzyqError",
            &[py.get_type::<PyException>().into_any()],
            "Base class of every error fuzzyq raises.",
        )?;
        let b = base.bind(py).clone().into_any();
        let sub = |name: &str, other: Bound<'_, PyAny>, doc: &str| {
            make(py, name, &[b.clone(), other], doc)
        };
        Ok(Classes {
            config: sub(
                "ConfigError",
                py.get_type::<PyValueError>().into_any(),
                "An invalid setting, grid or model definition.",
            )?,
            input: sub(
                "InputError",
                py.get_type::<PyValueError>().into_any(),
                "An array of the wrong shape, or with values out of range.",
            )?,
            input_type: sub(
                "InputTypeError",
                py.get_type::<PyTypeError>().into_any(),
                "An argument of the wrong type or dtype.",
            )?,
            model: sub(
                "ModelError",
                py.get_type::<PyValueError>().into_any(),
                "A model returned data of the wrong shape or non-finite values.",
            )?,
            policy_file: sub(
                "PolicyFileError",
                py.get_type::<PyOSError>().into_any(),
                "A policy file that cannot be read or written.",
            )?,
            solver: sub(
                "SolverError",
                py.get_type::<PyRuntimeError>().into_any(),
                "A problem the solver refuses to solve.",
            )?,
            base,
        })
    })
}

/// Adds the classes to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let c = classes(m.py())?;
    for t in [
        &c.base,
        &c.config,
        &c.input,
        &c.input_type,
        &c.model,
        &c.policy_file,
        &c.solver,
    ] {
        let t = t.bind(m.py());
        m.add(t.name()?, t)?;
    }
    Ok(())
}

/// An error of `kind` with `message`.
pub(crate) fn error(py: Python<'_>, kind: Kind, message: impl Into<String>) -> PyErr {
    let message = message.into();
    match classes(py) {
        Ok(c) => {
            let t = match kind {
                Kind::Config => &c.config,
                Kind::Input => &c.input,
                Kind::InputType => &c.input_type,
                Kind::Model => &c.model,
                Kind::PolicyFile => &c.policy_file,
                Kind::Solver => &c.solver,
            };
            PyErr::from_type(t.bind(py).clone(), message)
        }
        Err(e) => e,
    }
}

/// Maps a solver error.
pub(crate) fn solve_error(py: Python<'_>, e: &SolveError) -> PyErr {
    let kind = match e {
        SolveError::Eval(EvalError::Length { .. } | EvalError::OutOfRange { .. }) => Kind::Input,
        SolveError::Eval(EvalError::NotFinite { .. }) => Kind::Input,
        SolveError::NonFinite { .. } => Kind::Model,
        SolveError::TooLarge { .. } | SolveError::Interrupted { .. } => Kind::Solver,
        _ => Kind::Config,
    };
    error(py, kind, e.to_string())
}

/// Maps a sim error.
pub(crate) fn sim_error(py: Python<'_>, e: &SimError) -> PyErr {
    match e {
        SimError::Solve(s) => solve_error(py, s),
        SimError::Config(c) => config_error(py, c),
        SimError::Eval(_) => error(py, Kind::Input, e.to_string()),
        SimError::Grid(_) => error(py, Kind::Config, e.to_string()),
        SimError::PolicyFile(f) => policy_file_error(py, f),
        _ => error(py, Kind::Solver, e.to_string()),
    }
}

/// Maps a configuration error.
pub(crate) fn config_error(py: Python<'_>, e: &ConfigError) -> PyErr {
    error(py, Kind::Config, e.to_string())
}

/// Maps a policy-file error.
pub(crate) fn policy_file_error(py: Python<'_>, e: &PolicyFileError) -> PyErr {
    error(py, Kind::PolicyFile, e.to_string())
}

/// Maps an evaluation error (bad states, buffers).
pub(crate) fn eval_error(py: Python<'_>, e: &EvalError) -> PyErr {
    error(py, Kind::Input, e.to_string())
}
