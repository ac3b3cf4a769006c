//! The fuzzy Q-iteration driver (feature `std`; parallel with feature `parallel`).
//!
//! # What it computes
//! Fuzzy Q-iteration for the `joint` layout: `theta_{k+1} = (P o H o F)(theta_k)` from
//! `theta_0 = 0`,
//! `theta_{k+1}[d, u] = rho(x_d, u) + gamma * sum_{d'} mu_{d'}(f(x_d, u)) max_{u'} theta_k[d', u']`.
//! Only `V_k[d] = max_u theta_k[d, u]` is stored (one value per core): `theta_{k+1}` is a
//! function of `V_k`, so the paper's 2.56e9 Q-values are never materialised. Memory is
//! `O(cores)`.
//!
//! # Two backup paths
//! - **generic**: per core and joint action, step the model and interpolate `V` over the
//!   successor's at most `2^E` active cores.
//! - **block**: when the model declares independent dynamics blocks
//!   ([`Model::n_blocks`]), each block gets a small sparse table: for each
//!   block core and block action, the memberships of the block's successor. The expectation
//!   `sum_{d'} mu_{d'}(f(x_d, u)) V[d']` factors over blocks, and is computed for all cores and
//!   joint actions as a sequence of per-block sparse products (see [`crate::backup::contract`]).
//!   On the paper's grid that is about 1e10 multiply-adds per sweep instead of 6.6e11 look-ups.
//!
//! Blocks are contracted in reverse declaration order; internally `V` is kept in that block
//! order (the first contracted block's core slowest), and converted back to the grid's
//! row-major order at the end. The first contracted block's cores define **slabs**: the cores
//! sharing it.
//!
//! # Sweeps and the stopping rule
//! - **synchronous** (Jacobi, the paper's eq 20): every core reads `V_k`. The paper's stopping
//!   rule `||theta_{k+1} - theta_k||_inf <= xi` is applied exactly, without storing `theta`:
//!   `theta_{k+1} - theta_k = gamma P (V_k - V_{k-1})`, so
//!   `||V_{k+1} - V_k|| <= ||theta_{k+1} - theta_k|| <= gamma ||V_k - V_{k-1}||`. The driver
//!   decides from these bounds and, only when they straddle `xi`, computes the exact value with
//!   one extra pass over `V_k - V_{k-1}`. The sweep it stops at is therefore exactly the first
//!   sweep whose theta change is at most `xi`. After the final sweep the exact final delta is
//!   computed if it is not known yet. For sweep 1, `theta_1 = rho` and the delta is `max |rho|`.
//! - **asynchronous** (Gauss-Seidel): slabs are updated in order, in place, each reading the
//!   values earlier slabs already wrote (within a slab all cores read the same values, which
//!   keeps the result independent of the thread count). A `theta_k` over all cores is not
//!   defined for these sweeps, so the stopping rule uses the change of `V` instead.
//!
//! - **extrapolated** ([`SolverConfig::extrapolate`], synchronous only): the backup commutes
//!   with constant shifts, `T(V + c) = T(V) + gamma c` (memberships sum to 1), so MacQueen's
//!   bounds `V* in V_{k+1} + gamma/(1-gamma) [min dV, max dV]` hold. Every other sweep moves
//!   `V` to their midpoint, which removes the slowest mode (on the paper's task, 114 sweeps
//!   become 37). The stopping rule is tested only on sweeps whose input was not shifted, where
//!   `theta_{k+1} = H(theta_k)` holds, so the a-posteriori bound
//!   `||theta_K - theta*|| <= gamma/(1-gamma) * delta_K` keeps holding. Not used with an
//!   absorbing goal or terminal states, where the shift property fails.
//! - **coarse start** ([`SolverConfig::coarse_start`], modified policy iteration only): the
//!   run starts from the solution on the grid with every other core, interpolated, instead of
//!   `V = 0`; the stopping rule and bound come from the run's own full backups, so they hold
//!   as from any start (see the `coarse` module).
//!
//! # Terminal states
//! For a model that [declares terminal states](Model::has_terminal_states), a transition into
//! a terminal state contributes no future value:
//! `theta[d, u] = rho(x_d, u) + gamma * (0 if f(x_d, u) is terminal else V~(f(x_d, u)))`.
//! The generic path tests every successor it computes. The block path cannot factor a
//! terminal test over blocks, so it precomputes, once, the (core, joint action) pairs whose
//! successor (assembled from the blocks' successors) is terminal; slabs without such pairs
//! keep the fused kernels, the others deliver full rows with those entries set to 0 before
//! the reduction. A tabulated model's terminal successors get no memberships. Models without
//! terminal states run exactly as before, bit for bit.
//!
//! All converge to the same fixed point (Theorems 1-2 of the paper; the operator is a
//! `gamma`-contraction in the infinity norm). With `theta_0 = 0` the a-priori bound of eq 37,
//! `k <= log_gamma(xi (1 - gamma) / (R (1 + gamma)))` with `R = max |rho|`, is reported.
//!
//! # Kernels
//! The block products run in kernels chosen at run time from the CPU's features (AVX-512F + VL,
//! AVX2 + FMA, or portable scalar code; [`Kernel`] forces one). They are register-blocked, and
//! the last stage is fused with the maximum over actions: it bounds each action's row first
//! and skips rows that provably cannot raise the maximum. Every instance sums in the same order
//! with fused multiply-adds, so all return bit-identical results.
//!
//! # Determinism
//! Every value is computed by one task in a fixed order; work is split between threads only
//! at boundaries that do not change any sum, and maxima are exact. Results are bit-identical
//! for any thread count.
//!
//! # Greedy actions
//! After the last sweep one more pass computes, for every core, the lowest-index joint action
//! maximising `theta_{K+1}[d, .] = rho + gamma P V_K` (modified policy iteration skips that
//! pass when it returns the input of its last full backup, which recorded exactly those
//! actions; see [`Scheme::ModifiedPolicy`]): the same Q-function the greedy policy
//! evaluates at any state from `V_K`, and the per-core table the interpolated policy (eq 22)
//! needs. When the reward does not depend on the action, `theta[d, u]` differs between actions
//! only through the expected value `(P V_K)[d, u]`, so ties are decided on that value (rounding
//! in `rho + gamma ev` could otherwise merge distinct values into a false tie).

mod block;
mod coarse;
mod generic;
mod iterate;
mod par;
mod plan;
mod qiter;
mod rewards;
pub(crate) mod simd;
mod slabs;
mod state;
mod sweeps;
mod table;

pub use block::decide::{DecisionBlock, DecisionTables};
pub use coarse::CoarseStart;
pub use iterate::{MakeSweeps, solve, solve_from, solve_on, solve_with};
pub use plan::{BlockPlan, PlanTable};
pub use qiter::{QSolution, solve_q};
pub use slabs::SlabLayout;
pub use state::SolverState;
pub use sweeps::{Buf, DiffStats, Local, Sweeps, diff_stats, shift};
pub use table::{BlockTable, RowsTable, TabulatedModel};

