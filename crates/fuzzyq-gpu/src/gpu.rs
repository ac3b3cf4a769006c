//! The GPU context: one wgpu adapter and device, and what was measured of them.

use std::sync::Arc;

use crate::context::{AdapterSummary, Checks, Context, OpeningSeconds};
use crate::error::GpuError;

/// One GPU: wgpu's device and queue, shared by every run that uses it (cheap to clone).
#[derive(Clone)]
pub struct Gpu {
    pub(crate) inner: Arc<Context>,
    /// The generic kernels (`block.wgsl`, `diff.wgsl`), shared by every run.
    pub(crate) kernels: Arc<crate::kernels::Kernels>,
    /// The largest storage binding a run uses (the adapter's, or less).
    pub(crate) max_binding: u64,
    /// The device memory a run's buffers may take (the adapter's, or less), if known.
    pub(crate) memory: Option<u64>,
    /// Bytes of a batch's largest stage buffer.
    pub(crate) batch_bytes: u64,
    /// Bytes of a part of `V` (at most one storage binding).
    pub(crate) part_bytes: u64,
    /// Bytes of a piece of the result read back at the end of a run.
    pub(crate) read_bytes: u64,
    /// Whether the last stage may reduce a core's lanes by subgroup operations.
    pub(crate) subgroups: bool,
    /// How the fused last stage takes a core's rows.
    pub(crate) last: LastStage,
    /// Whether the stages before it take a block core's rows merged by column.
    pub(crate) merged_stages: bool,
    /// Whether the stages before it have their block's rows compiled in.
    pub(crate) unrolled_stages: bool,
    /// The kernels of a problem whose full backup costs fewer multiply-adds than
    /// `compile_in_from`: whether the stages compile their rows in, and the last stage
    /// ([`Gpu::with_rows_compiled_in_from`]).
    pub(crate) small: (bool, LastStage),
    pub(crate) compile_in_from: f64,
    /// How policy evaluation splits the contraction.
    pub(crate) evaluation: Evaluation,
}

/// Multiply-adds of a full backup from which a GPU's default kernels compile the block's
/// rows in ([`Gpu::with_rows_compiled_in_from`]): about 0.25 s of full backup with the rows
/// read from the tables on an H200, so that a run of ten full backups repays a compilation
/// on the driver's first sight of the kernels.
pub const COMPILE_IN_FROM: f64 = 1e11;

/// How a policy-evaluation sweep splits the block contraction ([`Gpu::with_evaluation`], or
/// `FUZZYQ_GPU_EVAL`: `auto`, `nested` or `stages:K`). A core's expected value under its
/// action is the nested sum over its action's rows, block 0 innermost; the first stages of a
/// full backup compute the inner sums for every action at once, shared by every core below
/// each item. Every split computes the same sums in the same order, so the same bits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Evaluation {
    /// The split with the least work, estimated from each block's mean row length, a
    /// multiply-add of a stage with its rows compiled in ([`Gpu::with_unrolled_stages`])
    /// counted as a third of a nested one (the default). On the paper's cores, rows of 3.66
    /// entries on average, with the rows compiled in: the paper's grid (four blocks) runs two
    /// stages, half the multiply-adds of nested per core; three point masses (six blocks)
    /// three, 16 times fewer with 3 forces per axis and 5 times fewer with 5.
    Auto,
    /// The first `stages` stages of a full backup for every action, in its batches, then a
    /// thread per core nests its own action's rows of the other blocks over the output of the
    /// last of them (`0`: every block per core over `V`, `nested`). Where that output is cut
    /// into parts, or `stages` is not below the blocks, the largest split below it that
    /// reads one buffer.
    Stages(u32),
}

impl Evaluation {
    /// `auto`, `nested` (`Stages(0)`) or `stages:K` (`None` for anything else).
    #[must_use]
    pub fn parse(s: &str) -> Option<Self> {
        match s.split_once(':') {
            None if s == "auto" => Some(Evaluation::Auto),
            None if s == "nested" => Some(Evaluation::Stages(0)),
            Some(("stages", k)) => k.parse().ok().map(Evaluation::Stages),
            _ => None,
        }
    }
}

