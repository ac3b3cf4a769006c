//! The learned fuzzy model: block transition tables estimated from transitions.
//!
//! # What is estimated
//! The task declares which state variables and action components form independent blocks
//! (for the point masses, each agent's `(s_x, v_x)` moved by `u_x`, and the same for `y`), its
//! action sets and the range of each state variable. [`fit`] estimates, for every block, every
//! block core `x_c` and every block action `a`, the distribution of the block's successor
//! `x'` from `(x_c, a)` as the fuzzy grid sees it: the expected memberships
//! `P[c, a, k] = E[mu_k(x')]` over the block's cores `k`. It never calls the model's
//! transition function; the reward stays the task's.
//!
//! # The estimator: local linear regression around each core
//! For row `(c, a)`, the samples whose block action is `a` are weighted by a triangular
//! kernel around `x_c` that equals the core's own membership function (so a sample counts for
//! the cores it activates, by how much it activates them). Each successor variable `x'_j` is
//! regressed by weighted least squares on `1, x - x_c`; the intercept is the mean successor
//! at the core, `m_c`. Why this estimator: a membership-weighted *average* of the samples'
//! successors would blur the dynamics over a whole cell (the successors of states around the
//! core, not of the core), while the local linear fit is exact for dynamics that are linear
//! over the kernel's support, which the point masses are everywhere (constant friction), and
//! first-order accurate for smooth nonlinear ones.
//!
//! - **Clamped successors.** A successor variable at its range's edge was clamped by the
//!   plant; it says nothing about the slope, so it is left out of that variable's fit. A mean
//!   beyond the edge saturates in the memberships exactly as the clamp would.
//! - **The distribution.** The fit's residuals `r_i = x'_i - (m_c + beta (x_i - x_c))` of the
//!   weighted samples are the noise around the mean; the row averages the memberships of
//!   `m_c + r_i` with the kernel weights. Rows stay non-negative and sum to 1, so the backup
//!   remains a gamma-contraction. Without noise every residual is rounding, and the row is the
//!   memberships of `m_c` (entries below `1e-9` are dropped and the row renormalised).
//! - **Periodic variables.** A variable the task declares periodic ([`Dynamics::is_periodic`],
//!   a robot's heading) is fitted on wrapped differences: offsets from the core and steps
//!   `x'_j - x_j` are taken the short way round, so a successor across the range's ends
//!   continues the core's side, and the row's successors are wrapped back into the range
//!   (never clamped).
//! - **Too few samples.** A row needs [`FitConfig::min_samples`] samples for every successor
//!   variable, with offsets that surround the core: the fitted mean's variance may be at
//!   most [`MAX_INTERCEPT_VARIANCE`] times a weighted mean's. A fit that extrapolates
//!   (samples on one side of the core, or on a nearly flat set such as a robot turning in
//!   place) makes the mean a guess. Where the core's own kernel does not hold such samples,
//!   it widens by doubling one variable at a time, always the one whose kernel covers the
//!   smallest fraction of its range (a grid dense near a goal first widens where it is
//!   dense, before the kernel blurs a coarse variable), each up to
//!   [`FitConfig::max_widening`]. A core that no window surrounds (at a range's edge) takes
//!   the determined fit with the smallest intercept variance. Every such row is *reported*
//!   ([`BlockFit::under_sampled`]) with the widening per variable it needed. A block action
//!   with no sample at all is an error: there is nothing to estimate from.

use fuzzyq_core::{Membership, Model, Partition, ProductPartition};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{ConfigError, require};
use crate::learn::samples::Transitions;
use crate::model::learned::{BlockTable, BlockTables};
use crate::model::{BlockSpec, Dynamics, EnvModel, F64Model};

/// Settings of [`fit`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FitConfig {
    /// Samples a row's fit needs per successor variable (at least the block's dimension
    /// plus 1); fewer widen the kernel.
    pub min_samples: usize,
    /// Largest kernel widening per variable (a power of 2); a row that still lacks samples
    /// uses the widest window it has.
    pub max_widening: usize,
    /// The grid's membership functions, which the rows' expected memberships are taken with
    /// (the kernel around each core stays triangular).
    pub membership: Membership,
}

impl Default for FitConfig {
    fn default() -> Self {
        Self {
            min_samples: 6,
            max_widening: 64,
            membership: Membership::Triangular,
        }
    }
}

/// A row that needed a wider kernel than its core's membership function.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UnderSampled {
    /// The block core's state (the block's variables).
    pub core: Vec<f64>,
    /// The block action's values.
    pub action: Vec<f64>,
    /// Samples of the action under the core's own kernel.
    pub samples: usize,
    /// The widening factor used per block variable (`None`: even the widest window lacked
    /// samples, and the row used what it had).
    pub widening: Option<Vec<usize>>,
    /// Whether no window's samples surrounded the core (a core at a range's edge, or data on
    /// one side of it), so the fit with the smallest intercept variance was taken.
    pub extrapolated: bool,
}

/// The largest variance of a row's fitted mean relative to a weighted mean of its samples
/// (`1 + D^2`, `D` the core's Mahalanobis distance from the samples' weighted centroid): a
/// fit whose samples do not surround its core within 3 standard deviations extrapolates,
/// and its kernel widens instead (see the [module docs](self)).
pub const MAX_INTERCEPT_VARIANCE: f64 = 10.0;