use std::time::Instant;
use std::vec::Vec;

use crate::action::JointActions;
use crate::backup::Backup;
use crate::error::{EvalError, PartitionError};
use crate::model::{Model, joint_actions};
use crate::partition::{Membership, ProductPartition};
use crate::real::Real;

use block::BlockOperator;
use generic::GenericOperator;

/// Slab size (cores) of the generic path. Fixed, so results do not depend on thread count.
const GENERIC_SLAB: usize = 256;

/// An owned fuzzy grid: the cores of every state variable, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid<T> {
    cores: Vec<Vec<T>>,
    n_cores: usize,
    membership: Membership,
}

impl<T: Real> Grid<T> {
    /// Validates the cores of each state variable (see [`ProductPartition::try_new`]).
    pub fn new(cores: Vec<Vec<T>>) -> Result<Self, PartitionError> {
        let n_cores = {
            let views: Vec<&[T]> = cores.iter().map(Vec::as_slice).collect();
            ProductPartition::try_new(&views)?.n_cores()
        };
        Ok(Self {
            cores,
            n_cores,
            membership: Membership::Triangular,
        })
    }

    /// The same cores with membership functions of kind `membership` (triangular by
    /// default; [`Membership::Crisp`] makes the grid a crisp state aggregation).
    #[must_use]
    pub fn with_membership(mut self, membership: Membership) -> Self {
        self.membership = membership;
        self
    }

    /// The kind of membership functions.
    #[must_use]
    pub fn membership(&self) -> Membership {
        self.membership
    }

    /// The borrowed product partition over these cores.
    #[must_use]
    pub fn view(&self) -> ProductPartition<'_, T> {
        let mut views: [&[T]; crate::MAX_DIMS] = [&[]; crate::MAX_DIMS];
        for (v, c) in views.iter_mut().zip(&self.cores) {
            *v = c;
        }
        ProductPartition::try_new(&views[..self.cores.len()])
            .expect("cores were validated when the grid was built")
            .with_membership(self.membership)
    }

    /// The cores of every state variable.
    #[must_use]
    pub fn cores(&self) -> &[Vec<T>] {
        &self.cores
    }

    /// Number of state variables.
    #[must_use]
    pub fn n_dims(&self) -> usize {
        self.cores.len()
    }

    /// Number of joint cores.
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.n_cores
    }
}

crate::named_option! {
    /// Synchronous (Jacobi) or asynchronous (Gauss-Seidel) sweeps.
    #[derive(Default)]
    pub enum SweepMode: "sweep" {
        /// Every core reads the previous sweep's values (the paper's eq 20).
        #[default]
        Synchronous = "sync" => "every core reads the previous sweep's values (Jacobi, the paper's eq 20)",
        /// Slabs update in place and later slabs read the new values.
        Asynchronous = "async" => "slabs update in place, later ones read the new values (Gauss-Seidel)",
    }
}

crate::named_option! {
    /// Where a run's passes over `V` compute.
    #[derive(Default)]
    pub enum Device: "device" {
        /// The CPU's kernels, on every thread of the pool.
        #[default]
        Cpu = "cpu" => "the CPU's kernels, on every thread of the pool",
        /// A GPU through wgpu (Vulkan, Metal, DX12): the block path in `f32`, with the CPU's
        /// bits where the adapter fuses multiply-adds (the `fuzzyq-gpu` crate).
        Gpu = "gpu" => "a GPU through wgpu (the block path in f32; fuzzyq-gpu)",
    }
}

crate::named_option! {
    /// Which backup implementation to use.
    #[derive(Default)]
    pub enum BackupPath: "backup" {
        /// The block path when the model declares blocks, the generic path otherwise.
        #[default]
        Auto = "auto" => "the block path when the model declares blocks, else the generic one",
        /// Per-block sparse products; an error if the model declares no blocks.
        Block = "block" => "per-block sparse products (the model must declare blocks)",
        /// Step the model and interpolate over all active successor cores.
        Generic = "generic" => "step the model and interpolate over every active successor core",
    }
}

crate::named_option! {
    /// An instruction set for the block path's kernels (see [`Operator::with_kernel`]). Every
    /// instance computes bit-identical results; they differ only in speed. [`NamedOption::ALL`](crate::NamedOption::ALL)
    /// lists them fastest first.
    pub enum Kernel: "kernel" {
        /// x86-64 AVX-512F with AVX-512VL (its 256-bit masked operations) and FMA.
        Avx512 = "avx512" => "x86-64 AVX-512F + VL",
        /// x86-64 AVX2 with FMA.
        Avx2 = "avx2" => "x86-64 AVX2 with FMA",
        /// Portable code the compiler vectorises (no intrinsics); on x86-64 built for AVX2
        /// with FMA, elsewhere for the target's baseline.
        Portable = "portable" => "portable code the compiler vectorises (AVX2 + FMA on x86-64)",
        /// Scalar code, one lane at a time (fused multiply-add through `mul_add`).
        Scalar = "scalar" => "scalar code, one lane at a time",
    }
}

impl Kernel {
    /// Whether this CPU can run the instance.
    #[must_use]
    pub fn is_available(self) -> bool {
        simd::select::<f32>(Some(self)).is_some()
    }

    /// The instance the block path uses by default on this CPU (the fastest it runs).
    #[must_use]
    pub fn best() -> Self {
        let name = simd::select::<f32>(None).map_or("scalar", |k| k.name);
        <Self as crate::NamedOption>::ALL
            .iter()
            .copied()
            .find(|k| k.name() == name)
            .unwrap_or(Self::Scalar)
    }
}

/// The machine's measured fused multiply-add throughput ([`fma_peak`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FmaPeak {
    /// The kernel instance measured.
    pub kernel: &'static str,
    /// Threads that ran the probe at once.
    pub threads: usize,
    /// Fused multiply-adds per second over all threads, in billions.
    pub gfma_per_second: f64,
}

/// Measures the fused multiply-add throughput this machine reaches with a kernel instance
/// (`None`: the best available) in precision `T`: every thread of the pool (one without
/// feature `parallel`) runs 12 independent chains of vector fused multiply-adds, in
/// registers, for about `seconds`. This is the ceiling the block backup's kernels are
/// measured against (`fuzzyq bench`); `None` if this CPU cannot run the instance.
#[must_use]
pub fn fma_peak<T: Real>(kernel: Option<Kernel>, seconds: f64) -> Option<FmaPeak> {
    let k = simd::select_real::<T>(kernel)?;
    const ITERS: usize = 1 << 16;
    let per_call = (ITERS * simd::PEAK_CHAINS * k.lanes) as f64;
    use core::hint::black_box as bb;
    let (seed, a, b) = (T::from_f64(0.5), T::from_f64(0.999_999), T::from_f64(1e-7));
    let runs = par::broadcast(|| {
        let start = Instant::now();
        let mut calls = 0u64;
        loop {
            bb((k.peak)(bb(ITERS), bb(seed), bb(a), bb(b)));
            calls += 1;
            let t = start.elapsed().as_secs_f64();
            // A NaN or non-positive duration ends after one call.
            if t >= seconds || seconds.is_nan() {
                return calls as f64 * per_call / t;
            }
        }
    });
    Some(FmaPeak {
        kernel: k.name,
        threads: runs.len(),
        gfma_per_second: runs.iter().sum::<f64>() / 1e9,
    })
}

