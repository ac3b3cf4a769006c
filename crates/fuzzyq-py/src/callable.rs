//! `CallableModel`: a model defined by a vectorised Python function, tabulated on the grid to
//! be solved (in full, or per declared independent dynamics block), with terminal successors.

use fuzzyq_core::solver::{BlockTable, Grid as CoreGrid, Precision, SolveError, TabulatedModel};
use fuzzyq_core::{ActionSet, JointActions, Real};
use fuzzyq_sim::memory::{Estimate, Limit};
use numpy::ndarray::Array2;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{arg, distinct, finite_vector, matrix, vector};
use crate::errors::{Kind, error, guard};

/// A model defined by a vectorised Python function.
///
/// `transition(states, actions)` receives a batch of states, shape `(n, state_dim)`, and of
/// joint action vectors, shape `(n, action_dim)` (float64), and returns
/// `(next_states, rewards)` of shapes `(n, state_dim)` and `(n,)`, or
/// `(next_states, rewards, terminal)` with `terminal` a boolean array of shape `(n,)`: a
/// transition into a terminal state is worth its reward and nothing after it. `actions` holds
/// each agent's discrete actions, an array of shape `(n_actions, components)` (or
/// `(n_actions,)` for one component); the joint action vector concatenates the agents'
/// actions, and joint actions are numbered with agent 0 most significant
/// (`joint_index`, `agent_indices`).
///
/// Without `blocks`, the solver calls `transition` once on every (core, joint action) pair of
/// the grid and keeps every successor. `blocks` declares independent dynamics blocks: a
/// sequence of `(state_indices, action_components)` pairs, a partition of the state variables
/// in which each group's next value depends only on the group itself and on those components
/// of the joint action vector (a point mass's position and velocity on one axis, driven by its
/// force on that axis). The solver then keeps per block only its successors at its own cores
/// (a few values per block core and block action), and runs the block backup: the memory of a
/// solve is that of the rewards, one value per (core, joint action) pair. The declaration is
/// checked on every pair: a successor that differs from the blocks' is refused.
#[pyclass(module = "fuzzyq", frozen)]
pub struct CallableModel {
    transition: Py<PyAny>,
    state_dim: usize,
    pub(crate) actions: Vec<(Vec<f64>, usize)>,
    /// Declared blocks: state variables (increasing) and action components.
    blocks: Vec<(Vec<usize>, Vec<usize>)>,
    batch_size: usize,
}

/// One batch of transitions as the function returned them, checked.
struct Batch {
    next: Vec<f64>,
    rewards: Vec<f64>,
    terminal: Option<Vec<bool>>,
}

/// What tabulating a [`CallableModel`] on a grid gives, in float64.
pub(crate) struct Tables {
    rewards: Vec<f64>,
    successors: Successors,
    /// The (core, joint action) pairs whose successor is terminal.
    terminal: Vec<(usize, usize)>,
}

enum Successors {
    Full(Vec<f64>),
    Blocks(Vec<BlockTable<f64>>),
}

impl Tables {
    /// The solver's model on `grid` in precision `T` (built with the GIL released).
    pub(crate) fn model_on<T: Real>(
        self,
        py: Python<'_>,
        grid: &crate::model::Grid,
        actions: &[(Vec<f64>, usize)],
    ) -> PyResult<TabulatedModel<T>> {
        let grid_t = grid.to_precision::<T>(py)?;
        crate::pool::detach(py, || self.model(grid_t, actions))
            .map_err(|e| crate::errors::solve_error(py, &e))
    }

