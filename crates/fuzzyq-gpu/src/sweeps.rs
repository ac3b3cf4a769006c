//! [`GpuSweeps`]: the passes over `V` of a run, on the GPU.

use std::borrow::Cow;
use std::collections::HashMap;

use fuzzyq_core::Model;
use fuzzyq_core::solver::{Buf, DiffStats, Operator, Scheme, Sweeps};

use crate::batches::{Batches, Step};
use crate::buffers::{self, with_data, zeroed};
use crate::compile::{Stage, compile};
use crate::error::GpuError;
use crate::gpu::Gpu;
use crate::kernels::{
    self, DiffParams, Entry, Kernels, MAX_BLOCKS, PARAM_STRIDE, Params, bind_group, params_bytes,
};
use crate::last::{Last, MergedAt};
use crate::parts::Parts;
use crate::shape::Shape;

/// The last stage's reduction (`mode` in `block.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// `V` only.
    Max = 0,
    /// `V` and the greedy actions.
    MaxArg = 1,
    /// The greedy actions only.
    Arg = 2,
    /// The maximum absolute expected value per core (0 at goal cores).
    Abs = 3,
}

/// A buffer of one value per core, cut into [`Parts`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum PerCore {
    V(u8),
    /// The absolute maxima of the exact delta.
    Scratch,
    /// The change the exact delta contracts.
    Dv,
    Policy,
    /// The rewards per core (or the reward table, in one part).
    Rewards,
}

/// Which device buffer a binding takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Slot {
    /// Part `k` of a per-core buffer.
    Part(PerCore, u32),
    Stage(usize),
    Rows,
    Partial,
    DummyRead,
    DummyWrite,
}

/// Group 0's bindings of a dispatch: `[src, dst, aux, src2, rewards]`.
type Slots = [Slot; 5];

/// What group 1 of a dispatch binds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Group1 {
    /// The parts of a per-core buffer (`v_at`: the first stage of a full backup and policy
    /// evaluation read `V` at other cores).
    V(PerCore),
    /// Stage `b`'s own, where its input or output is cut into parts ([`Shape::stage_parts`]):
    /// the parts it reads (of the per-core buffer, for the first stage, else of the stage
    /// before, where that is cut), then those it writes (where its own output is cut).
    Stage(usize, Option<PerCore>),
}

/// One dispatch.
#[derive(Clone, Copy, Debug)]
struct Dispatch {
    entry: Entry,
    params: Params,
    slots: Slots,
    /// What group 1 binds, if anything.
    group1: Option<Group1>,
    /// Workgroups `(x, y)`.
    groups: (u32, u32),
}

/// The passes over `V` of one run on a GPU ([`Sweeps`]): the block tables, `V`'s three
/// buffers and the policy buffer live on the device; every pass computes each core's value as
/// the CPU's [`fuzzyq_core::solver::Local`] does, in the same order, with the adapter's
/// `fma` (so with the CPU's bits where it is fused), and only scalars come back between
/// passes (the change statistics, the exact delta).
pub struct GpuSweeps {
    gpu: Gpu,
    k: std::sync::Arc<Kernels>,
    /// The stages before the last (and the last, where it writes full rows), compiled with
    /// this problem's constants.
    stage_kernels: Vec<Stage>,
    /// The fused last stage compiled for this problem (`last1.wgsl` or `lastm.wgsl`), where
    /// it applies.
    last: Option<Last>,
    /// Policy evaluation compiled for this problem ([`kernels::evaluation_source`]), where
    /// the run can evaluate.
    evaluate: Option<wgpu::ComputePipeline>,
    /// The stages policy evaluation runs for every action first ([`Shape::evaluation_stages`]).
    eval_stages: usize,
    /// Seconds the driver took to compile this problem's kernels ([`Self::compile_seconds`]).
    compile_seconds: f64,
    shape: Shape,
    table: [wgpu::Buffer; 3],
    /// The rewards per core, a buffer per part (or the reward table, one buffer).
    rewards: Vec<wgpu::Buffer>,
    goal: wgpu::Buffer,
    map: wgpu::Buffer,
    /// `V`'s buffers (those of the run's scheme; another when a pass first asks for it), the
    /// policy, and the exact delta's two work buffers (made when it first runs), each a
    /// buffer per part.
    v: [Vec<wgpu::Buffer>; 3],
    policy: Vec<wgpu::Buffer>,
    scratch: Vec<wgpu::Buffer>,
    dv: Vec<wgpu::Buffer>,
    /// Each written stage's output for one batch: one buffer, or its parts.
    stages: Vec<Vec<wgpu::Buffer>>,
    rows: Option<wgpu::Buffer>,
    partial: wgpu::Buffer,
    diff_out: Option<wgpu::Buffer>,
    params: wgpu::Buffer,
    params_cap: usize,
    dummy_r: wgpu::Buffer,
    dummy_w: wgpu::Buffer,
    binds: HashMap<Slots, wgpu::BindGroup>,
    /// Group 1's layout for the parts of a per-core buffer read through `v_at`, and group
    /// 1's bind groups.
    parts_layout: wgpu::BindGroupLayout,
    group1: HashMap<Group1, wgpu::BindGroup>,
    /// Seconds and dispatches per kernel (and stage), when profiling
    /// ([`GpuSweeps::set_profiling`]).
    profile: Option<std::collections::BTreeMap<String, (f64, usize)>>,
}

impl core::fmt::Debug for GpuSweeps {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("GpuSweeps")
            .field("gpu", &self.gpu)
            .field("cores", &self.shape.n)
            .field("batches", &self.shape.batches)
            .field("parts", &self.shape.parts.count())
            .finish()
    }
}

/// Partial results of `max_pass` / `diff_range`: values per workgroup.
const PER_WG: u64 = 4096;

/// A count or index of a dispatch as the shaders take it: within one storage binding (a part
/// of `V`, a stage buffer), so within `u32` whatever the grid's core count.
/// Items of the stage before that `items` items from `lo` (`n` below each) lie below.
fn parents(lo: u64, items: u64, n: u64) -> u64 {
    (lo + items - 1) / n - lo / n + 1
}

fn index(x: u64) -> u32 {
    u32::try_from(x).expect("an index within one binding fits u32")
}