crate::named_option! {
    /// Which fuzzy Q-iteration operator a run iterates (see the crate docs of `fuzzyq-sim`
    /// and `docs/design.md` for how the two differ).
    #[derive(Default)]
    pub enum IterationOperator: "operator" {
        /// `theta[d, u] = rho + gamma sum_d' mu_d'(x') V[d']`: only `V` is stored ([`solve`]).
        #[default]
        Values = "values" => "interpolate the per-core maxima; only V is stored (any grid size)",
        /// `theta[d, u] = rho + gamma max_u' sum_d' mu_d'(x') theta[d', u']` with `theta`
        /// stored ([`solve_q`], Busoniu's operator as the ApproxRL toolbox runs it).
        QValues = "q-values" => "Busoniu's fuzzy Q-iteration, theta stored (the ApproxRL toolbox's)",
    }
}

crate::named_option! {
    /// The floating-point type a solver runs in.
    #[derive(Default)]
    pub enum Precision: "precision" {
        /// Single precision (half the memory, twice the SIMD width).
        #[default]
        F32 = "f32" => "single precision: half the memory, twice the SIMD width",
        /// Double precision.
        F64 = "f64" => "double precision",
    }
}

impl Precision {
    /// `v` rounded to this precision (and back to `f64`).
    #[inline]
    #[must_use]
    pub fn round(self, v: f64) -> f64 {
        match self {
            Self::F32 => f64::from(v as f32),
            Self::F64 => v,
        }
    }
}

/// Settings of a fuzzy Q-iteration run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverConfig {
    /// Discount factor, in `[0, 1)`.
    pub gamma: f64,
    /// Stopping threshold on the sweep's change, `> 0`.
    pub xi: f64,
    /// Sweep limit, `>= 1`: every sweep counts, full backups and evaluation sweeps alike.
    /// Under modified policy iteration the last sweep allowed is a full backup, so that a run
    /// cut short ends on MacQueen's bound like one that converged.
    pub max_sweeps: usize,
    /// Synchronous or asynchronous sweeps.
    pub sweep: SweepMode,
    /// Goal states collect their reward and have zero future value.
    pub absorbing_goal: bool,
    /// Backup implementation.
    pub path: BackupPath,
    /// Force a kernel instance (default: the fastest this CPU supports).
    pub kernel: Option<Kernel>,
    /// Extrapolate synchronous sweeps to the midpoint of MacQueen's bounds every other
    /// sweep (ignored with an absorbing goal or a model with
    /// [terminal states](Model::has_terminal_states)). The stopping rule is tested only on
    /// sweeps whose input was not shifted, so it keeps its meaning and its error bound.
    pub extrapolate: bool,
    /// Modified policy iteration: at most this many policy-evaluation sweeps after each full
    /// backup (0: value iteration, one full backup per sweep, as the paper). See
    /// [`Scheme::ModifiedPolicy`] for the scheme, its stopping rule and where it applies.
    pub evaluation_sweeps: usize,
    /// Modified policy iteration starts from the `V` of a run on the grid with every other
    /// core of each state variable ([`Grid::coarsened`]), interpolated onto the grid
    /// ([`Grid::interpolated_from`]), instead of `V = 0`: the same stopping rule and error
    /// bound, fewer sweeps where the grid is fine (the Khepera robots': 52 instead of 80).
    /// Ignored by value iteration, on grids with no variable of 4 cores or more, for models
    /// known only on the grid being solved (tables of a Python callable, learned block
    /// tables), and when a run continues from a saved state (which holds its `V`).
    pub coarse_start: bool,
}

impl Default for SolverConfig {
    /// The paper's settings: `gamma = 0.96`, `xi = 0.05`, synchronous sweeps.
    fn default() -> Self {
        Self {
            gamma: 0.96,
            xi: 0.05,
            max_sweeps: 1000,
            sweep: SweepMode::Synchronous,
            absorbing_goal: false,
            path: BackupPath::Auto,
            kernel: None,
            extrapolate: false,
            evaluation_sweeps: 0,
            coarse_start: false,
        }
    }
}

impl SolverConfig {
    /// Checks the ranges of every field.
    pub fn validate(&self) -> Result<(), SolveError> {
        if !(self.gamma >= 0.0 && self.gamma < 1.0) {
            return Err(SolveError::Gamma(self.gamma));
        }
        if !(self.xi > 0.0 && self.xi.is_finite()) {
            return Err(SolveError::Xi(self.xi));
        }
        if self.max_sweeps == 0 {
            return Err(SolveError::MaxSweeps);
        }
        Ok(())
    }

    /// The a-priori sweep bound of eq 37 from `theta_0 = 0` for rewards bounded by
    /// `reward_bound`: the smallest `k` with `gamma^k (1 + gamma) R / (1 - gamma) <= xi`.
    #[must_use]
    pub fn sweep_bound(&self, reward_bound: f64) -> usize {
        let g0 = reward_bound / (1.0 - self.gamma);
        if g0 * (1.0 + self.gamma) <= self.xi || self.gamma == 0.0 {
            return 1;
        }
        let k = (self.xi / (g0 * (1.0 + self.gamma))).ln() / self.gamma.ln();
        (k.ceil() as usize).max(1)
    }
}

