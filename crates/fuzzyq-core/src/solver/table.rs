//! Models known only at a grid's cores: [`TabulatedModel`].
//!
//! A model written in another language (a vectorised Python callable, say) is evaluated once at
//! every (core, joint action) pair of the grid to be solved; fuzzy Q-iteration needs nothing
//! else, because `theta[d, u] = rho(x_d, u) + gamma V~(f(x_d, u))` only involves the cores
//! `x_d`, and so do the greedy and interpolated policies. The solver reads the table directly
//! (successors' memberships are precomputed once); [`Model::step`] and [`Model::reward`] look
//! the table up, so they are defined at the cores and the discrete joint actions only.

use std::collections::HashSet;
use std::vec::Vec;

use super::{Grid, SolveError};
use crate::action::{ActionSet, MAX_AGENTS};
use crate::model::{Block, Model, Tabulated};
use crate::real::Real;

/// One independent dynamics block of a [`TabulatedModel`] (see the [model docs](crate::model)):
/// the block's successors at every block core and block action.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockTable<T> {
    /// The block's state variables, increasing.
    pub state_dims: Vec<usize>,
    /// The joint-action-vector components driving the block.
    pub action_components: Vec<usize>,
    /// The distinct values the joint actions give those components (block actions),
    /// `n_actions * action_components.len()` values, in order of first appearance over the
    /// joint actions (agent 0 most significant).
    pub actions: Vec<T>,
    /// The block's successor variables per block core (row-major over `state_dims`, the last
    /// fastest, with the grid's cores) and block action: `n_block_cores * n_actions *
    /// state_dims.len()` values.
    pub next: Vec<T>,
}

impl<T: Real> BlockTable<T> {
    /// The distinct tuples of `components` over the joint actions of `actions` (per agent:
    /// values, action-major, and components per action), in order of first appearance, and the
    /// first joint action giving each.
    pub fn block_actions(
        actions: &[(Vec<T>, usize)],
        components: &[usize],
    ) -> Result<(Vec<T>, Vec<usize>), SolveError> {
        let sets = action_sets(actions)?;
        let joint = crate::action::JointActions::try_new(&sets)?;
        let mut u = vec![T::ZERO; joint.dim()];
        let mut tuples: Vec<T> = Vec::new();
        let mut first = Vec::new();
        let k = components.len();
        for j in 0..joint.n_joint() {
            joint.vector_unchecked(j, &mut u);
            let t: Vec<T> = components.iter().map(|&c| u[c]).collect();
            let seen = if k == 0 {
                !first.is_empty()
            } else {
                tuples.chunks(k).any(|s| s == t.as_slice())
            };
            if !seen {
                tuples.extend_from_slice(&t);
                first.push(j);
            }
        }
        Ok((tuples, first))
    }

    fn n_actions(&self) -> usize {
        if self.action_components.is_empty() {
            1
        } else {
            self.actions.len() / self.action_components.len()
        }
    }
}

/// One independent dynamics block's transitions given as rows (a learned or stochastic table):
/// the owned form of [`BlockRows`](crate::model::BlockRows), whose docs define the layout.
/// Block cores are those of the grid's cores of [`state_dims`](Self::state_dims).
#[derive(Clone, Debug, PartialEq)]
pub struct RowsTable<T> {
    /// The block's state variables, increasing.
    pub state_dims: Vec<usize>,
    /// The joint-action-vector components driving the block.
    pub action_components: Vec<usize>,
    /// The block actions, as [`BlockTable::block_actions`] gives them.
    pub actions: Vec<T>,
    /// Row starts, `n_block_cores * n_actions + 1` values.
    pub ptr: Vec<u32>,
    /// Block core of each entry.
    pub col: Vec<u32>,
    /// Expected membership of each entry.
    pub weight: Vec<T>,
}

impl<T: Real> RowsTable<T> {
    fn n_actions(&self) -> usize {
        match self.action_components.len() {
            0 => 1,
            k => self.actions.len() / k,
        }
    }
}

/// What a [`TabulatedModel`] stores of its successors.
#[derive(Clone, Debug)]
enum Successors<T> {
    /// Every (core, joint action) pair's successor: `N * M * E` values.
    Full(Vec<T>),
    /// Per independent dynamics block, its successors at its block cores.
    Blocks(Vec<BlockTable<T>>),
    /// Per independent dynamics block, its rows of expected memberships.
    Rows(Vec<RowsTable<T>>),
}

