//! `solve`, `load`, `Solution` and `Policy`.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use fuzzyq_core::solver::{self, Kernel, Progress, SolveError, TabulatedModel};
use fuzzyq_core::{Backup, Real};
use fuzzyq_sim::PolicyArtifact;
use fuzzyq_sim::io::config::{
    Backup as BackupSetting, EnvConfig, GridConfig, KernelChoice, Precision, SolverSettings, Sweep,
    TrainConfig,
};
use fuzzyq_sim::io::policy_file::{TrainSummary, Values};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::convert::{finite_vector, one_or_batch};
use crate::engine::{Engine, Owned, PointMass32, PointMass64, Table32, Table64};
use crate::errors::{Kind, error, eval_error, policy_file_error, sim_error, solve_error};
use crate::model::{CallableModel, Grid, PointMass};

/// Where a solution came from: what a policy needs besides `V`.
enum Source {
    /// A built-in point-mass model; the configuration can be saved.
    PointMass {
        model: Arc<fuzzyq_sim::PointMass>,
        config: Box<TrainConfig>,
    },
    /// A tabulated model (from a Python callable), in the solver's precision.
    Table32(Arc<TabulatedModel<f32>>),
    Table64(Arc<TabulatedModel<f64>>),
}

/// The result of [`solve`] or [`load`]: `V`, the greedy actions, the run's record, and
/// policies.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Solution {
    v: Py<PyAny>,
    greedy: Py<PyArray1<u32>>,
    grid: Py<Grid>,
    summary: TrainSummary,
    gamma: f64,
    xi: f64,
    absorbing_goal: bool,
    precision: Precision,
    source: Source,
    engine: OnceLock<Arc<dyn Engine>>,
}

#[allow(clippy::too_many_arguments)] // the solver's settings, as given to `solve`
fn parse_settings(
    py: Python<'_>,
    gamma: f64,
    xi: f64,
    max_sweeps: usize,
    sweep: &str,
    extrapolate: bool,
    absorbing_goal: bool,
    precision: &str,
    backup: &str,
    kernel: Option<&str>,
) -> PyResult<SolverSettings> {
    let bad = |what: &str, allowed: &str, got: &str| {
        error(
            py,
            Kind::Config,
            format!("{what}: expected one of {allowed}, got {got:?}"),
        )
    };
    Ok(SolverSettings {
        gamma,
        xi,
        max_sweeps,
        sweep: match sweep {
            "sync" => Sweep::Sync,
            "async" => Sweep::Async,
            other => return Err(bad("sweep", "\"sync\", \"async\"", other)),
        },
        absorbing_goal,
        backup: match backup {
            "auto" => BackupSetting::Auto,
            "block" => BackupSetting::Block,
            "generic" => BackupSetting::Generic,
            other => return Err(bad("backup", "\"auto\", \"block\", \"generic\"", other)),
        },
        precision: match precision {
            "f32" | "float32" => Precision::F32,
            "f64" | "float64" => Precision::F64,
            other => return Err(bad("precision", "\"f32\", \"f64\"", other)),
        },
        extrapolate,
        kernel: match kernel {
            None => None,
            Some("scalar") => Some(KernelChoice::Scalar),
            Some("avx2") => Some(KernelChoice::Avx2),
            Some("avx512") => Some(KernelChoice::Avx512),
            Some(other) => return Err(bad("kernel", "\"scalar\", \"avx2\", \"avx512\"", other)),
        },
        operator: fuzzyq_sim::io::config::IterationOperator::Values,
    })
}

/// Runs `f` on `threads` threads (a dedicated pool) or on the global pool.
fn with_pool<R: Send>(threads: Option<usize>, f: impl FnOnce() -> R + Send) -> Result<R, String> {
    match threads {
        None => Ok(f()),
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map(|p| p.install(f))
            .map_err(|e| e.to_string()),
    }
}

