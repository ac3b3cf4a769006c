//! The exception hierarchy and the mapping of Rust errors onto it.
//!
//! ```text
//! FuzzyqError(Exception)
//! ├── ConfigError(FuzzyqError, ValueError)      invalid settings, grids, models
//! ├── InputError(FuzzyqError, ValueError)       arrays of the wrong shape or with bad values
//! ├── InputTypeError(FuzzyqError, TypeError)    arguments of the wrong type or dtype
//! ├── ModelError(FuzzyqError, ValueError)       a model returned unusable data
//! ├── PolicyFileError(FuzzyqError, OSError)     policy files that cannot be read or written
//! ├── SolverError(FuzzyqError, RuntimeError)    anything else the solver refuses, and runs
//! │                                             larger than the memory limit
//! └── InternalError(FuzzyqError, RuntimeError)  a bug in fuzzyq (a Rust panic), never bad input
//! ```
//!
//! Which class an argument's error takes: the wrong type of value (a string for a number, a
//! float for a count, a list for a grid) is an `InputTypeError`; a scalar argument of the right
//! type with a value it cannot take (a negative count, a non-finite number, an unknown name, an
//! inconsistent setting) a `ConfigError`; an array of the wrong shape or with bad values, or an
//! index out of range, an `InputError`. Every message is one line and names the argument it
//! is about, mostly first (`max_sweeps: expected an integer >= 0, got int -1`; the sim crate's
//! checks name the configuration field, `env.mass: must be a positive number, got -1`).
//!
//! The classes are created at import with `type(name, bases, ...)`, since an exception with
//! two bases cannot be declared with `create_exception!`. The base class folds the note pyo3
//! adds to a failed argument conversion (`while processing 'max_sweeps'`) into the message,
//! so that the converters of `convert` need not know the argument's name.
//!
//! Every entry point runs its body through [`guard`], which turns a Rust panic into an
//! `InternalError` (pyo3's own `PanicException` derives from `BaseException`, so that
//! `except Exception` would miss it).

use fuzzyq_core::EvalError;
use fuzzyq_core::solver::SolveError;
use fuzzyq_sim::memory::Limit;
use fuzzyq_sim::{ConfigError, PolicyFileError, SimError};
use pyo3::exceptions::{PyException, PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

use crate::panics::catch;

/// The exception classes, created once.
struct Classes {
    base: Py<PyType>,
    config: Py<PyType>,
    input: Py<PyType>,
    input_type: Py<PyType>,
    model: Py<PyType>,
    policy_file: Py<PyType>,
    solver: Py<PyType>,
    internal: Py<PyType>,
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
    Internal,
}

/// Methods of `FuzzyqError`, in Python: `add_note` folds the argument name pyo3 reports for
/// a failed conversion (`while processing 'gamma'`) into the message (`gamma: ...`), so that
/// the message stays one line naming the argument; any other note is kept as a note.
const BASE_METHODS: &std::ffi::CStr = cr#"
import re as _re

_ARGUMENT = _re.compile(r"while processing '([^']+)'")

def add_note(self, note, /):
    match = _ARGUMENT.fullmatch(note) if isinstance(note, str) else None
    if match is None or len(self.args) != 1 or not isinstance(self.args[0], str):
        return Exception.add_note(self, note)
    name = match.group(1)
    if not self.args[0].startswith(name + ":"):
        self.args = (f"{name}: {self.args[0]}",)
"#;

fn make(
    py: Python<'_>,
    name: &str,
    bases: &[Bound<'_, PyAny>],
    doc: &str,
    dict: Bound<'_, PyDict>,
) -> PyResult<Py<PyType>> {
    dict.set_item("__doc__", doc)?;
    dict.set_item("__module__", "fuzzyq")?;
    let ty = py
        .get_type::<PyType>()
        .call1((name, PyTuple::new(py, bases)?, dict))?;
    Ok(ty.cast_into::<PyType>()?.unbind())
}

fn classes(py: Python<'_>) -> PyResult<&Classes> {
    CLASSES.get_or_try_init(py, || {
        let methods = PyDict::new(py);
        methods.set_item("__name__", "fuzzyq")?;
        py.run(BASE_METHODS, Some(&methods), None)?;
        let base_dict = PyDict::new(py);
        base_dict.set_item("add_note", methods.as_any().get_item("add_note")?)?;
        let base = make(
            py,
            "FuzzyqError",
            &[py.get_type::<PyException>().into_any()],
            "Base class of every error fuzzyq raises.",
            base_dict,
        )?;
        let b = base.bind(py).clone().into_any();
        let sub = |name: &str, other: Bound<'_, PyAny>, doc: &str| {
            make(py, name, &[b.clone(), other], doc, PyDict::new(py))
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
                "A problem the solver refuses to solve, or a run too large for the memory limit.",
            )?,
            internal: sub(
                "InternalError",
                py.get_type::<PyRuntimeError>().into_any(),
                "A bug in fuzzyq (a Rust panic), never caused by bad input: please report it.",
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
        &c.internal,
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
                Kind::Internal => &c.internal,
            };
            PyErr::from_type(t.bind(py).clone(), message)
        }
        Err(e) => e,
    }
}

/// The machine's memory limit (90% of its memory), for runs without a `max_memory_gb`.
pub(crate) fn machine_limit(py: Python<'_>) -> PyResult<Limit> {
    Limit::new(None).map_err(|e| sim_error(py, &e))
}

/// The `SolverError` of a run larger than its memory limit (`e`, the sim crate's
/// `SimError::Memory`), naming the argument `arg` that makes it so large (or that raises the
/// limit).
pub(crate) fn memory_error(py: Python<'_>, arg: &str, e: &SimError) -> PyErr {
    let hint = if arg == "max_memory_gb" {
        "; pass a larger max_memory_gb to run it anyway"
    } else {
        ""
    };
    error(py, Kind::Solver, format!("{arg}: {e}{hint}"))
}

/// Maps a solver error.
pub(crate) fn solve_error(py: Python<'_>, e: &SolveError) -> PyErr {
    let kind = match e {
        SolveError::Eval(EvalError::Length { .. } | EvalError::OutOfRange { .. }) => Kind::Input,
        SolveError::Eval(EvalError::NotFinite { .. } | EvalError::BeyondPrecision { .. }) => {
            Kind::Input
        }
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
        // A run the GPU path does not take, one too large for the adapter, or a mistyped
        // `FUZZYQ_GPU_*` setting: the settings'.
        SimError::Gpu(
            fuzzyq_gpu::GpuError::Unsupported(_)
            | fuzzyq_gpu::GpuError::TooLarge { .. }
            | fuzzyq_gpu::GpuError::OutOfMemory { .. }
            | fuzzyq_gpu::GpuError::Setting { .. },
        ) => error(py, Kind::Config, e.to_string()),
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

/// Runs the body of an entry point (a function or method called from Python): a Rust panic
/// inside it becomes an `InternalError` rather than pyo3's `PanicException`.
pub(crate) fn guard<T>(py: Python<'_>, body: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch(body).unwrap_or_else(|message| {
        Err(error(
            py,
            Kind::Internal,
            format!("internal error (a bug in fuzzyq, please report it): {message}"),
        ))
    })
}