    /// The solver's model in precision `T` on `grid` (the grid tabulated, in `T`).
    pub(crate) fn model<T: Real>(
        self,
        grid: CoreGrid<T>,
        actions: &[(Vec<f64>, usize)],
    ) -> Result<TabulatedModel<T>, SolveError> {
        let conv = |v: &[f64]| v.iter().map(|&x| T::from_f64(x)).collect::<Vec<T>>();
        let actions: Vec<(Vec<T>, usize)> = actions.iter().map(|(v, d)| (conv(v), *d)).collect();
        let rewards = conv(&self.rewards);
        drop(self.rewards);
        let mut model = match self.successors {
            Successors::Full(next) => {
                let next_t = conv(&next);
                drop(next);
                TabulatedModel::new(grid, actions, next_t, rewards)?
            }
            Successors::Blocks(blocks) => {
                let blocks = blocks
                    .into_iter()
                    .map(|b| BlockTable {
                        actions: conv(&b.actions),
                        next: conv(&b.next),
                        state_dims: b.state_dims,
                        action_components: b.action_components,
                    })
                    .collect();
                TabulatedModel::with_blocks(grid, actions, blocks, rewards)?
            }
        };
        for (d, j) in self.terminal {
            model.mark_terminal(d, j)?;
        }
        Ok(model)
    }
}

/// Row-major digits of `index` over `lens`, into `out`.
fn digits(mut index: usize, lens: &[usize], out: &mut [usize]) {
    for (o, &n) in out.iter_mut().zip(lens).rev() {
        *o = index % n;
        index /= n;
    }
}

impl CallableModel {
    /// The declared blocks (empty: none).
    pub(crate) fn declared_blocks(&self) -> &[(Vec<usize>, Vec<usize>)] {
        &self.blocks
    }

    /// The peak memory of tabulating and solving `n` cores x `m` joint actions of a state of
    /// `e` variables in `precision`. Without blocks: first the tables in float64 and their copy
    /// in the solver's precision, then that copy and the successors' memberships the solver
    /// precomputes (up to `2^e` active cores per pair, held twice while they are built). With
    /// blocks: the rewards in float64, their copy and the solver's copy in its precision, and
    /// the per-core vectors of the block backup.
    pub(crate) fn memory(&self, n: usize, m: usize, precision: Precision) -> Estimate {
        let e = self.state_dim;
        let pairs = n as f64 * m as f64;
        let s: f64 = match precision {
            Precision::F32 => 4.0,
            Precision::F64 => 8.0,
        };
        let bytes = if self.blocks.is_empty() {
            let values = (e + 1) as f64;
            let active = 2f64.powi(e as i32);
            // An entry is a core index (4 bytes) and a weight, also as an aligned pair.
            let entry = 4.0 + s + (4.0 + s).max(2.0 * s);
            let tabulate = pairs * values * (8.0 + s);
            let solve = pairs * (values * s + 16.0 + active * entry);
            tabulate.max(solve)
        } else {
            pairs * (8.0 + 2.0 * s) + n as f64 * 8.0 * s
        };
        Estimate {
            bytes,
            what: format!(
                "{n} cores x {m} joint actions of a CallableModel ({})",
                if self.blocks.is_empty() {
                    "its successors, rewards and the successors' memberships"
                } else {
                    "its rewards, with successors per declared block"
                }
            ),
        }
    }