/// How many under-sampled rows a [`BlockFit`] lists (it counts them all).
pub const UNDER_SAMPLED_LISTED: usize = 1000;

/// How one block's table was estimated.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BlockFit {
    /// The block's state variables.
    pub state_dims: Vec<usize>,
    /// The block's action components.
    pub action_components: Vec<usize>,
    /// Rows (block cores x block actions).
    pub rows: usize,
    /// Transitions per block action.
    pub samples_per_action: Vec<usize>,
    /// Mean number of entries per row (1 to `2^d` without noise).
    pub entries_per_row: f64,
    /// Root mean square of the fits' residuals per state variable (noise and misfit).
    pub residual_rms: Vec<f64>,
    /// Rows that needed a wider kernel.
    pub under_sampled_rows: usize,
    /// The first [`UNDER_SAMPLED_LISTED`] of them.
    pub under_sampled: Vec<UnderSampled>,
}

/// What [`fit`] reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FitReport {
    /// Transitions used.
    pub samples: usize,
    /// One entry per block.
    pub blocks: Vec<BlockFit>,
    /// Transitions whose recorded reward differs from the task's reward by more than `1e-9`
    /// (the task's reward is used; a mismatch means the data and the task disagree).
    pub reward_mismatches: usize,
}

impl FitReport {
    /// Rows that needed a wider kernel, over every block.
    #[must_use]
    pub fn under_sampled_rows(&self) -> usize {
        self.blocks.iter().map(|b| b.under_sampled_rows).sum()
    }
}

/// What [`fit`] needs of a task: each state variable's range and periodicity and each
/// agent's actions. A built-in task gives it ([`TaskShape::of`]); a user's system known only
/// through its transitions declares it.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskShape {
    /// The range of each state variable.
    pub bounds: Vec<(f64, f64)>,
    /// Whether each state variable is periodic over its range (see
    /// [`Dynamics::is_periodic`]).
    pub periodic: Vec<bool>,
    /// Per agent: its actions' components (action-major) and components per action.
    pub actions: Vec<(Vec<f64>, usize)>,
}

impl TaskShape {
    /// The shape of a built-in task.
    #[must_use]
    pub fn of(task: &EnvModel) -> Self {
        let e = F64Model::state_dim(task);
        let table = F64Model::actions(task);
        Self {
            bounds: (0..e).map(|d| Dynamics::state_bounds(task, d)).collect(),
            periodic: (0..e).map(|d| Dynamics::is_periodic(task, d)).collect(),
            actions: vec![(table.values().to_vec(), table.dim()); F64Model::n_agents(task)],
        }
    }

    /// Length of the state vector.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        self.bounds.len()
    }

    /// The joint actions' vectors, joint-action-major (agent 0 most significant), and their
    /// length.
    pub fn joint_vectors(&self) -> Result<(Vec<f64>, usize), ConfigError> {
        let sets = self
            .actions
            .iter()
            .map(|(v, k)| fuzzyq_core::ActionSet::try_new(v, *k))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|err| ConfigError::invalid("actions", err.to_string()))?;
        let joint = fuzzyq_core::JointActions::try_new(&sets)
            .map_err(|err| ConfigError::invalid("actions", err.to_string()))?;
        let mut out = vec![0.0; joint.n_joint() * joint.dim()];
        for (u, chunk) in out.chunks_mut(joint.dim().max(1)).enumerate() {
            joint
                .vector(u, chunk)
                .map_err(|err| ConfigError::invalid("actions", err.to_string()))?;
        }
        Ok((out, joint.dim()))
    }
}

/// Estimates the block tables of `task` on the grid `cores` from `data` (see the
/// [module docs](self)); `blocks` declares the independent blocks (usually the task's own,
/// [`F64Model::blocks`], or one block of everything for a task without blocks). The report
/// counts the transitions whose reward differs from the task's.
pub fn fit(
    task: &EnvModel,
    cores: &[Vec<f64>],
    blocks: &[BlockSpec],
    data: &Transitions,
    config: &FitConfig,
) -> Result<(BlockTables, FitReport), ConfigError> {
    let (tables, fits) = fit_shape(&TaskShape::of(task), cores, blocks, data, config)?;
    let reward_mismatches = (0..data.len())
        .filter(|&i| {
            let (x, u, _, r) = data.get(i);
            (Dynamics::reward(task, x, u, fuzzyq_core::solver::Precision::F64) - r).abs() > 1e-9
        })
        .count();
    Ok((
        tables,
        FitReport {
            samples: data.len(),
            blocks: fits,
            reward_mismatches,
        },
    ))
}

