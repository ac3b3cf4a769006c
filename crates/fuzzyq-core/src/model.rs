//! The deterministic model a fuzzy Q-iteration solves: `x' = f(x, u)`, `r = rho(x, u)`.
//!
//! The trait lives in the core, not in `fuzzyq-sim`, because its consumers live here: the
//! solver driver and the model-based greedy policy need it, and the core must not depend on the
//! crate of concrete models. It uses slices only, so a controller without an allocator can
//! implement it too.
//!
//! # Independent dynamics blocks
//! A model may declare **blocks**: a partition of the state variables into groups whose next
//! value depends only on the group itself and on some components of the joint action vector.
//! A point mass with constant friction separates per agent and per axis: the block
//! `(s_1x, v_1x)` moves with `u_1x` alone. The solver then factors each transition into small
//! per-block tables and computes a backup as a sequence of per-block products instead of
//! `2^E` corner look-ups per core and action (see `solver`). A declaration is a promise; the
//! solver spot-checks it and tests compare the block and generic backups.
//!
//! For the gather-free fast path, declare blocks in the order of the joint action's mixed
//! radix, slowest first (for point masses: agent 1 x, agent 1 y, agent 2 x, ...).
//!
//! # Block tables given directly (learned or stochastic models)
//! A model that knows its blocks' transitions only as tables (estimated from samples, or with
//! a successor *distribution* instead of one successor) returns them from
//! [`Model::block_rows`]: per (block core, block action) the expected memberships of the
//! block's successor over the block's cores. Rows are non-negative and sum to 1, so the backup
//! `rho + gamma sum_k P[d, u, k] V[k]` stays a gamma-contraction, and the product of the
//! blocks' rows is the joint successor distribution (the blocks' noises are independent). A
//! deterministic successor is the special case of one point: its row is its memberships. Only
//! the block path reads such tables; the generic path, which steps the model, refuses the
//! model (`SolveError::BlockRowsOnly`).
//!
//! # Terminal states
//! An episodic model declares [terminal states](Model::is_terminal): a transition into one is
//! worth its reward and nothing after it. This is independent of the blocks (the block backup
//! handles terminal transitions as a correction, see `solver`) and of the absorbing-goal option
//! ([`Model::is_goal`]).

use crate::action::{ActionSet, JointActions, MAX_AGENTS};
use crate::error::EvalError;
use crate::real::Real;

/// A group of state variables that evolves independently of the rest of the state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block<'a> {
    /// The state variables of the block (indices into the state vector), in increasing order.
    pub state_dims: &'a [usize],
    /// The joint-action-vector components the block's next value depends on.
    pub action_components: &'a [usize],
}

/// One block's transition table, given directly by the model ([`Model::block_rows`]).
///
/// Block cores are numbered row-major over the block's state variables in the order of
/// [`Block::state_dims`] (the last variable fastest), with each variable's cores those of the
/// grid being solved. Row `c * n_actions + a` holds the entries `ptr[i]..ptr[i + 1]` of
/// `col` (block cores) and `weight` (expected memberships: finite, non-negative, summing to 1
/// within `1e-4`).
#[derive(Clone, Copy, Debug)]
pub struct BlockRows<'a, T> {
    /// Number of block actions (rows per block core).
    pub n_actions: usize,
    /// The values of the block's action components per block action, in row order:
    /// `n_actions * action_components.len()` values. Every value the joint actions give the
    /// components must be one of them.
    pub actions: &'a [T],
    /// Row starts, `n_cores * n_actions + 1` values from 0 to `col.len()`.
    pub ptr: &'a [u32],
    /// Block core of each entry.
    pub col: &'a [u32],
    /// Expected membership of each entry.
    pub weight: &'a [T],
}

/// Transitions precomputed at every (core, joint action) pair of a grid: what a model
/// defined outside Rust provides (see [`Model::tabulated`]). Entries are ordered by core
/// (row-major grid order), then joint action.
#[derive(Clone, Copy, Debug)]
pub struct Tabulated<'a, T> {
    /// Number of cores of the grid the table was computed on.
    pub n_cores: usize,
    /// Successor states, `n_cores * M * E` values.
    pub next_states: &'a [T],
    /// Rewards, `n_cores * M` values.
    pub rewards: &'a [T],
}

/// A deterministic multi-agent model with discrete per-agent action sets.
pub trait Model<T: Real> {
    /// Length `E` of the state vector.
    fn state_dim(&self) -> usize;

    /// Number of agents `n` (1 to [`MAX_AGENTS`]).
    fn n_agents(&self) -> usize;

    /// The discrete action set of agent `agent` (`0 <= agent < n_agents()`).
    fn action_set(&self, agent: usize) -> ActionSet<'_, T>;

    /// The range `[lo, hi]` that state variable `dim` stays in.
    fn state_bounds(&self, dim: usize) -> (T, T);

    /// The transition `f`: writes the successor of state `x` under joint action vector `u` into
    /// `next`. `x` and `next` have length `E`; `u` has the joint action vector's length. The
    /// action need not be one of the discrete actions (the interpolated policy produces
    /// weighted averages of them).
    fn step(&self, x: &[T], u: &[T], next: &mut [T]);

    /// The reward `rho(x, u)`, evaluated at the current state.
    fn reward(&self, x: &[T], u: &[T]) -> T;