    fn joint(&self) -> JointActions<'_, f64> {
        let sets: Vec<ActionSet<'_, f64>> = self
            .actions
            .iter()
            .map(|(v, d)| ActionSet::try_new(v, *d).expect("validated"))
            .collect();
        JointActions::try_new(&sets).expect("validated")
    }

    /// Calls the function on `b` states `xs` and joint action vectors `us`; `first` numbers
    /// the batch's first pair in messages.
    fn call(
        &self,
        py: Python<'_>,
        xs: Vec<f64>,
        us: Vec<f64>,
        b: usize,
        first: usize,
    ) -> PyResult<Batch> {
        let (e, a) = (self.state_dim, us.len() / b.max(1));
        let xs = PyArray2::from_owned_array(py, Array2::from_shape_vec((b, e), xs).expect("b x e"));
        let us = PyArray2::from_owned_array(py, Array2::from_shape_vec((b, a), us).expect("b x a"));
        let out = self.transition.bind(py).call1((xs, us))?;
        let model_error =
            |msg: String| error(py, Kind::Model, format!("transition returned {msg}"));
        let parts: Vec<Bound<'_, PyAny>> = out
            .cast::<PyTuple>()
            .ok()
            .filter(|t| t.len() == 2 || t.len() == 3)
            .map(|t| t.iter().collect())
            .ok_or_else(|| {
                model_error(
                    "something other than a tuple (next_states, rewards) or (next_states, \
                     rewards, terminal)"
                        .into(),
                )
            })?;
        let (_, _, next) = matrix(&parts[0], "next_states", Some(b), Some(e))
            .map_err(|err| model_error(err.value(py).to_string()))?;
        let rewards = vector(&parts[1], "rewards", Some(b))
            .map_err(|err| model_error(err.value(py).to_string()))?;
        if let Some(i) = next.iter().position(|v| !v.is_finite()) {
            return Err(model_error(format!(
                "a non-finite next state (pair {})",
                first + i / e
            )));
        }
        if let Some(i) = rewards.iter().position(|v| !v.is_finite()) {
            return Err(model_error(format!(
                "a non-finite reward (pair {})",
                first + i
            )));
        }
        let terminal = match parts.get(2) {
            None => None,
            Some(t) => Some(flags(py, t, b).map_err(model_error)?),
        };
        Ok(Batch {
            next,
            rewards,
            terminal,
        })
    }

    /// Evaluates the transition on every (core, joint action) pair of `grid`, in batches, and
    /// per declared block on its block cores: the rewards, the successors (in full, or per
    /// block) and the terminal pairs. A problem whose tables would exceed `limit` is refused
    /// first ([`Self::memory`]); with blocks, every successor is checked against the blocks'.
    pub(crate) fn tabulate(
        &self,
        py: Python<'_>,
        grid: &CoreGrid<f64>,
        precision: Precision,
        limit: &Limit,
    ) -> PyResult<Tables> {
        let e = self.state_dim;
        if grid.n_dims() != e {
            return Err(error(
                py,
                Kind::Config,
                format!(
                    "the grid has {} state variables but the model's state has {e}",
                    grid.n_dims()
                ),
            ));
        }
        let joint = self.joint();
        let (n, m, a) = (grid.n_cores(), joint.n_joint(), joint.dim());
        limit
            .check(&self.memory(n, m, precision))
            .map_err(|err| crate::errors::memory_error(py, "max_memory_gb", &err))?;
        // Beyond a deliberately raised limit, the tables may still not fit in memory: a typed
        // error rather than an abort.
        let too_large = || {
            error(
                py,
                Kind::Solver,
                format!("{n} cores x {m} joint actions: the tables do not fit in memory"),
            )
        };
        let total = n.checked_mul(m).ok_or_else(too_large)?;
        let blocks = self.block_tables(py, grid)?;
        let lens: Vec<usize> = grid.cores().iter().map(Vec::len).collect();
        // Per block: its action index per joint action.
        let block_action: Vec<Vec<usize>> =
            blocks.iter().map(|t| block_action_of(&joint, t)).collect();
        let mut next_all = Vec::new();
        if blocks.is_empty() {
            total
                .checked_mul(e)
                .ok_or_else(too_large)
                .and_then(|len| next_all.try_reserve_exact(len).map_err(|_| too_large()))?;
        }
        let mut rewards = Vec::new();
        rewards.try_reserve_exact(total).map_err(|_| too_large())?;
        let mut terminal = Vec::new();
        let view = grid.view();
        let mut core_digits = vec![0usize; e];
        let mut start = 0;
        while start < total {
            let b = self.batch_size.min(total - start);
            let mut xs = vec![0.0; b * e];
            let mut us = vec![0.0; b * a];
            for i in 0..b {
                let (d, u) = ((start + i) / m, (start + i) % m);
                view.core_state(d, &mut xs[i * e..(i + 1) * e])
                    .expect("core in range");
                joint.vector_unchecked(u, &mut us[i * a..(i + 1) * a]);
            }
            let batch = self.call(py, xs, us, b, start)?;
            if blocks.is_empty() {
                next_all.extend_from_slice(&batch.next);
            } else {
                for i in 0..b {
                    let (d, u) = ((start + i) / m, (start + i) % m);
                    digits(d, &lens, &mut core_digits);
                    let got = &batch.next[i * e..(i + 1) * e];
                    for (t, actions) in blocks.iter().zip(&block_action) {
                        let k = t.state_dims.len();
                        let c = t
                            .state_dims
                            .iter()
                            .fold(0, |c, &dim| c * lens[dim] + core_digits[dim]);
                        let na = t.actions.len() / t.action_components.len().max(1);
                        let na = if t.action_components.is_empty() {
                            1
                        } else {
                            na
                        };
                        let s = &t.next[(c * na + actions[u]) * k..][..k];
                        for (&dim, &want) in t.state_dims.iter().zip(s) {
                            let v = got[dim];
                            if (v - want).abs() > 1e-9 * v.abs().max(want.abs()).max(1.0) {
                                return Err(error(
                                    py,
                                    Kind::Config,
                                    format!(
                                        "blocks: state variable {dim}'s successor depends on \
                                         more than its block's variables {:?} and action \
                                         components {:?}: at core {d}, joint action {u} the \
                                         transition gives {v} but {want} at the block's \
                                         reference state",
                                        t.state_dims, t.action_components
                                    ),
                                ));
                            }
                        }
                    }
                }
            }
            rewards.extend_from_slice(&batch.rewards);
            if let Some(flags) = &batch.terminal {
                terminal.extend(
                    flags
                        .iter()
                        .enumerate()
                        .filter(|&(_, &t)| t)
                        .map(|(i, _)| ((start + i) / m, (start + i) % m)),
                );
            }
            start += b;
            py.check_signals()?;
        }
        Ok(Tables {
            rewards,
            successors: if blocks.is_empty() {
                Successors::Full(next_all)
            } else {
                Successors::Blocks(blocks)
            },
            terminal,
        })
    }

    /// Each declared block's successors at its block cores (the other variables at their
    /// first core, the other action components those of the first joint action giving the
    /// block action).
    fn block_tables(&self, py: Python<'_>, grid: &CoreGrid<f64>) -> PyResult<Vec<BlockTable<f64>>> {
        let e = self.state_dim;
        let joint = self.joint();
        let a = joint.dim();
        let cores = grid.cores();
        let base: Vec<f64> = cores.iter().map(|c| c[0]).collect();
        let mut out = Vec::with_capacity(self.blocks.len());
        for (dims, comps) in &self.blocks {
            let (tuples, first) = BlockTable::block_actions(&self.actions, comps)
                .map_err(|err| error(py, Kind::Config, format!("blocks: {err}")))?;
            let lens: Vec<usize> = dims.iter().map(|&d| cores[d].len()).collect();
            let n_cores: usize = lens.iter().product();
            let na = first.len();
            let total = n_cores * na;
            let mut next = Vec::with_capacity(total * dims.len());
            let mut digit = vec![0usize; dims.len()];
            let mut start = 0;
            while start < total {
                let b = self.batch_size.min(total - start);
                let mut xs = Vec::with_capacity(b * e);
                let mut us = vec![0.0; b * a];
                for i in 0..b {
                    let (c, k) = ((start + i) / na, (start + i) % na);
                    digits(c, &lens, &mut digit);
                    let mut x = base.clone();
                    for (&d, &i) in dims.iter().zip(&digit) {
                        x[d] = cores[d][i];
                    }
                    xs.extend_from_slice(&x);
                    joint.vector_unchecked(first[k], &mut us[i * a..(i + 1) * a]);
                }
                let batch = self.call(py, xs, us, b, 0)?;
                for row in batch.next.chunks_exact(e) {
                    next.extend(dims.iter().map(|&d| row[d]));
                }
                start += b;
                py.check_signals()?;
            }
            out.push(BlockTable {
                state_dims: dims.clone(),
                action_components: comps.clone(),
                actions: tuples,
                next,
            });
        }
        Ok(out)
    }

    /// The declared blocks of `obj`: pairs of state indices and action components, a
    /// partition of the state variables.
    pub(crate) fn parse_blocks(
        py: Python<'_>,
        obj: &Bound<'_, PyAny>,
        e: usize,
        a: usize,
    ) -> PyResult<Vec<(Vec<usize>, Vec<usize>)>> {
        let bad = |msg: String| error(py, Kind::Config, format!("blocks: {msg}"));
        let items = obj.try_iter().map_err(|_| {
            error(
                py,
                Kind::InputType,
                "blocks: expected a sequence of (state_indices, action_components) pairs",
            )
        })?;
        let mut blocks = Vec::new();
        let mut owner = vec![None; e];
        for (b, item) in items.enumerate() {
            let item = item?;
            let (dims, comps): (Vec<usize>, Vec<usize>) = item.extract().map_err(|_| {
                error(
                    py,
                    Kind::InputType,
                    format!(
                        "blocks[{b}]: expected a pair (state_indices, action_components) of \
                         integer sequences, got {}",
                        crate::convert::describe(&item)
                    ),
                )
            })?;
            if dims.is_empty() {
                return Err(bad(format!("block {b} has no state variables")));
            }
            let mut sorted = dims.clone();
            sorted.sort_unstable();
            for &d in &sorted {
                if d >= e {
                    return Err(bad(format!(
                        "block {b} names state variable {d}, but the state has {e}"
                    )));
                }
                if let Some(o) = owner[d] {
                    return Err(bad(format!(
                        "state variable {d} is in blocks {o} and {b}; blocks must not overlap"
                    )));
                }
                owner[d] = Some(b);
            }
            let mut comps_sorted = comps.clone();
            comps_sorted.sort_unstable();
            comps_sorted.dedup();
            if let Some(&c) = comps_sorted.iter().find(|&&c| c >= a) {
                return Err(bad(format!(
                    "block {b} names action component {c}, but the joint action vector has {a}"
                )));
            }
            blocks.push((sorted, comps_sorted));
        }
        if blocks.is_empty() {
            return Err(bad("expected at least one block (or blocks=None)".into()));
        }
        if let Some(d) = owner.iter().position(Option::is_none) {
            return Err(bad(format!(
                "state variable {d} is in no block; blocks must cover the whole state"
            )));
        }
        Ok(blocks)
    }
}