/// [`fit`] for a task given by its [`TaskShape`]: the tables and each block's report.
pub fn fit_shape(
    shape: &TaskShape,
    cores: &[Vec<f64>],
    blocks: &[BlockSpec],
    data: &Transitions,
    config: &FitConfig,
) -> Result<(BlockTables, Vec<BlockFit>), ConfigError> {
    let e = shape.state_dim();
    let (vectors, dim) = shape.joint_vectors()?;
    require!(
        data.state_dim() == e && data.action_dim() == dim,
        "transitions",
        format!(
            "have states of {} and actions of {} values; the task has {e} and {dim}",
            data.state_dim(),
            data.action_dim(),
        ),
    );
    require!(!data.is_empty(), "transitions", "there are none");
    require!(
        cores.len() == e,
        "grid",
        "needs cores for every state variable"
    );
    for b in blocks {
        require!(
            config.min_samples > b.state_dims.len(),
            "min_samples",
            format!(
                "must exceed the block dimension {} (a linear fit has {} parameters)",
                b.state_dims.len(),
                b.state_dims.len() + 1
            ),
        );
    }
    let mut tables = Vec::with_capacity(blocks.len());
    let mut fits = Vec::with_capacity(blocks.len());
    for spec in blocks {
        // Distinct values of the block's action components, in order of first appearance.
        let k = spec.action_components.len();
        let mut actions: Vec<f64> = Vec::new();
        let mut n_actions = 0;
        for u in vectors.chunks(dim.max(1)) {
            let t: Vec<f64> = spec.action_components.iter().map(|&c| u[c]).collect();
            if !(0..n_actions).any(|a| actions[a * k..(a + 1) * k] == t[..]) {
                actions.extend_from_slice(&t);
                n_actions += 1;
            }
        }
        let block = BlockFitter {
            cores: spec.state_dims.iter().map(|&d| &cores[d][..]).collect(),
            spec,
            periodic: spec.state_dims.iter().map(|&d| shape.periodic[d]).collect(),
            bounds: spec.state_dims.iter().map(|&d| shape.bounds[d]).collect(),
            config,
        };
        let (table, report) = block.run(data, &actions, n_actions)?;
        tables.push(table);
        fits.push(report);
    }
    Ok((
        BlockTables {
            cores: cores.to_vec(),
            blocks: tables,
            membership: config.membership,
        },
        fits,
    ))
}

/// One block's estimation.
struct BlockFitter<'a> {
    spec: &'a BlockSpec,
    cores: Vec<&'a [f64]>,
    /// Whether each block variable is periodic over its bounds.
    periodic: Vec<bool>,
    bounds: Vec<(f64, f64)>,
    config: &'a FitConfig,
}

/// One estimated row and how it was obtained.
struct RowFit {
    /// `(block core, expected membership)`, increasing cores.
    entries: Vec<(u32, f64)>,
    /// Samples under the core's own kernel.
    own: usize,
    /// The widening used per variable.
    widening: Vec<usize>,
    /// Whether even the widest window could not support a fit.
    fell_back: bool,
    /// Whether no window surrounded the core (the least extrapolating fit was taken).
    extrapolated: bool,
    /// Kernel-weighted squared residuals and their weights, per variable.
    sq: Vec<f64>,
    sq_n: Vec<f64>,
}

/// One row's weighted window: sample indices and kernel weights.
type Window = Vec<(usize, f64)>;

/// A row's fit: the means at the core and the residuals (sample-major).
type Fitted = (Vec<f64>, Vec<f64>);