/// Calls the progress callback (and checks for Ctrl-C) after each sweep; a raised exception
/// stops the solve and is kept to be re-raised.
fn observer<'a>(
    callback: Option<&'a Py<PyAny>>,
    failure: &'a Mutex<Option<PyErr>>,
) -> impl FnMut(&Progress) -> ControlFlow<()> + Send + 'a {
    move |p: &Progress| {
        Python::attach(|py| {
            let result = py.check_signals().and_then(|()| match callback {
                None => Ok(()),
                Some(cb) => {
                    let d = PyDict::new(py);
                    d.set_item("sweep", p.record.sweep)?;
                    d.set_item("delta_lower", p.record.delta.lower)?;
                    d.set_item("delta_upper", p.record.delta.upper)?;
                    d.set_item("extrapolated", p.record.extrapolated)?;
                    d.set_item("seconds", p.record.seconds)?;
                    d.set_item("bound", p.bound)?;
                    d.set_item("xi", p.xi)?;
                    cb.call1(py, (d,)).map(|_| ())
                }
            });
            match result {
                Ok(()) => ControlFlow::Continue(()),
                Err(e) => {
                    *failure.lock().expect("not poisoned") = Some(e);
                    ControlFlow::Break(())
                }
            }
        })
    }
}

/// Solves a model on a grid by fuzzy Q-iteration (the paper's eq 20), with the GIL released.
///
/// `model` is a `PointMass` or a `CallableModel`. `callback(info)` is called after every sweep
/// with a dict (`sweep`, `delta_lower`, `delta_upper`, `extrapolated`, `seconds`, `bound`,
/// `xi`); an exception it raises stops the solve and propagates. Ctrl-C raises
/// `KeyboardInterrupt` at the end of the current sweep.
#[pyfunction]
#[pyo3(signature = (
    model,
    grid,
    *,
    gamma = 0.96,
    xi = 0.05,
    max_sweeps = 1000,
    sweep = "sync",
    extrapolate = true,
    absorbing_goal = false,
    precision = "f32",
    backup = "auto",
    kernel = None,
    threads = None,
    callback = None,
))]
#[allow(clippy::too_many_arguments)] // the solver's settings, as keyword arguments
pub(crate) fn solve(
    py: Python<'_>,
    model: &Bound<'_, PyAny>,
    grid: &Bound<'_, Grid>,
    gamma: f64,
    xi: f64,
    max_sweeps: usize,
    sweep: &str,
    extrapolate: bool,
    absorbing_goal: bool,
    precision: &str,
    backup: &str,
    kernel: Option<&str>,
    threads: Option<usize>,
    callback: Option<Py<PyAny>>,
) -> PyResult<Solution> {
    let settings = parse_settings(
        py,
        gamma,
        xi,
        max_sweeps,
        sweep,
        extrapolate,
        absorbing_goal,
        precision,
        backup,
        kernel,
    )?;
    if threads == Some(0) {
        return Err(error(py, Kind::Config, "threads: must be at least 1"));
    }
    if let Some(cb) = &callback
        && !cb.bind(py).is_callable()
    {
        return Err(error(py, Kind::InputType, "callback: expected a callable"));
    }
    let failure = Mutex::new(None);
    let finish = |py: Python<'_>, e: SolveError| -> PyErr {
        match failure.lock().expect("not poisoned").take() {
            Some(err) => err,
            None => solve_error(py, &e),
        }
    };
    let g = grid.get();

    if let Ok(pm) = model.cast::<PointMass>() {
        let pm = pm.get();
        let config = TrainConfig {
            env: EnvConfig::Pointmass(pm.model.config().clone()),
            grid: GridConfig::explicit(g.inner.cores().to_vec()),
            solver: settings,
        };
        config
            .validate()
            .map_err(|e| crate::errors::config_error(py, &e))?;
        let cb = callback.as_ref();
        let result = py
            .detach(|| {
                with_pool(threads, || {
                    fuzzyq_sim::train::train(&config, observer(cb, &failure))
                })
            })
            .map_err(|e| error(py, Kind::Config, format!("threads: {e}")))?;
        let artifact = match result {
            Ok(a) => a,
            Err(fuzzyq_sim::SimError::Solve(e)) => return Err(finish(py, e)),
            Err(e) => return Err(sim_error(py, &e)),
        };
        return Solution::from_artifact(
            py,
            artifact,
            Some(pm.model.clone()),
            Some(grid.clone().unbind()),
        );
    }

    let Ok(cm) = model.cast::<CallableModel>() else {
        return Err(error(
            py,
            Kind::InputType,
            "model: expected a fuzzyq.PointMass or a fuzzyq.CallableModel",
        ));
    };
    let cm = cm.get();
    let (next, rewards) = cm.tabulate(py, &g.inner)?;
    let config = settings.solver_config();
    let cb = callback.as_ref();
    macro_rules! run {
        ($t:ty, $variant:ident) => {{
            let conv = |v: &[f64]| v.iter().map(|&x| <$t>::from_f64(x)).collect::<Vec<$t>>();
            let actions = cm.actions.iter().map(|(v, d)| (conv(v), *d)).collect();
            let table =
                TabulatedModel::new(g.to_precision::<$t>(), actions, conv(&next), conv(&rewards))
                    .map_err(|e| solve_error(py, &e))?;
            let table = Arc::new(table);
            let grid_t = g.to_precision::<$t>();
            let result = py
                .detach(|| {
                    with_pool(threads, || {
                        solver::solve(&*table, &grid_t, &config, observer(cb, &failure))
                    })
                })
                .map_err(|e| error(py, Kind::Config, format!("threads: {e}")))?;
            let s = result.map_err(|e| finish(py, e))?;
            let summary = TrainSummary::from_solution(&s);
            let v = PyArray1::from_vec(py, s.v).into_any().unbind();
            Solution::assemble(
                py,
                v,
                s.greedy,
                grid.clone().unbind(),
                summary,
                &settings,
                Source::$variant(table),
            )
        }};
    }
    match settings.precision {
        Precision::F32 => run!(f32, Table32),
        Precision::F64 => run!(f64, Table64),
    }
}