/// Each agent's discrete actions of `obj` (a sequence of one array per agent, of shape
/// `(n_actions, components)` or `(n_actions,)`), checked: finite, distinct, 1 to
/// [`fuzzyq_core::MAX_AGENTS`] agents, at most `u32::MAX` joint actions.
pub(crate) fn parse_actions(
    py: Python<'_>,
    actions: &Bound<'_, PyAny>,
) -> PyResult<Vec<(Vec<f64>, usize)>> {
    let items = actions.try_iter().map_err(|_| {
        error(
            py,
            Kind::InputType,
            "actions: expected a sequence of arrays, one per agent",
        )
    })?;
    let mut sets = Vec::new();
    for (i, item) in items.enumerate() {
        let item = item?;
        let what = format!("actions[{i}]");
        let (values, dim) = match matrix(&item, &what, None, None) {
            Ok((_, c, v)) => (v, c),
            Err(_) => (finite_vector(&item, &what, None)?, 1),
        };
        crate::convert::check_finite(py, &what, &values)?;
        ActionSet::try_new(&values, dim)
            .map_err(|e| error(py, Kind::Config, format!("{what}: {e}")))?;
        distinct(py, &what, "action", &values, dim)?;
        sets.push((values, dim));
    }
    if sets.is_empty() || sets.len() > fuzzyq_core::MAX_AGENTS {
        return Err(error(
            py,
            Kind::Config,
            format!(
                "actions: expected 1 to {} agents, got {}",
                fuzzyq_core::MAX_AGENTS,
                sets.len()
            ),
        ));
    }
    let n: Option<usize> = sets
        .iter()
        .try_fold(1usize, |acc, (v, d)| acc.checked_mul(v.len() / d));
    if n.is_none_or(|n| n > u32::MAX as usize) {
        return Err(error(py, Kind::Config, "actions: too many joint actions"));
    }
    Ok(sets)
}