/// Why a solve was refused or stopped.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum SolveError {
    /// `gamma` outside `[0, 1)`.
    Gamma(f64),
    /// `xi` not a positive finite number.
    Xi(f64),
    /// A sweep limit of 0.
    MaxSweeps,
    /// The grid's dimension differs from the model's state dimension.
    StateDim {
        /// The model's state dimension.
        model: usize,
        /// The grid's number of state variables.
        grid: usize,
    },
    /// A model or buffer check failed.
    Eval(EvalError),
    /// A state variable belongs to no block or to several.
    BlockCoverage {
        /// The state variable.
        dim: usize,
        /// In how many blocks it appears.
        count: usize,
    },
    /// A block names an action component that does not exist, or no state variable.
    BlockDeclaration {
        /// The block.
        block: usize,
        /// What is wrong.
        reason: &'static str,
    },
    /// A block's successor changed when only variables outside the block changed: the model
    /// declares blocks its dynamics do not have.
    BlockMismatch {
        /// The block.
        block: usize,
    },
    /// The block path was requested for a model without blocks.
    NoBlocks,
    /// The model gives its transitions as block tables ([`Model::block_rows`]: learned or
    /// stochastic), which only the block path of the value iteration reads; `what` asked for
    /// something else.
    BlockRowsOnly {
        /// What was asked for (`"the generic backup path"`, `"Q-iteration"`).
        what: &'static str,
    },
    /// The model produced a non-finite successor state or reward.
    NonFinite {
        /// Where (`"successor"` or `"reward"`).
        what: &'static str,
    },
    /// A table the solver needs would exceed 2^32 entries.
    TooLarge {
        /// Which table.
        what: &'static str,
    },
    /// The requested kernel instance cannot run on this CPU.
    KernelUnavailable(Kernel),
    /// [`Operator::decision_tables`] on an operator whose greedy decisions need the model.
    NoDecisionTables {
        /// Why.
        why: &'static str,
    },
    /// [`Operator::evaluate_policy`] on an operator that cannot evaluate a policy.
    PolicyEvaluation,
    /// A state to continue from ([`solve_from`]) does not fit the run.
    Resume {
        /// What does not fit.
        reason: &'static str,
    },
    /// A slab range, halo or buffer given to the slab entry points
    /// ([`Operator::apply_slabs`]) does not fit the operator.
    Slabs {
        /// What does not fit.
        reason: &'static str,
    },
    /// The observer asked to stop.
    Interrupted {
        /// Sweeps completed before the stop.
        sweeps: usize,
    },
}

impl core::fmt::Display for SolveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Gamma(g) => write!(f, "gamma must be in [0, 1), got {g}"),
            Self::Xi(x) => write!(f, "xi must be a positive number, got {x}"),
            Self::MaxSweeps => f.write_str("the sweep limit must be at least 1"),
            Self::StateDim { model, grid } => write!(
                f,
                "the grid has {grid} state variables but the model's state has {model}"
            ),
            Self::Eval(e) => write!(f, "{e}"),
            Self::BlockRowsOnly { what } => write!(
                f,
                "the model gives its transitions as block tables (learned or stochastic), \
                 which {what} cannot use; use the block backup path"
            ),
            Self::BlockCoverage { dim, count } => write!(
                f,
                "state variable {dim} appears in {count} dynamics blocks (must be exactly 1)"
            ),
            Self::BlockDeclaration { block, reason } => {
                write!(f, "dynamics block {block}: {reason}")
            }
            Self::BlockMismatch { block } => write!(
                f,
                "dynamics block {block} is not independent: its successor changed with \
                 variables outside it"
            ),
            Self::NoBlocks => {
                f.write_str("the block backup was requested but the model declares no blocks")
            }
            Self::NonFinite { what } => write!(f, "the model produced a non-finite {what}"),
            Self::TooLarge { what } => write!(f, "the {what} would exceed 2^32 entries"),
            Self::NoDecisionTables { why } => write!(
                f,
                "greedy decisions need the model here ({why}): only a block-path operator \
                 without terminal states or an absorbing goal, with rewards of the state alone, \
                 can be written as tables"
            ),
            Self::KernelUnavailable(k) if simd::left_out(*k) => write!(
                f,
                "this build has no {} kernels (a development build on a CPU that cannot run \
                 them; a release build, or FUZZYQ_KERNELS=all, holds every instance)",
                k.name()
            ),
            Self::KernelUnavailable(k) => {
                write!(f, "this CPU cannot run the {} kernels", k.name())
            }
            Self::PolicyEvaluation => f.write_str(
                "policy evaluation needs the block backup with several blocks, a state-only \
                 reward, no absorbing goal and no terminal states",
            ),
            Self::Resume { reason } => write!(f, "cannot continue the solve: {reason}"),
            Self::Slabs { reason } => write!(f, "slab backup: {reason}"),
            Self::Interrupted { sweeps } => write!(f, "interrupted after {sweeps} sweeps"),
        }
    }
}

impl std::error::Error for SolveError {}

impl From<EvalError> for SolveError {
    fn from(e: EvalError) -> Self {
        Self::Eval(e)
    }
}

/// The change of one sweep: `lower <= ||theta_{k+1} - theta_k||_inf <= upper`.
///
/// `lower == upper` when the value is known exactly. The bounds come from `V` in the solver's
/// precision, so they hold up to its rounding (in `f32`, about `1e-7` relative to `max |V|`).
/// For asynchronous sweeps both equal the change of `V` (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Delta {
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
}

impl Delta {
    fn exact(v: f64) -> Self {
        Self { lower: v, upper: v }
    }

    /// The exact value, if known.
    #[must_use]
    pub fn value(&self) -> Option<f64> {
        (self.lower == self.upper).then_some(self.lower)
    }
}

/// One sweep's record.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SweepRecord {
    /// Sweep number, from 1.
    pub sweep: usize,
    /// The sweep's change.
    pub delta: Delta,
    /// `||V_{k+1} - V_k||_inf`.
    pub delta_v: f64,
    /// Seconds since the solve started, at the end of this sweep.
    pub seconds: f64,
    /// The sweep started from an extrapolated `V`: its change is not tested against `xi`.
    pub extrapolated: bool,
    /// A policy-evaluation sweep (one action per core) of [`Scheme::ModifiedPolicy`], not a
    /// full backup.
    pub evaluation: bool,
}

/// What the observer sees after each sweep.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    /// The sweep just completed.
    pub record: SweepRecord,
    /// The a-priori sweep bound (eq 37).
    pub bound: usize,
    /// The threshold `xi`.
    pub xi: f64,
    /// How the run iterates: the same in every report of a run, decided before its first
    /// sweep from the settings and what the model and its operator allow.
    pub scheme: Scheme,
    /// Whether the run's sweeps move `V` to the midpoint of MacQueen's bounds (see
    /// [`SolverConfig::extrapolate`]; false where that cannot apply).
    pub extrapolate: bool,
    /// The run's coarse start ([`SolverConfig::coarse_start`]), done before its first sweep,
    /// if it had one.
    pub coarse: Option<CoarseStart>,
}

/// Why the iteration stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The change fell to `xi` or below.
    Converged,
    /// The sweep limit was reached first.
    SweepLimit,
}