/// How the fused last stage of a full backup takes a core's rows (its block actions)
/// ([`Gpu::with_last_stage`], or `FUZZYQ_GPU_LAST`: `rows`, `merged`, `merged:CORES`, `tile`,
/// `tile:THREADS`, `unrolled` or `joined`; the
/// default [`LastStage::default`]). Every
/// choice gives the same bits; they differ in how often the stage before is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LastStage {
    /// One row at a time (`last1.wgsl`): each value of the stage before is read once per row
    /// that has its column.
    Rows,
    /// The core's rows merged by column (`lastm.wgsl`,
    /// [`PlanTable::merged_steps`](fuzzyq_core::solver::PlanTable::merged_steps)): each value
    /// is read once per core and feeds every action whose row has its column (the paper's
    /// point masses: 8.1 steps per core against 18.3 row entries); `cores` cores in turn per
    /// group of lanes, neighbours whose columns are mostly shared. Blocks of more than 32
    /// actions take [`LastStage::Rows`].
    Merged {
        /// Cores each group of lanes takes in turn (at least 1).
        cores: u32,
    },
    /// A workgroup of `threads` threads per item of the stage before (`lastw.wgsl`): the
    /// item's values (the last block's cores times the product actions before it: 22.5 KB on
    /// the paper's grid) loaded once into workgroup memory, which its cores' lanes then read,
    /// one row at a time; where they do not fit the adapter's workgroup memory,
    /// [`LastStage::Rows`]. Not a default: on an H200 the paper grid's last stage took
    /// 48.6 ms so, against 23.1 ms one row at a time.
    Tile {
        /// Threads per workgroup (a power of two from 32 to 256).
        threads: u32,
    },
    /// The last block's rows compiled into the kernel as constants (`lastu`): a workgroup per
    /// item of the stage before, each lane taking a few of the item's product-action columns
    /// for every core, loading each value a core's rows read once and running each row as a
    /// chain of `fma`s with constant weights; the cores' maxima then reduce over the lanes a
    /// chunk of cores at a time, each exchange halving the cores a lane holds. Where the
    /// table is too large to compile in, [`LastStage::MERGED`] on a software adapter and
    /// [`LastStage::Rows`] on a GPU. The default ([`LastStage::default`]; on a GPU for
    /// problems from [`COMPILE_IN_FROM`] multiply-adds per full backup).
    Unrolled,
    /// [`LastStage::Unrolled`] with the stage before it joined in (`lastj`): the workgroup
    /// of an item computes the item's values itself, each lane those of its own columns where
    /// a core first reads them, from the stage before that (its block core's rows read from
    /// the tables), so the stage before the last is neither dispatched nor written (on the
    /// paper's grid, 2 GB written and read again per full backup). Where there is no such
    /// stage (two blocks or fewer), its output is cut into parts, or its rows hold more than
    /// 16 entries, [`LastStage::Unrolled`]. Not a default: on an H200, the paper's grid, it
    /// took 15.2 ms where [`LastStage::Unrolled`] and the stage before it took 5.8 and 3.1 ms.
    Joined,
    /// A workgroup of `threads` threads per item of the stage before, which computes that
    /// item's values itself into workgroup memory (`lasts.wgsl`), a pass over a share of
    /// the item's product-action columns at a time: each thread one column of the stage
    /// before's block-core row, its entries held in registers, over the item's cores of the
    /// last block; then each core of the item taken by a few lanes, its rows' entries held
    /// in registers over the lane's columns read from workgroup memory, each lane keeping
    /// its largest over the passes; the lanes of a core folded once at the end. The stage
    /// before the last is neither dispatched nor written, and neither kernel compiles rows
    /// in (no compiler time that grows with the tables). A pass takes as many columns as
    /// the adapter's workgroup memory holds, rounded down to a whole number per thread
    /// where a pass takes more than there are threads (all 125 of the paper's grid,
    /// 22.5 KB; 256 of the 3,125 of three masses with 5 forces per axis in 48 KB with 256
    /// threads), at most `columns` where given. Where there is no such stage (two blocks
    /// or fewer), its output is cut into parts, a row of either block holds more than 16
    /// entries or not one column of the item fits the workgroup memory,
    /// [`LastStage::MERGED`] on a software adapter and [`LastStage::Rows`] on a GPU. Not yet
    /// timed on a GPU.
    Staged {
        /// Threads per workgroup (at least 1, at most the adapter allows; the setting takes
        /// a power of two from 32 to 1024).
        threads: u32,
        /// Most product-action columns per pass (`None`: as many as fit; at least 1).
        columns: Option<u32>,
    },
}