/// Each agent's actions (values, components per action) as arrays of shape
/// `(n_actions, components)`.
pub(crate) fn action_arrays<'py>(
    py: Python<'py>,
    actions: &[(Vec<f64>, usize)],
) -> Vec<Bound<'py, PyArray2<f64>>> {
    actions
        .iter()
        .map(|(v, d)| {
            PyArray2::from_owned_array(
                py,
                Array2::from_shape_vec((v.len() / d, *d), v.clone()).expect("rows"),
            )
        })
        .collect()
}

/// The boolean flags of a terminal array of `b` entries (dtype bool, or integers 0 and 1).
fn flags(py: Python<'_>, obj: &Bound<'_, PyAny>, b: usize) -> Result<Vec<bool>, String> {
    let np = py.import("numpy").map_err(|e| e.to_string())?;
    let arr = np
        .call_method1("asarray", (obj,))
        .map_err(|e| e.to_string())?;
    let kind: String = arr
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .map_err(|e| e.to_string())?;
    let shape: Vec<usize> = arr
        .getattr("shape")
        .and_then(|s| s.extract())
        .map_err(|e| e.to_string())?;
    if shape != [b] {
        return Err(format!("terminal of shape {shape:?}, expected ({b},)"));
    }
    let arr = match kind.as_str() {
        "b" => arr,
        "i" | "u" => {
            let ok: bool = arr
                .call_method1("__eq__", (0,))
                .and_then(|z| z.call_method1("__or__", (arr.call_method1("__eq__", (1,))?,)))
                .and_then(|m| m.call_method0("all"))
                .and_then(|v| v.extract())
                .map_err(|e| e.to_string())?;
            if !ok {
                return Err("terminal flags other than 0 and 1".into());
            }
            arr.call_method1("astype", ("bool",))
                .map_err(|e| e.to_string())?
        }
        _ => {
            return Err(format!(
                "terminal of dtype kind {kind:?}, expected booleans"
            ));
        }
    };
    let arr = arr
        .cast_into::<PyArray1<bool>>()
        .map_err(|e| e.to_string())?;
    let ro = arr.readonly();
    Ok(ro.as_array().iter().copied().collect())
}

