//! `Solution`: what `solve` and `load` return (`V`, the greedy actions, the run's record,
//! policies), with its source (a built-in model's configuration, a `CallableModel` or a
//! learned `Task`), pickling and saving.

use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{CoarseStart, Precision, TabulatedModel};
use fuzzyq_sim::io::config::{SolverSettings, TrainConfig};
use fuzzyq_sim::io::policy_file::{
    PolicyArtifact, PolicyFile, TabulatedArtifact, TrainSummary, Values,
};
use fuzzyq_sim::learn::samples::Transitions;
use fuzzyq_sim::memory::Limit;
use fuzzyq_sim::model::learned::BlockTables;
use fuzzyq_sim::run::policy::{FqiPolicy, Policy as SimPolicy};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::callable::CallableModel;
use crate::convert::{arg, finite_vector};
use crate::errors::{Kind, error, guard, policy_file_error, sim_error};
use crate::model::Grid;
use crate::policy::Policy;
use crate::task::Task;

use crate::convert::{parse_option, transitions_dict, transitions_of};

/// What a solution's policy needs besides `V` and the greedy actions.
pub(crate) enum Source {
    /// A built-in model: the training configuration (model, grid, settings) and, for a
    /// policy of a learned model, its transition tables; can be saved.
    Env(Box<TrainConfig>, Option<Box<BlockTables>>),
    /// A `CallableModel`, with its table in the solver's precision (tabulated again on first
    /// use when the solution was unpickled).
    Callable(Py<CallableModel>, OnceLock<Table>),
    /// A `Task` learned from transitions: the task, the transitions, the estimation's report
    /// and the learned table in the solver's precision (learned again on first use when the
    /// solution was unpickled).
    Learned {
        task: Py<Task>,
        data: Arc<Transitions>,
        report: serde_json::Value,
        table: OnceLock<Table>,
    },
}

/// A tabulated model in the solver's precision.
#[derive(Clone)]
pub(crate) enum Table {
    F32(Arc<TabulatedModel<f32>>),
    F64(Arc<TabulatedModel<f64>>),
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
    /// The sim crate's policy, built (and prepared) on first use.
    policy: OnceLock<Arc<SimPolicy>>,
    /// Whether the callback stopped the solve.
    pub(crate) stopped: bool,
}

impl Solution {
    pub(crate) fn assemble(
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
            policy: OnceLock::new(),
            stopped: false,
        })
    }

    pub(crate) fn from_artifact(
        py: Python<'_>,
        a: PolicyArtifact,
        grid: Option<Py<Grid>>,
    ) -> PyResult<Self> {
        let grid = match grid {
            Some(g) => g,
            None => {
                let inner = a.config.grid::<f64>().map_err(|e| sim_error(py, &e))?;
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
            Source::Env(Box::new(a.config), a.learned),
        )
    }

    /// A copy of `V` in the solver's precision.
    fn values(&self, py: Python<'_>) -> PyResult<Values> {
        let v = self.v.bind(py);
        Ok(match self.precision {
            Precision::F32 => {
                Values::F32(v.cast::<PyArray1<f32>>()?.readonly().as_slice()?.to_vec())
            }
            Precision::F64 => {
                Values::F64(v.cast::<PyArray1<f64>>()?.readonly().as_slice()?.to_vec())
            }
        })
    }

    /// The sim crate's policy of this solution, built and prepared (with the GIL released) on
    /// first use from a copy of `V`.
    pub(crate) fn sim_policy(&self, py: Python<'_>) -> PyResult<Arc<SimPolicy>> {
        if let Some(p) = self.policy.get() {
            return Ok(p.clone());
        }
        let greedy: Vec<u32> = self.greedy.bind(py).readonly().as_slice()?.to_vec();
        let values = self.values(py)?;
        let (gamma, absorbing) = (self.gamma, self.absorbing_goal);
        let prepared = |p: FqiPolicy| p.prepare().map(|()| p);
        let built = match (&self.source, values) {
            (Source::Env(config, learned), values) => {
                let config = (**config).clone();
                let learned = learned.as_deref().cloned();
                crate::pool::detach(py, || {
                    FqiPolicy::with_model(config, learned, values, greedy).and_then(prepared)
                })
            }
            (_, values) => {
                let table = self.table(py)?;
                match (table, values) {
                    (Table::F32(t), Values::F32(v)) => {
                        let grid = self.grid.get().to_precision::<f32>(py)?;
                        crate::pool::detach(py, || {
                            FqiPolicy::tabulated(t, grid, v, greedy, gamma, absorbing)
                                .and_then(prepared)
                        })
                    }
                    (Table::F64(t), Values::F64(v)) => {
                        let grid = self.grid.get().to_precision::<f64>(py)?;
                        crate::pool::detach(py, || {
                            FqiPolicy::tabulated(t, grid, v, greedy, gamma, absorbing)
                                .and_then(prepared)
                        })
                    }
                    _ => unreachable!("a tabulated model is solved in the precision of its table"),
                }
            }
        };
        let policy = built.map_err(|e| sim_error(py, &e))?;
        Ok(self
            .policy
            .get_or_init(|| Arc::new(SimPolicy::Fqi(policy)))
            .clone())
    }
}