/// Reads a policy file written by `fuzzyq train` or `Solution.save`.
#[pyfunction]
pub(crate) fn load(py: Python<'_>, path: PathBuf) -> PyResult<Solution> {
    let artifact = py
        .detach(|| PolicyArtifact::load(&path))
        .map_err(|e| policy_file_error(py, &e))?;
    Solution::from_artifact(py, artifact, None, None)
}

/// The kernel instances this CPU runs, fastest first (`"avx512"`, `"avx2"`, `"scalar"`).
#[pyfunction]
pub(crate) fn available_kernels() -> Vec<&'static str> {
    <Kernel as fuzzyq_core::NamedOption>::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available())
        .map(Kernel::name)
        .collect()
}

impl Solution {
    fn assemble(
        py: Python<'_>,
        v: Py<PyAny>,
        greedy: Vec<u32>,
        grid: Py<Grid>,
        summary: TrainSummary,
        settings: &SolverSettings,
        source: Source,
    ) -> PyResult<Self> {
        Ok(Self {
            v,
            greedy: PyArray1::from_vec(py, greedy).unbind(),
            grid,
            summary,
            gamma: settings.gamma,
            xi: settings.xi,
            absorbing_goal: settings.absorbing_goal,
            precision: settings.precision,
            source,
            engine: OnceLock::new(),
        })
    }

    fn from_artifact(
        py: Python<'_>,
        a: PolicyArtifact,
        model: Option<Arc<fuzzyq_sim::PointMass>>,
        grid: Option<Py<Grid>>,
    ) -> PyResult<Self> {
        let model = match model {
            Some(m) => m,
            None => {
                match fuzzyq_sim::train::build_model(&a.config).map_err(|e| sim_error(py, &e))? {
                    fuzzyq_sim::model::EnvModel::PointMass(m) => Arc::new(m),
                    other => {
                        let e = fuzzyq_sim::SimError::from(fuzzyq_sim::ConfigError::invalid(
                            "env",
                            format!(
                                "{} policies are not available from Python yet; use the fuzzyq CLI",
                                other.name()
                            ),
                        ));
                        return Err(sim_error(py, &e));
                    }
                }
            }
        };
        let grid = match grid {
            Some(g) => g,
            None => {
                let inner = fuzzyq_sim::train::build_grid::<f64>(&a.config)
                    .map_err(|e| sim_error(py, &e))?;
                Py::new(py, Grid::from_inner(inner))?
            }
        };
        let v = match a.values {
            Values::F32(v) => PyArray1::from_vec(py, v).into_any().unbind(),
            Values::F64(v) => PyArray1::from_vec(py, v).into_any().unbind(),
        };
        let settings = a.config.solver.clone();
        Self::assemble(
            py,
            v,
            a.greedy,
            grid,
            a.summary,
            &settings,
            Source::PointMass {
                model,
                config: Box::new(a.config),
            },
        )
    }

