//! The kernels compiled for one problem ([`compile`]): each stage's, the fused last stage's
//! and policy evaluation's, with the problem's sizes as constants, side by side on threads of
//! their own.

use fuzzyq_core::solver::PlanTable;

use crate::error::GpuError;
use crate::gpu::Gpu;
use crate::kernels::{self, Kernels};
use crate::last::{Last, MergedAt, compile_last};
use crate::parts::Parts;
use crate::shape::Shape;

/// Elements of one block core a stage needs to take its rows merged (`stagem.wgsl`): a
/// subgroup's worth, so that neighbouring threads share each step (one-block models, whose
/// threads each take a core of their own, keep `stagec.wgsl`).
const MERGED_SHARED: u64 = 32;

/// A stage compiled for one problem ([`compile`]): `stagec.wgsl` (a thread per element),
/// `stagem.wgsl` (a thread per element's `per_thread` actions, the block's rows merged) or
/// `stage_u` (`per_thread` `None`: a thread per element of each item of the stage before,
/// taking every core below it).
pub(crate) struct Stage {
    pub(crate) pipeline: wgpu::ComputePipeline,
    pub(crate) per_thread: Option<u64>,
    pub(crate) name: &'static str,
    /// Its group 1's layout where it reads or writes a stage output in parts
    /// ([`Group1::Stage`]).
    pub(crate) group1: Option<wgpu::BindGroupLayout>,
}

/// The kernels compiled for one problem ([`compile`]).
pub(crate) struct Compiled {
    pub(crate) stages: Vec<Stage>,
    pub(crate) last: Option<Last>,
    pub(crate) evaluate: Option<wgpu::ComputePipeline>,
    pub(crate) eval_stages: usize,
}

/// Stage `b`'s kernel compiled with the problem's sizes as constants (`stagec.wgsl`, or
/// `stagem.wgsl` where `merged` and the block core's elements fill a subgroup): reading `V`
/// through its parts (`parts`: group 1's layout and `v_at`) for the first stage of several
/// blocks, else the stage before (`src`, or its parts), and writing its output (`dst`, or
/// its parts: `put`).
fn compile_stage(
    gpu: &Gpu,
    k: &Kernels,
    shape: &Shape,
    b: usize,
    parts: (&wgpu::BindGroupLayout, &str),
    merged: Option<MergedAt>,
    table: &PlanTable<'_, f32>,
) -> Result<Stage, GpuError> {
    let nb = shape.n_blocks();
    let [n_b, a_b, r_b, p_b] = shape.blocks[b];
    let mut consts = vec![
        ("SB", b as u32),
        ("SN", n_b),
        ("SA", a_b),
        ("SR", r_b),
        ("SP", p_b),
    ];
    // A merged stage reads the step's column `k`, the other the entry's. Merged where a
    // block core's elements fill a subgroup, whose threads then share its steps.
    let shared = u64::from(r_b) * u64::from(p_b) >= MERGED_SHARED;
    let (t, column, per_thread) = match merged.filter(|_| gpu.merged_stages && shared) {
        Some(at) => {
            consts.extend(at.constants());
            ((include_str!("stagem.wgsl"), "stage_m"), "k", a_b)
        }
        None => ((include_str!("stagec.wgsl"), "stage_c"), "col[e]", 1),
    };
    let reads_v = b == 0 && nb > 1;
    let parts_in = match b {
        0 => None,
        b => shape.stage_parts.get(b - 1).and_then(Option::as_ref),
    };
    let parts_out = shape.stage_parts.get(b).and_then(Option::as_ref);
    // Group 1: the parts read (of `V`, or of the stage before), then those written.
    let first_out = if reads_v {
        shape.parts.count()
    } else {
        parts_in.map_or(0, Parts::count)
    };
    let mut io = String::new();
    if reads_v {
        io.push_str(parts.1);
    } else if let Some(p) = parts_in {
        io.push_str(&(p.declare(0, "sp", "read") + &p.getter("s_at", "sp")));
    }
    // The value of column `column` at the thread's `(r, p)`.
    let src_at = |column: &str| {
        if reads_v {
            format!("v_at({column}, r)")
        } else if parts_in.is_some() {
            format!("s_at(base + {column}, r * SP + p)")
        } else {
            format!("src[((base + {column}) * SR + r) * SP + p]")
        }
    };
    // The block's rows compiled in, where asked for and the table is small enough.
    let unrolled = gpu
        .unrolled_stages
        .then(|| crate::unrolled::stage_source(table, |k| src_at(&format!("{k}u"))))
        .flatten();
    let at = src_at(column);
    match parts_out {
        Some(p) => {
            io.push_str(&(p.declare(first_out, "dp", "read_write") + &p.setter("put", "dp")))
        }
        None => io.push_str("fn put(o: u32, x: f32) {\n    dst[o] = x;\n}\n"),
    }
    let own = (parts_in.is_some() || parts_out.is_some()).then(|| {
        let reads = (0..first_out).map(|_| true);
        let writes = (0..parts_out.map_or(0, Parts::count)).map(|_| false);
        kernels::group1_layout(&gpu.inner, reads.chain(writes))
    });
    let layout = match (&own, reads_v) {
        (Some(l), _) => Some(l),
        (None, true) => Some(parts.0),
        (None, false) => None,
    };
    let replace = [("SRC_AT", at.as_str())];
    let (body, t, per_thread) = match unrolled {
        Some(text) => (io + &text, (t.0, "stage_u"), None),
        None => (io + t.0, t, Some(u64::from(per_thread))),
    };
    let pipeline = kernels::specialized(
        &gpu.inner,
        k,
        (&body, t.1),
        &consts,
        &replace,
        false,
        layout.map(|l| (l, "")),
    )?;
    Ok(Stage {
        pipeline,
        per_thread,
        name: t.1,
        group1: own,
    })
}

