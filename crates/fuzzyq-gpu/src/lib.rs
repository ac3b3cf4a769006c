//! Fuzzy Q-iteration's block backup on a GPU, through [wgpu](https://wgpu.rs) (Vulkan, Metal,
//! DX12: NVIDIA, AMD, Intel and Apple GPUs), with the CPU kernels' bits.
//!
//! # Design
//! The iteration itself (sweep records, the stopping rule, MacQueen's extrapolation,
//! modified policy iteration's evaluation budget, the coarse start) stays in
//! `fuzzyq-core`'s driver, which asks a [`Sweeps`](fuzzyq_core::solver::Sweeps) backend for
//! every pass over `V` (a fresh run's coarse start on the GPU while the host prepares the
//! run's operator: [`fuzzyq_core::solver::solve_with`]). [`GpuSweeps`] is that backend on a GPU: the block tables
//! ([`BlockPlan`](fuzzyq_core::solver::BlockPlan)), `V`'s buffers and the policy live on
//! the device, and only scalars come back between passes (the range of a sweep's change, the
//! exact delta); `V` and the greedy actions come back at the end, a few slabs at a time put
//! in grid order as they arrive, through two staging buffers that take turns (the device
//! copies one piece while the host places the other; [`Gpu::with_read_bytes`]: the host
//! never holds `V` twice),
//! and when an observer asks for the run's state (a checkpoint).
//!
//! A full backup runs the block contraction a batch at a time ([`Batches`]: a run of slabs, or
//! where one slab's stage outputs would not fit, a run of cores of a later block below fixed
//! cores of the earlier ones, whose shared stages are kept from batch to batch). Batches bound
//! the stage buffers (256 MiB by default, [`Gpu::with_batch_bytes`]). Every kernel is compiled
//! with the problem's sizes as constants.
//!
//! Each stage before the last writes its output for the batch, by one of three kernels:
//! - a thread per element and every action of its block, the block core's rows merged by
//!   column so that each value of the stage before is read once per step (`stagem.wgsl`,
//!   [`Gpu::with_merged_stages`]; the default on GPUs for problems below
//!   [`COMPILE_IN_FROM`] multiply-adds per full backup);
//! - a thread per element and action (`stagec.wgsl`);
//! - a thread per element of an item of the stage before, taking every core of the block
//!   below it, with the block's rows compiled into the kernel as constants (`unrolled.rs`,
//!   [`Gpu::with_unrolled_stages`]; the default on software adapters, and on GPUs from
//!   [`COMPILE_IN_FROM`] multiply-adds per full backup, where it repays the driver's
//!   compiler: [`Gpu::with_rows_compiled_in_from`]).
//!
//! The last stage is fused with the maximum over actions ([`LastStage`]; the default
//! [`LastStage::default`], as measured on an H200 and on lavapipe):
//! - one row at a time, up to 32 lanes per core, each taking several of the core's columns
//!   so that a weight feeds several multiply-adds (`last1.wgsl`; the default on GPUs below
//!   [`COMPILE_IN_FROM`]);
//! - the core's rows merged by column, so that each value of the stage before is read once
//!   per core and feeds every action whose row has its column, several neighbouring cores in
//!   turn (`lastm.wgsl`);
//! - a workgroup per item of the stage before, whose values it loads into workgroup memory
//!   once (`lastw.wgsl`);
//! - a workgroup per item with the last block's rows compiled in, each lane taking a few of
//!   the item's columns for every core, the cores' maxima reduced over the lanes by halving
//!   (`unrolled.rs`; the default on software adapters, and on GPUs from
//!   [`COMPILE_IN_FROM`]: an H200 runs the paper grid's last stage in 5.8 ms so, 23.1 ms
//!   one row at a time);
//! - the same computing the stage before it too, each lane the values of its own columns
//!   where a core first reads them, so that stage is neither dispatched nor written
//!   ([`LastStage::Joined`]);
//! - a workgroup per item of the stage before that computes the item's values into
//!   workgroup memory from the stage before that, each thread one column's row held in
//!   registers, then takes each core with a few lanes, each action's row held in registers
//!   over the lane's columns, as many of the item's columns a pass as the workgroup memory
//!   holds: that stage neither dispatched nor written, and no rows compiled in
//!   (`lasts.wgsl`, [`LastStage::Staged`]).
//!
//! The lanes reduce to the largest value at the lowest action by subgroup shuffles, or in
//! workgroup memory where the adapter has no single subgroup size or a start-up probe finds a
//! workgroup of that size is not one subgroup. Where the actions are renumbered or the reward
//! depends on the action, the last stage instead writes full rows that one thread per core
//! reduces over the joint actions in order (`block.wgsl`).
//!
//! A policy-evaluation sweep runs the first stages of a full backup for every action (their
//! sums are shared by every core below each item), then a thread per core sums its own
//! action's rows of the other blocks over the last stage's output, nested
//! (generated per problem); how many stages is [`Evaluation`]'s choice, by default the least
//! estimated work (three point masses: three of six, 16 times fewer multiply-adds than
//! nesting every block per core).
//!
//! # The CPU's bits
//! Every element is the CPU's sum: a chain over its row's entries in order, `fma` from 0, and
//! `V = rho + gamma m` rounded as two operations (the product is XORed with a runtime zero so
//! that no shader compiler fuses it). Maxima are exact in any order. So on an adapter whose
//! `fma` is fused (measured at start-up, [`AdapterSummary::fused_fma`]; NVIDIA's are) a run
//! gives the CPU's policy bytes. An adapter that rounds the product first (Mesa's lavapipe)
//! gives the bits of [`reference::HostSweeps`] with [`reference::Rounding::Product`], which
//! the tests check on every CI run. The change statistics use `f64` in shaders where the
//! adapter has it, and otherwise read `V` back.
//!
//! # No row bounds
//! The CPU's last stage bounds each action's row and skips rows that provably cannot raise the
//! maximum (a quarter of a full backup's time there). The GPU's computes every row: its time
//! goes to reading the stage before (each value once per core and step, feeding every action
//! whose row has its column), not to multiply-adds (those of a full backup of the paper's grid
//! take 0.35 ms of an H200), and a skipped row saves multiply-adds only, while its bound needs
//! the maximum of each of its columns: a second read of the same values, or another output of
//! the stage before. The bounds skip only rows that cannot change the maximum or its lowest
//! index, so both give the same bits.
//!
//! # Parts of `V`
//! `V` and the other per-core buffers (the policy, the rewards, the exact delta's work
//! buffers) are cut into parts of whole slabs, each within one storage binding (2 GiB through
//! wgpu, on every backend; three point masses on the paper's cores, `V` 33 GB, take 23). A
//! stage's output over one binding (there, one slab's first stage: 3.69 GB) is cut the same
//! way, into runs of the values one column of the next stage reads. Every index a shader
//! computes is within a part or a stage buffer, so it fits `u32` however many cores the grid
//! has. The first stage of a full backup and policy evaluation read `V` at other cores: they
//! bind every part (group 1) and pick one from the first block's core (`v_at`); the other
//! passes run a part at a time, and a batch of the last stage never straddles two parts. Any
//! parts give the same bits ([`Gpu::with_part_bytes`]).
//!
//! # Runtime checks
//! wgpu compiles untrusted WGSL with runtime checks: workgroup memory zeroed before each
//! workgroup starts, a 64-bit counter on every loop, integer division guarded against a zero
//! divisor, and indices clamped to their array's length. These kernels need none of them, so
//! they are compiled without ([`Checks`], [`Gpu::with_checks`], `FUZZYQ_GPU_CHECKS`):
//! - every read of workgroup memory follows a write of the same element in the same
//!   workgroup, behind a barrier (the reductions over lanes, the staged and per-item last
//!   stages' tiles, the exchange of an unrolled stage's values, the change statistics);
//! - every loop counts up by a positive step to a bound of a few thousand at most (a row's
//!   entries, a block's cores, a pass's columns);
//! - every divisor is a positive constant compiled in or a size checked on the host;
//! - every index is a core, column or entry of a table that the host built and checked
//!   against the buffer it indexes, or a lane's slot in an array of the workgroup's size.
//!
//! None of the checks changes a result; each costs instructions. The tests run every kind of
//! stage and last stage with every check on and compare the bits with the default's.
//!
//! # Limits
//! `f32` only; the block path only (a model that declares no blocks is refused, as are models
//! with terminal states and asynchronous sweeps); one slab of `V`, one column's values of a
//! stage's output and the last stage's input for one batch must fit one storage binding, and
//! the parts a kernel binds its storage bindings
//! ([`AdapterSummary::max_storage_buffers`] less ten). All of a run's buffers must fit the
//! adapter's memory: `V` as often as the run's scheme uses it
//! ([`Scheme::value_buffers`](fuzzyq_core::solver::Scheme::value_buffers): twice for modified
//! policy iteration, three times for value iteration, with two work buffers for its exact
//! stopping rule), the policy, the tables, rewards and stage buffers. Both are checked before
//! anything is allocated ([`GpuError::TooLarge`], [`GpuError::OutOfMemory`]; the memory where
//! the API reports it, Vulkan, through wgpu-hal as wgpu has no API for it).