    /// The decision engine, built on first use from a copy of `V`.
    fn engine(&self, py: Python<'_>) -> PyResult<Arc<dyn Engine>> {
        if let Some(e) = self.engine.get() {
            return Ok(e.clone());
        }
        let greedy: Vec<u32> = self.greedy.bind(py).readonly().as_slice()?.to_vec();
        let grid = self.grid.get();
        let v = self.v.bind(py);
        macro_rules! owned {
            ($t:ty, $model:expr) => {{
                let v: Vec<$t> = v.cast::<PyArray1<$t>>()?.readonly().as_slice()?.to_vec();
                Owned {
                    model: $model,
                    grid: grid.to_precision::<$t>(),
                    v,
                    greedy,
                }
            }};
        }
        let backup32 = Backup {
            gamma: self.gamma as f32,
            absorbing_goal: self.absorbing_goal,
        };
        let backup64 = Backup {
            gamma: self.gamma,
            absorbing_goal: self.absorbing_goal,
        };
        let built: Result<Arc<dyn Engine>, SolveError> = match (&self.source, self.precision) {
            (Source::PointMass { model, .. }, Precision::F32) => {
                let o = owned!(f32, model.clone());
                py.detach(|| {
                    PointMass32::build(o, backup32).map(|e| Arc::new(e) as Arc<dyn Engine>)
                })
            }
            (Source::PointMass { model, .. }, Precision::F64) => {
                let o = owned!(f64, model.clone());
                py.detach(|| {
                    PointMass64::build(o, backup64).map(|e| Arc::new(e) as Arc<dyn Engine>)
                })
            }
            (Source::Table32(t), _) => {
                let o = owned!(f32, t.clone());
                py.detach(|| Table32::build(o, backup32).map(|e| Arc::new(e) as Arc<dyn Engine>))
            }
            (Source::Table64(t), _) => {
                let o = owned!(f64, t.clone());
                py.detach(|| Table64::build(o, backup64).map(|e| Arc::new(e) as Arc<dyn Engine>))
            }
        };
        let engine = built.map_err(|e| solve_error(py, &e))?;
        Ok(self.engine.get_or_init(|| engine).clone())
    }
}

#[pymethods]
impl Solution {
    /// `V[d] = max_u theta[d, u]` per core (row-major grid order), in the solver's precision.
    #[getter(V)]
    fn v(&self, py: Python<'_>) -> Py<PyAny> {
        self.v.clone_ref(py)
    }

    /// The lowest-index greedy joint action of every core.
    #[getter]
    fn greedy(&self, py: Python<'_>) -> Py<PyArray1<u32>> {
        self.greedy.clone_ref(py)
    }

    /// The grid.
    #[getter]
    fn grid(&self, py: Python<'_>) -> Py<Grid> {
        self.grid.clone_ref(py)
    }

    /// Sweeps performed.
    #[getter]
    fn sweeps(&self) -> usize {
        self.summary.sweeps
    }

    /// Whether the stopping rule was met.
    #[getter]
    fn converged(&self) -> bool {
        self.summary.converged
    }

    /// The exact change `||theta_K - theta_{K-1}||_inf` of the last sweep.
    #[getter]
    fn final_delta(&self) -> f64 {
        self.summary.final_delta
    }

    /// `gamma / (1 - gamma) * final_delta`: a bound on the distance to the fixed point.
    #[getter]
    fn error_bound(&self) -> f64 {
        self.gamma / (1.0 - self.gamma) * self.summary.final_delta
    }

