//! Sharded sweeps from Python: [`SlabProblem`] answers one pass of the block backup for a
//! range of output slabs from its halo (numpy in and out, the GIL released), and
//! [`train_sharded`] drives a training run whose passes a Python backend (the Ray one of
//! `fuzzyq.distributed`) assembles from such answers. The driver is the solver's own
//! ([`fuzzyq_sim::train::train_on`]): the stopping rule, extrapolation and error bound are
//! not repeated here.

use std::borrow::Cow;
use std::ops::{ControlFlow, Range};
use std::path::PathBuf;

use fuzzyq_core::Real;
use fuzzyq_core::solver::{Buf, DiffStats, SolveError, Sweeps};
use fuzzyq_sim::SimError;
use fuzzyq_sim::io::checkpoint::{Checkpoint, RunState};
use fuzzyq_sim::io::config::TrainConfig;
use fuzzyq_sim::slabs;
use numpy::{Element, PyArray1, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::arg;
use crate::errors::{Kind, config_error, error, guard, sim_error, solve_error};
use crate::solution::Solution;

/// The block operator of a training configuration (TOML text, as `fuzzyq config` writes
/// it), for computing sweeps in shards: each method computes one pass for the output slabs
/// `start..stop` from `halo` (the input slabs `input_slabs(start, stop)` returns, or more,
/// increasing) and the values of those slabs one after another, in the operator's internal
/// order and the configured precision (`dtype`). Every process that builds it from the same
/// configuration computes the same bits.
#[pyclass(module = "fuzzyq", frozen)]
pub(crate) struct SlabProblem {
    inner: slabs::SlabProblem,
}

/// Runs `$body` with `$op` the problem's operator in its precision and `$t` its value type.
macro_rules! with_op {
    ($self:expr, |$op:ident: $t:ident| $body:expr) => {
        match $self.inner.precision() {
            fuzzyq_core::solver::Precision::F32 => {
                type $t = f32;
                $self.inner.with_f32(|$op| $body).expect("f32 problem")
            }
            fuzzyq_core::solver::Precision::F64 => {
                type $t = f64;
                $self.inner.with_f64(|$op| $body).expect("f64 problem")
            }
        }
    };
}

/// The range `start..stop` of slabs.
fn range(start: usize, stop: usize) -> Range<usize> {
    start..stop
}

/// `a` as a slice of `T`, or a typed error naming `what` and the dtype expected.
fn values<'py, T: Element>(
    py: Python<'py>,
    a: &Bound<'py, PyAny>,
    what: &str,
) -> PyResult<PyReadonlyArray1<'py, T>> {
    a.extract::<PyReadonlyArray1<'py, T>>().map_err(|_| {
        error(
            py,
            Kind::InputType,
            format!(
                "{what}: expected a one-dimensional numpy array of {}",
                std::any::type_name::<T>()
            ),
        )
    })
}

/// The pass `f` on slices, GIL released, into a new array of `n` values.
fn pass<U: Element + Copy + Default + Send>(
    py: Python<'_>,
    n: usize,
    f: impl FnOnce(&mut [U]) -> Result<(), SolveError> + Send,
) -> PyResult<Py<PyAny>> {
    let mut out = vec![U::default(); n];
    crate::pool::detach(py, || f(&mut out)).map_err(|e| solve_error(py, &e))?;
    Ok(PyArray1::from_vec(py, out).into_any().unbind())
}

impl SlabProblem {
    /// The cores of the slabs `r`.
    fn cores(&self, r: &Range<usize>) -> usize {
        r.len() * self.inner.layout().slab_len
    }
}

#[pymethods]
impl SlabProblem {
    #[new]
    fn new(py: Python<'_>, #[pyo3(from_py_with = arg)] config: &str) -> PyResult<Self> {
        guard(py, || {
            let config = TrainConfig::from_toml(config).map_err(|e| config_error(py, &e))?;
            let inner = crate::pool::detach(py, || slabs::SlabProblem::new(&config))
                .map_err(|e| sim_error(py, &e))?;
            Ok(Self { inner })
        })
    }

    /// Slabs of `V` (the first contracted block's cores).
    #[getter]
    fn n_slabs(&self) -> usize {
        self.inner.layout().n_slabs
    }

    /// Cores per slab.
    #[getter]
    fn slab_len(&self) -> usize {
        self.inner.layout().slab_len
    }

