//! [`GpuSweeps`]: the passes over `V` of a run, on the GPU.

use std::borrow::Cow;
use std::collections::HashMap;

use fuzzyq_core::Model;
use fuzzyq_core::solver::{Buf, DiffStats, Operator, Sweeps};

use crate::batches::{Batches, Step, Tree};
use crate::buffers::{self, with_data, zeroed};
use crate::error::GpuError;
use crate::gpu::Gpu;
use crate::kernels::{
    self, DiffParams, Entry, Kernels, MAX_BLOCKS, PARAM_STRIDE, Params, WG, bind_group,
    params_bytes,
};

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

/// One dispatch: the kernel, its parameters, its bindings `[src, dst, aux, src2]` and its
/// workgroups `(x, y)`.
type Dispatch = (Entry, Params, [Slot; 4], (u32, u32));

/// Which device buffer a binding takes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Slot {
    V(u8),
    Stage(usize),
    Rows,
    Scratch,
    Dv,
    Policy,
    Partial,
    DummyRead,
    DummyWrite,
}

/// The shape of the block path, from [`fuzzyq_core::solver::BlockPlan`].
#[derive(Clone, Debug)]
struct Shape {
    /// Cores.
    n: usize,
    /// Per block (contraction order): (cores, actions, R, P).
    blocks: Vec<[u32; 4]>,
    /// Per block: the index of its first row start in the joint `row_ptr` buffer.
    row_base: Vec<u32>,
    /// Joint actions.
    n_joint: u32,
    /// Product actions (`P` of the last block times its actions).
    n_product: u64,
    /// The blocks' sizes for batching, and the batches a pass runs in.
    tree: Tree,
    batches: Batches,
    /// Whether the last stage reduces in place (the identity action map and a state-only
    /// reward); else it writes full rows that `reduce_rows` reduces.
    fused: bool,
    /// Whether the absolute maximum reduces in place (the identity map).
    fused_abs: bool,

    gamma: f32,
    has_goal: bool,
    reward_table: bool,
    can_evaluate: bool,
}

impl Shape {
    /// The shape of `plan`'s block path over `n` cores, its blocks' sizes and row bases from
    /// [`BlockArrays`]; batches of one slab until [`Self::batch_within`].
    fn of(
        plan: &fuzzyq_core::solver::BlockPlan<'_, f32>,
        n: usize,
        blocks: Vec<[u32; 4]>,
        row_base: Vec<u32>,
    ) -> Self {
        let last = plan.tables.last().expect("at least one block");
        let identity = plan.joint_to_product.is_none();
        let reward_table = plan.rewards.is_none();
        let n_product = (last.p_len * last.n_actions) as u64;
        let (fused, fused_abs) = (identity && !reward_table, identity);
        let rows = (!fused || !fused_abs).then_some(n_product);
        let tree = Tree::new(&blocks, rows);
        Self {
            n,
            batches: tree.batches(0, 1),
            tree,
            blocks,
            row_base,
            n_joint: plan.n_joint as u32,
            n_product,
            fused,
            fused_abs,
            gamma: plan.gamma,
            has_goal: !plan.goal.is_empty(),
            reward_table,
            can_evaluate: plan.can_evaluate,
        }
    }

    /// Whether some pass writes full rows for `reduce_rows` (a renumbered joint action or a
    /// reward of the action).
    fn writes_rows(&self) -> bool {
        self.rows_bytes().is_some()
    }

    /// Batches whose largest buffer takes at most `budget` bytes where one item's can
    /// ([`Tree::choose`]); refused where the smallest batch's buffer exceeds one storage
    /// binding of `max_binding` bytes.
    fn batch_within(&mut self, budget: u64, max_binding: u64) -> Result<(), GpuError> {
        self.batches = self.tree.choose(budget.min(max_binding));
        let largest = self.tree.largest_of(&self.batches);
        if largest > max_binding {
            return Err(GpuError::TooLarge {
                what: "the smallest batch's stage output",
                need: largest,
                limit: max_binding,
                kind: "storage binding",
            });
        }
        Ok(())
    }

    /// Bytes of the buffer of stage `b`'s output for one batch.
    fn stage_bytes(&self, b: usize) -> u64 {
        self.tree.stage_bytes(b, &self.batches)
    }

