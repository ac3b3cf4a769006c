//! A model learned from samples: a task's reward and action sets with transition tables
//! estimated from data ([`crate::learn::fit`] estimates them).
//!
//! The dynamics of a [`LearnedModel`] are its [`BlockTables`]: per declared block and per
//! (block core, block action), the expected memberships of the block's successor over the
//! block's cores, i.e. the successor *distribution* as the fuzzy grid sees it. The solver
//! reads them through [`fuzzyq_core::Model::block_rows`] (block path only), so fuzzy
//! Q-iteration runs unchanged on the learned model. Everything else (the reward, goal test,
//! action sets, state bounds) is the task's, which the agents are told: they learn how the
//! world moves, not what they are asked to do.
//!
//! [`Dynamics::step`] of a learned model is its mean successor: per block, the fuzzy
//! interpolation of the rows' mean successors over the active block cores (for a discrete
//! block action; any other action vector takes the nearest block action; a periodic
//! variable takes the circular mean, wrapped into its range).

use fuzzyq_core::solver::{Precision, RowsTable};
use fuzzyq_core::{Membership, Partition, ProductPartition, Real};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, require};
use crate::model::{ActionTable, BlockSpec, Dynamics, EnvModel, F64Model, WideBlockRows};

/// One block's learned transition table (see [`fuzzyq_core::BlockRows`] for the layout).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlockTable {
    /// The block's state variables, increasing.
    pub state_dims: Vec<usize>,
    /// The joint-action components the block's successor depends on.
    pub action_components: Vec<usize>,
    /// Number of block actions.
    pub n_actions: usize,
    /// The action components' values per block action, `n_actions * action_components.len()`.
    pub actions: Vec<f64>,
    /// Row starts, one row per (block core, block action), block core major.
    pub ptr: Vec<u32>,
    /// Block core of each entry (row-major over `state_dims`).
    pub col: Vec<u32>,
    /// Expected membership of each entry.
    pub weight: Vec<f64>,
}

impl BlockTable {
    /// The entries of row (block core `c`, block action `a`).
    #[must_use]
    pub fn row(&self, c: usize, a: usize) -> (&[u32], &[f64]) {
        let r = c * self.n_actions + a;
        let (lo, hi) = (self.ptr[r] as usize, self.ptr[r + 1] as usize);
        (&self.col[lo..hi], &self.weight[lo..hi])
    }

    /// Number of block cores.
    #[must_use]
    pub fn n_cores(&self) -> usize {
        (self.ptr.len() - 1) / self.n_actions.max(1)
    }
}

/// A learned model's transition tables and the cores they are on: what a policy file keeps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BlockTables {
    /// The cores of every state variable (the grid the tables were estimated on).
    pub cores: Vec<Vec<f64>>,
    /// One table per block, in the order of the blocks' declaration.
    pub blocks: Vec<BlockTable>,
    /// The grid's membership functions the rows' memberships were taken with (a crisp grid
    /// gives each successor to its nearest core).
    pub membership: Membership,
}

impl BlockTables {
    /// The tables as the core's [`RowsTable`]s in precision `T`, for
    /// [`TabulatedModel::with_block_rows`](fuzzyq_core::solver::TabulatedModel::with_block_rows)
    /// (a learned model known only at the cores, such as one learned from a Python system).
    #[must_use]
    pub fn rows<T: Real>(&self) -> Vec<RowsTable<T>> {
        let narrow = |v: &[f64]| v.iter().map(|&x| T::from_f64(x)).collect();
        self.blocks
            .iter()
            .map(|t| RowsTable {
                state_dims: t.state_dims.clone(),
                action_components: t.action_components.clone(),
                actions: narrow(&t.actions),
                ptr: t.ptr.clone(),
                col: t.col.clone(),
                weight: narrow(&t.weight),
            })
            .collect()
    }