    /// Whether `reward` depends on the action. When it does not, the solver evaluates it once
    /// per core instead of once per core and joint action.
    fn reward_depends_on_action(&self) -> bool {
        true
    }

    /// Whether `reward` reads state variable `dim` (`0 <= dim < state_dim()`). A model whose
    /// reward depends on the state alone ([`reward_depends_on_action`] false) and ignores
    /// some variables (the robots' reward reads their positions, not their headings) says so
    /// here, and the block path evaluates it once per class of cores that agree on the
    /// variables it reads, copying the value to the others. The default, `true` for every
    /// variable, evaluates it at every core. A reward that does read a variable declared
    /// unread gets the value of one core of its class for all of them.
    ///
    /// [`reward_depends_on_action`]: Self::reward_depends_on_action
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        let _ = dim;
        true
    }

    /// Whether `x` is a goal state. With the absorbing-goal option of the solver, a goal state
    /// collects its reward and then nothing (zero future value). Rollout metrics also use it.
    ///
    /// See [`is_terminal`](Self::is_terminal) for how this differs from a terminal state.
    fn is_goal(&self, x: &[T]) -> bool {
        let _ = x;
        false
    }

    /// Whether `x` is a **terminal** state: an episode ends on reaching it, so a transition
    /// *into* it is worth its reward and no future value,
    /// `theta[d, u] = rho(x_d, u) + gamma * (0 if f(x_d, u) is terminal else V~(f(x_d, u)))`
    /// (Busoniu et al. 2010, ch. 4; the ApproxRL toolbox's `cfg.term = 'zero'`). The car on
    /// the hill, for instance, ends when the car leaves `|p| <= 1` or `|p'| <= 3`.
    ///
    /// Terminal states are consulted only when [`has_terminal_states`](Self::has_terminal_states)
    /// returns `true`; override both together.
    ///
    /// **Terminal versus goal.** The two are independent:
    /// - terminality is a property of the *successor* `f(x_d, u)` of a transition and is part
    ///   of the model: whenever the model declares terminal states, every backup (generic,
    ///   block, tabulated, greedy and `Q(x, .)` evaluation, asynchronous sweeps) drops the
    ///   future value of transitions that end in one. The successor is usually off the grid's
    ///   cores and its own value is never used.
    /// - [`is_goal`](Self::is_goal) is a property of the *current* state `x_d` (a core) and
    ///   only matters with the solver's absorbing-goal option: a goal core keeps
    ///   `theta[d, u] = rho(x_d, u)` for every action, whatever its successor.
    fn is_terminal(&self, x: &[T]) -> bool {
        let _ = x;
        false
    }

    /// Whether the model has terminal states ([`is_terminal`](Self::is_terminal)). When it
    /// does not (the default), the solver never calls `is_terminal`, and the block backup
    /// keeps its fused fast path everywhere. When it does, the backup is no longer a shift
    /// commuting operator, so the solver does not extrapolate (like with an absorbing goal).
    fn has_terminal_states(&self) -> bool {
        false
    }

    /// Number of declared independent dynamics blocks (0: none; see the [module docs](self)).
    fn n_blocks(&self) -> usize {
        0
    }

    /// Precomputed transitions at the cores of the grid being solved, if the model is only
    /// known there (a table built from a Python callable). The solver then reads successors
    /// and rewards from the table instead of calling [`step`](Self::step) and
    /// [`reward`](Self::reward).
    fn tabulated(&self) -> Option<Tabulated<'_, T>> {
        None
    }

    /// Rewards precomputed at every (core, joint action) pair of the grid being solved
    /// (`n_cores * M` values, core-major in row-major grid order, then joint action), for a
    /// model known only at the cores that declares blocks (a Python callable with independent
    /// dynamics). The solver reads them instead of calling [`reward`](Self::reward) once per
    /// core and joint action in every sweep. `None` (the default) for every other model; a
    /// [`tabulated`](Self::tabulated) model's rewards are read from its table.
    fn reward_table(&self) -> Option<&[T]> {
        None
    }

    /// Block `b`'s transition table on the grid being solved, if the model gives it directly
    /// (a learned or stochastic model; see the [module docs](self)). The default, `None`,
    /// makes the solver build it by stepping the model from each block core.
    fn block_rows(&self, b: usize) -> Option<BlockRows<'_, T>> {
        let _ = b;
        None
    }

    /// Block `b` (`0 <= b < n_blocks()`).
    ///
    /// The default has no blocks, so it is never called; models that declare blocks override it.
    fn block(&self, b: usize) -> Block<'_> {
        let _ = b;
        Block {
            state_dims: &[],
            action_components: &[],
        }
    }
}

/// The joint action set of a model.
pub fn joint_actions<T: Real, M: Model<T> + ?Sized>(
    model: &M,
) -> Result<JointActions<'_, T>, EvalError> {
    let n = model.n_agents();
    if n == 0 || n > MAX_AGENTS {
        return Err(EvalError::Agents { found: n });
    }
    let mut sets = [ActionSet::default(); MAX_AGENTS];
    for (i, s) in sets.iter_mut().enumerate().take(n) {
        *s = model.action_set(i);
    }
    JointActions::try_new(&sets[..n])
}