    /// The value type: `"float32"` or `"float64"`.
    #[getter]
    fn dtype(&self) -> &'static str {
        match self.inner.precision() {
            fuzzyq_core::solver::Precision::F32 => "float32",
            fuzzyq_core::solver::Precision::F64 => "float64",
        }
    }

    /// The input slabs the output slabs `start..stop` read (increasing, each once).
    fn input_slabs<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
    ) -> PyResult<Bound<'py, PyArray1<u32>>> {
        guard(py, || {
            let halo = self
                .inner
                .input_slabs(range(start, stop))
                .map_err(|e| solve_error(py, &e))?;
            Ok(PyArray1::from_vec(py, halo))
        })
    }

    /// The backup `max_u (rho + gamma P V)` of the output slabs' cores.
    fn backup<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
        halo: PyReadonlyArray1<'py, u32>,
        v_halo: &Bound<'py, PyAny>,
    ) -> PyResult<Py<PyAny>> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let v = values::<T>(py, v_halo, "v_halo")?;
                let (h, v) = (halo.as_slice()?, v.as_slice()?);
                let n = self.cores(&r);
                pass::<T>(py, n, |o| op.apply_slabs(r.clone(), h, v, o))
            })
        })
    }

    /// [`backup`](Self::backup) and each core's greedy joint action: `(values, actions)`.
    fn backup_greedy<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
        halo: PyReadonlyArray1<'py, u32>,
        v_halo: &Bound<'py, PyAny>,
    ) -> PyResult<(Py<PyAny>, Py<PyAny>)> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let v = values::<T>(py, v_halo, "v_halo")?;
                let (h, v) = (halo.as_slice()?, v.as_slice()?);
                let n = self.cores(&r);
                let (mut out, mut acts) = (vec![T::ZERO; n], vec![0u32; n]);
                crate::pool::detach(py, || {
                    op.backup_greedy_slabs(r.clone(), h, v, &mut out, &mut acts)
                })
                .map_err(|e| solve_error(py, &e))?;
                Ok((
                    PyArray1::from_vec(py, out).into_any().unbind(),
                    PyArray1::from_vec(py, acts).into_any().unbind(),
                ))
            })
        })
    }

    /// The backup of `V = 0` (`max_u rho`) on the output slabs' cores.
    fn rewards<'py>(&self, py: Python<'py>, start: usize, stop: usize) -> PyResult<Py<PyAny>> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let n = self.cores(&r);
                pass::<T>(py, n, |o| op.reward_slabs(r.clone(), o))
            })
        })
    }

    /// One evaluation sweep of the output slabs' cores under `policy` (their joint actions).
    fn evaluate<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
        halo: PyReadonlyArray1<'py, u32>,
        v_halo: &Bound<'py, PyAny>,
        policy: PyReadonlyArray1<'py, u32>,
    ) -> PyResult<Py<PyAny>> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let v = values::<T>(py, v_halo, "v_halo")?;
                let (h, v, p) = (halo.as_slice()?, v.as_slice()?, policy.as_slice()?);
                let n = self.cores(&r);
                pass::<T>(py, n, |o| op.evaluate_slabs(r.clone(), h, v, p, o))
            })
        })
    }

    /// The greedy joint actions of the output slabs' cores.
    fn greedy<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
        halo: PyReadonlyArray1<'py, u32>,
        v_halo: &Bound<'py, PyAny>,
    ) -> PyResult<Py<PyAny>> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let v = values::<T>(py, v_halo, "v_halo")?;
                let (h, v) = (halo.as_slice()?, v.as_slice()?);
                let n = self.cores(&r);
                pass::<u32>(py, n, |o| op.greedy_slabs(r.clone(), h, v, o))
            })
        })
    }

    /// `gamma max |P (a - b)|` over the output slabs' cores, from the halos of two value
    /// buffers: the exact change of theta the stopping rule tests.
    fn abs_max<'py>(
        &self,
        py: Python<'py>,
        start: usize,
        stop: usize,
        halo: PyReadonlyArray1<'py, u32>,
        a_halo: &Bound<'py, PyAny>,
        b_halo: &Bound<'py, PyAny>,
    ) -> PyResult<f64> {
        guard(py, || {
            let r = range(start, stop);
            with_op!(self, |op: T| {
                let a = values::<T>(py, a_halo, "a_halo")?;
                let b = values::<T>(py, b_halo, "b_halo")?;
                let (h, a, b) = (halo.as_slice()?, a.as_slice()?, b.as_slice()?);
                if a.len() != b.len() {
                    return Err(error(
                        py,
                        Kind::Input,
                        "abs_max: a_halo and b_halo differ in length",
                    ));
                }
                crate::pool::detach(py, || {
                    let dv: Vec<T> = a.iter().zip(b).map(|(&x, &y)| x - y).collect();
                    op.abs_max_slabs(r.clone(), h, &dv)
                })
                .map(|m| m.to_f64())
                .map_err(|e| solve_error(py, &e))
            })
        })
    }

    /// `(max |a - b + shift|, min (a - b), max (a - b))` in float64: the change of a sweep
    /// on these cores (maxima and minima, so shards combine exactly).
    fn diff_stats<'py>(
        &self,
        py: Python<'py>,
        a: &Bound<'py, PyAny>,
        b: &Bound<'py, PyAny>,
        shift: f64,
    ) -> PyResult<(f64, f64, f64)> {
        guard(py, || {
            with_op!(self, |_op: T| {
                let (a, b) = (values::<T>(py, a, "a")?, values::<T>(py, b, "b")?);
                let (a, b) = (a.as_slice()?, b.as_slice()?);
                if a.len() != b.len() {
                    return Err(error(
                        py,
                        Kind::Input,
                        "diff_stats: a and b differ in length",
                    ));
                }
                let d = crate::pool::detach(py, || {
                    fuzzyq_core::solver::diff_stats(a, b, T::from_f64(shift))
                });
                Ok((d.change, d.lo, d.hi))
            })
        })
    }

    /// A copy of `v` with `shift` added to every value (in the value type).
    fn shifted<'py>(
        &self,
        py: Python<'py>,
        v: &Bound<'py, PyAny>,
        shift: f64,
    ) -> PyResult<Py<PyAny>> {
        guard(py, || {
            with_op!(self, |_op: T| {
                let v = values::<T>(py, v, "v")?;
                let mut out = v.as_slice()?.to_vec();
                crate::pool::detach(py, || {
                    fuzzyq_core::solver::shift(&mut out, T::from_f64(shift))
                });
                Ok(PyArray1::from_vec(py, out).into_any().unbind())
            })
        })
    }

    fn __repr__(&self) -> String {
        let l = self.inner.layout();
        format!(
            "SlabProblem(n_slabs={}, slab_len={}, dtype={})",
            l.n_slabs,
            l.slab_len,
            self.dtype()
        )
    }
}