impl Solution {
    /// The table of a solution of a model known only at the cores: kept from the solve, or
    /// computed again (a `CallableModel` tabulated, a `Task` learned) after unpickling.
    fn table(&self, py: Python<'_>) -> PyResult<Table> {
        let (cell, grid) = match &self.source {
            Source::Env(..) => unreachable!("a built-in model's solution has no table"),
            Source::Callable(_, t) | Source::Learned { table: t, .. } => (t, self.grid.get()),
        };
        if let Some(t) = cell.get() {
            return Ok(t.clone());
        }
        let built = match &self.source {
            Source::Callable(model, _) => {
                let limit = Limit::new(None).map_err(|e| sim_error(py, &e))?;
                let tables = model
                    .get()
                    .tabulate(py, &grid.inner, self.precision, &limit)?;
                let actions = &model.get().actions;
                match self.precision {
                    Precision::F32 => Table::F32(Arc::new(tables.model_on(py, grid, actions)?)),
                    Precision::F64 => Table::F64(Arc::new(tables.model_on(py, grid, actions)?)),
                }
            }
            Source::Learned { task, data, .. } => match self.precision {
                Precision::F32 => {
                    let g = grid.to_precision::<f32>(py)?;
                    Table::F32(Arc::new(task.get().learn(py, &grid.inner, g, data)?.model))
                }
                Precision::F64 => {
                    let g = grid.to_precision::<f64>(py)?;
                    Table::F64(Arc::new(task.get().learn(py, &grid.inner, g, data)?.model))
                }
            },
            Source::Env(..) => unreachable!("handled above"),
        };
        Ok(cell.get_or_init(|| built).clone())
    }
}

/// Pickling.
impl Solution {
    /// The policy artifact of a solution of a built-in model (what its file holds).
    fn artifact(&self, py: Python<'_>) -> PyResult<Option<PolicyArtifact>> {
        let Source::Env(config, learned) = &self.source else {
            return Ok(None);
        };
        Ok(Some(PolicyArtifact {
            config: (**config).clone(),
            values: self.values(py)?,
            greedy: self.greedy.bind(py).readonly().as_slice()?.to_vec(),
            summary: self.summary.clone(),
            learned: learned.clone(),
        }))
    }

    /// A solution read from a file of a `CallableModel`'s solution, acting with `model`
    /// (checked to have the file's state length and actions).
    pub(crate) fn from_tabulated(
        py: Python<'_>,
        t: TabulatedArtifact,
        model: &Bound<'_, CallableModel>,
    ) -> PyResult<Self> {
        let m = model.get();
        if t.cores.len() != m.state_dim() || t.actions != m.actions {
            return Err(error(
                py,
                Kind::Config,
                format!(
                    "model: the file's solution has a state of {} variables and actions {:?}; \
                     the model has {} and {:?}",
                    t.cores.len(),
                    t.actions,
                    m.state_dim(),
                    m.actions
                ),
            ));
        }
        let mut grid = Grid::checked(py, t.cores)?;
        grid.inner = grid.inner.with_membership(t.membership);
        let precision = t.values.precision();
        let v = match t.values {
            Values::F32(v) => PyArray1::from_vec(py, v).into_any().unbind(),
            Values::F64(v) => PyArray1::from_vec(py, v).into_any().unbind(),
        };
        Ok(Self {
            v,
            greedy: PyArray1::from_vec(py, t.greedy).unbind(),
            grid: Py::new(py, grid)?,
            summary: t.summary,
            gamma: t.gamma,
            xi: t.xi,
            absorbing_goal: t.absorbing_goal,
            precision,
            source: Source::Callable(model.clone().unbind(), OnceLock::new()),
            policy: OnceLock::new(),
            stopped: false,
        })
    }