    /// `(lower, upper)` bounds of every sweep's change, shape `(sweeps, 2)`.
    #[getter]
    fn deltas<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let flat: Vec<f64> = self
            .summary
            .deltas
            .iter()
            .flat_map(|&(a, b)| [a, b])
            .collect();
        PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((self.summary.deltas.len(), 2), flat).expect("pairs"),
        )
    }

    /// Wall-clock seconds of the solve.
    #[getter]
    fn seconds(&self) -> f64 {
        self.summary.seconds
    }

    /// The kernel instance used (`"avx512"`, `"avx2"`, `"scalar"` or `"generic"`).
    #[getter]
    fn kernel(&self) -> &str {
        &self.summary.kernel
    }

    /// The discount factor.
    #[getter]
    fn gamma(&self) -> f64 {
        self.gamma
    }

    /// The stopping threshold.
    #[getter]
    fn xi(&self) -> f64 {
        self.xi
    }

    /// `theta[d, u]` for every core and joint action, shape `(n_cores, n_joint_actions)`.
    /// Only for problems with at most 5e7 Q-values (the paper's has 2.56e9).
    fn theta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let engine = self.engine(py)?;
        let (n, m) = (engine.n_cores(), engine.n_joint());
        if n.saturating_mul(m) > 50_000_000 {
            return Err(error(
                py,
                Kind::Input,
                format!(
                    "theta: {n} cores x {m} joint actions is more than 5e7 Q-values; use V and policies"
                ),
            ));
        }
        let t = py
            .detach(|| engine.theta())
            .map_err(|e| solve_error(py, &e))?;
        Ok(PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((n, m), t).expect("n x m"),
        ))
    }

    /// `V` interpolated at state `x`.
    fn value(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        let engine = self.engine(py)?;
        let x = finite_vector(x, "x", Some(engine.state_dim()))?;
        engine.value(&x).map_err(|e| eval_error(py, &e))
    }

    /// A policy: `"greedy"` (eq 7, the maximiser of `Q(x, .)`) or `"interpolated"` (eq 22).
    #[pyo3(signature = (kind = "greedy"))]
    fn policy(&self, py: Python<'_>, kind: &str) -> PyResult<Policy> {
        let greedy = match kind {
            "greedy" => true,
            "interpolated" => false,
            other => {
                return Err(error(
                    py,
                    Kind::Config,
                    format!("kind: expected \"greedy\" or \"interpolated\", got {other:?}"),
                ));
            }
        };
        Ok(Policy {
            engine: self.engine(py)?,
            greedy,
        })
    }

    /// Writes the policy file (the format `fuzzyq rollout` reads), atomically. Only solutions
    /// of built-in models can be saved.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let Source::PointMass { config, .. } = &self.source else {
            return Err(error(
                py,
                Kind::Config,
                "save: only solutions of built-in models (PointMass) can be written to a policy file",
            ));
        };
        let v = self.v.bind(py);
        let values = match self.precision {
            Precision::F32 => {
                Values::F32(v.cast::<PyArray1<f32>>()?.readonly().as_slice()?.to_vec())
            }
            Precision::F64 => {
                Values::F64(v.cast::<PyArray1<f64>>()?.readonly().as_slice()?.to_vec())
            }
        };
        let artifact = PolicyArtifact {
            config: (**config).clone(),
            values,
            greedy: self.greedy.bind(py).readonly().as_slice()?.to_vec(),
            summary: self.summary.clone(),
        };
        artifact
            .check()
            .map_err(|e| error(py, Kind::Input, format!("save: {e}")))?;
        py.detach(|| artifact.save(&path))
            .map_err(|e| policy_file_error(py, &e))
    }

    fn __repr__(&self) -> String {
        format!(
            "Solution(sweeps={}, converged={}, final_delta={:.4}, seconds={:.2}, kernel={:?})",
            self.summary.sweeps,
            if self.summary.converged {
                "True"
            } else {
                "False"
            },
            self.summary.final_delta,
            self.summary.seconds,
            self.summary.kernel
        )
    }
}