/// How [`solve`] iterated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Scheme {
    /// Value iteration: every sweep is a full backup `V <- max_u (rho + gamma P_u V)` (the
    /// paper's fuzzy Q-iteration), stopped by the paper's rule on `||theta_{k+1} - theta_k||`.
    Value,
    /// Modified policy iteration: each full backup also records every core's greedy action
    /// `pi`, and up to [`SolverConfig::evaluation_sweeps`] evaluation sweeps
    /// `V <- rho + gamma P_pi V` follow (on the block path one row per core in the last
    /// stage instead of all joint actions). After every sweep `V` moves to the midpoint of
    /// MacQueen's bounds.
    ///
    /// The stopping rule is tested on full backups only: with `d = T(V) - V`, MacQueen's
    /// bounds `V* in T(V) + gamma/(1-gamma) [min d, max d]` give the returned
    /// `V = T(V) + gamma/(1-gamma) (min d + max d)/2` the bound
    /// `||V - V*||_inf <= gamma/(1-gamma) (max d - min d)/2`, and the run stops when
    /// `(max d - min d)/2 <= xi`: the same guarantee `gamma/(1-gamma) xi` as the paper's rule,
    /// and `theta = rho + gamma P V` is within `gamma` times it of `theta*`.
    /// [`Solution::final_delta`] is that half-span.
    ///
    /// When the backup's input is itself close enough, `||d||_inf <= gamma xi`, the run
    /// returns that input instead: `||V - V*||_inf <= ||d||_inf / (1-gamma)` is within the
    /// same guarantee, and the greedy actions the backup recorded are exactly those of the
    /// returned `V`, so no greedy pass is needed (a full backup's cost saved).
    /// [`Solution::final_delta`] is then `||d||_inf / gamma`, so that
    /// [`Solution::error_bound`] stays `gamma/(1-gamma) final_delta`.
    ///
    /// It needs [`SolverConfig::extrapolate`] and the bounds (no absorbing goal, no terminal
    /// states), synchronous sweeps and the
    /// block path with a fused last stage (several blocks, a state-only reward); elsewhere
    /// [`solve`] runs value iteration.
    ModifiedPolicy,
}

/// The result of a solve.
#[derive(Clone, Debug)]
pub struct Solution<T> {
    /// `V[d] = max_u theta[d, u]` per core, in the grid's row-major order.
    pub v: Vec<T>,
    /// The lowest-index greedy joint action of every core (see the [module docs](self)).
    pub greedy: Vec<u32>,
    /// Every sweep's record (full backups and evaluation sweeps).
    pub sweeps: Vec<SweepRecord>,
    /// How the run iterated.
    pub scheme: Scheme,
    /// Why it stopped.
    pub stop: Stop,
    /// The exact change of the last sweep (for asynchronous sweeps, of `V`; for
    /// [`Scheme::ModifiedPolicy`], the last full backup's half-span or its change over
    /// `gamma`, see there).
    pub final_delta: f64,
    /// The a-priori sweep bound (eq 37).
    pub bound: usize,
    /// `max |rho|` over cores and joint actions.
    pub reward_bound: f64,
    /// The backup path used (`Block` or `Generic`).
    pub path: BackupPath,
    /// The kernel instance (see [`Operator::kernel`]).
    pub kernel: &'static str,
    /// Multiply-adds of one sweep on the block path.
    pub multiply_adds_per_sweep: Option<f64>,
    /// Seconds spent in the sweeps themselves (without set-up, exact-delta and greedy passes).
    pub sweep_seconds: f64,
    /// The part of `sweep_seconds` spent in evaluation sweeps.
    pub evaluation_seconds: f64,
    /// Wall-clock seconds of the whole solve (a coarse start's included).
    pub seconds: f64,
    /// The part of `seconds` before the first sweep, without the coarse start: the operator
    /// (block tables, rewards) and the backend's buffers (on a GPU: its kernels, tables and
    /// `V`). `None` where a solver does not measure it.
    pub setup_seconds: Option<f64>,
    /// The part of `seconds` spent at the end bringing `V` and the greedy actions into
    /// [`Self::v`] and [`Self::greedy`] (on a GPU: reading them back). `None` where a solver
    /// does not measure it.
    pub result_seconds: Option<f64>,
    /// The coarse start, if the run had one ([`SolverConfig::coarse_start`]).
    pub coarse: Option<CoarseStart>,
}

impl<T> Solution<T> {
    /// Number of full backups (sweeps over every joint action).
    #[must_use]
    pub fn full_backups(&self) -> usize {
        self.sweeps.iter().filter(|r| !r.evaluation).count()
    }

    /// Number of policy-evaluation sweeps.
    #[must_use]
    pub fn evaluation_sweeps(&self) -> usize {
        self.sweeps.iter().filter(|r| r.evaluation).count()
    }

    /// Whether the iteration converged.
    #[must_use]
    pub fn converged(&self) -> bool {
        self.stop == Stop::Converged
    }

    /// The bound `gamma / (1 - gamma) * final_delta` on the distance of the result to the fixed
    /// point in the infinity norm.
    #[must_use]
    pub fn error_bound(&self, gamma: f64) -> f64 {
        gamma / (1.0 - gamma) * self.final_delta
    }
}

/// How a backup reduces one core's row of expected successor values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reduce {
    /// `max_u theta[d, u]`.
    Max,
    /// `gamma * max_u |ev[u]|` (zero for absorbing goal cores).
    AbsMax,
    /// The lowest `u` maximising `theta[d, u]` (on the expected value for state-only rewards).
    Argmax,
}

/// The backup operator `V -> max_u (rho + gamma P V)` of a model on a grid, prepared once.
///
/// [`solve`] drives it; it is public so that callers can evaluate decisions
/// ([`q_values`](Self::q_values)) against a stored `V` without repeating the setup.
pub struct Operator<'a, T: Real, M: ?Sized> {
    model: &'a M,
    grid: ProductPartition<'a, T>,
    joint: JointActions<'a, T>,
    backup: Backup<T>,
    gamma: T,
    /// `rho(x_d)` per core in internal order, when the reward does not depend on the action.
    rewards: Option<Vec<T>>,
    /// `rho(x_d, u)` per core (internal order) and joint action, for a tabulated model or a
    /// model's [`reward_table`](Model::reward_table) (copied into internal order on the block
    /// path).
    reward_table: Option<std::borrow::Cow<'a, [T]>>,
    /// Absorbing goal flags per core in internal order (empty unless absorbing).
    goal: Vec<bool>,
    reward_bound: f64,
    path: Path<T>,
}

enum Path<T: 'static> {
    Generic(GenericOperator<T>),
    Block(BlockOperator<T>),
}

/// Cores per task of the passes over every core's state (rewards, goals).
const STATE_CHUNK: usize = 4096;

/// Copies `(value, action)` pairs into `values` and `actions` (as many as the shorter holds).
fn split_pairs<T: Copy>(pairs: &[(T, u32)], values: &mut [T], actions: &mut [u32]) {
    for ((x, u), &(px, pu)) in values.iter_mut().zip(actions.iter_mut()).zip(pairs) {
        (*x, *u) = (px, pu);
    }
}