/// The default, as measured: the rows compiled in ([`LastStage::Unrolled`]). On an H200 the
/// last stage of a full backup of the paper's grid takes 5.4-5.8 ms so, against 23.1 ms one
/// row at a time and 48.6 ms in tiles; on a software adapter (Mesa's lavapipe) it is 9.5-19
/// times faster than merged rows with 4 cores in turn and 6-8.6 times faster than one row at
/// a time. On a GPU a problem below [`COMPILE_IN_FROM`] multiply-adds per full backup takes
/// [`LastStage::Rows`] instead ([`Gpu::with_rows_compiled_in_from`]).
impl Default for LastStage {
    fn default() -> Self {
        LastStage::Unrolled
    }
}

impl LastStage {
    /// Merged rows, 4 cores in turn (`merged`).
    pub const MERGED: LastStage = LastStage::Merged { cores: 4 };

    /// `rows`, `merged` (4 cores in turn), `merged:CORES`, `tile` (128 threads),
    /// `tile:THREADS`, `unrolled`, `joined`, `staged` (256 threads), `staged:THREADS` or
    /// `staged:THREADS:COLUMNS` (`None` for anything else).
    #[must_use]
    pub fn parse(s: &str) -> Option<Self> {
        let n = |n: &str| n.parse::<u32>().ok();
        match s.split_once(':') {
            None if s == "rows" => Some(LastStage::Rows),
            None if s == "merged" => Some(LastStage::MERGED),
            None if s == "tile" => Some(LastStage::Tile { threads: 128 }),
            None if s == "unrolled" => Some(LastStage::Unrolled),
            None if s == "joined" => Some(LastStage::Joined),
            None if s == "staged" => Some(LastStage::Staged {
                threads: 256,
                columns: None,
            }),
            Some(("merged", c)) => n(c)
                .filter(|&c| c > 0)
                .map(|cores| LastStage::Merged { cores }),
            Some(("tile", t)) => n(t)
                .filter(|t| t.is_power_of_two() && (32..=256).contains(t))
                .map(|threads| LastStage::Tile { threads }),
            Some(("staged", t)) => {
                let (t, columns) = match t.split_once(':') {
                    Some((t, c)) => (t, Some(n(c).filter(|&c| c > 0)?)),
                    None => (t, None),
                };
                n(t).filter(|t| t.is_power_of_two() && (32..=1024).contains(t))
                    .map(|threads| LastStage::Staged { threads, columns })
            }
            _ => None,
        }
    }
}

/// The process's GPU ([`Gpu::shared`]).
enum Shared {
    /// Not opened (or a failed open already reported).
    Closed,
    /// Open.
    Open(Gpu),
    /// A background open failed; the next [`Gpu::shared`] reports it.
    Failed(GpuError),
}

/// The process's GPU, locked while it is being opened.
fn shared_slot() -> std::sync::MutexGuard<'static, Shared> {
    static SHARED: std::sync::Mutex<Shared> = std::sync::Mutex::new(Shared::Closed);
    SHARED
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The process's GPU being opened on a thread of its own
/// ([`Gpu::open_shared_in_background`]).
#[derive(Debug)]
pub struct Opening(std::thread::JoinHandle<Result<f64, GpuError>>);

impl Opening {
    /// Waits for the open: its seconds (next to none where the GPU was open already), or why
    /// it failed.
    pub fn wait(self) -> Result<f64, GpuError> {
        self.0
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    }
}