    /// Rebuilds a pickled solution (see `__reduce__`).
    pub(crate) fn restore(py: Python<'_>, data: &Bound<'_, PyAny>) -> PyResult<Py<PyAny>> {
        let tag: String = data.get_item(0)?.extract()?;
        let mut solution = if tag == "env" {
            let (_, bytes, seconds, stopped): (String, Bound<'_, PyAny>, f64, bool) =
                data.extract()?;
            let file = PolicyFile::from_bytes(&crate::pickle::bytes(&bytes)?, "<pickle>".as_ref())
                .map_err(|e| policy_file_error(py, &e))?;
            let PolicyFile::Fqi(a) = file else {
                return Err(error(
                    py,
                    Kind::Input,
                    "_restore: not a fuzzy Q-iteration solution",
                ));
            };
            let mut s = Self::from_artifact(py, a, None)?;
            s.summary.seconds = seconds;
            s.stopped = stopped;
            s
        } else {
            #[allow(clippy::type_complexity)] // the pickled fields, in order
            let (_, model, grid, v, greedy, summary, gamma, xi, absorbing_goal, precision, stopped): (
                String,
                Bound<'_, PyAny>,
                Py<Grid>,
                Bound<'_, PyAny>,
                Vec<u32>,
                String,
                f64,
                f64,
                bool,
                String,
                bool,
            ) = data.extract()?;
            let precision: Precision = parse_option(py, "precision", &precision)?;
            let np = py.import("numpy")?;
            let dtype = match precision {
                Precision::F32 => "float32",
                Precision::F64 => "float64",
            };
            let v = np.call_method1("ascontiguousarray", (v, dtype))?.unbind();
            let summary: TrainSummary = serde_json::from_str(&summary)
                .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
            Self {
                v,
                greedy: PyArray1::from_vec(py, greedy).unbind(),
                grid,
                summary,
                gamma,
                xi,
                absorbing_goal,
                precision,
                source: restored_source(py, &tag, &model)?,
                policy: OnceLock::new(),
                stopped,
            }
        };
        solution.policy = OnceLock::new();
        Ok(Py::new(py, solution)?.into_any())
    }
}

/// The source of a pickled solution of a `CallableModel` (`tag` `"callable"`: the model) or
/// of a `Task` (`"learned"`: the task, its transitions and the estimation's report).
fn restored_source(py: Python<'_>, tag: &str, model: &Bound<'_, PyAny>) -> PyResult<Source> {
    if tag == "callable" {
        return Ok(Source::Callable(model.extract()?, OnceLock::new()));
    }
    let (task, data, report): (Py<Task>, Bound<'_, PyAny>, String) = model.extract()?;
    let t = task.get();
    let data = transitions_of(&data, t.shape.state_dim(), t.action_dim())?;
    let report = serde_json::from_str(&report)
        .map_err(|e| error(py, Kind::Input, format!("_restore: {e}")))?;
    Ok(Source::Learned {
        task,
        data: Arc::new(data),
        report,
        table: OnceLock::new(),
    })
}

/// The fuzzy Q-iteration policy inside a sim policy built by [`Solution::sim_policy`].
fn fqi(p: &SimPolicy) -> &FqiPolicy {
    match p {
        SimPolicy::Fqi(f) => f,
        SimPolicy::Additive(_) => unreachable!("a solution's policy is fuzzy Q-iteration"),
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

    /// The environment's name (`"pointmass"`, `"khepera"`, `"dcmotor"`, ...), or `None` for
    /// a `CallableModel`.
    #[getter]
    fn env(&self) -> Option<&'static str> {
        match &self.source {
            Source::Env(c, _) => Some(c.env.name()),
            _ => None,
        }
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

    /// Whether the callback stopped the solve (returning `False`): the solution is then that of
    /// the run limited to the sweeps done, with its error bound.
    #[getter]
    fn stopped(&self) -> bool {
        self.stopped
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
    fn deltas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(py, || {
            Ok(crate::convert::pairs_array(py, &self.summary.deltas))
        })
    }

    /// Wall-clock seconds of the solve (0 for a solution loaded from a file: files keep no
    /// timings, so that the same problem gives the same file).
    #[getter]
    fn seconds(&self) -> f64 {
        self.summary.seconds
    }

    /// The coarse start (`coarse_start=True`): a dict of the coarse grid's `cores`, its
    /// `sweeps` and the `seconds` of its solve and interpolation; `None` for a run without
    /// one and for a solution loaded from a file.
    #[getter]
    fn coarse_start<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.summary
            .coarse
            .as_deref()
            .map(|c| coarse_dict(py, c))
            .transpose()
    }

    /// How a `Task`'s model was learned from its transitions (None for every other model):
    /// ``samples``; per block, ``blocks`` (its ``state_dims`` and ``action_components``, its
    /// ``rows``, ``samples_per_action``, ``entries_per_row``, ``residual_rms`` per variable,
    /// ``under_sampled_rows`` and the first of them, ``under_sampled``: the rows that needed a
    /// wider kernel); and ``reward`` (None with a reward function, else
    /// ``depends_on_action``, ``pairs_without_samples``, ``cores_without_samples``,
    /// ``fallback`` and ``residual_rms``).
    #[getter]
    fn fit<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        match &self.source {
            Source::Learned { report, .. } => crate::json::to_python(py, report).map(Some),
            _ => Ok(None),
        }
    }

    /// The kernel instance used (`"avx512"`, `"avx2"`, `"portable"`, `"scalar"`, `"generic"` or
    /// `"q-values"`).
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
        guard(py, || {
            let policy = self.sim_policy(py)?;
            let p = fqi(&policy);
            let (n, m) = (p.n_cores(), p.n_joint_actions());
            if n.saturating_mul(m) > 50_000_000 {
                return Err(error(
                    py,
                    Kind::Input,
                    format!(
                        "theta: {n} cores x {m} joint actions is more than 5e7 Q-values; use V and policies"
                    ),
                ));
            }
            let t = crate::pool::detach(py, || p.theta()).map_err(|e| sim_error(py, &e))?;
            Ok(PyArray2::from_owned_array(
                py,
                Array2::from_shape_vec((n, m), t).expect("n x m"),
            ))
        })
    }