/// The arrays of every block's transition table, one after the other (row pointers shifted
/// to the concatenation), and each block's sizes.
struct BlockArrays {
    /// `[cores, actions, rows' length, products' length]` of each block.
    blocks: Vec<[u32; 4]>,
    /// Where each block's rows start in `ptr`.
    row_base: Vec<u32>,
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<f32>,
    /// Where each block's merged steps start (`stagem.wgsl`, `lastm.wgsl`), if its actions
    /// merge.
    merged: Vec<Option<MergedAt>>,
}

impl BlockArrays {
    fn of(plan: &fuzzyq_core::solver::BlockPlan<'_, f32>) -> Result<Self, GpuError> {
        let mut a = Self {
            blocks: Vec::new(),
            row_base: Vec::new(),
            ptr: Vec::new(),
            col: Vec::new(),
            weight: Vec::new(),
            merged: Vec::new(),
        };
        let small = |x: usize| {
            u32::try_from(x).map_err(|_| GpuError::Unsupported("runs blocks of at most 2^32 cores"))
        };
        for t in &plan.tables {
            a.blocks.push([
                small(t.n_cores)?,
                small(t.n_actions)?,
                small(t.r_len)?,
                small(t.p_len)?,
            ]);
            a.row_base.push(a.ptr.len() as u32);
            let entry_base = a.col.len() as u32;
            a.ptr.extend(t.ptr.iter().map(|&p| p + entry_base));
            a.col.extend_from_slice(t.col);
            a.weight.extend_from_slice(t.weight);
        }
        for t in &plan.tables {
            let m = crate::last::append_merged((&mut a.ptr, &mut a.col, &mut a.weight), t);
            a.merged.push(m);
        }
        Ok(a)
    }
}

/// Bytes of the rewards on the device: per core (`rho(x_d)`), or per core and joint action.
fn reward_bytes(plan: &fuzzyq_core::solver::BlockPlan<'_, f32>, n: usize) -> u64 {
    4 * match (plan.rewards, plan.reward_table) {
        (Some(r), _) => r.len(),
        (None, Some(t)) => t.len(),
        (None, None) => n * plan.n_joint,
    } as u64
}

/// The rewards on the device, a buffer per part: per core (`rho(x_d)`), or per core and
/// joint action (the model's table, or the rewards `op` computes, tabulated once). Where
/// there are several parts, each is on the device before the next is staged, so the host
/// stages one part at a time.
fn reward_buffers<M: Model<f32> + Sync + ?Sized>(
    gpu: &Gpu,
    plan: &fuzzyq_core::solver::BlockPlan<'_, f32>,
    op: &Operator<'_, f32, M>,
    parts: &Parts,
) -> Result<Vec<wgpu::Buffer>, GpuError> {
    let made = |label: &str, data: &[f32], width: usize| -> Result<Vec<wgpu::Buffer>, GpuError> {
        parts
            .split(data, width)
            .map(|d| {
                let b = buffers::filled(&gpu.inner, label, d)?;
                if parts.count() > 1 {
                    buffers::settle(&gpu.inner)?;
                }
                Ok(b)
            })
            .collect()
    };
    match (plan.rewards, plan.reward_table) {
        (Some(r), _) => made("rewards", r, 1),
        (None, Some(t)) => made("reward table", t, plan.n_joint),
        // A reward of the action that the model computes: tabulated once.
        (None, None) => made("reward table", &op.reward_rows(), plan.n_joint),
    }
}

/// The goal cores as bits, 32 to a word (`block.wgsl`'s `goal_at`): part `k`'s core `c` is
/// bit `c % 32` of word `k W + c / 32`, `W` words per part (none for a run without goal
/// cores).
fn goal_bits(goal: &[bool], parts: &Parts) -> Vec<u32> {
    if goal.is_empty() {
        return Vec::new();
    }
    let w = parts.goal_words() as usize;
    let mut bits = vec![0u32; w * parts.count()];
    for (k, part) in parts.split(goal, 1).enumerate() {
        for (c, _) in part.iter().enumerate().filter(|(_, g)| **g) {
            bits[k * w + c / 32] |= 1 << (c % 32);
        }
    }
    bits
}

/// The size of a buffer made for `bytes` bytes ([`buffers::zeroed`], [`with_data`]).
fn allocated(bytes: u64) -> u64 {
    bytes.max(4).next_multiple_of(4)
}

/// The per-core buffers a run of `scheme` holds, and what they are in words: the value
/// buffers its driver uses ([`Scheme::value_buffers`]), the policy, and the exact delta's two
/// work buffers where it asks for that.
fn per_core_buffers(scheme: Scheme) -> (u64, &'static str) {
    if scheme.uses_exact_delta() {
        let what = "V three times, the policy and two work buffers";
        (u64::from(scheme.value_buffers()) + 3, what)
    } else {
        (
            u64::from(scheme.value_buffers()) + 1,
            "V twice and the policy",
        )
    }
}

/// Refuses a run whose buffers would take more device memory than `gpu` has
/// ([`Gpu::with_memory_limit`]), before any is allocated: the per-core ones `scheme` uses
/// ([`per_core_buffers`], each part as allocated), the stage buffers of `shape`'s batches and
/// `other` (tables, rewards, partial results), each as allocated.
fn check_memory(
    gpu: &Gpu,
    shape: &Shape,
    scheme: Scheme,
    mut other: Vec<u64>,
) -> Result<(), GpuError> {
    let n = shape.n;
    other.extend((0..shape.written_stages()).map(|b| shape.stage_bytes(b)));
    other.extend(shape.rows_bytes());
    let parts = &shape.parts;
    let (count, what) = per_core_buffers(scheme);
    let per_core = count
        * (0..parts.count())
            .map(|k| allocated(4 * parts.len(k)))
            .sum::<u64>();
    let rest: u64 = other.iter().map(|&b| allocated(b)).sum();
    match gpu.memory.filter(|&m| per_core + rest > m) {
        None => Ok(()),
        Some(available) => Err(GpuError::OutOfMemory {
            what: format!(
                "{n} cores: {what}, {:.2} GB; the tables, rewards and stage buffers, {:.2} GB",
                per_core as f64 / 1e9,
                rest as f64 / 1e9
            ),
            need: per_core + rest,
            available,
        }),
    }
}