impl core::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Gpu")
            .field("adapter", &self.inner.summary)
            .finish()
    }
}

impl Gpu {
    /// Opens the most capable adapter wgpu finds (`FUZZYQ_GPU_ADAPTER` picks one by a part of
    /// its name, `WGPU_BACKEND` the API), compiles the generic kernels and runs the start-up
    /// probes (is `fma` fused; do subgroup shuffles reduce as the last stage needs).
    pub fn new() -> Result<Self, GpuError> {
        // Read before the adapter opens, so that a mistyped setting fails at once.
        let settings = Settings::from_env()?;
        let start = std::time::Instant::now();
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::from_env()
            .unwrap_or(wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12);
        desc.flags = wgpu::InstanceFlags::empty().with_env();
        let instance = wgpu::Instance::new(desc);
        let adapter = crate::context::pick_adapter(&instance)?;
        let info = adapter.get_info();
        let features = adapter.features() & (wgpu::Features::SHADER_F64 | wgpu::Features::SUBGROUP);
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("fuzzyq"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device {
            adapter: info.name.clone(),
            why: e.to_string(),
        })?;
        let summary = AdapterSummary {
            name: info.name.clone(),
            backend: info.backend.to_str().to_owned(),
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_owned(),
            fused_fma: false,
            f64: features.contains(wgpu::Features::SHADER_F64),
            max_buffer: limits.max_buffer_size,
            max_binding: limits.max_storage_buffer_binding_size,
            max_storage_buffers: limits.max_storage_buffers_per_shader_stage,
            memory: crate::memory::available(&adapter),
            subgroup_size: (features.contains(wgpu::Features::SUBGROUP)
                && info.subgroup_min_size == info.subgroup_max_size
                && (4..=64).contains(&info.subgroup_min_size))
            .then_some(info.subgroup_min_size),
            software: info.device_type == wgpu::DeviceType::Cpu,
            opening: OpeningSeconds::default(),
        };
        let mut ctx = Context {
            device,
            queue,
            summary,
            checks: settings.checks.unwrap_or(Checks::NONE),
        };
        let opened = start.elapsed().as_secs_f64();
        // The generic kernels, compiled once for every run on this GPU, and the probes.
        let kernels = crate::kernels::Kernels::new(&ctx)?;
        let compiled = start.elapsed().as_secs_f64();
        ctx.summary.fused_fma = crate::probe::fused_fma(&ctx, &kernels)?;
        ctx.summary.subgroup_size = match ctx.summary.subgroup_size {
            Some(s) if crate::probe::subgroups_work(&ctx, &kernels, s)? => Some(s),
            _ => None,
        };
        ctx.summary.opening = OpeningSeconds {
            device: opened,
            kernels: compiled - opened,
            probes: start.elapsed().as_secs_f64() - compiled,
        };
        // The stages before the last: merged, and with their rows compiled in (as measured
        // on lavapipe and an H200), unless a setting says otherwise; on a GPU, only for
        // problems large enough to repay the compiler's time.
        let software = ctx.summary.software;
        let (merged_stages, unrolled_stages) = settings.stages.unwrap_or((true, true));
        let last = settings.last.unwrap_or_default();
        let small = (
            settings.stages.is_some_and(|s| s.1),
            settings.last.unwrap_or(LastStage::Rows),
        );
        Ok(Self {
            max_binding: ctx.summary.max_binding,
            memory: ctx.summary.memory,
            batch_bytes: settings.batch_kib.map_or(256 << 20, |k| k << 10),
            part_bytes: settings.part_kib.map_or(u64::MAX, |k| k << 10),
            read_bytes: crate::buffers::STAGING_BYTES,
            subgroups: settings.subgroups.unwrap_or(true),
            last,
            merged_stages,
            unrolled_stages,
            small,
            compile_in_from: if software { 0.0 } else { COMPILE_IN_FROM },
            evaluation: settings.evaluation.unwrap_or(Evaluation::Auto),
            kernels: Arc::new(kernels),
            inner: Arc::new(ctx),
        })
    }

