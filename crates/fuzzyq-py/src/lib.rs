//! Python bindings of fuzzyq: the `fuzzyq._fuzzyq` extension module.
//!
//! A thin layer: arguments are converted and checked here (shapes and dtypes named in the
//! errors), the work runs in the Rust crates with the GIL released, and results come back as
//! numpy arrays that own the solver's buffers (no copies). The Python package `fuzzyq`
//! (`python/fuzzyq`) re-exports this module and adds the Gymnasium/PettingZoo environments.

mod convert;
mod engine;
mod errors;
mod model;
mod solve;

use pyo3::prelude::*;

/// The extension module.
#[pymodule]
fn _fuzzyq(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<model::Grid>()?;
    m.add_class::<model::PointMass>()?;
    m.add_class::<model::CallableModel>()?;
    m.add_class::<solve::Solution>()?;
    m.add_class::<solve::Policy>()?;
    m.add_function(wrap_pyfunction!(solve::solve, m)?)?;
    m.add_function(wrap_pyfunction!(solve::load, m)?)?;
    m.add_function(wrap_pyfunction!(solve::available_kernels, m)?)?;
    Ok(())
}