mod batches;
mod buffers;
mod compile;
mod context;
mod error;
mod gpu;
mod kernels;
mod last;
mod memory;
mod parts;
mod probe;
pub mod reference;
mod shape;
mod sweeps;
mod unrolled;

use core::ops::ControlFlow;

use fuzzyq_core::Model;
use fuzzyq_core::solver::{Grid, Progress, Solution, SolverConfig, SolverState};

pub use batches::Batches;
pub use context::{AdapterSummary, Checks, OpeningSeconds};
pub use error::GpuError;
pub use gpu::{COMPILE_IN_FROM, Evaluation, Gpu, LastStage, Opening};
pub use sweeps::GpuSweeps;

/// Runs fuzzy Q-iteration on `model` over `grid` on `gpu`, continued from `resume` or afresh:
/// [`fuzzyq_core::solver::solve_from`] with every pass over `V` on the GPU (the coarse start's
/// too). The observer sees every sweep and, with `show_state`, the run's state after each
/// (`V` read back from the device: for checkpoints).
pub fn solve_from<M>(
    gpu: &Gpu,
    model: &M,
    grid: &Grid<f32>,
    config: &SolverConfig,
    resume: Option<SolverState<'_, f32>>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, f32>>) -> ControlFlow<()>,
) -> Result<Solution<f32>, GpuError>
where
    M: Model<f32> + Sync + ?Sized,
{
    solve_on(
        || Ok(gpu.clone()),
        model,
        grid,
        config,
        (resume, show_state),
        observer,
    )
}

