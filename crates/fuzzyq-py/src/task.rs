//! `Task`: a system known only through its transitions (a Gymnasium environment, a simulator,
//! logged data), declared by its state ranges, its agents' actions and its independent
//! dynamics blocks. `solve(task, grid, transitions=...)` estimates the blocks' transition
//! tables with the estimator `fuzzyq train --learner learned-model` uses
//! ([`fuzzyq_sim::learn::fit`]), the rewards with [`fuzzyq_sim::learn::reward`] (or the
//! task's reward function at the cores), and solves the learned model.

use fuzzyq_core::Real;
use fuzzyq_core::solver::{Grid as CoreGrid, TabulatedModel};
use fuzzyq_sim::learn::fit::{FitConfig, TaskShape, fit_shape};
use fuzzyq_sim::learn::reward::fit_rewards;
use fuzzyq_sim::learn::samples::Transitions;
use fuzzyq_sim::model::BlockSpec;
use fuzzyq_sim::model::learned::BlockTables;
use numpy::PyArray2;
use numpy::ndarray::Array2;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::callable::{CallableModel, action_arrays, parse_actions};
use crate::convert::{arg, finite_vector, matrix};
use crate::errors::{Kind, config_error, error, guard, solve_error};

/// Pairs of (core, joint action) per call of a task's reward function.
const REWARD_BATCH: usize = 65_536;

/// A system known only through its transitions: its state ranges, each agent's discrete
/// actions, optional independent dynamics blocks, periodic state variables, and optionally its
/// reward function.
#[pyclass(module = "fuzzyq", frozen)]
pub struct Task {
    pub(crate) shape: TaskShape,
    /// Declared blocks (state variables, action components); one block of everything when
    /// none was declared.
    pub(crate) blocks: Vec<(Vec<usize>, Vec<usize>)>,
    declared_blocks: bool,
    reward: Option<Py<PyAny>>,
    reward_depends_on_action: bool,
}

/// What learning a task from transitions gives: the solver's model in the grid's precision
/// and the estimation's report.
pub(crate) struct Learned<T> {
    pub(crate) model: TabulatedModel<T>,
    pub(crate) report: serde_json::Value,
}

impl Task {
    /// Length of the joint action vector.
    pub(crate) fn action_dim(&self) -> usize {
        self.shape.actions.iter().map(|(_, d)| d).sum()
    }

    /// Learns the task's model on `grid` from `data`: the blocks' tables, the rewards at every
    /// (core, joint action) pair (learned, or the reward function's), in precision `T`.
    pub(crate) fn learn<T: Real>(
        &self,
        py: Python<'_>,
        grid: &CoreGrid<f64>,
        grid_t: CoreGrid<T>,
        data: &Transitions,
    ) -> PyResult<Learned<T>> {
        let cores = grid.cores().to_vec();
        let specs: Vec<BlockSpec> = self
            .blocks
            .iter()
            .map(|(d, c)| BlockSpec {
                state_dims: d.clone(),
                action_components: c.clone(),
            })
            .collect();
        let fit_config = FitConfig {
            membership: grid.membership(),
            ..FitConfig::default()
        };
        let shape = &self.shape;
        let (tables, fits) =
            crate::pool::detach(py, || fit_shape(shape, &cores, &specs, data, &fit_config))
                .map_err(|e| config_error(py, &e))?;
        let (rewards, reward_report) = match &self.reward {
            Some(f) => (self.reward_at_cores(py, f, grid)?, serde_json::Value::Null),
            None => {
                let depends = self.reward_depends_on_action;
                let (r, fit) = crate::pool::detach(py, || {
                    fit_rewards(shape, &cores, grid.membership(), data, depends)
                })
                .map_err(|e| config_error(py, &e))?;
                (r, serde_json::to_value(fit).expect("a plain report"))
            }
        };
        let report = serde_json::json!({
            "samples": data.len(),
            "blocks": fits,
            "reward": reward_report,
        });
        let model = build::<T>(grid_t, &self.shape.actions, &tables, &rewards)
            .map_err(|e| solve_error(py, &e))?;
        Ok(Learned { model, report })
    }