impl<'a, T: Real, M: Model<T> + Sync + ?Sized> Operator<'a, T, M> {
    /// Prepares the operator: validates the model against the grid, builds the block tables
    /// (if the path is `Block`, or `Auto` with declared blocks), evaluates per-core rewards.
    pub fn new(
        model: &'a M,
        grid: ProductPartition<'a, T>,
        backup: Backup<T>,
        path: BackupPath,
    ) -> Result<Self, SolveError> {
        if model.state_dim() != grid.n_dims() {
            return Err(SolveError::StateDim {
                model: model.state_dim(),
                grid: grid.n_dims(),
            });
        }
        let joint = joint_actions(model)?;
        let table = model.tabulated();
        if let Some(t) = &table {
            let (n, m, e) = (grid.n_cores(), joint.n_joint(), grid.n_dims());
            if t.n_cores != n {
                return Err(SolveError::Eval(EvalError::Length {
                    what: "tabulated model's cores",
                    expected: n,
                    found: t.n_cores,
                }));
            }
            crate::error::check_len("tabulated rewards", n * m, t.rewards.len())?;
            crate::error::check_len("tabulated next states", n * m * e, t.next_states.len())?;
        }
        let given_rows = (0..model.n_blocks()).any(|b| model.block_rows(b).is_some());
        if given_rows && (path == BackupPath::Generic || table.is_some()) {
            return Err(SolveError::BlockRowsOnly {
                what: "the generic backup path",
            });
        }
        let use_blocks = match path {
            _ if table.is_some() => false,
            BackupPath::Generic => false,
            BackupPath::Block if model.n_blocks() == 0 => return Err(SolveError::NoBlocks),
            BackupPath::Block => true,
            BackupPath::Auto => model.n_blocks() > 0,
        };
        let path = if use_blocks {
            Path::Block(BlockOperator::new(model, &grid, &joint)?)
        } else {
            generic::check_u32_cores(grid.n_cores(), "grid of the generic backup path")?;
            Path::Generic(GenericOperator::new(model, &grid, joint.n_joint(), table))
        };
        let m = joint.n_joint();
        let reward_table = match (table, model.reward_table()) {
            (Some(t), _) => Some(std::borrow::Cow::Borrowed(t.rewards)),
            (None, Some(t)) => {
                crate::error::check_len("reward table", grid.n_cores() * m, t.len())?;
                Some(match &path {
                    Path::Generic(_) => std::borrow::Cow::Borrowed(t),
                    Path::Block(b) => {
                        let mut out = vec![T::ZERO; t.len()];
                        b.for_each_grid_index(|i, g| {
                            out[i * m..(i + 1) * m].copy_from_slice(&t[g * m..(g + 1) * m]);
                        });
                        std::borrow::Cow::Owned(out)
                    }
                })
            }
            (None, None) => None,
        };
        let mut op = Self {
            model,
            grid,
            joint,
            backup,
            gamma: backup.gamma,
            rewards: None,
            reward_table,
            goal: Vec::new(),
            reward_bound: 0.0,
            path,
        };
        op.prepare_rewards()?;
        Ok(op)
    }

    /// Uses the block path's kernel instance `kernel` (no effect on the generic path).
    pub fn with_kernel(mut self, kernel: Kernel) -> Result<Self, SolveError> {
        if let Path::Block(b) = &mut self.path {
            b.set_kernel(kernel)?;
        }
        Ok(self)
    }