/// The problem's kernels, compiled with its sizes as constants: the stage kernel of every
/// stage the passes run as a stage (the first, where several blocks contract, reading `V`'s
/// parts through group 1, `parts`), the fused last stage (with the cores per workgroup) where
/// the joint actions are the product's and the reward does not depend on the action, and
/// policy evaluation where the run can evaluate, reading a stage's output or a `V` in several
/// parts. `sg`: the subgroup size the last stage reduces with, if any.
pub(crate) fn compile(
    gpu: &Gpu,
    k: &Kernels,
    shape: &Shape,
    sg: Option<u32>,
    parts: (&wgpu::BindGroupLayout, &str),
    merged: &[Option<MergedAt>],
    tables: &[PlanTable<'_, f32>],
) -> Result<Compiled, GpuError> {
    let nb = shape.n_blocks();
    // Every stage the passes run as a stage: those before the last, and the last where it
    // writes full rows.
    let compiled = if shape.writes_rows() { nb } else { nb - 1 };
    // The stage before the last joined into it (`lastj`): where there is a stage before
    // that (read from its buffer, not `V` or parts), its rows are short enough, and the
    // stages between write one buffer each.
    let before = (nb >= 3
        && shape.stage_parts[nb - 3..nb - 1]
            .iter()
            .all(Option::is_none))
    .then(|| crate::unrolled::Before::of(&tables[nb - 2]))
    .flatten();
    // The stages and the last stage compiled side by side, a thread each: the driver's
    // compiler takes most of a run's set-up where the rows are compiled in (on lavapipe,
    // the paper's grid: 0.29-0.31 s for the four kernels, of which the last stage's is the
    // longest).
    let (stages, last) = std::thread::scope(|scope| {
        let stages: Vec<_> = (0..compiled)
            .map(|b| {
                scope.spawn(move || compile_stage(gpu, k, shape, b, parts, merged[b], &tables[b]))
            })
            .collect();
        let last = shape.fused_abs.then(|| {
            let (table, merged) = (&tables[nb - 1], merged[nb - 1]);
            compile_last(gpu, k, &shape.blocks, sg, merged, table, before)
        });
        let stages = stages
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect::<Result<Vec<_>, GpuError>>();
        (stages, last.transpose())
    });
    let (stages, last) = (stages?, last?);
    let compiled_in: Vec<bool> = stages.iter().map(|s| s.per_thread.is_none()).collect();
    let eval_stages = shape.evaluation_stages(gpu.evaluation, &compiled_in);
    let evaluate = if shape.can_evaluate {
        Some(kernels::specialized(
            &gpu.inner,
            k,
            (
                &kernels::evaluation_source(&shape.blocks, eval_stages),
                "evaluate",
            ),
            &[],
            &[],
            false,
            (eval_stages == 0).then_some(parts),
        )?)
    } else {
        None
    };
    Ok(Compiled {
        stages,
        last,
        evaluate,
        eval_stages,
    })
}