    /// The process's GPU: opened by the first call ([`Gpu::new`]) and shared by every later
    /// one; a call while another thread opens it waits for that open. A failed open is tried
    /// again next time, except that a failed [`Gpu::open_shared_in_background`] is reported
    /// by the next call instead (the driver is not asked twice in a row).
    pub fn shared() -> Result<Self, GpuError> {
        let mut slot = shared_slot();
        match std::mem::replace(&mut *slot, Shared::Closed) {
            Shared::Open(g) => {
                *slot = Shared::Open(g.clone());
                Ok(g)
            }
            Shared::Failed(e) => Err(e),
            Shared::Closed => {
                let g = Self::new()?;
                *slot = Shared::Open(g.clone());
                Ok(g)
            }
        }
    }

    /// Starts opening the process's GPU ([`Gpu::shared`]) on a thread of its own and returns
    /// once that thread holds it, so that the host's set-up of a run (the rewards, the block
    /// tables) overlaps the driver's start-up and the run's own [`Gpu::shared`] waits for
    /// this open instead of starting another. `opened` is called with the GPU on that thread
    /// when it is open. [`Opening::wait`] gives the open's seconds or its error.
    pub fn open_shared_in_background(opened: impl FnOnce(&Gpu) + Send + 'static) -> Opening {
        let (holding, held) = std::sync::mpsc::sync_channel(0);
        let thread = std::thread::spawn(move || {
            let t0 = std::time::Instant::now();
            let mut slot = shared_slot();
            // The caller goes on only now: its next `shared` waits for this open.
            let _ = holding.send(());
            if !matches!(*slot, Shared::Open(_)) {
                *slot = Self::new().map_or_else(Shared::Failed, Shared::Open);
            }
            let seconds = t0.elapsed().as_secs_f64();
            match &*slot {
                Shared::Open(g) => {
                    opened(g);
                    Ok(seconds)
                }
                Shared::Failed(e) => Err(e.clone()),
                Shared::Closed => unreachable!("just opened or failed"),
            }
        });
        let _ = held.recv();
        Opening(thread)
    }

    /// The adapter and what was measured of it.
    #[must_use]
    pub fn summary(&self) -> &AdapterSummary {
        &self.inner.summary
    }

    /// The runtime checks this GPU's kernels are compiled with.
    #[must_use]
    pub fn checks(&self) -> Checks {
        self.inner.checks
    }

    /// This GPU with its kernels compiled with wgpu's runtime `checks` (by default none,
    /// [`Checks`]; `FUZZYQ_GPU_CHECKS` at the open), the generic kernels compiled again. The
    /// same device: every choice gives the same bits.
    pub fn with_checks(mut self, checks: Checks) -> Result<Self, GpuError> {
        if checks == self.inner.checks {
            return Ok(self);
        }
        let ctx = Context {
            device: self.inner.device.clone(),
            queue: self.inner.queue.clone(),
            summary: self.inner.summary.clone(),
            checks,
        };
        self.kernels = Arc::new(crate::kernels::Kernels::new(&ctx)?);
        self.inner = Arc::new(ctx);
        Ok(self)
    }

    /// This GPU with runs limited to storage bindings of at most `bytes` (the adapter's limit
    /// is the default): `V` is cut into parts of at most that size, and a run whose slab of
    /// `V` (or whose `V`, with one block) or smallest batch's stage output exceeds it is
    /// refused before anything is allocated ([`GpuError::TooLarge`]). For trying a smaller
    /// card's limits.
    #[must_use]
    pub fn with_binding_limit(mut self, bytes: u64) -> Self {
        self.max_binding = bytes.min(self.inner.summary.max_binding);
        self
    }

    /// This GPU with runs limited to `bytes` of device memory (the adapter's, as
    /// [`AdapterSummary::memory`] reports it, is the default): a run whose buffers would take
    /// more is refused before anything is allocated ([`GpuError::OutOfMemory`]). For a card
    /// shared with other work, or trying a smaller card's memory.
    #[must_use]
    pub fn with_memory_limit(mut self, bytes: u64) -> Self {
        self.memory = Some(self.inner.summary.memory.map_or(bytes, |m| m.min(bytes)));
        self
    }