    /// Bytes of the full rows of one batch, where a pass writes them.
    fn rows_bytes(&self) -> Option<u64> {
        self.tree.rows_bytes(&self.batches)
    }

    fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// The stages whose outputs go to memory (those before the last).
    fn written_stages(&self) -> usize {
        self.n_blocks() - 1
    }

    /// The base parameters of every dispatch.
    fn params(&self) -> Params {
        let mut blocks = [[0u32; 4]; MAX_BLOCKS];
        let mut rows = [[0u32; 4]; MAX_BLOCKS];
        for (b, blk) in self.blocks.iter().enumerate() {
            blocks[b] = *blk;
            rows[b][0] = self.row_base[b];
        }
        Params {
            n_joint: self.n_joint,
            has_map: 0,
            reward_table: u32::from(self.reward_table),
            has_goal: u32::from(self.has_goal),
            gamma: self.gamma,
            n_blocks: self.blocks.len() as u32,
            len: self.n as u32,
            blocks,
            rows,
            ..Params::default()
        }
    }
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
    /// this problem's constants (`stagec.wgsl`).
    stage_c: Vec<wgpu::ComputePipeline>,
    /// The fused last stage compiled for this problem (`last1.wgsl`), where it applies, with
    /// its cores per workgroup.
    last1: Option<(wgpu::ComputePipeline, u32)>,
    /// Whether `last1` reduces by subgroup operations.
    subgroups: bool,
    shape: Shape,
    table: [wgpu::Buffer; 3],
    rewards: wgpu::Buffer,
    goal: wgpu::Buffer,
    map: wgpu::Buffer,
    v: [wgpu::Buffer; 3],
    policy: wgpu::Buffer,
    stages: Vec<wgpu::Buffer>,
    rows: Option<wgpu::Buffer>,
    scratch: Option<wgpu::Buffer>,
    dv: Option<wgpu::Buffer>,
    partial: wgpu::Buffer,
    diff_out: Option<wgpu::Buffer>,
    params: wgpu::Buffer,
    params_cap: usize,
    dummy_r: wgpu::Buffer,
    dummy_w: wgpu::Buffer,
    binds: HashMap<[Slot; 4], wgpu::BindGroup>,
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
            .finish()
    }
}

/// Columns a lane of the fused last stage accumulates at once (`JC` in `last1.wgsl`).
const LAST_CHUNK: u32 = 8;

/// Partial results of `max_pass` / `diff_range`: values per workgroup.
const PER_WG: u64 = 4096;

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
}