    /// The reward function at every (core, joint action) pair of `grid`, core-major.
    fn reward_at_cores(
        &self,
        py: Python<'_>,
        f: &Py<PyAny>,
        grid: &CoreGrid<f64>,
    ) -> PyResult<Vec<f64>> {
        let (vectors, a) = self
            .shape
            .joint_vectors()
            .map_err(|e| config_error(py, &e))?;
        let (e, n) = (grid.n_dims(), grid.n_cores());
        let m = vectors.len() / a.max(1);
        let view = grid.view();
        let pairs = n * m;
        let mut out = Vec::with_capacity(pairs);
        let mut x = vec![0.0; e];
        let mut start = 0;
        while start < pairs {
            let len = REWARD_BATCH.min(pairs - start);
            let (mut xs, mut us) = (Vec::with_capacity(len * e), Vec::with_capacity(len * a));
            for p in start..start + len {
                let (d, j) = (p / m, p % m);
                view.core_state(d, &mut x)
                    .map_err(|err| error(py, Kind::Internal, err.to_string()))?;
                xs.extend_from_slice(&x);
                us.extend_from_slice(&vectors[j * a..(j + 1) * a]);
            }
            let xs =
                PyArray2::from_owned_array(py, Array2::from_shape_vec((len, e), xs).expect("rows"));
            let us =
                PyArray2::from_owned_array(py, Array2::from_shape_vec((len, a), us).expect("rows"));
            let r = f.bind(py).call1((xs, us))?;
            out.extend(finite_vector(&r, "reward(states, actions)", Some(len))?);
            start += len;
        }
        Ok(out)
    }
}

/// The solver's model of learned `tables` and `rewards` on `grid` in precision `T`.
fn build<T: Real>(
    grid: CoreGrid<T>,
    actions: &[(Vec<f64>, usize)],
    tables: &BlockTables,
    rewards: &[f64],
) -> Result<TabulatedModel<T>, fuzzyq_core::solver::SolveError> {
    let conv = |v: &[f64]| v.iter().map(|&x| T::from_f64(x)).collect::<Vec<T>>();
    let actions = actions.iter().map(|(v, d)| (conv(v), *d)).collect();
    TabulatedModel::with_block_rows(grid, actions, tables.rows::<T>(), conv(rewards))
}