    /// This GPU with the last stage's lanes reduced by subgroup operations where the adapter
    /// has them with one subgroup size (`true`, the default; `FUZZYQ_GPU_SUBGROUPS=0` turns
    /// them off), or in workgroup memory. Both give the same bits.
    #[must_use]
    pub fn with_subgroups(mut self, on: bool) -> Self {
        self.subgroups = on;
        self
    }

    /// This GPU with the fused last stage taking a core's rows as `last` says (the default
    /// [`LastStage::default`], or `FUZZYQ_GPU_LAST`), for every problem. All give the
    /// same bits.
    #[must_use]
    pub fn with_last_stage(mut self, last: LastStage) -> Self {
        self.last = last;
        self.small.1 = last;
        self
    }

    /// This GPU compiling the block's rows into the kernels by default only for problems
    /// whose full backup costs at least `multiply_adds`; below that, the stages before the
    /// last read their rows from the tables (merged by column) and the last stage takes one
    /// row at a time, unless [`Gpu::with_unrolled_stages`] or [`Gpu::with_last_stage`] (or
    /// their settings) choose for every problem. The same bits either way.
    ///
    /// The default on a GPU is [`COMPILE_IN_FROM`]: on an H200 the default point-mass run's
    /// set-up took 0.49 s with the paper's grid's rows compiled in (2.4 s on the driver's
    /// first sight of the kernels; measured before each core's rows became a function of
    /// their own, which cut Naga's share by 0.14 s of a Zen 4 core) against 0.12 s with the
    /// tables read, more than the 0.18 s
    /// its 9 full backups saved (7.3 against 29.5 ms each), while three point masses
    /// (`examples/three-point-masses.toml`, 3.2e11 multiply-adds per full backup) trained in
    /// 10.6 s instead of 24.5 s. On a software adapter it is 0 (always: lavapipe compiles the
    /// paper grid's kernels in 0.29-0.31 s and runs its full backup 10 times faster, 5.4
    /// against 52.6 s).
    #[must_use]
    pub fn with_rows_compiled_in_from(mut self, multiply_adds: f64) -> Self {
        self.compile_in_from = multiply_adds;
        self
    }

    /// The GPU's kernel choices for a problem of `multiply_adds` per full backup (`None`:
    /// not known, taken as large).
    pub(crate) fn for_problem(&self, multiply_adds: Option<f64>) -> Gpu {
        let mut g = self.clone();
        if multiply_adds.is_some_and(|m| m < self.compile_in_from) {
            (g.unrolled_stages, g.last) = self.small;
        }
        g
    }

    /// This GPU with the stages of a full backup before the last taking a block core's rows
    /// merged by column (`true`, the default: a thread computes an element for every action
    /// of the block, reading each value of the stage before once per step,
    /// [`PlanTable::merged_steps`](fuzzyq_core::solver::PlanTable::merged_steps)), or one
    /// row at a time (`false`, or `FUZZYQ_GPU_STAGES=rows`: a thread per element). Blocks of
    /// more than 32 actions, and stages whose block core has fewer than 32 elements (one-block
    /// models), take one row at a time. Both give the same bits.
    #[must_use]
    pub fn with_merged_stages(mut self, on: bool) -> Self {
        self.merged_stages = on;
        self
    }

    /// This GPU with the stages of a full backup before the last (and the last, where it
    /// writes full rows) compiled with their block's rows as constants (`true`, or
    /// `FUZZYQ_GPU_STAGES=unrolled`): a thread per element of an item of the stage before,
    /// taking every core of the block below it, the values each core's rows read loaded once
    /// and each row a chain of `fma`s with constant weights. A block whose table is too
    /// large to compile in takes [`Gpu::with_merged_stages`]'s choice. The same bits. The
    /// default (lavapipe: 2.7-3.5 times faster than merged rows; an H200: the three stages
    /// before the last of a full backup of the paper's grid 6.6 ms against 10.0-10.3 ms
    /// merged); `FUZZYQ_GPU_STAGES=merged` or `rows` chooses the others.
    #[must_use]
    pub fn with_unrolled_stages(mut self, on: bool) -> Self {
        self.unrolled_stages = on;
        self.small.0 = on;
        self
    }

