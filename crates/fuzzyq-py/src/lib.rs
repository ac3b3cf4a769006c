//! Python bindings of fuzzyq: the `fuzzyq._fuzzyq` extension module.
//!
//! A thin layer over the sim crate: arguments are converted and checked here (shapes and
//! dtypes named in the errors), models, policies, policy files and rollouts are the sim
//! crate's (the same code as the `fuzzyq` command line), the work runs with the GIL released,
//! and results come back as numpy arrays. The Python package `fuzzyq` (`python/fuzzyq`)
//! re-exports this module and adds the Gymnasium/PettingZoo environments.

mod callable;
mod classic;
mod convert;
mod errors;
mod joint;
mod json;
mod khepera;
mod model;
mod panics;
mod pickle;
mod policy;
mod pool;
mod samples;
mod slabs;
mod solution;
mod solve;
mod task;
mod vector;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _fuzzyq(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<model::Grid>()?;
    m.add_class::<model::PointMass>()?;
    m.add_class::<khepera::Khepera>()?;
    m.add_class::<khepera::KheperaPlant>()?;
    m.add_class::<callable::CallableModel>()?;
    m.add_class::<classic::ClassicModel>()?;
    m.add_class::<classic::DcMotor>()?;
    m.add_class::<classic::Pendulum>()?;
    m.add_class::<classic::CarHill>()?;
    m.add_class::<classic::Arm>()?;
    m.add_class::<solution::Solution>()?;
    m.add_class::<policy::Policy>()?;
    m.add_class::<slabs::SlabProblem>()?;
    m.add_class::<task::Task>()?;
    m.add_function(wrap_pyfunction!(solve::solve, m)?)?;
    m.add_function(wrap_pyfunction!(solve::load, m)?)?;
    m.add_function(wrap_pyfunction!(solve::collect, m)?)?;
    m.add_function(wrap_pyfunction!(samples::learn_from_samples, m)?)?;
    m.add_function(wrap_pyfunction!(solve::available_kernels, m)?)?;
    m.add_function(wrap_pyfunction!(slabs::train_sharded, m)?)?;
    m.add_function(wrap_pyfunction!(restore, m)?)?;
    m.add_function(wrap_pyfunction!(vector::_step_batch, m)?)?;
    m.add_function(wrap_pyfunction!(cli, m)?)?;
    Ok(())
}

/// Runs the `fuzzyq` command line on `argv` (the program's name first) with the GIL released
/// and returns its exit code: the package's `fuzzyq` command and `python -m fuzzyq` (not for
/// direct use). The command line is the Rust binary's own code (`fuzzyq_cli::run`), so a wheel
/// carries the whole tool.
#[pyfunction]
#[pyo3(name = "_cli")]
fn cli(py: Python<'_>, argv: Vec<std::ffi::OsString>) -> u8 {
    py.detach(|| fuzzyq_cli::run(argv))
}

/// Rebuilds a pickled object (the inverse of the classes' `__reduce__`; not for direct use).
#[pyfunction]
#[pyo3(name = "_restore")]
fn restore(py: Python<'_>, kind: &str, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
    errors::guard(py, || match kind {
        "grid" => model::Grid::restore(py, data),
        "pointmass" => model::PointMass::restore(py, data),
        "khepera" => khepera::Khepera::restore(py, data),
        "solution" => solution::Solution::restore(py, data),
        "policy" => policy::Policy::restore(py, data),
        other => Err(errors::error(
            py,
            errors::Kind::Input,
            format!("_restore: unknown kind {other:?} (a pickle of another fuzzyq version?)"),
        )),
    })
}