#[pymethods]
impl Task {
    #[new]
    #[pyo3(signature = (
        *, state_bounds, actions, blocks = None, periodic = None, reward = None,
        reward_depends_on_action = true
    ))]
    fn new(
        py: Python<'_>,
        state_bounds: &Bound<'_, PyAny>,
        actions: &Bound<'_, PyAny>,
        blocks: Option<&Bound<'_, PyAny>>,
        periodic: Option<Vec<usize>>,
        reward: Option<Bound<'_, PyAny>>,
        #[pyo3(from_py_with = arg)] reward_depends_on_action: bool,
    ) -> PyResult<Self> {
        guard(py, || {
            let (e, _, b) = matrix(state_bounds, "state_bounds", None, Some(2))?;
            crate::convert::check_finite(py, "state_bounds", &b)?;
            if e == 0 || e > fuzzyq_core::MAX_DIMS {
                return Err(error(
                    py,
                    Kind::Config,
                    format!(
                        "state_bounds: expected 1 to {} variables, got {e}",
                        fuzzyq_core::MAX_DIMS
                    ),
                ));
            }
            let bounds: Vec<(f64, f64)> = b.chunks(2).map(|p| (p[0], p[1])).collect();
            if let Some(d) = bounds.iter().position(|(lo, hi)| lo >= hi) {
                return Err(error(
                    py,
                    Kind::Config,
                    format!("state_bounds[{d}]: expected lo < hi, got {:?}", bounds[d]),
                ));
            }
            let sets = parse_actions(py, actions)?;
            let a: usize = sets.iter().map(|(_, d)| d).sum();
            let declared = blocks.is_some_and(|b| !b.is_none());
            let blocks = match blocks {
                Some(b) if !b.is_none() => CallableModel::parse_blocks(py, b, e, a)?,
                _ => vec![((0..e).collect(), (0..a).collect())],
            };
            let mut flags = vec![false; e];
            for d in periodic.unwrap_or_default() {
                if d >= e {
                    return Err(error(
                        py,
                        Kind::Config,
                        format!("periodic: state variable {d}, but the state has {e}"),
                    ));
                }
                flags[d] = true;
            }
            if let Some(f) = &reward
                && !f.is_callable()
            {
                return Err(error(
                    py,
                    Kind::InputType,
                    "reward: expected a callable or None",
                ));
            }
            Ok(Self {
                shape: TaskShape {
                    bounds,
                    periodic: flags,
                    actions: sets,
                },
                blocks,
                declared_blocks: declared,
                reward: reward.map(Bound::unbind),
                reward_depends_on_action,
            })
        })
    }

    /// Length of the state vector.
    #[getter]
    fn state_dim(&self) -> usize {
        self.shape.state_dim()
    }

    /// Number of agents.
    #[getter]
    fn n_agents(&self) -> usize {
        self.shape.actions.len()
    }

    /// Length of the joint action vector.
    #[getter(action_dim)]
    fn action_dim_py(&self) -> usize {
        self.action_dim()
    }

    /// The range of each state variable, shape `(state_dim, 2)`.
    #[getter]
    fn state_bounds<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        crate::convert::pairs_array(py, &self.shape.bounds)
    }

    /// The periodic state variables.
    #[getter]
    fn periodic(&self) -> Vec<usize> {
        (0..self.shape.periodic.len())
            .filter(|&d| self.shape.periodic[d])
            .collect()
    }

    /// Each agent's actions, shape `(n_actions, components)`.
    #[getter]
    fn actions<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        action_arrays(py, &self.shape.actions)
    }

    /// Every joint action vector, shape `(n_joint_actions, action_dim)` (agent 0 most
    /// significant).
    #[getter]
    fn joint_actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (v, a) = self
            .shape
            .joint_vectors()
            .map_err(|e| config_error(py, &e))?;
        Ok(PyArray2::from_owned_array(
            py,
            Array2::from_shape_vec((v.len() / a.max(1), a), v).expect("rows"),
        ))
    }

    /// The blocks, `(state_indices, action_components)` pairs (one block of everything when
    /// none were declared).
    #[getter]
    fn blocks(&self) -> Vec<(Vec<usize>, Vec<usize>)> {
        self.blocks.clone()
    }

    /// The reward function, or None (rewards learned from the transitions).
    #[getter]
    fn reward(&self, py: Python<'_>) -> Option<Py<PyAny>> {
        self.reward.as_ref().map(|f| f.clone_ref(py))
    }

    /// Whether the reward depends on the action (learned per joint action, else per core).
    #[getter]
    fn reward_depends_on_action(&self) -> bool {
        self.reward_depends_on_action
    }

    /// Pickling: the declaration (a reward function pickles by reference).
    fn __getnewargs_ex__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
        let kwargs = PyDict::new(py);
        kwargs.set_item("state_bounds", self.state_bounds(py))?;
        kwargs.set_item("actions", self.actions(py))?;
        if self.declared_blocks {
            kwargs.set_item("blocks", self.blocks.clone())?;
        }
        kwargs.set_item("periodic", self.periodic())?;
        kwargs.set_item("reward", self.reward(py))?;
        kwargs.set_item("reward_depends_on_action", self.reward_depends_on_action)?;
        Ok((PyTuple::empty(py), kwargs))
    }

    fn __repr__(&self) -> String {
        format!(
            "Task(state_dim={}, n_agents={}, blocks={}, reward={})",
            self.shape.state_dim(),
            self.shape.actions.len(),
            self.blocks.len(),
            if self.reward.is_some() {
                "function"
            } else {
                "learned"
            }
        )
    }
}