    /// Number of cores.
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.grid.n_cores()
    }

    /// The joint action set.
    #[must_use]
    pub fn joint(&self) -> &JointActions<'a, T> {
        &self.joint
    }

    /// The path in use (`Block` or `Generic`).
    #[must_use]
    pub fn path(&self) -> BackupPath {
        match self.path {
            Path::Generic(_) => BackupPath::Generic,
            Path::Block(_) => BackupPath::Block,
        }
    }

    /// The kernel instance of the block path (`"avx512"`, `"avx2"`, `"portable"`, `"scalar"`), or
    /// `"generic"` for the generic path.
    #[must_use]
    pub fn kernel(&self) -> &'static str {
        match &self.path {
            Path::Generic(_) => "generic",
            Path::Block(b) => b.kernel_name(),
        }
    }

    /// Multiply-adds of one synchronous sweep on the block path (`None` on the generic path,
    /// whose cost is dominated by model steps and look-ups).
    #[must_use]
    pub fn multiply_adds_per_sweep(&self) -> Option<f64> {
        match &self.path {
            Path::Generic(_) => None,
            Path::Block(b) => Some(b.multiply_adds()),
        }
    }

    /// `max |rho|` over cores and joint actions.
    #[must_use]
    pub fn reward_bound(&self) -> f64 {
        self.reward_bound
    }

    fn state_dim(&self) -> usize {
        self.grid.n_dims()
    }

    /// Internal core index -> row-major grid index.
    fn to_grid_index(&self, internal: usize) -> usize {
        match &self.path {
            Path::Generic(_) => internal,
            Path::Block(b) => b.to_grid_index(internal),
        }
    }

    /// Core state of an internal core index.
    fn core_state(&self, internal: usize, out: &mut [T]) {
        let _ = self.grid.core_state(self.to_grid_index(internal), out);
    }

    /// Calls `f(i, x)` with the state `x` of every internal core `i` in `range`, in order
    /// (`coords` from [`Self::block_coords`]; on the block path, no division per core).
    fn for_each_core_state(
        &self,
        coords: &[Vec<T>],
        range: core::ops::Range<usize>,
        x: &mut [T],
        mut f: impl FnMut(usize, &[T]),
    ) {
        match &self.path {
            Path::Block(b) => b.for_each_core_state(coords, range, x, f),
            Path::Generic(_) => {
                for i in range {
                    self.core_state(i, x);
                    f(i, x);
                }
            }
        }
    }

    /// The block path's per-block core coordinates for [`Self::for_each_core_state`] (empty
    /// on the generic path).
    fn block_coords(&self) -> Vec<Vec<T>> {
        match &self.path {
            Path::Block(b) => b.block_coords(self.state_dim(), |g, x| {
                let _ = self.grid.core_state(g, x);
            }),
            Path::Generic(_) => Vec::new(),
        }
    }

    fn is_goal(&self, internal: usize) -> bool {
        !self.goal.is_empty() && self.goal[internal]
    }

    /// Reduces core `internal`'s expected successor values `ev` (one per joint action: joint
    /// action `u` at `ev[map[u]]` with the block path's map, [`Self::ev_map`], else at `ev[u]`).
    fn reduce(
        &self,
        internal: usize,
        ev: &[T],
        kind: Reduce,
        work: &mut ReduceWork<T>,
    ) -> (T, u32) {
        let goal = self.is_goal(internal);
        let map = self.ev_map();
        let m = self.joint.n_joint();
        let at = |u: usize| match map {
            None => ev[u],
            Some(p) => ev[p[u] as usize],
        };
        match kind {
            Reduce::AbsMax => {
                if goal {
                    return (T::ZERO, 0);
                }
                let mut best = T::ZERO;
                match map {
                    None => {
                        for &x in ev {
                            best = best.max_of(x.abs());
                        }
                    }
                    Some(_) => {
                        for u in 0..m {
                            best = best.max_of(at(u).abs());
                        }
                    }
                }
                (self.gamma * best, 0)
            }
            Reduce::Max | Reduce::Argmax => {
                if let Some(r) = &self.rewards {
                    // State-only reward: theta = r + gamma ev is monotone in ev, so the max
                    // commutes with it exactly, and the greedy action is decided on ev (the
                    // lowest joint index with the largest expected value; rounding in
                    // r + gamma ev cannot merge distinct values into a false tie).
                    let rd = r[internal];
                    if goal {
                        return (rd, 0);
                    }
                    let mut best = at(0);
                    let mut arg = 0u32;
                    for u in 1..m {
                        let x = at(u);
                        if x > best {
                            best = x;
                            arg = u as u32;
                        }
                    }
                    return (rd + self.gamma * best, arg);
                }
                let reward_at = |u: usize, work: &mut ReduceWork<T>| -> T {
                    match (&self.rewards, &self.reward_table) {
                        (Some(r), _) => r[internal],
                        (None, Some(t)) => t[internal * m + u],
                        (None, None) => {
                            self.joint.vector_unchecked(u, &mut work.u);
                            self.model.reward(&work.x, &work.u)
                        }
                    }
                };
                if self.rewards.is_none() && self.reward_table.is_none() {
                    self.core_state(internal, &mut work.x);
                }
                let mut best = T::ZERO;
                let mut arg = 0u32;
                for u in 0..m {
                    let r = reward_at(u, work);
                    let theta = if goal { r } else { r + self.gamma * at(u) };
                    if u == 0 || theta > best {
                        best = theta;
                        arg = u as u32;
                    }
                }
                (best, arg)
            }
        }
    }

    /// `V` of a core from the maximum `m` of its expected values (state-only reward): the
    /// same expression as [`Self::reduce`]'s fast path, so both give the same bits.
    fn finish_max(&self, internal: usize, m: T) -> T {
        let r = self.rewards.as_ref().expect("state-only reward")[internal];
        if self.is_goal(internal) {
            r
        } else {
            r + self.gamma * m
        }
    }

    /// [`Self::finish_max`] of the run of cores from `first`, one per maximum in `m`, each
    /// with its action in `args` (0 for all when `args` is empty; 0 at goal cores), written
    /// to `out` through `pick`: slices zipped, without an index check per core on this pass
    /// over every core of every sweep.
    #[inline]
    fn finish_run<U>(
        &self,
        first: usize,
        (m, args): (&[T], &[u32]),
        out: &mut [U],
        pick: impl Fn((T, u32)) -> U,
    ) {
        let span = first..first + m.len();
        let r = &self.rewards.as_ref().expect("state-only reward")[span.clone()];
        let out = &mut out[..m.len()];
        let gamma = self.gamma;
        match (self.goal.is_empty(), args.is_empty()) {
            (true, true) => {
                for ((o, &r), &x) in out.iter_mut().zip(r).zip(m) {
                    *o = pick((r + gamma * x, 0));
                }
            }
            (true, false) => {
                for (((o, &r), &x), &u) in out.iter_mut().zip(r).zip(m).zip(&args[..m.len()]) {
                    *o = pick((r + gamma * x, u));
                }
            }
            (false, _) => {
                let goal = &self.goal[span];
                for (i, (((o, &r), &x), &g)) in out.iter_mut().zip(r).zip(m).zip(goal).enumerate() {
                    let u = if g || args.is_empty() { 0 } else { args[i] };
                    *o = pick((if g { r } else { r + gamma * x }, u));
                }
            }
        }
    }

    /// The theta change of a core from the maximum `m` of its |expected value changes|.
    fn finish_abs(&self, internal: usize, m: T) -> T {
        if self.is_goal(internal) {
            T::ZERO
        } else {
            self.gamma * m
        }
    }

    fn ev_map(&self) -> Option<&[u32]> {
        match &self.path {
            Path::Generic(_) => None,
            Path::Block(b) => b.joint_to_product(),
        }
    }

    fn reduce_work(&self) -> ReduceWork<T> {
        ReduceWork {
            x: vec![T::ZERO; self.state_dim()],
            u: vec![T::ZERO; self.joint.dim()],
            ev: Vec::new(),
        }
    }

    /// Zeros in internal order.
    fn zeros(&self) -> Vec<T> {
        vec![T::ZERO; self.n_cores()]
    }

    /// One synchronous sweep: `out = max_u (rho + gamma P v)`, internal order.
    fn sweep_sync(&self, v: &[T], out: &mut [T]) -> Result<(), SolveError> {
        self.each_core(v, out, Reduce::Max, |r| r.0)
    }

    /// Reduces every core against `v` into `out` (internal order), keeping `pick` of each
    /// `(value, action)` result.
    fn each_core<U: Send>(
        &self,
        v: &[T],
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
    ) -> Result<(), SolveError> {
        match &self.path {
            Path::Generic(g) => g.each_core(self, v, out, kind, pick),
            Path::Block(b) => {
                b.each_core(self, v, out, kind, pick);
                Ok(())
            }
        }
    }

    /// [`Self::each_core`], or with `policy` one policy-evaluation sweep (`out = rho + gamma
    /// P_policy v`; only where [`Self::can_evaluate`] holds), also returning the range of
    /// `value(out[i]) - v[i]` where the block path can take it while the results are in cache
    /// (`None` on the generic path, whose callers take it in a pass of their own).
    fn each_core_range<U: Send>(
        &self,
        v: &[T],
        policy: Option<&[u32]>,
        out: &mut [U],
        kind: Reduce,
        pick: impl Fn((T, u32)) -> U + Sync + Send,
        value: impl Fn(&U) -> T + Sync + Send,
    ) -> Result<Option<(f64, f64)>, SolveError> {
        match &self.path {
            Path::Block(b) => Ok(Some(
                b.each_core_range(self, v, policy, out, kind, pick, value),
            )),
            Path::Generic(_) if policy.is_some() => unreachable!("checked by can_evaluate"),
            Path::Generic(g) => g.each_core(self, v, out, kind, pick).map(|()| None),
        }
    }

    /// A full backup of `v` into `values` with every core's greedy joint action in `actions`
    /// (internal order), and the range of `values - v` where the block path takes it (`None`
    /// on the generic path, which reduces into `pairs` and splits them).
    fn each_core_greedy(
        &self,
        v: &[T],
        (values, actions): (&mut [T], &mut [u32]),
        pairs: &mut Vec<(T, u32)>,
    ) -> Result<Option<(f64, f64)>, SolveError> {
        match &self.path {
            Path::Block(b) => Ok(Some(b.each_core_greedy(self, v, values, actions))),
            Path::Generic(g) => {
                pairs.resize(v.len(), (T::ZERO, 0));
                g.each_core(self, v, pairs, Reduce::Argmax, |r| r)?;
                let pairs = &pairs[..];
                let chunk = sweeps::PASS_CHUNK;
                par::map_reduce_chunks_mut2(
                    (values, actions),
                    chunk,
                    || (),
                    |_, i, xs, us| split_pairs(&pairs[i * chunk..], xs, us),
                    (),
                    |(), ()| (),
                );
                Ok(None)
            }
        }
    }

    /// One asynchronous sweep in place; returns `||V_new - V_old||_inf`.
    fn sweep_async(&self, v: &mut [T]) -> Result<f64, SolveError> {
        match &self.path {
            Path::Generic(g) => g.sweep_async(self, v),
            Path::Block(b) => Ok(b.sweep_async(self, v)),
        }
    }

    /// `gamma * max_{d non-goal, u} |(P dv)[d, u]|`, internal order.
    fn abs_max(&self, dv: &[T]) -> Result<T, SolveError> {
        match &self.path {
            Path::Generic(g) => g.abs_max(self, dv),
            Path::Block(b) => Ok(b.abs_max(self, dv)),
        }
    }

    /// Greedy joint action per core, internal order.
    fn greedy_internal(&self, v: &[T], out: &mut [u32]) -> Result<(), SolveError> {
        self.each_core(v, out, Reduce::Argmax, |r| r.1)
    }

    /// One policy-evaluation sweep of `v` (grid order) under the joint actions `policy` (one
    /// per core, grid order): `rho + gamma P_policy v` per core, the evaluation sweep of
    /// [`Scheme::ModifiedPolicy`]. Under the greedy actions of `v` it equals [`Self::apply`]
    /// bit for bit.
    ///
    /// Needs what that scheme needs of the operator: the block path with several blocks, a
    /// state-only reward, no absorbing goal and no terminal states
    /// ([`SolveError::PolicyEvaluation`] otherwise).
    pub fn evaluate_policy(&self, v: &[T], policy: &[u32]) -> Result<Vec<T>, SolveError> {
        crate::error::check_len("V", self.n_cores(), v.len())?;
        crate::error::check_len("policy", self.n_cores(), policy.len())?;
        self.check_policy(policy)?;
        let (vi, pi) = (self.to_internal(v), self.to_internal(policy));
        let mut out = self.zeros();
        self.each_core_range(&vi, Some(&pi), &mut out, Reduce::Max, |r| r.0, |&x| x)?;
        Ok(self.to_grid(&out))
    }

    /// That every entry of `policy` names a joint action and that the operator can evaluate
    /// a policy.
    fn check_policy(&self, policy: &[u32]) -> Result<(), SolveError> {
        let n_joint = self.joint.n_joint();
        if let Some(&u) = policy.iter().find(|&&u| u as usize >= n_joint) {
            return Err(EvalError::OutOfRange {
                what: "joint action",
                index: u as usize,
                len: n_joint,
            }
            .into());
        }
        if !self.can_evaluate() {
            return Err(SolveError::PolicyEvaluation);
        }
        Ok(())
    }

    /// Whether [`Self::evaluate`] runs on this operator (see [`Scheme::ModifiedPolicy`]).
    fn can_evaluate(&self) -> bool {
        match &self.path {
            Path::Block(b) => self.goal.is_empty() && b.can_evaluate(self),
            Path::Generic(_) => false,
        }
    }

    /// Row-major grid order -> internal order.
    fn to_internal<U: bytemuck::Pod + Default + Send + Sync>(&self, v: &[U]) -> Vec<U> {
        match &self.path {
            Path::Generic(_) => v.to_vec(),
            Path::Block(b) => b.reorder(v, false),
        }
    }

    /// Internal order -> row-major grid order.
    fn to_grid<U: bytemuck::Pod + Default + Send + Sync>(&self, v: &[U]) -> Vec<U> {
        match &self.path {
            Path::Generic(_) => v.to_vec(),
            Path::Block(b) => b.reorder(v, true),
        }
    }

    /// One synchronous backup of `v` (grid order): `max_u (rho + gamma P v)` per core.
    pub fn apply(&self, v: &[T]) -> Result<Vec<T>, SolveError> {
        crate::error::check_len("V", self.n_cores(), v.len())?;
        let vi = self.to_internal(v);
        let mut out = self.zeros();
        self.sweep_sync(&vi, &mut out)?;
        Ok(self.to_grid(&out))
    }

    /// The greedy joint action of every core for `v` (grid order): the lowest-index maximiser
    /// of `theta[d, .] = rho + gamma P v`.
    pub fn greedy(&self, v: &[T]) -> Result<Vec<u32>, SolveError> {
        crate::error::check_len("V", self.n_cores(), v.len())?;
        let vi = self.to_internal(v);
        let mut out = vec![0u32; self.n_cores()];
        self.greedy_internal(&vi, &mut out)?;
        Ok(self.to_grid(&out))
    }

    /// What a controller needs to take the greedy decisions of [`Self::q_values`] without the
    /// model ([`DecisionTables`]): block path only, without terminal states or an absorbing
    /// goal, with rewards of the state alone ([`SolveError::NoDecisionTables`] otherwise).
    pub fn decision_tables(&self) -> Result<DecisionTables<T>, SolveError> {
        match &self.path {
            Path::Block(b) => b.decision_tables(self),
            Path::Generic(_) => Err(SolveError::NoDecisionTables {
                why: "the operator takes the generic path",
            }),
        }
    }

    /// `out[u] = Q(x, u) = sum_d mu_d(x) theta[d, u]` at any state `x`, with
    /// `theta[d, u] = rho(x_d, u) + gamma V~(f(x_d, u))` recomputed from `v` (grid order). The
    /// block path mixes the active cores' block tables first, so a decision costs a few small
    /// products instead of `2^E` model steps per joint action.
    pub fn q_values(&self, v: &[T], x: &[T], out: &mut [T]) -> Result<(), SolveError> {
        crate::error::check_len("V", self.n_cores(), v.len())?;
        crate::error::check_len("Q-values", self.joint.n_joint(), out.len())?;
        match &self.path {
            Path::Block(b) => b.q_values(self, v, x, out),
            Path::Generic(_) => {
                let e = self.state_dim();
                let mut scratch = vec![T::ZERO; crate::backup::scratch_len(e, self.joint.dim())];
                let mut row = vec![T::ZERO; self.joint.n_joint()];
                crate::backup::q_values_from_v(
                    self.model,
                    &self.grid,
                    &self.joint,
                    v,
                    self.backup,
                    x,
                    &mut scratch,
                    &mut row,
                    out,
                )?;
                Ok(())
            }
        }
    }
}

/// Per-task buffers of [`Operator::reduce`].
struct ReduceWork<T> {
    x: Vec<T>,
    u: Vec<T>,
    /// A row of expected values with terminal entries zeroed (block path; grows on first use).
    ev: Vec<T>,
}