/// Successors and rewards of every (core, joint action) pair of one grid, and the terminal
/// successors.
///
/// Successors are stored in full (`N * M * E` values) or, for a model with independent
/// dynamics blocks, per block (a few values per block core and block action): the solver then
/// runs the block backup, and the memory is that of the rewards (`N * M` values).
#[derive(Clone, Debug)]
pub struct TabulatedModel<T> {
    grid: Grid<T>,
    /// Per agent: action components (action-major) and components per action.
    actions: Vec<(Vec<T>, usize)>,
    n_joint: usize,
    successors: Successors<T>,
    rewards: Vec<T>,
    /// Whether some core's rewards differ between joint actions.
    depends_on_action: bool,
    /// Terminal successor states, by the bits of their values.
    terminal: HashSet<Vec<u64>>,
}

/// Agent `i`'s action set of `actions`.
fn action_sets<T: Real>(actions: &[(Vec<T>, usize)]) -> Result<Vec<ActionSet<'_, T>>, SolveError> {
    if actions.is_empty() || actions.len() > MAX_AGENTS {
        return Err(crate::EvalError::Agents {
            found: actions.len(),
        }
        .into());
    }
    actions
        .iter()
        .map(|(values, dim)| ActionSet::try_new(values, *dim).map_err(SolveError::from))
        .collect()
}

/// The key of state `x` in the terminal set.
fn key<T: Real>(x: &[T]) -> Vec<u64> {
    x.iter().map(|v| v.to_f64().to_bits()).collect()
}