    /// Checks the tables against `task` (state and action dimensions, coverage of the state
    /// variables, one row per (block core, block action), rows of non-negative weights that
    /// sum to 1); errors name `learned_model`.
    pub fn check(&self, task: &EnvModel) -> Result<(), ConfigError> {
        const FIELD: &str = "learned_model";
        let e = F64Model::state_dim(task);
        let a_dim = F64Model::actions(task).dim() * F64Model::n_agents(task);
        require!(
            self.cores.len() == e,
            FIELD,
            format!(
                "has cores for {} state variables, the task has {e}",
                self.cores.len()
            ),
        );
        let mut count = vec![0usize; e];
        for (b, t) in self.blocks.iter().enumerate() {
            let bad = |what: &str| ConfigError::invalid(FIELD, format!("block {b}: {what}"));
            if t.state_dims.is_empty() || t.state_dims.iter().any(|&d| d >= e) {
                return Err(bad("its state variables are out of range"));
            }
            if t.action_components.iter().any(|&c| c >= a_dim) {
                return Err(bad("its action components are out of range"));
            }
            for &d in &t.state_dims {
                count[d] += 1;
            }
            let n_cores: usize = t.state_dims.iter().map(|&d| self.cores[d].len()).product();
            if t.n_actions == 0 || t.actions.len() != t.n_actions * t.action_components.len() {
                return Err(bad("its action values do not match its action count"));
            }
            if t.ptr.len() != n_cores * t.n_actions + 1
                || t.ptr[0] != 0
                || t.ptr.windows(2).any(|w| w[0] > w[1])
                || *t.ptr.last().unwrap_or(&0) as usize != t.col.len()
                || t.col.len() != t.weight.len()
            {
                return Err(bad(
                    "it does not have one row per (block core, block action)",
                ));
            }
            if t.col.iter().any(|&k| k as usize >= n_cores)
                || t.weight.iter().any(|w| !w.is_finite() || *w < 0.0)
            {
                return Err(bad(
                    "an entry is outside its cores or has a negative weight",
                ));
            }
            for r in 0..n_cores * t.n_actions {
                let sum: f64 = t.weight[t.ptr[r] as usize..t.ptr[r + 1] as usize]
                    .iter()
                    .sum();
                if (sum - 1.0).abs() > 1e-9 {
                    return Err(bad(&format!("row {r} sums to {sum}, not 1")));
                }
            }
        }
        if let Some(d) = count.iter().position(|&c| c != 1) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("state variable {d} is in {} blocks, not one", count[d]),
            ));
        }
        for (d, c) in self.cores.iter().enumerate() {
            Partition::try_from_cores(&c[..]).map_err(|e| {
                ConfigError::invalid(FIELD, format!("the cores of state variable {d}: {e}"))
            })?;
        }
        Ok(())
    }
}

/// A task whose dynamics are [`BlockTables`] (see the [module docs](self)).
#[derive(Clone, Debug)]
pub struct LearnedModel {
    task: EnvModel,
    tables: BlockTables,
    specs: Vec<BlockSpec>,
    /// Per block: actions and weights in `f32`.
    narrow: Vec<(Vec<f32>, Vec<f32>)>,
}

impl LearnedModel {
    /// The model of `task` (reward, goal, actions, bounds) moving as `tables` say; the tables
    /// are checked against the task ([`BlockTables::check`]). A task with terminal states is
    /// refused: a terminal test needs the joint successor, which block tables do not keep.
    pub fn new(task: EnvModel, tables: BlockTables) -> Result<Self, ConfigError> {
        require!(
            !Dynamics::has_terminal_states(&task),
            "learner",
            format!(
                "learned-model cannot learn {}: its episodes end in terminal states, which \
                 block tables cannot represent",
                task.name()
            ),
        );
        tables.check(&task)?;
        let specs = tables
            .blocks
            .iter()
            .map(|t| BlockSpec {
                state_dims: t.state_dims.clone(),
                action_components: t.action_components.clone(),
            })
            .collect();
        let narrow = tables
            .blocks
            .iter()
            .map(|t| {
                (
                    t.actions.iter().map(|&v| v as f32).collect(),
                    t.weight.iter().map(|&v| v as f32).collect(),
                )
            })
            .collect();
        Ok(Self {
            task,
            tables,
            specs,
            narrow,
        })
    }

    /// The task (reward, goal, actions, bounds, and the true dynamics, which the learned
    /// model does not use).
    #[must_use]
    pub fn task(&self) -> &EnvModel {
        &self.task
    }

    /// The transition tables.
    #[must_use]
    pub fn tables(&self) -> &BlockTables {
        &self.tables
    }