    /// This GPU with policy evaluation split as `evaluation` says (the default
    /// [`Evaluation::Auto`], or `FUZZYQ_GPU_EVAL`). All give the same bits.
    #[must_use]
    pub fn with_evaluation(mut self, evaluation: Evaluation) -> Self {
        self.evaluation = evaluation;
        self
    }

    /// This GPU with `V` and the other per-core buffers cut into parts of about `bytes`
    /// (whole slabs of `V`, at least one, and at most one storage binding, the default, or
    /// `FUZZYQ_GPU_PART_KB` kibibytes; larger
    /// where a kernel could not bind that many parts: [`AdapterSummary::max_storage_buffers`]
    /// less ten). The
    /// first stage of a full backup and policy evaluation read `V` through all its parts;
    /// the other passes run a part at a time. Any parts give the same bits; a `V` larger
    /// than one binding (three point masses on the paper's cores: 33 GB, 23 parts) needs them.
    #[must_use]
    pub fn with_part_bytes(mut self, bytes: u64) -> Self {
        self.part_bytes = bytes;
        self
    }

    /// This GPU reading a run's result (`V` and the greedy actions, at the end) back in pieces
    /// of about `bytes` (whole slabs, at least one; default 32 MiB), each put in grid order
    /// as it arrives while the device copies the next: the host holds the result and two
    /// pieces, never `V` twice (three point masses on the paper's cores: 33 GB of `V`, 33 GB
    /// of greedy actions). Any pieces give the same result.
    #[must_use]
    pub fn with_read_bytes(mut self, bytes: u64) -> Self {
        self.read_bytes = bytes;
        self
    }

    /// This GPU with batches whose largest stage output takes at most `bytes` where one
    /// item's can (default 256 MiB, or `FUZZYQ_GPU_BATCH_MB`): runs of slabs where a slab
    /// fits, else of cores of a later block below fixed cores of the earlier ones
    /// ([`Batches`](crate::Batches)). Any batches give the same bits; larger batches mean
    /// fewer, larger dispatches.
    #[must_use]
    pub fn with_batch_bytes(mut self, bytes: u64) -> Self {
        self.batch_bytes = bytes;
        self
    }
}

/// The kernels and sizes a process's environment chooses (`FUZZYQ_GPU_*`), each `None` where
/// its variable is unset or empty.
struct Settings {
    /// `FUZZYQ_GPU_STAGES`: `rows`, `merged` or `unrolled`, as (merged, rows compiled in).
    stages: Option<(bool, bool)>,
    /// `FUZZYQ_GPU_LAST` ([`LastStage::parse`]).
    last: Option<LastStage>,
    /// `FUZZYQ_GPU_EVAL` ([`Evaluation::parse`]).
    evaluation: Option<Evaluation>,
    /// `FUZZYQ_GPU_SUBGROUPS`: `1` or `0`.
    subgroups: Option<bool>,
    /// `FUZZYQ_GPU_CHECKS` ([`Checks::parse`]).
    checks: Option<Checks>,
    /// `FUZZYQ_GPU_BATCH_MB` and `FUZZYQ_GPU_PART_KB`, in kibibytes.
    batch_kib: Option<u64>,
    part_kib: Option<u64>,
}