/// Checks blocks (state variables, action components, block actions) against the grid and
/// the action sets: each names valid variables in increasing order, the blocks partition the
/// state, and each block's actions are the joint actions' distinct values. Returns each
/// block's number of block cores.
fn check_layout<'a, T: Real + 'a>(
    grid: &Grid<T>,
    actions: &[(Vec<T>, usize)],
    blocks: impl Iterator<Item = (&'a [usize], &'a [usize], &'a [T])>,
) -> Result<Vec<usize>, SolveError> {
    let e = grid.n_dims();
    let a_dim: usize = actions.iter().map(|(_, d)| *d).sum();
    let mut count = vec![0usize; e];
    let mut n_cores = Vec::new();
    for (b, (state_dims, components, block_actions)) in blocks.enumerate() {
        let bad = |reason| SolveError::BlockDeclaration { block: b, reason };
        if state_dims.is_empty() || state_dims.windows(2).any(|w| w[0] >= w[1]) {
            return Err(bad(
                "its state variables must be given in increasing order, at least one",
            ));
        }
        for &d in state_dims {
            if d >= e {
                return Err(bad("it names a state variable beyond the state's length"));
            }
            count[d] += 1;
        }
        if components.iter().any(|&c| c >= a_dim) {
            return Err(bad(
                "it names an action component beyond the joint action's length",
            ));
        }
        let (tuples, _) = BlockTable::block_actions(actions, components)?;
        if tuples != block_actions {
            return Err(bad(
                "its block actions are not the joint actions' distinct values",
            ));
        }
        n_cores.push(state_dims.iter().map(|&d| grid.cores()[d].len()).product());
    }
    if let Some(dim) = count.iter().position(|&c| c != 1) {
        return Err(SolveError::BlockCoverage {
            dim,
            count: count[dim],
        });
    }
    Ok(n_cores)
}

impl<T: Real> TabulatedModel<T> {
    /// Builds the table. `actions[i]` holds agent `i`'s actions (`values`, action-major, and the
    /// number of components per action); `next_states` has `N * M * E` values and `rewards`
    /// `N * M`, ordered by core (row-major) then joint action (agent 0 most significant).
    pub fn new(
        grid: Grid<T>,
        actions: Vec<(Vec<T>, usize)>,
        next_states: Vec<T>,
        rewards: Vec<T>,
    ) -> Result<Self, SolveError> {
        let (n_joint, pairs) = Self::check(&grid, &actions, &rewards)?;
        crate::error::check_len("next states", pairs * grid.n_dims(), next_states.len())?;
        if next_states.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite { what: "successor" });
        }
        Ok(Self::assemble(
            grid,
            actions,
            n_joint,
            Successors::Full(next_states),
            rewards,
        ))
    }

    /// Builds the table of a model with independent dynamics blocks: the successors per block
    /// (`blocks`: a partition of the state variables, each with the block actions
    /// [`BlockTable::block_actions`] gives) and `rewards` as in [`new`](Self::new). The solver
    /// runs the block backup on it.
    pub fn with_blocks(
        grid: Grid<T>,
        actions: Vec<(Vec<T>, usize)>,
        blocks: Vec<BlockTable<T>>,
        rewards: Vec<T>,
    ) -> Result<Self, SolveError> {
        let (n_joint, _) = Self::check(&grid, &actions, &rewards)?;
        let layout = blocks
            .iter()
            .map(|t| (&t.state_dims[..], &t.action_components[..], &t.actions[..]));
        let n_cores = check_layout(&grid, &actions, layout)?;
        for (t, cores) in blocks.iter().zip(n_cores) {
            crate::error::check_len(
                "block successors",
                cores * t.n_actions() * t.state_dims.len(),
                t.next.len(),
            )?;
            if t.next.iter().any(|v| !v.is_finite()) {
                return Err(SolveError::NonFinite { what: "successor" });
            }
        }
        Ok(Self::assemble(
            grid,
            actions,
            n_joint,
            Successors::Blocks(blocks),
            rewards,
        ))
    }

    /// Builds the table of a model whose blocks' transitions are given as rows (a model
    /// learned from transitions): `rows` partition the state variables as in
    /// [`with_blocks`](Self::with_blocks), `rewards` as in [`new`](Self::new). Only the block
    /// backup reads it (the solver checks the rows); [`Model::step`] gives NaN.
    pub fn with_block_rows(
        grid: Grid<T>,
        actions: Vec<(Vec<T>, usize)>,
        rows: Vec<RowsTable<T>>,
        rewards: Vec<T>,
    ) -> Result<Self, SolveError> {
        let (n_joint, _) = Self::check(&grid, &actions, &rewards)?;
        let layout = rows
            .iter()
            .map(|t| (&t.state_dims[..], &t.action_components[..], &t.actions[..]));
        let n_cores = check_layout(&grid, &actions, layout)?;
        for (t, cores) in rows.iter().zip(n_cores) {
            crate::error::check_len("block rows", cores * t.n_actions() + 1, t.ptr.len())?;
            crate::error::check_len("block row weights", t.col.len(), t.weight.len())?;
            if t.weight.iter().any(|v| !v.is_finite()) {
                return Err(SolveError::NonFinite { what: "successor" });
            }
        }
        Ok(Self::assemble(
            grid,
            actions,
            n_joint,
            Successors::Rows(rows),
            rewards,
        ))
    }

    /// Checks the action sets and the rewards' length and values: `(M, N * M)`.
    fn check(
        grid: &Grid<T>,
        actions: &[(Vec<T>, usize)],
        rewards: &[T],
    ) -> Result<(usize, usize), SolveError> {
        let mut n_joint = 1usize;
        for set in action_sets(actions)? {
            n_joint = n_joint
                .checked_mul(set.n_actions())
                .ok_or(SolveError::TooLarge {
                    what: "joint action set",
                })?;
        }
        let pairs = grid
            .n_cores()
            .checked_mul(n_joint)
            .ok_or(SolveError::TooLarge {
                what: "transition table",
            })?;
        crate::error::check_len("rewards", pairs, rewards.len())?;
        if rewards.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite { what: "reward" });
        }
        Ok((n_joint, pairs))
    }

    fn assemble(
        grid: Grid<T>,
        actions: Vec<(Vec<T>, usize)>,
        n_joint: usize,
        successors: Successors<T>,
        rewards: Vec<T>,
    ) -> Self {
        let depends_on_action = rewards
            .chunks(n_joint)
            .any(|row| row.iter().any(|&r| r != row[0]));
        Self {
            grid,
            actions,
            n_joint,
            successors,
            rewards,
            depends_on_action,
            terminal: HashSet::new(),
        }
    }

    /// The grid the table was computed on.
    #[must_use]
    pub fn grid(&self) -> &Grid<T> {
        &self.grid
    }

    /// Number of joint actions.
    #[must_use]
    pub fn n_joint(&self) -> usize {
        self.n_joint
    }

    /// Whether the transitions are stored per independent dynamics block (successors or
    /// rows).
    #[must_use]
    pub fn has_blocks(&self) -> bool {
        !matches!(self.successors, Successors::Full(_))
    }

    /// The successor of core `d` (row-major) under joint action `j`, into `next`. A table of
    /// rows ([`with_block_rows`](Self::with_block_rows)) has distributions, not successors:
    /// [`SolveError::BlockRowsOnly`].
    pub fn successor(&self, d: usize, j: usize, next: &mut [T]) -> Result<(), SolveError> {
        let (n, e) = (self.grid.n_cores(), self.grid.n_dims());
        if d >= n {
            return Err(crate::EvalError::OutOfRange {
                what: "core",
                index: d,
                len: n,
            }
            .into());
        }
        if j >= self.n_joint {
            return Err(crate::EvalError::OutOfRange {
                what: "joint action",
                index: j,
                len: self.n_joint,
            }
            .into());
        }
        crate::error::check_len("successor", e, next.len())?;
        match &self.successors {
            Successors::Full(all) => {
                let i = (d * self.n_joint + j) * e;
                next.copy_from_slice(&all[i..i + e]);
            }
            Successors::Blocks(blocks) => {
                let mut x = vec![T::ZERO; e];
                self.grid.view().core_state(d, &mut x)?;
                let mut u = vec![T::ZERO; self.actions.iter().map(|(_, k)| *k).sum()];
                let sets = action_sets(&self.actions)?;
                crate::action::JointActions::try_new(&sets)?.vector_unchecked(j, &mut u);
                self.step_blocks(blocks, &x, &u, next);
            }
            Successors::Rows(_) => {
                return Err(SolveError::BlockRowsOnly {
                    what: "a successor state",
                });
            }
        }
        Ok(())
    }

    /// Declares the successor of core `d` under joint action `j` terminal: a transition into
    /// it (from any pair) is worth its reward and nothing after it.
    pub fn mark_terminal(&mut self, d: usize, j: usize) -> Result<(), SolveError> {
        let mut next = vec![T::ZERO; self.grid.n_dims()];
        self.successor(d, j, &mut next)?;
        self.terminal.insert(key(&next));
        Ok(())
    }

    /// Number of distinct terminal successor states.
    #[must_use]
    pub fn n_terminal(&self) -> usize {
        self.terminal.len()
    }

    /// The index of `v` among `cores`, if it is exactly one of them.
    fn position(cores: &[T], v: T) -> Option<usize> {
        cores.iter().position(|&c| c == v)
    }

    /// The successor of `x` under `u` from the block tables; NaN where `x`'s block variables
    /// are not cores or `u`'s block components not a block action.
    fn step_blocks(&self, blocks: &[BlockTable<T>], x: &[T], u: &[T], next: &mut [T]) {
        for t in blocks {
            let k = t.state_dims.len();
            let mut c = Some(0usize);
            for &d in &t.state_dims {
                let cores = &self.grid.cores()[d];
                c = c.and_then(|c| Some(c * cores.len() + Self::position(cores, x[d])?));
            }
            let na = t.n_actions();
            let q = t.action_components.len();
            let a = (0..na).find(|&a| {
                t.action_components
                    .iter()
                    .enumerate()
                    .all(|(i, &comp)| t.actions[a * q + i] == u[comp])
            });
            match (c, a) {
                (Some(c), Some(a)) => {
                    let s = &t.next[(c * na + a) * k..][..k];
                    for (&d, &v) in t.state_dims.iter().zip(s) {
                        next[d] = v;
                    }
                }
                _ => {
                    for &d in &t.state_dims {
                        next[d] = T::from_f64(f64::NAN);
                    }
                }
            }
        }
    }

    /// The core index of `x` if every component is exactly a core.
    fn core_of(&self, x: &[T]) -> Option<usize> {
        let mut d = 0;
        for (c, &v) in self.grid.cores().iter().zip(x) {
            let i = Self::position(c, v)?;
            d = d * c.len() + i;
        }
        Some(d)
    }

    /// The joint index of `u` if each agent's components are exactly one of its actions.
    fn joint_of(&self, u: &[T]) -> Option<usize> {
        let mut j = 0;
        let mut off = 0;
        for (values, dim) in &self.actions {
            let m = values.len() / dim;
            let a = (0..m).find(|&a| values[a * dim..(a + 1) * dim] == u[off..off + dim])?;
            j = j * m + a;
            off += dim;
        }
        Some(j)
    }
}