impl GpuSweeps {
    /// Uploads `op`'s block tables and allocates the run's buffers on `gpu`.
    ///
    /// Refused ([`GpuError::Unsupported`]): the generic path (no blocks), terminal states,
    /// more than 8 blocks. [`GpuError::TooLarge`] where a buffer exceeds the adapter's limits, and
    /// [`GpuError::OutOfMemory`] where the run's buffers exceed its memory (both checked
    /// before allocating). `V` and the other per-core buffers are cut into parts of at most
    /// one storage binding ([`Gpu::with_part_bytes`]).
    pub fn new<M: Model<f32> + Sync + ?Sized>(
        gpu: &Gpu,
        op: &Operator<'_, f32, M>,
    ) -> Result<Self, GpuError> {
        Self::for_scheme(gpu, op, Scheme::Value)
    }

    /// [`Self::new`] for a run of `scheme`: the device memory is checked for, and made for,
    /// the buffers that scheme's driver uses ([`Scheme::value_buffers`], the exact delta's
    /// work buffers where [`Scheme::uses_exact_delta`]): modified policy iteration holds `V`
    /// twice and the policy, so that three point masses on the paper's cores fit one H200. A
    /// buffer a pass asks for beyond them is made when first used.
    pub fn for_scheme<M: Model<f32> + Sync + ?Sized>(
        gpu: &Gpu,
        op: &Operator<'_, f32, M>,
        scheme: Scheme,
    ) -> Result<Self, GpuError> {
        let plan = op.block_plan().ok_or(GpuError::Unsupported(
            "runs the block backup only, and this model declares no independent blocks",
        ))?;
        if plan.terminals {
            return Err(GpuError::Unsupported(
                "does not run models with terminal states",
            ));
        }
        if plan.tables.len() > MAX_BLOCKS {
            return Err(GpuError::Unsupported("runs models of at most 8 blocks"));
        }
        let n = op.n_cores();
        // The kernels for a problem of this size (the rows compiled in where that repays).
        let gpu = &gpu.for_problem(op.multiply_adds_per_sweep());
        let max_binding = gpu.max_binding;
        let check = |what: &'static str, bytes: u64| -> Result<(), GpuError> {
            if bytes > max_binding {
                return Err(GpuError::over_binding(what, bytes, max_binding));
            }
            Ok(())
        };
        let arrays = BlockArrays::of(&plan)?;
        let [n0, _, r0, _] = arrays.blocks[0];
        // One block: `V` is the block's cores, read whole by the last stage.
        let one_block = arrays.blocks.len() == 1;
        if one_block {
            check("V", 4 * n as u64)?;
        }
        // Group 1 binds the parts beside group 0's ten storage buffers.
        let max_parts = u64::from(gpu.summary().max_storage_buffers).saturating_sub(10);
        let wish = if one_block {
            max_binding
        } else {
            gpu.part_bytes
        };
        let parts = Parts::new(u64::from(n0), u64::from(r0), max_binding, wish, max_parts)?;
        if plan.rewards.is_none() {
            // The reward table, cut as `V` is.
            let largest = parts.largest();
            let what = if parts.count() == 1 {
                "the reward table"
            } else {
                "a part of the reward table"
            };
            check(what, 4 * largest * plan.n_joint as u64)?;
        }
        let mut shape = Shape::of(
            &plan,
            n,
            arrays.blocks.clone(),
            arrays.row_base.clone(),
            parts,
        );
        shape.batch_within(gpu.batch_bytes, max_binding, max_parts)?;
        let rewards_bytes = reward_bytes(&plan, n);
        Self::allocate(gpu, op, &plan, (shape, scheme), &arrays, rewards_bytes)
    }

    /// The run's buffers and kernels for `shape`, checked against the adapter's memory first.
    fn allocate<M: Model<f32> + Sync + ?Sized>(
        gpu: &Gpu,
        op: &Operator<'_, f32, M>,
        plan: &fuzzyq_core::solver::BlockPlan<'_, f32>,
        (shape, scheme): (Shape, Scheme),
        arrays: &BlockArrays,
        rewards_bytes: u64,
    ) -> Result<Self, GpuError> {
        let parts = shape.parts;
        let map = plan.joint_to_product.unwrap_or(&[]);
        let goal = goal_bits(plan.goal, &parts);
        let (gx, gy) = kernels::groups(parts.largest().div_ceil(PER_WG));
        let partial_len = u64::from(gx) * u64::from(gy);
        let k = gpu.kernels.clone();
        // Dispatches per submission: a pass's, up to 1,024.
        let per_pass = shape.batches.count * (shape.n_blocks() as u64 + 1);
        let params_cap = per_pass.clamp(4, 1024) as usize;
        // Every buffer but the per-core ones and the stages'.
        let mut other = vec![
            rewards_bytes,
            4 * goal.len() as u64,
            4 * map.len() as u64,
            4 * arrays.ptr.len() as u64,
            4 * arrays.col.len() as u64,
            4 * arrays.weight.len() as u64,
            4 * partial_len,
            params_cap as u64 * PARAM_STRIDE,
            4,
            4,
        ];
        if k.diff.is_some() {
            other.push(16 * partial_len);
        }
        check_memory(gpu, &shape, scheme, other)?;

        let ctx = &gpu.inner;
        let device = &ctx.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let parts_layout = if parts.count() == 1 {
            k.one_part.clone()
        } else {
            kernels::parts_layout(ctx, parts.count())
        };
        let sg = ctx.summary.subgroup_size.filter(|_| gpu.subgroups);
        let compile_start = std::time::Instant::now();
        let compiled = compile(
            gpu,
            &k,
            &shape,
            sg,
            (&parts_layout, &parts.reader()),
            &arrays.merged,
            &plan.tables,
        )?;
        let compile_seconds = compile_start.elapsed().as_secs_f64();
        let sweeps = Self {
            gpu: gpu.clone(),
            compile_seconds,
            stage_kernels: compiled.stages,
            last: compiled.last,
            evaluate: compiled.evaluate,
            eval_stages: compiled.eval_stages,
            table: [
                with_data(ctx, "row_ptr", &arrays.ptr),
                with_data(ctx, "col", &arrays.col),
                with_data(ctx, "weight", &arrays.weight),
            ],
            rewards: reward_buffers(gpu, plan, op, &parts)?,
            goal: with_data(ctx, "goal", &goal),
            map: with_data(ctx, "map", map),
            v: [
                parts.zeroed(ctx, "V0"),
                parts.zeroed(ctx, "V1"),
                if scheme.value_buffers() > 2 {
                    parts.zeroed(ctx, "V2")
                } else {
                    Vec::new()
                },
            ],
            policy: parts.zeroed(ctx, "policy"),
            scratch: Vec::new(),
            dv: Vec::new(),
            stages: (0..shape.written_stages())
                .map(|b| match &shape.stage_parts[b] {
                    None => vec![zeroed(ctx, "stage", shape.stage_bytes(b))],
                    Some(p) => p.zeroed(ctx, "stage part"),
                })
                .collect(),
            rows: shape.rows_bytes().map(|b| zeroed(ctx, "rows", b)),
            partial: zeroed(ctx, "max partials", 4 * partial_len),
            diff_out: k
                .diff
                .is_some()
                .then(|| zeroed(ctx, "diff partials", 16 * partial_len)),
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("params"),
                size: params_cap as u64 * PARAM_STRIDE,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            params_cap,
            dummy_r: zeroed(ctx, "dummy", 4),
            dummy_w: zeroed(ctx, "dummy", 4),
            binds: HashMap::new(),
            parts_layout,
            group1: HashMap::new(),
            profile: None,
            k,
            shape,
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Failed(format!(
                "the run's buffers do not fit in the GPU's memory: {e}"
            )));
        }
        Ok(sweeps)
    }

    /// The GPU this backend runs on.
    #[must_use]
    pub fn gpu(&self) -> &Gpu {
        &self.gpu
    }

    /// The kernel of each stage a full backup runs as a stage (`stage_c`: a thread per
    /// element; `stage_m`: a block core's rows merged, [`Gpu::with_merged_stages`];
    /// `stage_u`: the block's rows compiled in, [`Gpu::with_unrolled_stages`]).
    #[must_use]
    pub fn stage_kernels(&self) -> Vec<&'static str> {
        self.stage_kernels.iter().map(|s| s.name).collect()
    }

    /// The fused last stage's kernel (`last1`: rows one at a time, `lastm`: merged, `lastw`:
    /// from workgroup memory, `lastu`: the rows compiled in, `lastj`: and the stage before
    /// joined in), where
    /// the run has one ([`Gpu::with_last_stage`]).
    #[must_use]
    pub fn last_stage(&self) -> Option<&'static str> {
        self.last.as_ref().map(|l| l.name)
    }

    /// The stages of a full backup a policy-evaluation sweep runs for every action before a
    /// thread per core nests its own action's rows of the other blocks (0: every block nested
    /// over `V`; [`Gpu::with_evaluation`]).
    #[must_use]
    pub fn evaluation_stages(&self) -> usize {
        self.eval_stages
    }

    /// Whether the last stage reduces a core's lanes by subgroup operations
    /// ([`Gpu::with_subgroups`]).
    #[must_use]
    pub fn uses_subgroups(&self) -> bool {
        self.last.as_ref().is_some_and(|l| l.subgroups)
    }

    /// Seconds of the set-up spent compiling this problem's kernels (each compiled with the
    /// problem's sizes as constants, side by side; the rows compiled in take the driver
    /// longest: [`Gpu::with_rows_compiled_in_from`]).
    #[must_use]
    pub fn compile_seconds(&self) -> f64 {
        self.compile_seconds
    }

    /// The batches a full pass runs in (the stage buffers hold one batch).
    #[must_use]
    pub fn batches(&self) -> Batches {
        self.shape.batches
    }

    /// How many parts `V` and the other per-core buffers are cut into, each within one
    /// storage binding ([`Gpu::with_part_bytes`]): 1 unless `V` exceeds a binding.
    #[must_use]
    pub fn parts(&self) -> usize {
        self.shape.parts.count()
    }

    /// How many parts each written stage's output for one batch is cut into: 1 unless it
    /// exceeds one storage binding ([`Gpu::with_binding_limit`]; three point masses on the
    /// paper's cores: the first stage's, 3.69 GB, in 2 parts of wgpu's 2 GiB).
    #[must_use]
    pub fn stage_parts(&self) -> Vec<usize> {
        self.stages.iter().map(Vec::len).collect()
    }

    /// Bytes of device memory this run's buffers take now (a buffer made on first use, such
    /// as the exact delta's two, once a pass asked for it): for the buffers of the run's
    /// scheme, at most what [`Self::for_scheme`] estimated and checked against
    /// [`AdapterSummary::memory`](crate::AdapterSummary::memory).
    #[must_use]
    pub fn device_bytes(&self) -> u64 {
        let mut all: Vec<&wgpu::Buffer> = vec![
            &self.goal,
            &self.map,
            &self.partial,
            &self.params,
            &self.dummy_r,
            &self.dummy_w,
        ];
        all.extend(&self.table);
        all.extend(self.v.iter().flatten());
        all.extend(self.rewards.iter().chain(&self.policy));
        all.extend(self.scratch.iter().chain(&self.dv));
        all.extend(self.stages.iter().flatten());
        all.extend([&self.rows, &self.diff_out].into_iter().flatten());
        all.iter().map(|b| b.size()).sum()
    }

    /// Profiling on: every dispatch runs in a submission of its own, waited for, and its time
    /// is added to its kernel's ([`Self::profile`]). Slower; for finding where a pass spends.
    pub fn set_profiling(&mut self, on: bool) {
        self.profile = on.then(Default::default);
    }

    /// Seconds and dispatches per kernel (`stage 2`, `last_fused`, ...) since profiling was
    /// turned on.
    #[must_use]
    pub fn profile(&self) -> Vec<(String, f64, usize)> {
        self.profile
            .iter()
            .flatten()
            .map(|(k, &(t, n))| (k.clone(), t, n))
            .collect()
    }

    /// The parts of per-core buffer `b`.
    fn parts_of(&self, b: PerCore) -> &[wgpu::Buffer] {
        match b {
            PerCore::V(i) => &self.v[usize::from(i)],
            PerCore::Scratch => &self.scratch,
            PerCore::Dv => &self.dv,
            PerCore::Policy => &self.policy,
            PerCore::Rewards => &self.rewards,
        }
    }

    fn buffer(&self, s: Slot) -> &wgpu::Buffer {
        match s {
            Slot::Part(b, k) => &self.parts_of(b)[k as usize],
            Slot::Stage(b) => &self.stages[b][0],
            Slot::Rows => self.rows.as_ref().expect("allocated with the rows path"),
            Slot::Partial => &self.partial,
            Slot::DummyRead => &self.dummy_r,
            Slot::DummyWrite => &self.dummy_w,
        }
    }

    /// The bind groups of dispatch `d`: group 0 reading `src`, `src2`, `rewards` and writing
    /// `dst`, `aux`; group 1 the parts it reads or writes, if any ([`Group1`]).
    fn bind(&mut self, d: &Dispatch) {
        if !self.binds.contains_key(&d.slots) {
            let [src, dst, aux, src2, rewards] = d.slots.map(|s| self.buffer(s));
            let bufs: [&wgpu::Buffer; 11] = [
                &self.params,
                &self.table[0],
                &self.table[1],
                &self.table[2],
                src,
                dst,
                aux,
                rewards,
                &self.goal,
                &self.map,
                src2,
            ];
            let g = bind_group(&self.gpu.inner, &self.k.layout, &bufs);
            self.binds.insert(d.slots, g);
        }
        if let Some(g1) = d.group1.filter(|g| !self.group1.contains_key(g)) {
            let g = match g1 {
                Group1::V(b) => {
                    let parts: Vec<_> = self.parts_of(b).iter().collect();
                    kernels::parts_group(&self.gpu.inner, &self.parts_layout, &parts)
                }
                Group1::Stage(b, v) => {
                    let cut = |b: usize| self.shape.stage_parts[b].is_some();
                    let reads = match v {
                        Some(v) => self.parts_of(v),
                        None if cut(b - 1) => &self.stages[b - 1],
                        None => &[],
                    };
                    let writes = if cut(b) { &self.stages[b][..] } else { &[] };
                    let parts: Vec<_> = reads.iter().chain(writes).collect();
                    let layout = self.stage_kernels[b].group1.as_ref();
                    let layout = layout.expect("compiled with group 1 where its stage is in parts");
                    kernels::parts_group(&self.gpu.inner, layout, &parts)
                }
            };
            self.group1.insert(g1, g);
        }
    }

    fn pipeline(&self, d: &Dispatch) -> &wgpu::ComputePipeline {
        match d.entry {
            Entry::StageConst => &self.stage_kernels[d.params.b as usize].pipeline,
            Entry::Last => &self.last.as_ref().expect("compiled where used").pipeline,
            Entry::Evaluate => self
                .evaluate
                .as_ref()
                .expect("compiled where it can evaluate"),
            e => self.k.pipeline(e),
        }
    }

    /// Runs `dispatches` in submissions of up to `params_cap` and waits for them.
    fn run(&mut self, dispatches: &[Dispatch]) -> Result<(), GpuError> {
        if self.profile.is_some() && dispatches.len() > 1 {
            for d in dispatches {
                let t0 = std::time::Instant::now();
                self.run(std::slice::from_ref(d))?;
                let key = match (d.entry, &self.last) {
                    (Entry::StageConst, _) => {
                        let b = d.params.b as usize;
                        format!("stage {b} ({})", self.stage_kernels[b].name)
                    }
                    (Entry::Last, Some(l)) => format!("last stage ({})", l.name),
                    (e, _) => format!("{e:?}"),
                };
                let p = self.profile.as_mut().expect("profiling");
                let e = p.entry(key).or_insert((0.0, 0));
                e.0 += t0.elapsed().as_secs_f64();
                e.1 += 1;
            }
            return Ok(());
        }
        for chunk in dispatches.chunks(self.params_cap) {
            for d in chunk {
                for s in d.slots {
                    if let Slot::Part(b, _) = s {
                        self.ensure(b);
                    }
                }
                if let Some(Group1::V(b) | Group1::Stage(_, Some(b))) = d.group1 {
                    self.ensure(b);
                }
                self.bind(d);
            }
            let ps: Vec<Params> = chunk.iter().map(|d| d.params).collect();
            let gpu = &self.gpu.inner;
            gpu.queue.write_buffer(&self.params, 0, &params_bytes(&ps));
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for (i, d) in chunk.iter().enumerate() {
                    pass.set_pipeline(self.pipeline(d));
                    let offset = (i as u64 * PARAM_STRIDE) as u32;
                    pass.set_bind_group(0, &self.binds[&d.slots], &[offset]);
                    if let Some(g) = d.group1 {
                        pass.set_bind_group(1, &self.group1[&g], &[]);
                    }
                    pass.dispatch_workgroups(d.groups.0, d.groups.1, 1);
                }
            }
            gpu.queue.submit([enc.finish()]);
            buffers::wait(&self.gpu.inner)?;
        }
        Ok(())
    }

    fn base(&self) -> Params {
        let mut p = self.shape.params();
        p.has_map = u32::from(!self.shape.fused_abs);
        p
    }

    /// `base` for a dispatch over part `k`'s cores from its core `out_lo` on: where its goal
    /// bits and its first slab are.
    fn in_part(&self, base: Params, k: usize, out_lo: u64) -> Params {
        let parts = &self.shape.parts;
        Params {
            out_lo: index(out_lo),
            goal_lo: index(k as u64 * parts.goal_words()),
            part_c0: index(parts.first_slab(k)),
            len: index(parts.len(k)),
            ..base
        }
    }

    /// The workgroups of stage `b`'s kernel over `count` elements from item `lo` (counted
    /// from the first child of the source's first item): a thread per element's
    /// `per_thread` actions, or with the rows compiled in, per element of each item of the
    /// stage before that the dispatch's items lie below.
    fn stage_grid(&self, b: usize, lo: u64, count: u64) -> (u32, u32) {
        let [n, a, r, p] = self.shape.blocks[b].map(u64::from);
        match self.stage_kernels[b].per_thread {
            Some(per_thread) => kernels::grid(count / per_thread),
            None => kernels::grid(parents(lo, count / (a * r * p), n) * r * p),
        }
    }

    /// The dispatch of stage `b` (one before the last) over `items` of its items from `lo`
    /// (counted from the first child of the source's first item), the first stage reading
    /// per-core buffer `input`.
    fn stage_dispatch(&self, b: usize, lo: u64, items: u64, input: PerCore) -> Dispatch {
        let s = &self.shape;
        let count = items * s.tree.item_len(b);
        let params = Params {
            b: b as u32,
            lo: index(lo),
            count: index(count),
            ..self.base()
        };
        // The first stage reads `V` through its parts; a stage output in parts is read and
        // written through group 1.
        let parts_in = b > 0 && s.stage_parts[b - 1].is_some();
        let parts_out = s.stage_parts[b].is_some();
        let v = (b == 0).then_some(input);
        let group1 = if parts_in || parts_out {
            Some(Group1::Stage(b, v))
        } else {
            v.map(Group1::V)
        };
        let src = if b == 0 || parts_in {
            Slot::DummyRead
        } else {
            Slot::Stage(b - 1)
        };
        let dst = if parts_out {
            Slot::DummyWrite
        } else {
            Slot::Stage(b)
        };
        let slots = [
            src,
            dst,
            Slot::DummyWrite,
            Slot::DummyRead,
            Slot::Part(PerCore::Rewards, 0),
        ];
        Dispatch {
            entry: Entry::StageConst,
            params,
            slots,
            group1,
            groups: self.stage_grid(b, lo, count),
        }
    }

    /// The dispatches of a policy-evaluation sweep from `input` into `out` that runs the
    /// first `eval_stages` stages of a full backup (at least one), batch by batch, and after
    /// each batch's stages a thread per core of the batch through the other blocks
    /// (`kernels::evaluation_source`), reading the last of them.
    fn evaluation_pass(&self, input: PerCore, out: PerCore) -> Vec<Dispatch> {
        let s = &self.shape;
        let (k, last) = (self.eval_stages, s.n_blocks() - 1);
        // The first item stage `k - 1`'s buffer holds, and its cores below one item.
        let mut held = 0;
        let below = u64::from(s.blocks[k - 1][2]);
        let mut ds = Vec::new();
        for step in s.tree.steps(&s.batches) {
            let (b, lo, items) = (step.stage, step.lo, step.items);
            if b < k {
                let rel = lo - step.src_lo * u64::from(s.blocks[b][0]);
                ds.push(self.stage_dispatch(b, rel, items, input));
                if b + 1 == k {
                    held = lo;
                }
                continue;
            }
            if b < last {
                continue;
            }
            // The batch's cores: within one part.
            let part = s.parts.of_core(lo);
            let base = Params {
                lo: index(lo - held * below),
                ..self.base()
            };
            let params = Params {
                count: index(items),
                ..self.in_part(base, part, lo - s.parts.cores(part).start)
            };
            let at = |b: PerCore| Slot::Part(b, part as u32);
            ds.push(Dispatch {
                entry: Entry::Evaluate,
                params,
                slots: [
                    Slot::Stage(k - 1),
                    at(out),
                    at(PerCore::Policy),
                    Slot::DummyRead,
                    at(PerCore::Rewards),
                ],
                group1: None,
                groups: kernels::grid(items),
            });
        }
        ds
    }

    /// The dispatches of one full pass of the last stage reducing as `mode` says, reading
    /// `input` and writing `out` (values, if any) and the policy (actions), batch by batch
    /// ([`Tree::steps`](crate::batches::Tree::steps)).
    fn full_pass(&mut self, input: PerCore, out: Option<PerCore>, mode: Mode) -> Vec<Dispatch> {
        let s = &self.shape;
        let last = s.n_blocks() - 1;
        let fused = if mode == Mode::Abs {
            s.fused_abs
        } else {
            s.fused
        };
        let cpw = self.last.as_ref().map(|l| l.cores_per_group);
        // The last stage computing the stage before it (`lastj`): that stage is not
        // dispatched, and the last reads the one before it, from its item `src_lo_before`.
        let join = fused && self.last.as_ref().is_some_and(|l| l.joined);
        let mut src_lo_before = 0;
        let base = self.base();
        let mut ds = Vec::new();
        for step in s.tree.steps(&s.batches) {
            let Step {
                stage: b,
                lo,
                items,
                src_lo,
            } = step;
            if join && b + 1 == last {
                src_lo_before = src_lo;
                continue;
            }
            // `lo` from the first child of the source's first item: within the buffers.
            let lo = if join && b == last {
                lo - src_lo_before * u64::from(s.blocks[b - 1][0]) * u64::from(s.blocks[b][0])
            } else {
                lo - src_lo * u64::from(s.blocks[b][0])
            };
            if b < last {
                ds.push(self.stage_dispatch(b, lo, items, input));
                continue;
            }
            let p = Params {
                b: b as u32,
                lo: index(lo),
                ..base
            };
            let src = match b {
                0 => Slot::Part(input, 0),
                b if join => Slot::Stage(b - 2),
                b => Slot::Stage(b - 1),
            };
            // The batch's cores: within one part.
            let first = step.lo;
            let k = s.parts.of_core(first);
            debug_assert_eq!(s.parts.of_core(first + items - 1), k);
            let p = self.in_part(p, k, first - s.parts.cores(k).start);
            let part = |b: PerCore| Slot::Part(b, k as u32);
            let dst = out.map_or(Slot::DummyWrite, part);
            let (aux, rewards) = (part(PerCore::Policy), part(PerCore::Rewards));
            let p = Params {
                count: index(items),
                mode: mode as u32,
                ..p
            };
            if fused {
                let groups = match cpw.expect("compiled where fused") {
                    Some(cpw) => items.div_ceil(u64::from(cpw)),
                    // A workgroup per item of the stage before that the cores touch.
                    None => parents(lo, items, u64::from(s.blocks[last][0])),
                };
                ds.push(Dispatch {
                    entry: Entry::Last,
                    params: p,
                    slots: [src, dst, aux, Slot::DummyRead, rewards],
                    group1: None,
                    groups: kernels::groups(groups),
                });
            } else {
                let count = items * s.n_product;
                let rows = Params {
                    count: index(count),
                    ..p
                };
                let slots = [src, Slot::Rows, Slot::DummyWrite, Slot::DummyRead, rewards];
                ds.push(Dispatch {
                    entry: Entry::StageConst,
                    params: rows,
                    slots,
                    group1: None,
                    groups: self.stage_grid(b, lo, count),
                });
                let p = Params {
                    len: s.n_product as u32,
                    ..p
                };
                ds.push(Dispatch {
                    entry: Entry::ReduceRows,
                    params: p,
                    slots: [Slot::Rows, dst, aux, Slot::DummyRead, rewards],
                    group1: None,
                    groups: kernels::grid(items),
                });
            }
        }
        ds
    }

    fn v_of(b: Buf) -> PerCore {
        PerCore::V(b.0)
    }

    fn distinct(a: Buf, b: Buf) {
        assert_ne!(a, b, "a pass reads and writes distinct buffers");
    }

    /// A pass over every part: `entry` with group 0 binding `slots(k)` for part `k`, and
    /// group 1 the parts of `reads`.
    fn per_part(
        &mut self,
        entry: Entry,
        slots: impl Fn(u32) -> Slots,
        reads: Option<PerCore>,
        shift: f32,
    ) -> Result<(), GpuError> {
        let base = Params {
            shift,
            ..self.base()
        };
        let ds: Vec<Dispatch> = (0..self.shape.parts.count())
            .map(|k| {
                let params = self.in_part(base, k, 0);
                let params = Params {
                    count: params.len,
                    ..params
                };
                Dispatch {
                    entry,
                    params,
                    slots: slots(k as u32),
                    group1: reads.map(Group1::V),
                    groups: kernels::grid(u64::from(params.len)),
                }
            })
            .collect();
        self.run(&ds)
    }

    /// The maximum of per-core buffer `src` from 0, as `T::max_of` folds (exact in any order).
    fn max_of(&mut self, src: PerCore) -> Result<f32, GpuError> {
        let mut m = 0.0f32;
        for k in 0..self.shape.parts.count() {
            let len = self.shape.parts.len(k);
            let params = Params {
                count: PER_WG as u32,
                ..self.in_part(self.base(), k, 0)
            };
            let groups = kernels::groups(len.div_ceil(PER_WG));
            let slots = [
                Slot::Part(src, k as u32),
                Slot::Partial,
                Slot::DummyWrite,
                Slot::DummyRead,
                Slot::Part(PerCore::Rewards, 0),
            ];
            self.run(&[Dispatch {
                entry: Entry::Max,
                params,
                slots,
                group1: None,
                groups,
            }])?;
            let n = (groups.0 * groups.1) as usize;
            let parts: Vec<f32> = buffers::read_as(&self.gpu.inner, &self.partial, n)?;
            m = parts.into_iter().fold(m, |m, x| if m >= x { m } else { x });
        }
        Ok(m)
    }

    /// Per-core buffer `b`, made (zeroed) if the run has not made it yet: the exact delta's
    /// work buffers when it first runs, a value buffer beyond the scheme's.
    fn ensure(&mut self, b: PerCore) {
        if !self.parts_of(b).is_empty() {
            return;
        }
        let made = self.shape.parts.zeroed(&self.gpu.inner, "per core");
        match b {
            PerCore::V(i) => self.v[usize::from(i)] = made,
            PerCore::Scratch => self.scratch = made,
            PerCore::Dv => self.dv = made,
            PerCore::Policy | PerCore::Rewards => unreachable!("made with the run"),
        }
    }

    /// Per-core buffer `b` read back, its parts one after the other (zeros where it was never
    /// made: a buffer starts at 0).
    fn read_all<T: bytemuck::Pod>(&self, b: PerCore) -> Result<Vec<T>, GpuError> {
        if self.parts_of(b).is_empty() {
            return Ok(vec![T::zeroed(); self.shape.n]);
        }
        let mut out = Vec::with_capacity(self.shape.n);
        for (k, buf) in self.parts_of(b).iter().enumerate() {
            let len = self.shape.parts.len(k) as usize;
            out.extend(buffers::read_as::<T>(&self.gpu.inner, buf, len)?);
        }
        Ok(out)
    }

    /// Per-core buffer `b` read back a few slabs at a time ([`Gpu::with_read_bytes`], at
    /// least one slab), each piece handed to `each(first core, values)` ([`Sweeps::values_by_piece`]):
    /// zeros where it was never made.
    fn read_by_piece<T: bytemuck::Pod>(
        &self,
        b: PerCore,
        each: &mut dyn FnMut(usize, &[T]),
    ) -> Result<(), GpuError> {
        let parts = self.shape.parts;
        let piece = (self.gpu.read_bytes / (4 * parts.slab)).max(1) * parts.slab;
        if self.parts_of(b).is_empty() {
            let zeros = vec![T::zeroed(); piece.min(self.shape.n as u64) as usize];
            for first in (0..self.shape.n).step_by(zeros.len().max(1)) {
                each(first, &zeros[..zeros.len().min(self.shape.n - first)]);
            }
            return Ok(());
        }
        for (k, buf) in self.parts_of(b).iter().enumerate() {
            let start = parts.cores(k).start as usize;
            let len = parts.len(k) as usize;
            buffers::read_pieces(
                &self.gpu.inner,
                buf,
                len,
                piece as usize,
                &mut |first, v| {
                    each(start + first, v);
                },
            )?;
        }
        Ok(())
    }

    /// `data` (one value per core) written to per-core buffer `b`, part by part.
    fn write_all<T: bytemuck::Pod>(&mut self, b: PerCore, data: &[T]) -> Result<(), GpuError> {
        self.ensure(b);
        let parts = self.shape.parts;
        for (buf, d) in self.parts_of(b).iter().zip(parts.split(data, 1)) {
            let gpu = &self.gpu.inner;
            buffers::write_pieces(gpu, buf, d, buffers::staged::<T>())?;
            if parts.count() > 1 {
                buffers::settle(gpu)?;
            }
        }
        Ok(())
    }
}