/// A pass failed in the solver or in the Python backend.
enum ShardError {
    Sim(SimError),
    Py(PyErr),
}

impl From<SimError> for ShardError {
    fn from(e: SimError) -> Self {
        Self::Sim(e)
    }
}

impl From<SolveError> for ShardError {
    fn from(e: SolveError) -> Self {
        Self::Sim(e.into())
    }
}

impl From<PyErr> for ShardError {
    fn from(e: PyErr) -> Self {
        Self::Py(e)
    }
}

/// A Python object answering the passes by buffer number (0, 1, 2), as
/// `fuzzyq.distributed`'s backend does.
struct PyBackend<'py> {
    obj: Bound<'py, PyAny>,
}

impl<'py> PyBackend<'py> {
    fn call(
        &self,
        name: &str,
        args: impl pyo3::call::PyCallArgs<'py>,
    ) -> Result<Bound<'py, PyAny>, ShardError> {
        Ok(self.obj.call_method1(name, args)?)
    }
}

impl<T: Real + Element> Sweeps<T> for PyBackend<'_> {
    type Error = ShardError;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), ShardError> {
        self.call("backup", (v.0, out.0)).map(drop)
    }

    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), ShardError> {
        self.call("backup_greedy", (v.0, out.0)).map(drop)
    }

    fn rewards(&mut self, out: Buf) -> Result<(), ShardError> {
        self.call("rewards", (out.0,)).map(drop)
    }

    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), ShardError> {
        self.call("evaluate", (v.0, out.0)).map(drop)
    }

    fn sweep_async(&mut self, _: Buf) -> Result<f64, ShardError> {
        // Refused with the configuration (`slabs::check_shardable`) before any pass.
        Err(SolveError::Slabs {
            reason: "asynchronous sweeps cannot be sharded",
        }
        .into())
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: T) -> Result<DiffStats, ShardError> {
        let (change, lo, hi) = self
            .call("diff_stats", (a.0, b.0, s.to_f64()))?
            .extract::<(f64, f64, f64)>()?;
        Ok(DiffStats { change, lo, hi })
    }

    fn shift(&mut self, v: Buf, s: T) -> Result<(), ShardError> {
        self.call("shift", (v.0, s.to_f64())).map(drop)
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, ShardError> {
        Ok(self.call("exact_delta", (a.0, b.0))?.extract::<f64>()?)
    }

    fn greedy(&mut self, v: Buf) -> Result<(), ShardError> {
        self.call("greedy", (v.0,)).map(drop)
    }

    fn load(&mut self, v: Buf, values: &[T]) -> Result<(), ShardError> {
        let a = PyArray1::from_slice(self.obj.py(), values);
        self.call("load", (v.0, a)).map(drop)
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), ShardError> {
        let a = PyArray1::from_slice(self.obj.py(), policy);
        self.call("load_policy", (a,)).map(drop)
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [T]>, ShardError> {
        let a = self.call("values", (v.0,))?;
        let a = a.extract::<PyReadonlyArray1<'_, T>>()?;
        Ok(Cow::Owned(a.as_slice().map_err(PyErr::from)?.to_vec()))
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, ShardError> {
        let a = self.call("policy", ())?;
        let a = a.extract::<PyReadonlyArray1<'_, u32>>()?;
        Ok(Cow::Owned(a.as_slice().map_err(PyErr::from)?.to_vec()))
    }
}

/// Trains the configuration `config` (TOML text) with every pass over `V` run by `backend`
/// (an object with the methods `backup`, `backup_greedy`, `rewards`, `evaluate`,
/// `diff_stats`, `shift`, `exact_delta`, `greedy`, `load`, `load_policy`, `values` and
/// `policy`, on value buffers numbered 0, 1 and 2 in the internal order of
/// [`SlabProblem`]), and returns the `Solution` `fuzzyq train --config` would write.
///
/// With `checkpoint`, the run's state is written there (atomically, the format of
/// `fuzzyq train --checkpoint`) after every sweep but the last; `resume` continues from
/// such a file. `on_sweep(record)` sees each sweep (a dict: `sweep`, `delta`, `delta_v`,
/// `evaluation`, `seconds`, `bound`); returning `False` stops the run with a `SolverError`.
#[pyfunction]
#[pyo3(signature = (config, backend, *, resume = None, checkpoint = None, on_sweep = None))]
pub(crate) fn train_sharded(
    py: Python<'_>,
    #[pyo3(from_py_with = arg)] config: &str,
    backend: Bound<'_, PyAny>,
    #[pyo3(from_py_with = arg)] resume: Option<PathBuf>,
    #[pyo3(from_py_with = arg)] checkpoint: Option<PathBuf>,
    on_sweep: Option<Bound<'_, PyAny>>,
) -> PyResult<Solution> {
    guard(py, || {
        let config = TrainConfig::from_toml(config).map_err(|e| config_error(py, &e))?;
        slabs::check_shardable(&config).map_err(|e| config_error(py, &e))?;
        let settings = config.to_toml();
        let state = match &resume {
            None => None,
            Some(path) => {
                let c = crate::pool::detach(py, || {
                    let c = Checkpoint::load(path)?;
                    c.check_settings(&settings, path)?;
                    Ok(c)
                })
                .map_err(|e: fuzzyq_sim::io::checkpoint::CheckpointError| {
                    error(py, Kind::Input, format!("resume: {e}"))
                })?;
                match c.state {
                    RunState::Fqi(s) => Some(s),
                    RunState::Fql(_) => {
                        return Err(error(
                            py,
                            Kind::Input,
                            format!(
                                "resume: {} continues a fuzzy Q-learning run, not fuzzy \
                                 Q-iteration",
                                path.display()
                            ),
                        ));
                    }
                }
            }
        };
        let mut backend = PyBackend { obj: backend };
        let mut failure: Option<PyErr> = None;
        let observer =
            |p: &fuzzyq_core::solver::Progress,
             s: Option<&fuzzyq_sim::io::checkpoint::FqiState<'_>>| {
                let step = || -> PyResult<ControlFlow<()>> {
                    if let (Some(path), Some(s)) = (&checkpoint, s) {
                        let c = Checkpoint {
                            settings: Cow::Borrowed(&settings),
                            state: RunState::Fqi(s.borrowed()),
                        };
                        c.save(path)
                            .map_err(|e| error(py, Kind::PolicyFile, format!("checkpoint: {e}")))?;
                    }
                    let Some(f) = &on_sweep else {
                        return Ok(ControlFlow::Continue(()));
                    };
                    let r = &p.record;
                    let d = PyDict::new(py);
                    d.set_item("sweep", r.sweep)?;
                    d.set_item("delta", r.delta.value().unwrap_or(r.delta.upper))?;
                    d.set_item("delta_v", r.delta_v)?;
                    d.set_item("evaluation", r.evaluation)?;
                    d.set_item("seconds", r.seconds)?;
                    d.set_item("bound", p.bound)?;
                    crate::solve::set_run_choices(&d, p)?;
                    let go = f.call1((d,))?;
                    Ok(if go.is(pyo3::types::PyBool::new(py, false)) {
                        ControlFlow::Break(())
                    } else {
                        ControlFlow::Continue(())
                    })
                };
                step().unwrap_or_else(|e| {
                    failure = Some(e);
                    ControlFlow::Break(())
                })
            };
        let result = fuzzyq_sim::train::train_on(
            &config,
            &mut backend,
            state,
            checkpoint.is_some(),
            observer,
        );
        if let Some(e) = failure {
            return Err(e);
        }
        match result {
            Ok(artifact) => Solution::from_artifact(py, artifact, None),
            Err(ShardError::Py(e)) => Err(e),
            Err(ShardError::Sim(e)) => Err(sim_error(py, &e)),
        }
    })
}