impl BlockFitter<'_> {
    fn run(
        &self,
        data: &Transitions,
        actions: &[f64],
        n_actions: usize,
    ) -> Result<(BlockTable, BlockFit), ConfigError> {
        let d = self.spec.state_dims.len();
        let k = self.spec.action_components.len();
        // Each transition's block action.
        let mut by_action: Vec<Vec<usize>> = vec![Vec::new(); n_actions];
        for i in 0..data.len() {
            let (_, u, _, _) = data.get(i);
            let a = (0..n_actions)
                .find(|&a| {
                    self.spec
                        .action_components
                        .iter()
                        .zip(&actions[a * k..(a + 1) * k])
                        .all(|(&c, &v)| u[c] == v)
                })
                .ok_or_else(|| {
                    ConfigError::invalid(
                        "transitions",
                        format!("transition {i}: its action is not one of the task's actions"),
                    )
                })?;
            by_action[a].push(i);
        }
        // Each action's samples in increasing order of the block's first variable, so that a
        // window is found by two binary searches and a scan of its slab.
        let first = self.spec.state_dims[0];
        for samples in &mut by_action {
            samples.sort_by(|&i, &j| data.get(i).0[first].total_cmp(&data.get(j).0[first]));
        }
        if let Some(a) = by_action.iter().position(Vec::is_empty) {
            return Err(ConfigError::invalid(
                "transitions",
                format!(
                    "no transition takes action {:?} of block {:?}: collect more samples",
                    &actions[a * k..(a + 1) * k],
                    self.spec.state_dims
                ),
            ));
        }
        let parts: Vec<Partition<'_, f64>> = self
            .cores
            .iter()
            .map(|c| Partition::try_from_cores(c))
            .collect::<Result<_, _>>()
            .map_err(|err| ConfigError::invalid("grid", err.to_string()))?;
        let sub = ProductPartition::from_partitions(&parts)
            .map_err(|err| ConfigError::invalid("grid", err.to_string()))?
            .with_membership(self.config.membership);
        let n_cores = sub.n_cores();
        // Rows in parallel over block cores, merged in core order: the same tables for any
        // thread count.
        let per_core: Vec<Result<Vec<RowFit>, ConfigError>> = (0..n_cores)
            .into_par_iter()
            .map(|c| {
                let mut core = vec![0.0; d];
                sub.core_state(c, &mut core)
                    .map_err(|err| ConfigError::invalid("grid", err.to_string()))?;
                Ok(by_action
                    .iter()
                    .map(|samples| self.row(data, samples, &core, &sub))
                    .collect())
            })
            .collect();
        let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
        let (mut under_sampled, mut under_sampled_rows) = (Vec::new(), 0);
        let (mut sq, mut sq_n) = (vec![0.0f64; d], vec![0.0f64; d]);
        let mut core = vec![0.0; d];
        for (c, rows) in per_core.into_iter().enumerate() {
            for (a, row) in rows?.into_iter().enumerate() {
                if row.widening.iter().any(|&h| h > 1) || row.fell_back || row.extrapolated {
                    under_sampled_rows += 1;
                    if under_sampled.len() < UNDER_SAMPLED_LISTED {
                        sub.core_state(c, &mut core)
                            .map_err(|err| ConfigError::invalid("grid", err.to_string()))?;
                        under_sampled.push(UnderSampled {
                            core: core.clone(),
                            action: actions[a * k..(a + 1) * k].to_vec(),
                            samples: row.own,
                            widening: (!row.fell_back).then_some(row.widening),
                            extrapolated: row.extrapolated,
                        });
                    }
                }
                for j in 0..d {
                    sq[j] += row.sq[j];
                    sq_n[j] += row.sq_n[j];
                }
                for (kc, w) in row.entries {
                    col.push(kc);
                    weight.push(w);
                }
                ptr.push(
                    u32::try_from(col.len()).map_err(|_| {
                        ConfigError::invalid("grid", "the learned table is too large")
                    })?,
                );
            }
        }
        let rows = n_cores * n_actions;
        let fit = BlockFit {
            state_dims: self.spec.state_dims.clone(),
            action_components: self.spec.action_components.clone(),
            rows,
            samples_per_action: by_action.iter().map(Vec::len).collect(),
            entries_per_row: col.len() as f64 / rows as f64,
            residual_rms: sq
                .iter()
                .zip(&sq_n)
                .map(|(s, n)| if *n > 0.0 { (s / n).sqrt() } else { 0.0 })
                .collect(),
            under_sampled_rows,
            under_sampled,
        };
        let table = BlockTable {
            state_dims: self.spec.state_dims.clone(),
            action_components: self.spec.action_components.clone(),
            n_actions,
            actions: actions.to_vec(),
            ptr,
            col,
            weight,
        };
        Ok((table, fit))
    }

    /// Row (`core`, the action of `samples`): fitted on the narrowest window that supports
    /// it (see the [module docs](self)).
    fn row(
        &self,
        data: &Transitions,
        samples: &[usize],
        core: &[f64],
        sub: &ProductPartition<'_, f64>,
    ) -> RowFit {
        let d = core.len();
        let mut widening = vec![1usize; d];
        // The core's distances to its neighbours below and above, per variable.
        let sides: Vec<[f64; 2]> = (0..d).map(|j| self.sides(j, core[j])).collect();
        let mut own = None;
        // The first window whose fit surrounds the core; failing that, the determined fit
        // with the smallest intercept variance (a core at a range's edge is never
        // surrounded).
        let mut best: Option<(f64, Vec<usize>, Window, Fitted)> = None;
        let fitted = loop {
            let window = self.window(data, samples, core, &sides, &widening);
            own.get_or_insert(window.len());
            if let Some((mean, residuals, variance)) = self.fit_row(data, &window, core) {
                if variance <= MAX_INTERCEPT_VARIANCE {
                    break Some((window, (mean, residuals)));
                }
                if best.as_ref().is_none_or(|b| variance < b.0) {
                    best = Some((variance, widening.clone(), window, (mean, residuals)));
                }
            }
            // Widen the variable whose kernel covers the smallest fraction of its range.
            let narrowest = (0..d)
                .filter(|&j| widening[j] < self.config.max_widening)
                .map(|j| {
                    let width = widening[j] as f64 * (sides[j][0] + sides[j][1]);
                    let (lo, hi) = self.bounds[j];
                    (j, width / (hi - lo).max(f64::MIN_POSITIVE))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match narrowest {
                Some((j, _)) => widening[j] *= 2,
                None => break None,
            }
        };
        let extrapolated = fitted.is_none() && best.is_some();
        let fitted = fitted.or_else(|| {
            best.map(|(_, w, window, fit)| {
                widening = w;
                (window, fit)
            })
        });
        let fell_back = fitted.is_none();
        let (window, (mean, residuals)) = fitted.unwrap_or_else(|| {
            // The widest window (every sample of the action if it is empty), with whatever
            // it supports.
            let mut window = self.window(data, samples, core, &sides, &widening);
            if window.is_empty() {
                window = samples.iter().map(|&i| (i, 1.0)).collect();
            }
            let row = self.fallback_row(data, &window, core);
            (window, row)
        });
        // The memberships of the mean plus each residual, kernel-weighted.
        let (mut sq, mut sq_n) = (vec![0.0f64; d], vec![0.0f64; d]);
        let mut point = vec![0.0; d];
        let mut acc: Vec<(u32, f64)> = Vec::new();
        let total: f64 = window.iter().map(|&(_, w)| w).sum();
        for (&(_, w), r) in window.iter().zip(residuals.chunks(d)) {
            for j in 0..d {
                point[j] = self.in_range(j, mean[j] + r[j]);
                if r[j] != 0.0 {
                    sq[j] += w / total * r[j] * r[j];
                    sq_n[j] += w / total;
                }
            }
            sub.active_unchecked(&point)
                .for_each(|kc, mu| acc.push((kc as u32, w / total * mu)));
        }
        // Merge equal columns (a stable sort keeps each column's sum in sample order).
        acc.sort_by_key(|&(kc, _)| kc);
        let mut entries: Vec<(u32, f64)> = Vec::new();
        for (kc, v) in acc {
            match entries.last_mut() {
                Some((last, sum)) if *last == kc => *sum += v,
                _ => entries.push((kc, v)),
            }
        }
        entries.retain(|&(_, v)| v >= 1e-9);
        let kept: f64 = entries.iter().map(|&(_, v)| v).sum();
        for e in &mut entries {
            e.1 /= kept;
        }
        RowFit {
            entries,
            own: own.unwrap_or(0),
            widening,
            fell_back,
            extrapolated,
            sq,
            sq_n,
        }
    }

    /// The samples of `samples` under the triangular kernel around `core` (whose neighbours
    /// lie `sides[j]` below and above it) widened by `widening[j]` along variable `j` (all 1:
    /// the core's membership function), with their weights.
    fn window(
        &self,
        data: &Transitions,
        samples: &[usize],
        core: &[f64],
        sides: &[[f64; 2]],
        widening: &[usize],
    ) -> Window {
        let first = self.spec.state_dims[0];
        // The slab of the first variable by two binary searches (the whole list if it is
        // periodic: its window may wrap).
        let slab = if self.periodic[0] {
            samples
        } else {
            let h = widening[0] as f64;
            let (lo, hi) = (core[0] - h * sides[0][0], core[0] + h * sides[0][1]);
            let key = |i: usize| data.get(i).0[first];
            let start = samples.partition_point(|&i| key(i) <= lo);
            let end = samples.partition_point(|&i| key(i) < hi);
            &samples[start..end.max(start)]
        };
        slab.iter()
            .filter_map(|&i| {
                let (x, _, _, _) = data.get(i);
                let mut w = 1.0;
                for (j, &dim) in self.spec.state_dims.iter().enumerate() {
                    let dx = self.offset(j, x[dim], core[j]);
                    let width = widening[j] as f64 * sides[j][usize::from(dx >= 0.0)];
                    w *= (1.0 - dx.abs() / width).max(0.0);
                }
                (w > 0.0).then_some((i, w))
            })
            .collect()
    }

    /// `v - from` for variable `j`, the short way round if it is periodic.
    fn offset(&self, j: usize, v: f64, from: f64) -> f64 {
        let dx = v - from;
        if !self.periodic[j] {
            return dx;
        }
        let (lo, hi) = self.bounds[j];
        let period = hi - lo;
        (dx + 0.5 * period).rem_euclid(period) - 0.5 * period
    }

    /// `v` in variable `j`'s range: clamped, or wrapped into `(lo, hi]` if it is periodic.
    fn in_range(&self, j: usize, v: f64) -> f64 {
        let (lo, hi) = self.bounds[j];
        if !self.periodic[j] {
            return v.clamp(lo, hi);
        }
        let w = lo + (v - lo).rem_euclid(hi - lo);
        if w <= lo { w + (hi - lo) } else { w.min(hi) }
    }

    /// Sample `i`'s successor of block variable `j` as the fit sees it: the recorded value,
    /// or for a periodic variable the core's value plus the wrapped offset of the sample
    /// from the core plus its wrapped step (continuous across the range's ends).
    fn successor(&self, data: &Transitions, i: usize, j: usize, core: f64) -> f64 {
        let dim = self.spec.state_dims[j];
        let (x, _, next, _) = data.get(i);
        if self.periodic[j] {
            core + self.offset(j, x[dim], core) + self.offset(j, next[dim], x[dim])
        } else {
            next[dim]
        }
    }

    /// The distances from the core at `c` of variable `j` to its neighbours below and above
    /// (the other neighbour's at the edges; the whole range for a single core).
    fn sides(&self, j: usize, c: f64) -> [f64; 2] {
        let cs = self.cores[j];
        if cs.len() == 1 {
            let (lo, hi) = self.bounds[j];
            return [(hi - lo).max(f64::MIN_POSITIVE); 2];
        }
        let i = cs.iter().position(|&v| v == c).unwrap_or(0);
        let up = (i + 1 < cs.len()).then(|| cs[i + 1] - c);
        let down = (i > 0).then(|| c - cs[i - 1]);
        match (down, up) {
            (Some(a), Some(b)) => [a, b],
            (Some(s), None) | (None, Some(s)) => [s, s],
            (None, None) => [1.0, 1.0],
        }
    }

    /// Whether the successor's variable `j` sits at an edge of its range (clamped; never for
    /// a periodic variable).
    fn clamped(&self, j: usize, v: f64) -> bool {
        if self.periodic[j] {
            return false;
        }
        let (lo, hi) = self.bounds[j];
        let tol = 1e-12 * (hi - lo).abs().max(1.0);
        v <= lo + tol || v >= hi - tol
    }

    /// The local linear fit of every successor variable over `window`: the means at `core`,
    /// the residuals (sample-major, 0 for clamped values) and the largest intercept variance
    /// relative to a weighted mean's (see [`MAX_INTERCEPT_VARIANCE`]); `None` if some
    /// variable lacks [`FitConfig::min_samples`] unclamped samples with independent offsets.
    fn fit_row(
        &self,
        data: &Transitions,
        window: &Window,
        core: &[f64],
    ) -> Option<(Vec<f64>, Vec<f64>, f64)> {
        let d = self.spec.state_dims.len();
        let p = d + 1;
        let mut largest_variance = 0.0f64;
        let mut means = Vec::with_capacity(d);
        let mut residuals = vec![0.0; window.len() * d];
        for j in 0..d {
            let dim = self.spec.state_dims[j];
            let rows: Vec<(usize, f64)> = window
                .iter()
                .enumerate()
                .filter(|&(_, &(i, _))| !self.clamped(j, data.get(i).2[dim]))
                .map(|(s, &(_, w))| (s, w))
                .collect();
            if rows.len() < self.config.min_samples {
                return None;
            }
            let mut design = DMatrix::<f64>::zeros(rows.len(), p);
            let mut target = DVector::<f64>::zeros(rows.len());
            for (r, &(s, w)) in rows.iter().enumerate() {
                let i = window[s].0;
                let (x, _, _, _) = data.get(i);
                let sw = w.sqrt();
                design[(r, 0)] = sw;
                for (l, &ld) in self.spec.state_dims.iter().enumerate() {
                    design[(r, l + 1)] = sw * self.offset(l, x[ld], core[l]);
                }
                target[r] = sw * self.successor(data, i, j, core[j]);
            }
            let svd = design.clone().svd(true, true);
            let smax = svd.singular_values.max();
            if svd.singular_values.min() <= 1e-9 * smax.max(f64::MIN_POSITIVE) {
                return None;
            }
            // The intercept's variance relative to a weighted mean's, `[(X'WX)^-1]_00 sum w`:
            // `1 + D^2`, D the core's Mahalanobis distance from the samples' weighted centroid.
            let v_t = svd.v_t.as_ref()?;
            let total: f64 = rows.iter().map(|&(_, w)| w).sum();
            let intercept_variance: f64 = total
                * (0..p)
                    .map(|k| (v_t[(k, 0)] / svd.singular_values[k]).powi(2))
                    .sum::<f64>();
            if !intercept_variance.is_finite() {
                return None;
            }
            largest_variance = largest_variance.max(intercept_variance);
            let beta = svd.solve(&target, 0.0).ok()?;
            means.push(beta[0]);
            for &(s, _) in &rows {
                let i = window[s].0;
                let (x, _, _, _) = data.get(i);
                let mut pred = beta[0];
                for (l, &ld) in self.spec.state_dims.iter().enumerate() {
                    pred += beta[l + 1] * self.offset(l, x[ld], core[l]);
                }
                residuals[s * d + j] = self.successor(data, i, j, core[j]) - pred;
            }
        }
        Some((means, residuals, largest_variance))
    }

    /// A row whose widest window cannot support a fit: each variable's mean is the weighted
    /// mean of the window's successors (the clamped value if every one is clamped), with no
    /// spread.
    fn fallback_row(
        &self,
        data: &Transitions,
        window: &Window,
        core: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let d = self.spec.state_dims.len();
        let total: f64 = window.iter().map(|&(_, w)| w).sum();
        let means = (0..d)
            .map(|j| {
                let m: f64 = window
                    .iter()
                    .map(|&(i, w)| w * self.successor(data, i, j, core[j]))
                    .sum::<f64>()
                    / total;
                if m.is_finite() { m } else { core[j] }
            })
            .collect();
        (means, vec![0.0; window.len() * d])
    }
}

/// How far the estimated rows are from the true ones, where the true model is known.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TableError {
    /// The block's state variables.
    pub state_dims: Vec<usize>,
    /// Largest L1 distance between an estimated row and the true one (0 to 2).
    pub max_l1: f64,
    /// Mean L1 distance over the rows.
    pub mean_l1: f64,
}