/// Per joint action, its block action index in `t` (the position of its components' values
/// among the block actions).
fn block_action_of(joint: &JointActions<'_, f64>, t: &BlockTable<f64>) -> Vec<usize> {
    let k = t.action_components.len();
    let mut u = vec![0.0; joint.dim()];
    (0..joint.n_joint())
        .map(|j| {
            if k == 0 {
                return 0;
            }
            joint.vector_unchecked(j, &mut u);
            t.actions
                .chunks_exact(k)
                .position(|s| s.iter().zip(&t.action_components).all(|(&v, &c)| v == u[c]))
                .expect("every joint action's block action is listed")
        })
        .collect()
}

#[pymethods]
impl CallableModel {
    #[new]
    #[pyo3(signature = (transition, *, state_dim, actions, blocks = None, batch_size = 65536))]
    fn new(
        py: Python<'_>,
        transition: Bound<'_, PyAny>,
        #[pyo3(from_py_with = arg)] state_dim: usize,
        actions: &Bound<'_, PyAny>,
        blocks: Option<&Bound<'_, PyAny>>,
        #[pyo3(from_py_with = arg)] batch_size: usize,
    ) -> PyResult<Self> {
        guard(py, || {
            if !transition.is_callable() {
                return Err(error(
                    py,
                    Kind::InputType,
                    "transition: expected a callable",
                ));
            }
            if state_dim == 0 || state_dim > fuzzyq_core::MAX_DIMS {
                return Err(error(
                    py,
                    Kind::Config,
                    format!(
                        "state_dim: expected 1 to {}, got {state_dim}",
                        fuzzyq_core::MAX_DIMS
                    ),
                ));
            }
            if batch_size == 0 {
                return Err(error(py, Kind::Config, "batch_size: must be at least 1"));
            }
            let sets = parse_actions(py, actions)?;
            let a: usize = sets.iter().map(|(_, d)| d).sum();
            let blocks = match blocks {
                None => Vec::new(),
                Some(b) if b.is_none() => Vec::new(),
                Some(b) => Self::parse_blocks(py, b, state_dim, a)?,
            };
            Ok(Self {
                transition: transition.unbind(),
                state_dim,
                actions: sets,
                blocks,
                batch_size,
            })
        })
    }