    /// The block action of `u` in table `t`: the exact match, else the nearest.
    fn block_action(t: &BlockTable, u: &[f64]) -> usize {
        let k = t.action_components.len();
        let dist = |a: usize| -> f64 {
            t.action_components
                .iter()
                .zip(&t.actions[a * k..(a + 1) * k])
                .map(|(&c, &v)| (u[c] - v).powi(2))
                .sum()
        };
        (0..t.n_actions)
            .min_by(|&a, &b| dist(a).total_cmp(&dist(b)))
            .unwrap_or(0)
    }
}

impl Dynamics for LearnedModel {
    fn sample_time(&self) -> f64 {
        Dynamics::sample_time(&self.task)
    }
    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        Dynamics::state_bounds(&self.task, dim)
    }
    fn is_periodic(&self, dim: usize) -> bool {
        Dynamics::is_periodic(&self.task, dim)
    }
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        for t in &self.tables.blocks {
            let parts: Vec<Partition<'_, f64>> = t
                .state_dims
                .iter()
                .map(|&d| {
                    Partition::try_from_cores(&self.tables.cores[d][..])
                        .expect("checked on construction")
                })
                .collect();
            let sub = ProductPartition::from_partitions(&parts).expect("checked on construction");
            let xb: Vec<f64> = t.state_dims.iter().map(|&d| x[d]).collect();
            let a = Self::block_action(t, u);
            // A periodic variable's mean is the circular one: its values as angles over the
            // period, averaged as unit vectors.
            let angles: Vec<Option<(f64, f64)>> = t
                .state_dims
                .iter()
                .map(|&d| {
                    let (lo, hi) = Dynamics::state_bounds(&self.task, d);
                    Dynamics::is_periodic(&self.task, d).then_some((lo, hi - lo))
                })
                .collect();
            let mut mean = vec![0.0; t.state_dims.len()];
            let mut sin = vec![0.0; t.state_dims.len()];
            let mut core = vec![0.0; t.state_dims.len()];
            sub.active_unchecked(&xb).for_each(|c, mu| {
                let (cols, ws) = t.row(c, a);
                for (&k, &w) in cols.iter().zip(ws) {
                    sub.core_state(k as usize, &mut core)
                        .expect("columns are checked on construction");
                    for (j, &v) in core.iter().enumerate() {
                        match angles[j] {
                            None => mean[j] += mu * w * v,
                            Some((lo, period)) => {
                                let theta = std::f64::consts::TAU * (v - lo) / period;
                                mean[j] += mu * w * theta.cos();
                                sin[j] += mu * w * theta.sin();
                            }
                        }
                    }
                }
            });
            for (j, &d) in t.state_dims.iter().enumerate() {
                next[d] = match angles[j] {
                    None => mean[j],
                    Some((lo, period)) => {
                        let turns = sin[j].atan2(mean[j]) / std::f64::consts::TAU;
                        let v = lo + period * turns.rem_euclid(1.0);
                        if v <= lo { v + period } else { v }
                    }
                };
            }
        }
    }
    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64 {
        Dynamics::reward(&self.task, x, u, precision)
    }
    fn reward_depends_on_action(&self) -> bool {
        Dynamics::reward_depends_on_action(&self.task)
    }
    fn is_goal(&self, x: &[f64]) -> bool {
        Dynamics::is_goal(&self.task, x)
    }
}

impl F64Model for LearnedModel {
    fn state_dim(&self) -> usize {
        F64Model::state_dim(&self.task)
    }
    fn n_agents(&self) -> usize {
        F64Model::n_agents(&self.task)
    }
    fn actions(&self) -> &ActionTable {
        F64Model::actions(&self.task)
    }
    fn blocks(&self) -> &[BlockSpec] {
        &self.specs
    }
    fn block_rows(&self, b: usize) -> Option<WideBlockRows<'_>> {
        let t = &self.tables.blocks[b];
        let (a32, w32) = &self.narrow[b];
        Some(WideBlockRows {
            n_actions: t.n_actions,
            actions: (a32, &t.actions),
            ptr: &t.ptr,
            col: &t.col,
            weight: (w32, &t.weight),
        })
    }
}

crate::model::impl_model!(LearnedModel);