/// The L1 distance of every estimated row to the row of the true, noise-free model `truth`
/// (its transition from each block core, the other variables at their first cores and the
/// other action components from joint action 0): a check for tasks whose model is known. A
/// periodic variable's two end cores, one state, count as one.
pub fn table_error(tables: &BlockTables, truth: &EnvModel) -> Result<Vec<TableError>, ConfigError> {
    let e = F64Model::state_dim(truth);
    let joint = fuzzyq_core::model::joint_actions::<f64, _>(truth)
        .map_err(|err| ConfigError::invalid("env", err.to_string()))?;
    let mut u = vec![0.0; joint.dim()];
    joint
        .vector(0, &mut u)
        .map_err(|err| ConfigError::invalid("env", err.to_string()))?;
    let mut x: Vec<f64> = tables.cores.iter().map(|c| c[0]).collect();
    let mut next = vec![0.0; e];
    tables
        .blocks
        .iter()
        .map(|t| {
            let parts: Vec<Partition<'_, f64>> = t
                .state_dims
                .iter()
                .map(|&d| Partition::try_from_cores(&tables.cores[d][..]))
                .collect::<Result<_, _>>()
                .map_err(|err| ConfigError::invalid("grid", err.to_string()))?;
            let sub = ProductPartition::from_partitions(&parts)
                .map_err(|err| ConfigError::invalid("grid", err.to_string()))?
                .with_membership(tables.membership);
            let k = t.action_components.len();
            // A periodic variable whose cores include both ends of its range has one state
            // under two cores (a heading of -pi and pi): both count as the first.
            let wrapped_ends: Vec<bool> = t
                .state_dims
                .iter()
                .map(|&d| {
                    let (lo, hi) = Dynamics::state_bounds(truth, d);
                    let c = &tables.cores[d];
                    Dynamics::is_periodic(truth, d)
                        && c.len() > 1
                        && c[0] == lo
                        && c[c.len() - 1] == hi
                })
                .collect();
            let mut index = vec![0usize; t.state_dims.len()];
            let canonical: Vec<usize> = (0..sub.n_cores())
                .map(|kc| {
                    sub.unravel(kc, &mut index)
                        .expect("an index below the core count");
                    (0..index.len())
                        .map(|j| {
                            let last = sub.dim(j).n_cores() - 1;
                            let i = if wrapped_ends[j] && index[j] == last {
                                0
                            } else {
                                index[j]
                            };
                            i * sub.strides()[j]
                        })
                        .sum()
                })
                .collect();
            let (mut max_l1, mut sum_l1) = (0.0f64, 0.0);
            let mut core = vec![0.0; t.state_dims.len()];
            let mut truth_row = vec![0.0; sub.n_cores()];
            let mut row = vec![0.0; sub.n_cores()];
            for c in 0..sub.n_cores() {
                sub.core_state(c, &mut core)
                    .map_err(|err| ConfigError::invalid("grid", err.to_string()))?;
                for (&dim, &v) in t.state_dims.iter().zip(&core) {
                    x[dim] = v;
                }
                for a in 0..t.n_actions {
                    for (&comp, &v) in t.action_components.iter().zip(&t.actions[a * k..]) {
                        u[comp] = v;
                    }
                    Model::<f64>::step(truth, &x, &u, &mut next);
                    let succ: Vec<f64> = t.state_dims.iter().map(|&d| next[d]).collect();
                    let mut touched: Vec<usize> = Vec::new();
                    sub.active_unchecked(&succ).for_each(|kc, w| {
                        truth_row[canonical[kc]] += w;
                        touched.push(canonical[kc]);
                    });
                    let (cols, ws) = t.row(c, a);
                    for (&kc, &w) in cols.iter().zip(ws) {
                        row[canonical[kc as usize]] += w;
                        touched.push(canonical[kc as usize]);
                    }
                    touched.sort_unstable();
                    touched.dedup();
                    let mut l1 = 0.0;
                    for &kc in &touched {
                        l1 += (row[kc] - truth_row[kc]).abs();
                        row[kc] = 0.0;
                        truth_row[kc] = 0.0;
                    }
                    max_l1 = max_l1.max(l1);
                    sum_l1 += l1;
                }
            }
            Ok(TableError {
                state_dims: t.state_dims.clone(),
                max_l1,
                mean_l1: sum_l1 / (sub.n_cores() * t.n_actions) as f64,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::{Collection, Exploration, collect};
    use crate::model::pointmass::{PointMass, PointMassConfig};
    use crate::paper;

    fn one_agent(noise: f64) -> EnvModel {
        EnvModel::PointMass(
            PointMass::new(PointMassConfig {
                agents: 1,
                velocity_noise: noise,
                ..PointMassConfig::default()
            })
            .unwrap(),
        )
    }

    fn cores() -> Vec<Vec<f64>> {
        let (p, v) = (
            paper::POSITION_CORES.to_vec(),
            paper::VELOCITY_CORES.to_vec(),
        );
        vec![p.clone(), p, v.clone(), v]
    }

    fn data(task: &EnvModel, samples: usize, seed: u64) -> Transitions {
        let starts = crate::learn::tasks::pointmass::default_starts();
        let c = Collection {
            samples,
            episode_steps: 50,
            seed,
        };
        collect(
            task,
            &c,
            |rng, x| starts.draw(rng, x),
            &mut Exploration::Random,
        )
        .unwrap()
    }

    fn fitted(task: &EnvModel, d: &Transitions) -> (BlockTables, FitReport) {
        fit(
            task,
            &cores(),
            F64Model::blocks(task),
            d,
            &FitConfig::default(),
        )
        .unwrap()
    }

    #[test]
    fn recovers_the_exact_point_mass_tables_without_noise() {
        let task = one_agent(0.0);
        let (tables, report) = fitted(&task, &data(&task, 2000, 1));
        assert_eq!(report.reward_mismatches, 0);
        for e in table_error(&tables, &task).unwrap() {
            assert!(e.max_l1 < 1e-9, "{e:?}");
        }
        // At most 4 successor cores per row of a 2-variable block, as the model's own rows.
        for b in &report.blocks {
            assert!(b.entries_per_row <= 4.0, "{b:?}");
        }
        tables.check(&task).unwrap();
    }

    #[test]
    fn noise_spreads_rows_that_still_sum_to_one() {
        let sigma = 0.1;
        let task = one_agent(sigma);
        let (tables, report) = fitted(&task, &data(&task, 4000, 2));
        tables.check(&task).unwrap();
        for b in &report.blocks {
            // Positions carry no noise; velocities carry sigma (a local fit's residuals).
            assert!(b.residual_rms[0] < 1e-9, "{b:?}");
            let v = b.residual_rms[1];
            assert!((0.8 * sigma..1.2 * sigma).contains(&v), "{b:?}");
        }
        let exact = fitted(&one_agent(0.0), &data(&one_agent(0.0), 4000, 2)).1;
        assert!(report.blocks[0].entries_per_row > exact.blocks[0].entries_per_row);
        let err = table_error(&tables, &task).unwrap();
        assert!(err.iter().all(|e| e.max_l1 > 1e-3), "{err:?}");
    }

    #[test]
    fn the_same_seed_gives_the_same_tables_for_any_thread_count() {
        let task = one_agent(0.05);
        let d = data(&task, 1500, 3);
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| fitted(&task, &d))
        };
        let (one, r1) = run(1);
        let (two, r2) = run(2);
        assert_eq!(one, two);
        assert_eq!(r1, r2);
        assert_eq!(data(&task, 1500, 3), d, "collection is seeded");
        assert_ne!(data(&task, 1500, 4), d);
    }

    /// A row whose own kernel holds only two tight clusters of samples on one side of the
    /// core (a nearly flat design) must not extrapolate its noisy fit to the core: the kernel
    /// widens until the samples surround it, and the row stays close to the true one.
    #[test]
    fn a_row_never_extrapolates_from_samples_on_one_side() {
        use rand::SeedableRng;
        let task = one_agent(0.05);
        let core = [3.0, 1.0];
        let own_kernel = |x: &[f64]| x[0] > 0.3 && x[0] < 6.0 && x[2] > 0.0 && x[2] < 3.0;
        let wide = data(&task, 3000, 6);
        let mut d = Transitions::new(4, 2);
        for i in 0..wide.len() {
            let (x, u, n, r) = wide.get(i);
            if !own_kernel(x) {
                d.push(x, u, n, r);
            }
        }
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let actions = F64Model::actions(&task).clone();
        let (mut next, mut k) = (vec![0.0; 4], 0.0);
        for centre in [[3.5, 1.2], [4.0, 1.5]] {
            for _ in 0..12 {
                for a in 0..actions.len() {
                    k += 1e-4;
                    let x = [centre[0] + k, 0.0, centre[1] - k, 0.0];
                    let u = actions.action(a);
                    Dynamics::step(&task, &x, u, &mut next);
                    task.add_process_noise(&mut next, &mut rng);
                    let r = Dynamics::reward(&task, &x, u, fuzzyq_core::solver::Precision::F64);
                    d.push(&x, u, &next, r);
                }
            }
        }
        let (tables, report) = fitted(&task, &d);
        for e in table_error(&tables, &task).unwrap() {
            assert!(e.max_l1 < 0.5, "{e:?}");
        }
        let listed = &report.blocks[0].under_sampled;
        assert!(
            listed.iter().any(|u| u.core == core && u.samples > 0),
            "the clustered rows widen"
        );
    }

    /// A periodic variable (the heading) is fitted across its range's ends: a robot turning
    /// from a heading core near pi gets a successor just past -pi, not one a full turn away,
    /// and learning on the rapier plant gives rows close to the kinematic model's.
    #[test]
    fn headings_are_fitted_across_the_ends_of_their_range() {
        use crate::learn::samples::collect_khepera;
        use crate::model::khepera::{KheperaConfig, KheperaModel};
        let model = KheperaModel::new(KheperaConfig {
            agents: 1,
            ..KheperaConfig::default()
        })
        .unwrap();
        let c = Collection {
            samples: 3000,
            episode_steps: 50,
            seed: 8,
        };
        let d = collect_khepera(&model, &c, &mut Exploration::Random).unwrap();
        let pi = std::f64::consts::PI;
        let heading: Vec<f64> = (0..=8)
            .map(|i| -pi + 2.0 * pi * f64::from(i) / 8.0)
            .collect();
        let position = vec![-6.0, -3.0, 0.0, 3.0, 6.0];
        let cores = vec![position.clone(), position, heading];
        let task = EnvModel::Khepera(model);
        let (tables, report) = fit(
            &task,
            &cores,
            F64Model::blocks(&task),
            &d,
            &FitConfig::default(),
        )
        .unwrap();
        tables.check(&task).unwrap();
        let err = table_error(&tables, &task).unwrap();
        assert!(
            err[0].mean_l1 < 0.05,
            "{err:?} {:?}",
            report.blocks[0].residual_rms
        );
    }

    #[test]
    fn refuses_data_it_cannot_use() {
        let task = one_agent(0.0);
        let d = data(&task, 200, 5);
        let (x, u, n, r) = d.get(0);
        let mut odd = Transitions::new(4, 2);
        odd.push(x, &[u[0] + 0.5, u[1]], n, r);
        let e = fit(
            &task,
            &cores(),
            F64Model::blocks(&task),
            &odd,
            &FitConfig::default(),
        );
        assert!(
            e.unwrap_err()
                .to_string()
                .contains("not one of the task's actions")
        );
        // Too few samples: some block action never taken.
        let e = fit(
            &task,
            &cores(),
            F64Model::blocks(&task),
            &d.truncated(3),
            &FitConfig::default(),
        );
        assert!(e.unwrap_err().to_string().contains("collect more"));
        let e =
            Transitions::from_columns(4, 2, vec![0.0; 4], vec![0.0; 2], vec![0.0; 3], vec![0.0]);
        assert!(e.unwrap_err().to_string().contains("next_states"));
    }
}