    /// `V` interpolated at state `x`.
    fn value(&self, py: Python<'_>, x: &Bound<'_, PyAny>) -> PyResult<f64> {
        guard(py, || {
            let policy = self.sim_policy(py)?;
            let p = fqi(&policy);
            let x = finite_vector(x, "x", Some(p.state_dim()))?;
            p.value(&x).map_err(|e| sim_error(py, &e))
        })
    }

    /// A policy: `"greedy"` (eq 7, the maximiser of `Q(x, .)`) or `"interpolated"` (eq 22).
    #[pyo3(signature = (kind = "greedy"))]
    fn policy(slf: &Bound<'_, Self>, #[pyo3(from_py_with = arg)] kind: &str) -> PyResult<Policy> {
        let py = slf.py();
        guard(py, || {
            let kind = parse_option::<PolicyKind>(py, "kind", kind)?;
            Ok(Policy::new(
                slf.get().sim_policy(py)?,
                kind,
                crate::policy::Origin::Solution(slf.clone().into_any().unbind()),
            ))
        })
    }

    /// Pickling (`pickle`, `copy`, `joblib`, process pools): a solution of a built-in model
    /// as its policy file's bytes (and its timing), a solution of a `CallableModel` as the
    /// model (its function pickled by reference: a module-level function), the grid, `V`, the
    /// greedy actions and the run's record; its table is computed again on first use.
    fn __reduce__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let data = match self.artifact(py)? {
            Some(a) => {
                let bytes = PolicyFile::Fqi(a)
                    .to_bytes()
                    .map_err(|e| sim_error(py, &e))?;
                (
                    "env",
                    pyo3::types::PyBytes::new(py, &bytes),
                    self.summary.seconds,
                    self.stopped,
                )
                    .into_pyobject(py)?
                    .into_any()
            }
            None => {
                let (tag, model) = match &self.source {
                    Source::Callable(model, _) => ("callable", model.bind(py).clone().into_any()),
                    Source::Learned {
                        task, data, report, ..
                    } => (
                        "learned",
                        (
                            task.clone_ref(py),
                            transitions_dict(py, data)?,
                            report.to_string(),
                        )
                            .into_pyobject(py)?
                            .into_any(),
                    ),
                    Source::Env(..) => unreachable!("a built-in model's solution has an artifact"),
                };
                let summary = serde_json::to_string(&self.summary)
                    .map_err(|e| error(py, Kind::Internal, e.to_string()))?;
                let greedy: Vec<u32> = self.greedy.bind(py).readonly().as_slice()?.to_vec();
                PyTuple::new(
                    py,
                    [
                        tag.into_pyobject(py)?.into_any(),
                        model,
                        self.grid.bind(py).clone().into_any(),
                        self.v.bind(py).clone(),
                        greedy.into_pyobject(py)?.into_any(),
                        summary.into_pyobject(py)?.into_any(),
                        self.gamma.into_pyobject(py)?.into_any(),
                        self.xi.into_pyobject(py)?.into_any(),
                        pyo3::types::PyBool::new(py, self.absorbing_goal)
                            .to_owned()
                            .into_any(),
                        self.precision.name().into_pyobject(py)?.into_any(),
                        pyo3::types::PyBool::new(py, self.stopped)
                            .to_owned()
                            .into_any(),
                    ],
                )?
                .into_any()
            }
        };
        crate::pickle::reduce(py, "solution", data)
    }

    /// Writes the policy file (the format `fuzzyq rollout` reads), atomically. Only solutions
    /// of built-in models can be saved; a solution of a `CallableModel` pickles.
    fn save(&self, py: Python<'_>, #[pyo3(from_py_with = arg)] path: PathBuf) -> PyResult<()> {
        guard(py, || {
            let Some(artifact) = self.artifact(py)? else {
                let Source::Callable(model, _) = &self.source else {
                    return Err(error(
                        py,
                        Kind::Config,
                        "save: a solution learned for a fuzzyq.Task is kept by pickling it (its \
                         policy file format holds built-in models and CallableModels)",
                    ));
                };
                let m = model.get();
                let g = &self.grid.get().inner;
                let file = PolicyFile::Tabulated(Box::new(TabulatedArtifact {
                    cores: g.cores().to_vec(),
                    membership: g.membership(),
                    actions: m.actions.clone(),
                    blocks: m.declared_blocks().to_vec(),
                    values: self.values(py)?,
                    greedy: self.greedy.bind(py).readonly().as_slice()?.to_vec(),
                    gamma: self.gamma,
                    xi: self.xi,
                    absorbing_goal: self.absorbing_goal,
                    summary: self.summary.clone(),
                }));
                file.check()
                    .map_err(|e| error(py, Kind::Input, format!("save: {e}")))?;
                return crate::pool::detach(py, || file.save(&path)).map_err(|e| sim_error(py, &e));
            };
            artifact
                .check()
                .map_err(|e| error(py, Kind::Input, format!("save: {e}")))?;
            crate::pool::detach(py, || PolicyFile::Fqi(artifact).save(&path))
                .map_err(|e| sim_error(py, &e))
        })
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok({
                format!(
                    "Solution(env={}, sweeps={}, converged={}, final_delta={:.4}, seconds={:.2}, kernel={:?})",
                    self.env()
                        .map_or_else(|| "None".into(), |e| format!("{e:?}")),
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
            })
        })
    }
}

/// A coarse start as a dict: the coarse grid's `cores`, its `sweeps` and the `seconds` of its
/// solve and interpolation.
pub(crate) fn coarse_dict<'py>(py: Python<'py>, c: &CoarseStart) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("cores", c.cores)?;
    d.set_item("sweeps", c.sweeps)?;
    d.set_item("seconds", c.seconds)?;
    Ok(d)
}