    /// The transition function.
    #[getter]
    fn transition(&self, py: Python<'_>) -> Py<PyAny> {
        self.transition.clone_ref(py)
    }

    /// Length of the state vector.
    #[getter]
    pub(crate) fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// Number of agents.
    #[getter]
    fn n_agents(&self) -> usize {
        self.actions.len()
    }

    /// Length of the joint action vector.
    #[getter]
    fn action_dim(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.joint().dim()))
    }

    /// Number of joint actions.
    #[getter]
    fn n_joint_actions(&self, py: Python<'_>) -> PyResult<usize> {
        guard(py, || Ok(self.joint().n_joint()))
    }

    /// Each agent's actions, one array of shape `(n_actions, components)` per agent.
    #[getter]
    fn actions<'py>(&self, py: Python<'py>) -> Vec<Bound<'py, PyArray2<f64>>> {
        action_arrays(py, &self.actions)
    }

    /// The declared blocks, `(state_indices, action_components)` pairs (empty: none).
    #[getter]
    fn blocks(&self) -> Vec<(Vec<usize>, Vec<usize>)> {
        self.blocks.clone()
    }

    /// The joint action vector of joint action `index`.
    fn joint_action<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(py, || crate::joint::vector(py, &self.joint(), index))
    }

    /// The joint action index of per-agent action indices (agent 0 most significant).
    fn joint_index(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = arg)] per_agent: Vec<usize>,
    ) -> PyResult<usize> {
        guard(py, || crate::joint::index(py, &self.joint(), &per_agent))
    }

    /// The per-agent action indices of joint action `index`.
    fn agent_indices(
        &self,
        py: Python<'_>,
        #[pyo3(from_py_with = crate::convert::index)] index: usize,
    ) -> PyResult<Vec<usize>> {
        guard(py, || crate::joint::per_agent(py, &self.joint(), index))
    }

    /// One transition: `(next_state, reward, terminal)` of state `x` under joint action vector
    /// `u` (`terminal` is `False` when the function returns no flags).
    fn step<'py>(
        &self,
        py: Python<'py>,
        x: &Bound<'py, PyAny>,
        u: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, f64, bool)> {
        guard(py, || {
            let x = finite_vector(x, "x", Some(self.state_dim))?;
            let u = finite_vector(u, "u", Some(self.joint().dim()))?;
            let batch = self.call(py, x, u, 1, 0)?;
            let terminal = batch.terminal.is_some_and(|t| t[0]);
            Ok((
                PyArray1::from_vec(py, batch.next),
                batch.rewards[0],
                terminal,
            ))
        })
    }

    /// Pickling: the function (pickled by reference, so a module-level function), the state
    /// length, the actions, the blocks and the batch size.
    fn __getnewargs_ex__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<(Bound<'py, PyTuple>, Bound<'py, PyDict>)> {
        let kwargs = PyDict::new(py);
        kwargs.set_item("state_dim", self.state_dim)?;
        kwargs.set_item("actions", self.actions(py))?;
        if !self.blocks.is_empty() {
            kwargs.set_item("blocks", self.blocks.clone())?;
        }
        kwargs.set_item("batch_size", self.batch_size)?;
        Ok((PyTuple::new(py, [self.transition.clone_ref(py)])?, kwargs))
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        guard(py, || {
            Ok(format!(
                "CallableModel(state_dim={}, agents={}, joint_actions={}, blocks={})",
                self.state_dim,
                self.actions.len(),
                self.joint().n_joint(),
                self.blocks.len()
            ))
        })
    }
}