impl<T: Real> Model<T> for TabulatedModel<T> {
    fn state_dim(&self) -> usize {
        self.grid.n_dims()
    }

    fn n_agents(&self) -> usize {
        self.actions.len()
    }

    fn action_set(&self, agent: usize) -> ActionSet<'_, T> {
        let (values, dim) = &self.actions[agent];
        ActionSet::try_new(values, *dim).expect("validated in new")
    }

    fn state_bounds(&self, dim: usize) -> (T, T) {
        let c = &self.grid.cores()[dim];
        (c[0], c[c.len() - 1])
    }

    /// The tabulated successor; NaN unless `x` is a core and `u` a joint action (for a model
    /// with blocks: unless each block's variables are cores and its components a block
    /// action). Always NaN for a table of rows, which has no successors.
    fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
        let e = self.grid.n_dims();
        match &self.successors {
            Successors::Blocks(blocks) => self.step_blocks(blocks, x, u, next),
            Successors::Rows(_) => next.fill(T::from_f64(f64::NAN)),
            Successors::Full(all) => match (self.core_of(x), self.joint_of(u)) {
                (Some(d), Some(j)) => {
                    let i = (d * self.n_joint + j) * e;
                    next.copy_from_slice(&all[i..i + e]);
                }
                _ => next.fill(T::from_f64(f64::NAN)),
            },
        }
    }

    /// The tabulated reward; NaN unless `x` is a core and `u` a joint action.
    fn reward(&self, x: &[T], u: &[T]) -> T {
        match (self.core_of(x), self.joint_of(u)) {
            (Some(d), Some(j)) => self.rewards[d * self.n_joint + j],
            _ => T::from_f64(f64::NAN),
        }
    }

    fn reward_depends_on_action(&self) -> bool {
        self.depends_on_action
    }

    fn is_terminal(&self, x: &[T]) -> bool {
        self.terminal.contains(&key(x))
    }

    fn has_terminal_states(&self) -> bool {
        !self.terminal.is_empty()
    }

    fn tabulated(&self) -> Option<Tabulated<'_, T>> {
        match &self.successors {
            Successors::Full(all) => Some(Tabulated {
                n_cores: self.grid.n_cores(),
                next_states: all,
                rewards: &self.rewards,
            }),
            Successors::Blocks(_) | Successors::Rows(_) => None,
        }
    }

    fn reward_table(&self) -> Option<&[T]> {
        match &self.successors {
            Successors::Blocks(_) | Successors::Rows(_) if self.depends_on_action => {
                Some(&self.rewards)
            }
            _ => None,
        }
    }

    fn n_blocks(&self) -> usize {
        match &self.successors {
            Successors::Blocks(b) => b.len(),
            Successors::Rows(r) => r.len(),
            Successors::Full(_) => 0,
        }
    }

    fn block(&self, b: usize) -> Block<'_> {
        match &self.successors {
            Successors::Blocks(blocks) => Block {
                state_dims: &blocks[b].state_dims,
                action_components: &blocks[b].action_components,
            },
            Successors::Rows(rows) => Block {
                state_dims: &rows[b].state_dims,
                action_components: &rows[b].action_components,
            },
            Successors::Full(_) => Block {
                state_dims: &[],
                action_components: &[],
            },
        }
    }

    fn block_rows(&self, b: usize) -> Option<crate::model::BlockRows<'_, T>> {
        match &self.successors {
            Successors::Rows(rows) => rows.get(b).map(|t| crate::model::BlockRows {
                n_actions: t.n_actions(),
                actions: &t.actions,
                ptr: &t.ptr,
                col: &t.col,
                weight: &t.weight,
            }),
            _ => None,
        }
    }
}