impl BlockArrays {
    fn of(plan: &fuzzyq_core::solver::BlockPlan<'_, f32>) -> Result<Self, GpuError> {
        let mut a = Self {
            blocks: Vec::new(),
            row_base: Vec::new(),
            ptr: Vec::new(),
            col: Vec::new(),
            weight: Vec::new(),
        };
        let small = |x: usize| {
            u32::try_from(x).map_err(|_| GpuError::Unsupported("runs grids of at most 2^32 cores"))
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

/// The rewards on the device: per core (`rho(x_d)`), or per core and joint action (the
/// model's table, or the rewards `op` computes, tabulated once).
fn reward_buffer<M: Model<f32> + Sync + ?Sized>(
    gpu: &Gpu,
    plan: &fuzzyq_core::solver::BlockPlan<'_, f32>,
    op: &Operator<'_, f32, M>,
) -> wgpu::Buffer {
    match (plan.rewards, plan.reward_table) {
        (Some(r), _) => with_data(&gpu.inner, "rewards", r),
        (None, Some(t)) => with_data(&gpu.inner, "reward table", t),
        // A reward of the action that the model computes: tabulated once.
        (None, None) => with_data(&gpu.inner, "reward table", &op.reward_rows()),
    }
}

/// The goal cores as bits, 32 to a word (`block.wgsl`'s `goal_at`): core `c` is bit `c % 32`
/// of word `c / 32` (none for a run without goal cores).
fn goal_bits(goal: &[bool]) -> Vec<u32> {
    goal.chunks(32)
        .map(|c| {
            c.iter()
                .enumerate()
                .fold(0u32, |w, (i, &g)| w | (u32::from(g) << i))
        })
        .collect()
}

/// The size of a buffer made for `bytes` bytes ([`buffers::zeroed`], [`with_data`]).
fn allocated(bytes: u64) -> u64 {
    bytes.max(4).next_multiple_of(4)
}

/// Refuses a run whose buffers would take more device memory than `gpu` has
/// ([`Gpu::with_memory_limit`]), before any is allocated: the per-core ones (`V` three times,
/// the policy, the exact delta's two work buffers), the stage buffers of `shape`'s batches
/// and `other` (tables, rewards, partial results), each as allocated.
fn check_memory(gpu: &Gpu, shape: &Shape, mut other: Vec<u64>) -> Result<(), GpuError> {
    let n = shape.n;
    other.extend((0..shape.written_stages()).map(|b| shape.stage_bytes(b)));
    other.extend(shape.rows_bytes());
    let per_core = 6 * allocated(4 * n as u64);
    let rest: u64 = other.iter().map(|&b| allocated(b)).sum();
    match gpu.memory.filter(|&m| per_core + rest > m) {
        None => Ok(()),
        Some(available) => Err(GpuError::OutOfMemory {
            what: format!(
                "{n} cores: V three times, the policy and two work buffers, {:.2} GB; the \
                 tables, rewards and stage buffers, {:.2} GB",
                per_core as f64 / 1e9,
                rest as f64 / 1e9
            ),
            need: per_core + rest,
            available,
        }),
    }
}

/// The problem's kernels, compiled with its sizes as constants: the stage kernel of every
/// stage the passes run as a stage, and the fused last stage (with the cores per workgroup)
/// where the joint actions are the product's and the reward does not depend on the action.
/// `sg`: the subgroup size the last stage reduces with, if any.
#[allow(clippy::type_complexity)] // the pipelines, as GpuSweeps keeps them
fn compile(
    gpu: &Gpu,
    k: &Kernels,
    shape: &Shape,
    sg: Option<u32>,
) -> Result<
    (
        Vec<wgpu::ComputePipeline>,
        Option<(wgpu::ComputePipeline, u32)>,
    ),
    GpuError,
> {
    let nb = shape.n_blocks();
    // Every stage the passes run as a stage: those before the last, and the last where it
    // writes full rows.
    let compiled = if shape.writes_rows() { nb } else { nb - 1 };
    let stage_c = (0..compiled)
        .map(|b| {
            let [n_b, a_b, r_b, p_b] = shape.blocks[b];
            let consts = [
                ("SB", b as u32),
                ("SN", n_b),
                ("SA", a_b),
                ("SR", r_b),
                ("SP", p_b),
            ];
            let t = (include_str!("stagec.wgsl"), "stage_c");
            kernels::specialized(&gpu.inner, k, t, &consts, &[], false)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let last1 = if shape.fused_abs {
        let [nl, al, _, pl] = shape.blocks[nb - 1];
        // A workgroup of one subgroup (or of 64 threads reducing in memory); a core's
        // lanes a power of two up to 32 (or the subgroup), each taking J columns.
        let wgs = sg.unwrap_or(WG);
        let tpc = pl.next_power_of_two().min(wgs).min(32);
        let j = pl.div_ceil(tpc);
        let jc = j.min(LAST_CHUNK);
        let consts = [
            ("LAST", (nb - 1) as u32),
            ("NL", nl),
            ("AL", al),
            ("PL", pl),
            ("TPC", tpc),
            ("JC", jc),
            ("NCH", j.div_ceil(jc)),
            ("CPW", wgs / tpc),
            ("WGS", wgs),
        ];
        let replace: &[(&str, &str)] = if sg.is_some() {
            &[
                ("LANE_PARAM", ", @builtin(subgroup_invocation_id) sid: u32"),
                ("LANE_EXPR", "sid"),
                ("REDUCE", kernels::REDUCE_SUBGROUP),
            ]
        } else {
            &[
                ("LANE_PARAM", ""),
                ("LANE_EXPR", "li"),
                ("REDUCE", kernels::REDUCE_MEMORY),
            ]
        };
        let t = (include_str!("last1.wgsl"), "last1");
        let p = kernels::specialized(&gpu.inner, k, t, &consts, replace, sg.is_some())?;
        Some((p, wgs / tpc))
    } else {
        None
    };
    Ok((stage_c, last1))
}

impl GpuSweeps {
    /// Uploads `op`'s block tables and allocates the run's buffers on `gpu`.
    ///
    /// Refused ([`GpuError::Unsupported`]): the generic path (no blocks), terminal states,
    /// more than 8 blocks. [`GpuError::TooLarge`] where a buffer exceeds the adapter's limits
    /// (checked before allocating).
    pub fn new<M: Model<f32> + Sync + ?Sized>(
        gpu: &Gpu,
        op: &Operator<'_, f32, M>,
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
        let max_binding = gpu.max_binding;
        let check = |what: &'static str, bytes: u64| -> Result<(), GpuError> {
            if bytes > max_binding {
                return Err(GpuError::TooLarge {
                    what,
                    need: bytes,
                    limit: max_binding,
                    kind: "storage binding",
                });
            }
            Ok(())
        };
        check("V", 4 * n as u64)?;
        let BlockArrays {
            blocks,
            row_base,
            ptr,
            col,
            weight,
        } = BlockArrays::of(&plan)?;
        let mut shape = Shape::of(&plan, n, blocks, row_base);
        shape.batch_within(gpu.batch_bytes, max_binding)?;

        let rewards_bytes = reward_bytes(&plan, n);
        if plan.rewards.is_none() {
            check("the reward table", rewards_bytes)?;
        }
        let map = plan.joint_to_product.unwrap_or(&[]);
        let goal = goal_bits(plan.goal);
        let partials = n.div_ceil(PER_WG as usize) as u64;
        let (gx, gy) = kernels::groups(partials);
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
            4 * ptr.len() as u64,
            4 * col.len() as u64,
            4 * weight.len() as u64,
            4 * partial_len,
            params_cap as u64 * PARAM_STRIDE,
            4,
            4,
        ];
        if k.diff.is_some() {
            other.push(16 * partial_len);
        }
        check_memory(gpu, &shape, other)?;

        let device = &gpu.inner.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let rewards = reward_buffer(gpu, &plan, op);

        let table = [
            with_data(&gpu.inner, "row_ptr", &ptr),
            with_data(&gpu.inner, "col", &col),
            with_data(&gpu.inner, "weight", &weight),
        ];
        let vbytes = 4 * n as u64;
        let stages = (0..shape.written_stages())
            .map(|b| zeroed(&gpu.inner, "stage", shape.stage_bytes(b)))
            .collect();
        let rows = shape.rows_bytes().map(|b| zeroed(&gpu.inner, "rows", b));
        let sg = gpu.inner.summary.subgroup_size.filter(|_| gpu.subgroups);
        let (stage_c, last1) = compile(gpu, &k, &shape, sg)?;
        let diff_out = k
            .diff
            .is_some()
            .then(|| zeroed(&gpu.inner, "diff partials", 16 * partial_len));
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: params_cap as u64 * PARAM_STRIDE,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let sweeps = Self {
            gpu: gpu.clone(),
            k,
            stage_c,
            last1,
            subgroups: sg.is_some() && shape.fused_abs,
            table,
            rewards,
            goal: with_data(&gpu.inner, "goal", &goal),
            map: with_data(&gpu.inner, "map", map),
            v: [
                zeroed(&gpu.inner, "V0", vbytes),
                zeroed(&gpu.inner, "V1", vbytes),
                zeroed(&gpu.inner, "V2", vbytes),
            ],
            policy: zeroed(&gpu.inner, "policy", vbytes),
            stages,
            rows,
            scratch: None,
            dv: None,
            partial: zeroed(&gpu.inner, "max partials", 4 * partial_len),
            diff_out,
            params,
            params_cap,
            dummy_r: zeroed(&gpu.inner, "dummy", 4),
            dummy_w: zeroed(&gpu.inner, "dummy", 4),
            binds: HashMap::new(),
            profile: None,
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

    /// Whether the last stage reduces a core's lanes by subgroup operations
    /// ([`Gpu::with_subgroups`]).
    #[must_use]
    pub fn uses_subgroups(&self) -> bool {
        self.subgroups
    }

    /// The batches a full pass runs in (the stage buffers hold one batch).
    #[must_use]
    pub fn batches(&self) -> Batches {
        self.shape.batches
    }

    /// Bytes of device memory this run's buffers take now (the exact delta's two work
    /// buffers once it has run): at most what [`Self::new`] estimated and checked against
    /// [`AdapterSummary::memory`](crate::AdapterSummary::memory).
    #[must_use]
    pub fn device_bytes(&self) -> u64 {
        let mut all: Vec<&wgpu::Buffer> = vec![
            &self.rewards,
            &self.goal,
            &self.map,
            &self.policy,
            &self.partial,
            &self.params,
            &self.dummy_r,
            &self.dummy_w,
        ];
        all.extend(&self.table);
        all.extend(&self.v);
        all.extend(&self.stages);
        all.extend(
            [&self.rows, &self.scratch, &self.dv, &self.diff_out]
                .into_iter()
                .flatten(),
        );
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

    fn buffer(&self, s: Slot) -> &wgpu::Buffer {
        match s {
            Slot::V(i) => &self.v[usize::from(i)],
            Slot::Stage(b) => &self.stages[b],
            Slot::Rows => self.rows.as_ref().expect("allocated with the rows path"),
            Slot::Scratch => self.scratch.as_ref().expect("allocated first"),
            Slot::Dv => self.dv.as_ref().expect("allocated first"),
            Slot::Policy => &self.policy,
            Slot::Partial => &self.partial,
            Slot::DummyRead => &self.dummy_r,
            Slot::DummyWrite => &self.dummy_w,
        }
    }

    /// The bind group reading `src`, `src2` and writing `dst`, `aux`.
    fn bind(&mut self, slots: [Slot; 4]) {
        if self.binds.contains_key(&slots) {
            return;
        }
        let [src, dst, aux, src2] = slots.map(|s| self.buffer(s));
        let bufs: [&wgpu::Buffer; 11] = [
            &self.params,
            &self.table[0],
            &self.table[1],
            &self.table[2],
            src,
            dst,
            aux,
            &self.rewards,
            &self.goal,
            &self.map,
            src2,
        ];
        let g = bind_group(&self.gpu.inner, &self.k.layout, &bufs);
        self.binds.insert(slots, g);
    }

    /// Runs `dispatches` (entry, parameters, bindings `[src, dst, aux, src2]`, threads or
    /// workgroups) in one submission and waits for it.
    fn run(&mut self, dispatches: &[Dispatch]) -> Result<(), GpuError> {
        if self.profile.is_some() && dispatches.len() > 1 {
            for d in dispatches {
                let t0 = std::time::Instant::now();
                self.run(std::slice::from_ref(d))?;
                let key = match d.0 {
                    Entry::StageConst => format!("stage {}", d.1.b),
                    e => format!("{e:?}"),
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
                self.bind(d.2);
            }
            let ps: Vec<Params> = chunk.iter().map(|d| d.1).collect();
            let gpu = &self.gpu.inner;
            gpu.queue.write_buffer(&self.params, 0, &params_bytes(&ps));
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            {
                let mut pass = enc.begin_compute_pass(&Default::default());
                for (i, (entry, _, slots, (gx, gy))) in chunk.iter().enumerate() {
                    let params = &chunk[i].1;
                    pass.set_pipeline(match entry {
                        Entry::StageConst => &self.stage_c[params.b as usize],
                        Entry::LastOne => &self.last1.as_ref().expect("compiled where used").0,
                        e => self.k.pipeline(*e),
                    });
                    let offset = (i as u64 * PARAM_STRIDE) as u32;
                    pass.set_bind_group(0, &self.binds[slots], &[offset]);
                    pass.dispatch_workgroups(*gx, *gy, 1);
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

    /// The dispatches of one full pass of the last stage reducing as `mode` says, reading
    /// `v` and writing `out` (values) and the policy buffer (actions), batch by batch
    /// ([`Tree::steps`]).
    fn full_pass(&mut self, input: Slot, out: Slot, mode: Mode) -> Vec<Dispatch> {
        let s = &self.shape;
        let last = s.n_blocks() - 1;
        let fused = if mode == Mode::Abs {
            s.fused_abs
        } else {
            s.fused
        };
        let dst = if mode == Mode::Abs {
            Slot::Scratch
        } else {
            out
        };
        let cpw = self.last1.as_ref().map(|l| l.1);
        let base = self.base();
        let mut ds = Vec::new();
        for step in s.tree.steps(&s.batches) {
            let Step {
                stage: b,
                lo,
                items,
                src_lo,
            } = step;
            let src = if b == 0 { input } else { Slot::Stage(b - 1) };
            let p = Params {
                b: b as u32,
                lo: lo as u32,
                src_lo: src_lo as u32,
                ..base
            };
            if b < last {
                let count = items * s.tree.item_len(b);
                let p = Params {
                    count: count as u32,
                    ..p
                };
                let slots = [src, Slot::Stage(b), Slot::DummyWrite, Slot::DummyRead];
                ds.push((Entry::StageConst, p, slots, kernels::grid(count)));
            } else if fused {
                let cpw = cpw.expect("compiled where fused");
                let p = Params {
                    count: items as u32,
                    mode: mode as u32,
                    ..p
                };
                let slots = [src, dst, Slot::Policy, Slot::DummyRead];
                let wgs = items.div_ceil(u64::from(cpw));
                ds.push((Entry::LastOne, p, slots, kernels::groups(wgs)));
            } else {
                let count = items * s.n_product;
                let rows = Params {
                    count: count as u32,
                    ..p
                };
                let slots = [src, Slot::Rows, Slot::DummyWrite, Slot::DummyRead];
                ds.push((Entry::StageConst, rows, slots, kernels::grid(count)));
                let p = Params {
                    count: items as u32,
                    mode: mode as u32,
                    len: s.n_product as u32,
                    ..p
                };
                let slots = [Slot::Rows, dst, Slot::Policy, Slot::DummyRead];
                ds.push((Entry::ReduceRows, p, slots, kernels::grid(items)));
            }
        }
        ds
    }

    fn v_slot(b: Buf) -> Slot {
        Slot::V(b.0)
    }

    fn distinct(a: Buf, b: Buf) {
        assert_ne!(a, b, "a pass reads and writes distinct buffers");
    }

    /// A pass over `len` values of `dst` (and `src`, `src2`).
    fn elementwise(&mut self, entry: Entry, slots: [Slot; 4], shift: f32) -> Result<(), GpuError> {
        let p = Params {
            shift,
            ..self.base()
        };
        let g = kernels::grid(self.shape.n as u64);
        self.run(&[(entry, p, slots, g)])
    }

    /// The maximum of `src` (n values) from 0, as `T::max_of` folds.
    fn max_of(&mut self, src: Slot) -> Result<f32, GpuError> {
        let n = self.shape.n as u64;
        let p = Params {
            count: PER_WG as u32,
            ..self.base()
        };
        let g = kernels::groups(n.div_ceil(PER_WG));
        self.run(&[(
            Entry::Max,
            p,
            [src, Slot::Partial, Slot::DummyWrite, Slot::DummyRead],
            g,
        )])?;
        let parts: Vec<f32> =
            buffers::read_as(&self.gpu.inner, &self.partial, (g.0 * g.1) as usize)?;
        Ok(parts
            .into_iter()
            .fold(0.0f32, |m, x| if m >= x { m } else { x }))
    }

    fn ensure(&mut self, slot: Slot) {
        let bytes = 4 * self.shape.n as u64;
        match slot {
            Slot::Scratch if self.scratch.is_none() => {
                self.scratch = Some(zeroed(&self.gpu.inner, "abs", bytes));
            }
            Slot::Dv if self.dv.is_none() => self.dv = Some(zeroed(&self.gpu.inner, "dv", bytes)),
            _ => {}
        }
    }

    fn values_of(&self, v: Buf) -> Result<Vec<f32>, GpuError> {
        buffers::read_as(&self.gpu.inner, &self.v[usize::from(v.0)], self.shape.n)
    }
}

impl Sweeps<f32> for GpuSweeps {
    type Error = GpuError;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        let ds = self.full_pass(Self::v_slot(v), Self::v_slot(out), Mode::Max);
        self.run(&ds)
    }

    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        let ds = self.full_pass(Self::v_slot(v), Self::v_slot(out), Mode::MaxArg);
        self.run(&ds)
    }

    fn rewards(&mut self, out: Buf) -> Result<(), GpuError> {
        if self.shape.reward_table {
            return Err(GpuError::Unsupported(
                "computes the backup of V = 0 only for rewards of the state alone",
            ));
        }
        let slots = [
            Slot::DummyRead,
            Self::v_slot(out),
            Slot::DummyWrite,
            Slot::DummyRead,
        ];
        self.elementwise(Entry::Rewards, slots, 0.0)
    }

    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), GpuError> {
        Self::distinct(v, out);
        if !self.shape.can_evaluate {
            return Err(fuzzyq_core::solver::SolveError::PolicyEvaluation.into());
        }
        let slots = [
            Self::v_slot(v),
            Self::v_slot(out),
            Slot::Policy,
            Slot::DummyRead,
        ];
        self.elementwise(Entry::Evaluate, slots, 0.0)
    }

    fn sweep_async(&mut self, _v: Buf) -> Result<f64, GpuError> {
        Err(GpuError::Unsupported(
            "runs synchronous sweeps only (solver.sweep = \"sync\")",
        ))
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: f32) -> Result<DiffStats, GpuError> {
        let n = self.shape.n as u64;
        let Some((layout, pipeline)) = self.k.diff.as_ref() else {
            // No f64 in this adapter's shaders: the statistics on the host.
            let (x, y) = (self.values_of(a)?, self.values_of(b)?);
            return Ok(fuzzyq_core::solver::diff_stats(&x, &y, s));
        };
        let out = self.diff_out.as_ref().expect("made with f64");
        let gpu = &self.gpu.inner;
        let g = kernels::groups(n.div_ceil(PER_WG));
        let p = DiffParams {
            len: n as u32,
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
            &self.v[usize::from(a.0)],
            &self.v[usize::from(b.0)],
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
        Ok(DiffStats::of_range(lo, hi, f64::from(s)))
    }

    fn shift(&mut self, v: Buf, s: f32) -> Result<(), GpuError> {
        if s == 0.0 {
            return Ok(());
        }
        let slots = [
            Slot::DummyRead,
            Self::v_slot(v),
            Slot::DummyWrite,
            Slot::DummyRead,
        ];
        self.elementwise(Entry::Shift, slots, s)
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, GpuError> {
        Self::distinct(a, b);
        self.ensure(Slot::Dv);
        self.ensure(Slot::Scratch);
        let slots = [Self::v_slot(a), Slot::Dv, Slot::DummyWrite, Self::v_slot(b)];
        self.elementwise(Entry::Sub, slots, 0.0)?;
        let ds = self.full_pass(Slot::Dv, Slot::Scratch, Mode::Abs);
        self.run(&ds)?;
        let m = self.max_of(Slot::Scratch)?;
        Ok(f64::from(self.shape.gamma * m))
    }

    fn greedy(&mut self, v: Buf) -> Result<(), GpuError> {
        let ds = self.full_pass(Self::v_slot(v), Slot::DummyWrite, Mode::Arg);
        self.run(&ds)
    }

    fn load(&mut self, v: Buf, values: &[f32]) -> Result<(), GpuError> {
        fuzzyq_core::error::check_len("V", self.shape.n, values.len())
            .map_err(fuzzyq_core::solver::SolveError::from)?;
        let gpu = &self.gpu.inner;
        gpu.queue
            .write_buffer(&self.v[usize::from(v.0)], 0, bytemuck::cast_slice(values));
        Ok(())
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), GpuError> {
        fuzzyq_core::error::check_len("policy", self.shape.n, policy.len())
            .map_err(fuzzyq_core::solver::SolveError::from)?;
        self.gpu
            .inner
            .queue
            .write_buffer(&self.policy, 0, bytemuck::cast_slice(policy));
        Ok(())
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [f32]>, GpuError> {
        Ok(Cow::Owned(self.values_of(v)?))
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, GpuError> {
        Ok(Cow::Owned(buffers::read_as(
            &self.gpu.inner,
            &self.policy,
            self.shape.n,
        )?))
    }

    fn kernel(&self) -> Option<&'static str> {
        Some("wgpu")
    }
}