/// A policy derived from a solution.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Policy {
    engine: Arc<dyn Engine>,
    greedy: bool,
}

impl Policy {
    fn require_greedy(&self, py: Python<'_>, what: &str) -> PyResult<()> {
        if self.greedy {
            Ok(())
        } else {
            Err(error(
                py,
                Kind::Config,
                format!("{what}: only the greedy policy has discrete actions"),
            ))
        }
    }

    fn greedy_index(&self, py: Python<'_>, x: &[f64]) -> PyResult<usize> {
        let mut q = vec![0.0; self.engine.n_joint()];
        self.engine
            .q_values(x, &mut q)
            .map_err(|e| solve_error(py, &e))?;
        Ok(fuzzyq_core::q::argmax(&q).unwrap_or(0))
    }

    fn act_into(&self, py: Python<'_>, x: &[f64], out: &mut [f64]) -> PyResult<()> {
        if self.greedy {
            let u = self.greedy_index(py, x)?;
            self.engine.joint_vector(u, out);
            Ok(())
        } else {
            self.engine
                .interpolated(x, out)
                .map_err(|e| eval_error(py, &e))
        }
    }
}

#[pymethods]
impl Policy {
    /// `"greedy"` or `"interpolated"`.
    #[getter]
    fn kind(&self) -> &'static str {
        if self.greedy {
            "greedy"
        } else {
            "interpolated"
        }
    }

    /// Length of the state vector.
    #[getter]
    fn state_dim(&self) -> usize {
        self.engine.state_dim()
    }

    /// Length of the joint action vector.
    #[getter]
    fn action_dim(&self) -> usize {
        self.engine.action_dim()
    }

    /// Number of joint actions.
    #[getter]
    fn n_joint_actions(&self) -> usize {
        self.engine.n_joint()
    }

    /// Number of agents.
    #[getter]
    fn n_agents(&self) -> usize {
        self.engine.n_agents()
    }

    /// The joint action vector at state `x` (the greedy action's, or the interpolated one).
    fn act<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = finite_vector(x, "x", Some(self.engine.state_dim()))?;
        let mut u = vec![0.0; self.engine.action_dim()];
        self.act_into(py, &x, &mut u)?;
        Ok(PyArray1::from_vec(py, u))
    }

    /// The joint action vectors at a batch of states, shape `(n, state_dim)` -> `(n, action_dim)`.
    fn act_batch<'py>(
        &self,
        py: Python<'py>,
        states: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (e, a) = (self.engine.state_dim(), self.engine.action_dim());
        let (xs, b) = one_or_batch(states, "states", e)?;
        let n = b.unwrap_or(1);
        let mut out = vec![0.0; n * a];
        for i in 0..n {
            self.act_into(py, &xs[i * e..(i + 1) * e], &mut out[i * a..(i + 1) * a])?;
        }
        Ok(PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((n, a), out).expect("n x a"),
        ))
    }

    /// The greedy joint action index at `x` (lowest index on ties).
    fn act_index(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<usize> {
        self.require_greedy(py, "act_index")?;
        let x = finite_vector(x, "x", Some(self.engine.state_dim()))?;
        self.greedy_index(py, &x)
    }

    /// The greedy action of each agent at `x` (indices into each agent's action set).
    fn agent_actions(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<Vec<usize>> {
        self.require_greedy(py, "agent_actions")?;
        let x = finite_vector(x, "x", Some(self.engine.state_dim()))?;
        let u = self.greedy_index(py, &x)?;
        Ok(self.engine.agent_indices(u))
    }

    /// `Q(x, .)`, one value per joint action.
    fn q_values<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let x = finite_vector(x, "x", Some(self.engine.state_dim()))?;
        let mut q = vec![0.0; self.engine.n_joint()];
        self.engine
            .q_values(&x, &mut q)
            .map_err(|e| solve_error(py, &e))?;
        Ok(PyArray1::from_vec(py, q))
    }

    fn __repr__(&self) -> String {
        format!(
            "Policy(kind={:?}, state_dim={}, action_dim={})",
            self.kind(),
            self.engine.state_dim(),
            self.engine.action_dim()
        )
    }
}