/// [`solve_from`] on the process's GPU ([`Gpu::shared`]), waited for only once the run's
/// operator is prepared (the rewards, the block tables: the CPU's part of the set-up), so
/// that an open begun beforehand ([`Gpu::open_shared_in_background`]) overlaps that
/// preparation instead of preceding it.
pub fn solve_shared<M>(
    model: &M,
    grid: &Grid<f32>,
    config: &SolverConfig,
    resume: Option<SolverState<'_, f32>>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&SolverState<'_, f32>>) -> ControlFlow<()>,
) -> Result<Solution<f32>, GpuError>
where
    M: Model<f32> + Sync + ?Sized,
{
    solve_on(
        Gpu::shared,
        model,
        grid,
        config,
        (resume, show_state),
        observer,
    )
}

/// [`solve_from`] on the GPU `gpu()` gives when each backend is made (the run's, and its
/// coarse start's).
fn solve_on<M>(
    gpu: impl Fn() -> Result<Gpu, GpuError> + Sync,
    model: &M,
    grid: &Grid<f32>,
    config: &SolverConfig,
    (resume, show_state): (Option<SolverState<'_, f32>>, bool),
    observer: impl FnMut(&Progress, Option<&SolverState<'_, f32>>) -> ControlFlow<()>,
) -> Result<Solution<f32>, GpuError>
where
    M: Model<f32> + Sync + ?Sized,
{
    if config.sweep != fuzzyq_core::solver::SweepMode::Synchronous {
        return Err(GpuError::Unsupported(
            "runs synchronous sweeps only (solver.sweep = \"sync\")",
        ));
    }
    fuzzyq_core::solver::solve_with(
        model,
        grid,
        config,
        resume,
        show_state,
        &mut |op, scheme| GpuSweeps::for_scheme(&gpu()?, op, scheme),
        observer,
    )
}