impl Settings {
    /// The settings of the environment; a variable set to anything its setting does not
    /// take is refused ([`GpuError::Setting`]) rather than ignored, so that a mistyped
    /// kernel name is not silently timed as the default.
    fn from_env() -> Result<Self, GpuError> {
        let count = |s: &str| s.parse::<u64>().ok().filter(|&n| n > 0);
        Ok(Self {
            stages: setting(
                "FUZZYQ_GPU_STAGES",
                "rows, merged or unrolled",
                |s| match s {
                    "rows" => Some((false, false)),
                    "merged" => Some((true, false)),
                    "unrolled" => Some((true, true)),
                    _ => None,
                },
            )?,
            last: setting(
                "FUZZYQ_GPU_LAST",
                "rows, merged, merged:CORES, tile, tile:THREADS (32 to 256, a power of two), \
                 unrolled, joined, staged, staged:THREADS (32 to 1024, a power of two) or \
                 staged:THREADS:COLUMNS",
                LastStage::parse,
            )?,
            evaluation: setting(
                "FUZZYQ_GPU_EVAL",
                "auto, nested or stages:K",
                Evaluation::parse,
            )?,
            subgroups: setting("FUZZYQ_GPU_SUBGROUPS", "1 or 0", |s| match s {
                "1" => Some(true),
                "0" => Some(false),
                _ => None,
            })?,
            checks: setting(
                "FUZZYQ_GPU_CHECKS",
                "all, none, or zero, loops, division and bounds joined by commas",
                Checks::parse,
            )?,
            batch_kib: setting(
                "FUZZYQ_GPU_BATCH_MB",
                "a positive whole number of MiB",
                |s| count(s).and_then(|m| m.checked_mul(1 << 10)),
            )?,
            part_kib: setting(
                "FUZZYQ_GPU_PART_KB",
                "a positive whole number of KiB",
                count,
            )?,
        })
    }
}

/// The setting in environment variable `name` (`None` where it is unset or empty), or
/// [`GpuError::Setting`] where `parse` does not take its value (`expected`: what it takes).
fn setting<T>(
    name: &'static str,
    expected: &'static str,
    parse: impl Fn(&str) -> Option<T>,
) -> Result<Option<T>, GpuError> {
    let Some(value) = std::env::var_os(name).filter(|v| !v.is_empty()) else {
        return Ok(None);
    };
    let value = value.to_string_lossy().into_owned();
    match parse(&value) {
        Some(t) => Ok(Some(t)),
        None => Err(GpuError::Setting {
            name,
            value,
            expected,
        }),
    }
}

/// Chains of `peak.wgsl` per thread.
const PEAK_CHAINS: u64 = 16;
/// Threads of one peak dispatch.
const PEAK_THREADS: u32 = 1 << 20;

impl Gpu {
    /// Measures the adapter's fused multiply-add throughput in `f32`, in billions per second:
    /// 2^20 threads each running 16 independent `fma` chains, dispatches repeated for about
    /// `seconds`; the best dispatch counts. The ceiling a full backup is set against
    /// (`fuzzyq bench --device gpu`).
    pub fn fma_peak(&self, seconds: f64) -> Result<f64, GpuError> {
        use wgpu::util::DeviceExt;
        let device = &self.inner.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("peak.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("peak.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("peak"),
            layout: None,
            module: &module,
            entry_point: Some("peak"),
            compilation_options: Default::default(),
            cache: None,
        });
        let out = crate::buffers::zeroed(&self.inner, "peak out", 4 * u64::from(PEAK_THREADS));
        let time = |iters: u32| -> Result<f64, GpuError> {
            let params: [u32; 4] = [iters, 0.999_999f32.to_bits(), 1e-7f32.to_bits(), 0];
            let ubuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("peak params"),
                contents: bytemuck::cast_slice(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.get_bind_group_layout(0),
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: ubuf.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: out.as_entire_binding(),
                    },
                ],
            });
            let mut enc = device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(PEAK_THREADS / 256, 1, 1);
            }
            let t0 = std::time::Instant::now();
            self.inner.queue.submit([enc.finish()]);
            crate::buffers::wait(&self.inner)?;
            Ok(t0.elapsed().as_secs_f64())
        };
        // Grow the chains until one dispatch takes a few milliseconds, then repeat it.
        let mut iters = 16u32;
        let mut t = time(iters)?;
        while t < 0.005 && iters < (1 << 24) {
            iters *= 4;
            t = time(iters)?;
        }
        let fmas = u64::from(PEAK_THREADS) * PEAK_CHAINS * u64::from(iters);
        let start = std::time::Instant::now();
        let mut best = t;
        while start.elapsed().as_secs_f64() < seconds {
            best = best.min(time(iters)?);
        }
        Ok(fmas as f64 / best / 1e9)
    }
}