impl Sweeps<f32> for GpuSweeps {
    type Error = GpuError;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        let ds = self.full_pass(Self::v_of(v), Some(Self::v_of(out)), Mode::Max);
        self.run(&ds)
    }

    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        let ds = self.full_pass(Self::v_of(v), Some(Self::v_of(out)), Mode::MaxArg);
        self.run(&ds)
    }

    fn rewards(&mut self, out: Buf) -> Result<(), GpuError> {
        if self.shape.reward_table {
            return Err(GpuError::Unsupported(
                "computes the backup of V = 0 only for rewards of the state alone",
            ));
        }
        let out = Self::v_of(out);
        let slots = |k| {
            [
                Slot::DummyRead,
                Slot::Part(out, k),
                Slot::DummyWrite,
                Slot::DummyRead,
                Slot::Part(PerCore::Rewards, k),
            ]
        };
        self.per_part(Entry::Rewards, slots, None, 0.0)
    }

    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        if !self.shape.can_evaluate {
            return Err(fuzzyq_core::solver::SolveError::PolicyEvaluation.into());
        }
        let out = Self::v_of(out);
        if self.eval_stages > 0 {
            let ds = self.evaluation_pass(Self::v_of(v), out);
            return self.run(&ds);
        }
        let slots = |k| {
            [
                Slot::DummyRead,
                Slot::Part(out, k),
                Slot::Part(PerCore::Policy, k),
                Slot::DummyRead,
                Slot::Part(PerCore::Rewards, k),
            ]
        };
        self.per_part(Entry::Evaluate, slots, Some(Self::v_of(v)), 0.0)
    }

    fn sweep_async(&mut self, _v: Buf) -> Result<f64, GpuError> {
        Err(GpuError::Unsupported(
            "runs synchronous sweeps only (solver.sweep = \"sync\")",
        ))
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: f32) -> Result<DiffStats, GpuError> {
        if self.k.diff.is_none() {
            // No f64 in this adapter's shaders: the statistics on the host.
            let (x, y) = (self.values_of(a)?, self.values_of(b)?);
            return Ok(fuzzyq_core::solver::diff_stats(&x, &y, s));
        }
        self.ensure(Self::v_of(a));
        self.ensure(Self::v_of(b));
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..self.shape.parts.count() {
            let (l, h) = self.diff_range(a, b, k)?;
            lo = lo.min(l);
            hi = hi.max(h);
        }
        Ok(DiffStats::of_range(lo, hi, f64::from(s)))
    }

    fn shift(&mut self, v: Buf, s: f32) -> Result<(), GpuError> {
        if s == 0.0 {
            return Ok(());
        }
        let v = Self::v_of(v);
        let slots = |k| {
            [
                Slot::DummyRead,
                Slot::Part(v, k),
                Slot::DummyWrite,
                Slot::DummyRead,
                Slot::Part(PerCore::Rewards, 0),
            ]
        };
        self.per_part(Entry::Shift, slots, None, s)
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, GpuError> {
        Self::distinct(a, b);
        let (a, b) = (Self::v_of(a), Self::v_of(b));
        let slots = |k| {
            [
                Slot::Part(a, k),
                Slot::Part(PerCore::Dv, k),
                Slot::DummyWrite,
                Slot::Part(b, k),
                Slot::Part(PerCore::Rewards, 0),
            ]
        };
        self.per_part(Entry::Sub, slots, None, 0.0)?;
        let ds = self.full_pass(PerCore::Dv, Some(PerCore::Scratch), Mode::Abs);
        self.run(&ds)?;
        let m = self.max_of(PerCore::Scratch)?;
        Ok(f64::from(self.shape.gamma * m))
    }

    fn greedy(&mut self, v: Buf) -> Result<(), GpuError> {
        let ds = self.full_pass(Self::v_of(v), None, Mode::Arg);
        self.run(&ds)
    }

    fn load(&mut self, v: Buf, values: &[f32]) -> Result<(), GpuError> {
        fuzzyq_core::error::check_len("V", self.shape.n, values.len())
            .map_err(fuzzyq_core::solver::SolveError::from)?;
        self.write_all(Self::v_of(v), values)
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), GpuError> {
        fuzzyq_core::error::check_len("policy", self.shape.n, policy.len())
            .map_err(fuzzyq_core::solver::SolveError::from)?;
        self.write_all(PerCore::Policy, policy)
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [f32]>, GpuError> {
        Ok(Cow::Owned(self.values_of(v)?))
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, GpuError> {
        Ok(Cow::Owned(self.read_all(PerCore::Policy)?))
    }

    fn values_by_piece(&self, v: Buf, each: &mut dyn FnMut(usize, &[f32])) -> Result<(), GpuError> {
        self.read_by_piece(Self::v_of(v), each)
    }

    fn policy_by_piece(&self, each: &mut dyn FnMut(usize, &[u32])) -> Result<(), GpuError> {
        self.read_by_piece(PerCore::Policy, each)
    }

    fn kernel(&self) -> Option<&'static str> {
        Some("wgpu")
    }
}

impl GpuSweeps {
    fn values_of(&self, v: Buf) -> Result<Vec<f32>, GpuError> {
        self.read_all(Self::v_of(v))
    }

    /// The range of `a - b` over part `k` (`diff.wgsl`, where the adapter has `f64`).
    fn diff_range(&self, a: Buf, b: Buf, k: usize) -> Result<(f64, f64), GpuError> {
        let (layout, pipeline) = self.k.diff.as_ref().expect("called with f64");
        let out = self.diff_out.as_ref().expect("made with f64");
        let gpu = &self.gpu.inner;
        let n = self.shape.parts.len(k);
        let g = kernels::groups(n.div_ceil(PER_WG));
        let p = DiffParams {
            len: index(n),
            per_wg: PER_WG as u32,
            zero: 0,
            pad: 0,
        };
        let ubuf = wgpu::util::DeviceExt::create_buffer_init(
            &gpu.device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("diff params"),
                contents: bytemuck::bytes_of(&p),
                usage: wgpu::BufferUsages::UNIFORM,
            },
        );
        let bufs = [
            &ubuf,
            &self.v[usize::from(a.0)][k],
            &self.v[usize::from(b.0)][k],
            out,
        ];
        let entries: Vec<wgpu::BindGroupEntry<'_>> = bufs
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bind = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout,
            entries: &entries,
        });
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(g.0, g.1, 1);
        }
        gpu.queue.submit([enc.finish()]);
        let parts: Vec<f64> = buffers::read_as(&self.gpu.inner, out, 2 * (g.0 * g.1) as usize)?;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for pair in parts.chunks_exact(2) {
            lo = lo.min(pair[0]);
            hi = hi.max(pair[1]);
        }
        Ok((lo, hi))
    }
}
