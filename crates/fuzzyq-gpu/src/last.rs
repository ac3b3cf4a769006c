//! The fused last stage of a full backup: the last block's contraction with the maximum over
//! joint actions, one row at a time (`last1.wgsl`), a core's rows merged by column
//! (`lastm.wgsl`), an item's values from workgroup memory (`lastw.wgsl`), computed there
//! from the stage before that (`lasts.wgsl`) or the rows compiled into the kernel
//! (`unrolled.rs`) ([`LastStage`]), compiled with the problem's sizes; and the
//! merged steps it and the merged stages (`stagem.wgsl`) read.

use fuzzyq_core::solver::PlanTable;

use crate::error::GpuError;
use crate::gpu::{Gpu, LastStage};
use crate::kernels::{self, Kernels, WG};
use crate::unrolled::Before;

/// Columns a lane of the fused last stage accumulates at once (`JC` in `last1.wgsl`).
const LAST_CHUNK: u32 = 8;

/// Most sums a lane of the merged last stage keeps (`AL JC` in `lastm.wgsl`).
const MERGED_SUMS: u32 = 40;

/// Most entries of a last block's row that the staged last stage holds in registers
/// (`lasts.wgsl`, `ML`).
const STAGED_ENTRIES: u32 = 16;

/// The fused last stage compiled for one problem ([`compile_last`]).
pub(crate) struct Last {
    /// `last1.wgsl`, `lastm.wgsl`, `lastw.wgsl`, `lasts.wgsl` or `unrolled.rs`'s with the
    /// problem's constants.
    pub pipeline: wgpu::ComputePipeline,
    /// Cores a workgroup takes (`None`: a workgroup per item of the stage before).
    pub cores_per_group: Option<u32>,
    /// Its kernel (`last1`, `lastm`, `lastw`, `lasts`, `lastu` or `lastj`).
    pub name: &'static str,
    /// Whether it reduces a core's lanes by subgroup operations.
    pub subgroups: bool,
    /// Whether it computes the stage before it itself (`lastj`, `lasts`), reading the one
    /// before that.
    pub joined: bool,
}

/// Where a block's rows merged by column ([`PlanTable::merged_steps`]) lie in the block
/// tables' arrays (`sweeps.rs`), after every block's table: step `s` of block core `c`
/// for `s` in `ptr[ptr_at + c]..ptr[ptr_at + c + 1]` reads column `col[col_at + s]`; action
/// `a` takes it where bit `a` of `col[mask_at + s]` is set, with weight
/// `weight[weight_at + s A + a]`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MergedAt {
    ptr_at: u32,
    col_at: u32,
    mask_at: u32,
    weight_at: u32,
}

impl MergedAt {
    /// The kernels' constants for where the steps lie (`MP`, `MC`, `MM`, `MW`).
    pub(crate) fn constants(self) -> [(&'static str, u32); 4] {
        [
            ("MP", self.ptr_at),
            ("MC", self.col_at),
            ("MM", self.mask_at),
            ("MW", self.weight_at),
        ]
    }
}

/// Appends `t`'s rows merged by column, per block core, to the tables' arrays ([`MergedAt`]);
/// `None` (nothing appended) where its actions do not merge.
pub(crate) fn append_merged(
    (ptr, col, weight): (&mut Vec<u32>, &mut Vec<u32>, &mut Vec<f32>),
    t: &PlanTable<'_, f32>,
) -> Option<MergedAt> {
    let na = t.n_actions;
    let (mut starts, mut cols, mut masks, mut ws) = (vec![0u32], vec![], vec![], vec![]);
    for c in 0..t.n_cores {
        let first = cols.len();
        t.merged_steps(c, |step, k, a, w| {
            let s = first + step;
            if s == cols.len() {
                cols.push(k);
                masks.push(0u32);
                ws.resize(ws.len() + na, 0.0);
            }
            masks[s] |= 1 << a;
            ws[s * na + a] = w;
        })?;
        starts.push(cols.len() as u32);
    }
    let at = MergedAt {
        ptr_at: ptr.len() as u32,
        col_at: col.len() as u32,
        mask_at: (col.len() + cols.len()) as u32,
        weight_at: weight.len() as u32,
    };
    ptr.extend(starts);
    col.extend(cols);
    col.extend(masks);
    weight.extend(ws);
    Some(at)
}

/// The fused last stage compiled for a problem of `blocks` (`[cores, actions, R, P]` in
/// contraction order), as [`Gpu::with_last_stage`] says (rows
/// one at a time where the last block's actions do not merge, `merged` `None`), with its
/// reduction over a core's lanes: a workgroup of one subgroup of `sg` lanes reducing by
/// shuffles, or of 64 threads reducing in memory.
pub(crate) fn compile_last(
    gpu: &Gpu,
    k: &Kernels,
    blocks: &[[u32; 4]],
    sg: Option<u32>,
    merged: Option<MergedAt>,
    table: &PlanTable<'_, f32>,
    before: Option<Before>,
) -> Result<Last, GpuError> {
    let nb = blocks.len();
    let [nl, al, _, pl] = blocks[nb - 1];
    if let (LastStage::Staged { threads, columns }, Some(before)) = (gpu.last, before)
        && let Some(last) = compile_staged(gpu, k, blocks, table, before, (threads, columns))?
    {
        return Ok(last);
    }
    if matches!(gpu.last, LastStage::Unrolled | LastStage::Joined) {
        // A workgroup of one subgroup exchanging by shuffles, else of 32 threads exchanging
        // through workgroup memory; the stage before joined in where asked for and it can be.
        let lanes = sg.unwrap_or(32);
        let before = before.filter(|_| gpu.last == LastStage::Joined);
        if let Some(text) = crate::unrolled::source(table, pl, lanes, sg.is_some(), before) {
            let consts = [
                ("LAST", (nb - 1) as u32),
                ("NL", nl),
                ("AL", al),
                ("PL", pl),
            ];
            let name = if before.is_some() { "lastj" } else { "lastu" };
            let pipeline = kernels::specialized(
                &gpu.inner,
                k,
                (text.as_str(), name),
                &consts,
                &[],
                sg.is_some(),
                None,
            )?;
            return Ok(Last {
                pipeline,
                cores_per_group: None,
                name,
                subgroups: sg.is_some(),
                joined: before.is_some(),
            });
        }
    }
    // Rows too many to compile in (or no stage before to stage): merged on a software
    // adapter, else one at a time.
    let choice = match gpu.last {
        LastStage::Unrolled | LastStage::Joined | LastStage::Staged { .. }
            if gpu.summary().software =>
        {
            LastStage::MERGED
        }
        LastStage::Unrolled | LastStage::Joined | LastStage::Staged { .. } => LastStage::Rows,
        other => other,
    };
    if let LastStage::Tile { threads } = choice {
        // The item's values and the reduction's two arrays in workgroup memory.
        let tile = 4 * (u64::from(nl) * u64::from(pl) + 2 * u64::from(threads));
        let limits = gpu.inner.device.limits();
        let fits = tile <= u64::from(limits.max_compute_workgroup_storage_size)
            && threads <= limits.max_compute_invocations_per_workgroup;
        if fits {
            return compile_tile(gpu, k, blocks, threads);
        }
    }
    // A core's lanes: a power of two up to 32 (or the subgroup), each taking J columns, JC
    // at a time (so that the sums stay in registers: of every action where rows merge).
    let wgs = sg.unwrap_or(WG);
    let tpc = pl.next_power_of_two().min(wgs).min(32);
    let j = pl.div_ceil(tpc);
    let (merged, cores) = match (choice, merged) {
        (LastStage::Merged { cores }, Some(at)) => (Some(at), cores.max(1)),
        _ => (None, 1),
    };
    let jc = match merged {
        Some(_) => j.min(LAST_CHUNK).min((MERGED_SUMS / al).max(1)),
        None => j.min(LAST_CHUNK),
    };
    let mut consts = lane_constants(blocks, wgs, tpc, jc);
    let t = match merged {
        Some(at) => {
            consts.push(("CR", cores));
            consts.extend(at.constants());
            (include_str!("lastm.wgsl"), "lastm")
        }
        None => (include_str!("last1.wgsl"), "last1"),
    };
    let replace: &[(&str, &str)] = if sg.is_some() {
        &[
            ("LANE_PARAM", ", @builtin(subgroup_invocation_id) sid: u32"),
            ("LANE_EXPR", "sid"),
            ("REDUCE", kernels::REDUCE_SUBGROUP),
            ("CORE_ROWS", kernels::CORE_ROWS),
            ("ROW_ITEM", "(base + col[e])"),
            ("ROW_VALUES", "src"),
        ]
    } else {
        &[
            ("LANE_PARAM", ""),
            ("LANE_EXPR", "li"),
            ("REDUCE", kernels::REDUCE_MEMORY),
            ("CORE_ROWS", kernels::CORE_ROWS),
            ("ROW_ITEM", "(base + col[e])"),
            ("ROW_VALUES", "src"),
        ]
    };
    let pipeline = kernels::specialized(&gpu.inner, k, t, &consts, replace, sg.is_some(), None)?;
    Ok(Last {
        pipeline,
        cores_per_group: Some(wgs / tpc * cores),
        name: t.1,
        subgroups: sg.is_some(),
        joined: false,
    })
}

/// The constants the fused last stages share: the last block (`LAST`) and its sizes (`NL`
/// cores, `AL` actions, `PL` product actions before it), `TPC` lanes per core in a workgroup
/// of `WGS = wgs` threads (`CPW` cores at a time), each lane taking `J` of a core's `PL`
/// columns, `JC` at a time in `NCH` chunks.
fn lane_constants(blocks: &[[u32; 4]], wgs: u32, tpc: u32, jc: u32) -> Vec<(&'static str, u32)> {
    let nb = blocks.len();
    let [nl, al, _, pl] = blocks[nb - 1];
    let j = pl.div_ceil(tpc);
    vec![
        ("LAST", (nb - 1) as u32),
        ("NL", nl),
        ("AL", al),
        ("PL", pl),
        ("TPC", tpc),
        ("JC", jc),
        ("NCH", j.div_ceil(jc)),
        ("CPW", wgs / tpc),
        ("WGS", wgs),
    ]
}

/// The fused last stage computing the stage before it into workgroup memory, a workgroup
/// of `threads` per item of that stage, at most `columns` of the item's product-action
/// columns per pass (`lasts.wgsl`, [`LastStage::Staged`]; `before`: its block); `None`
/// where not one column of the item's values fits the adapter's workgroup memory beside
/// the lanes' fold, `threads` is 0 or exceeds its workgroups, or a row holds more than
/// [`STAGED_ENTRIES`].
fn compile_staged(
    gpu: &Gpu,
    k: &Kernels,
    blocks: &[[u32; 4]],
    table: &PlanTable<'_, f32>,
    before: Before,
    (threads, columns): (u32, Option<u32>),
) -> Result<Option<Last>, GpuError> {
    let [nl, al, _, pl] = blocks[blocks.len() - 1];
    let limits = gpu.inner.device.limits();
    // Columns per pass: as many of the item's as the workgroup memory holds beside the
    // fold's two arrays, at most `columns`.
    let room = (u64::from(limits.max_compute_workgroup_storage_size) / 4)
        .saturating_sub(2 * u64::from(threads));
    let mut pc = (room / u64::from(nl.max(1))).min(u64::from(pl.min(columns.unwrap_or(pl)))) as u32;
    // Where the workgroup memory cuts the columns into passes of more than a column per
    // thread, a whole number per thread, so that no thread computes one column more than
    // the others in the passes' first phase.
    if pc < pl && pc > threads && columns.is_none() {
        pc -= pc % threads;
    }
    let fits = pc > 0
        && threads > 0
        && threads <= limits.max_compute_invocations_per_workgroup
        && threads <= limits.max_compute_workgroup_size_x;
    let most_entries = crate::unrolled::most_entries(table);
    if !fits || most_entries > STAGED_ENTRIES {
        return Ok(None);
    }
    // Lanes per core: as many as the workgroup holds for every core at once, at most the
    // pass's columns.
    let j = (threads / nl).clamp(1, pc);
    let cpw = threads / j;
    // Threads per group of the stage before's columns, and groups over its cores.
    let qt = pc.min(threads);
    let consts = [
        ("LAST", (blocks.len() - 1) as u32),
        ("NL", nl),
        ("AL", al),
        ("PL", pl),
        ("ML", most_entries.max(1)),
        ("N1", before.n),
        ("A1", before.a),
        ("P1", before.p),
        ("ME", before.max_entries),
        ("WGS", threads),
        ("PC", pc),
        ("TILE", nl * pc),
        ("J", j),
        ("CPW", cpw),
        ("ROUNDS", nl.div_ceil(cpw)),
        ("QT", qt),
        ("KG", threads / qt),
    ];
    let t = (include_str!("lasts.wgsl"), "lasts");
    let pipeline = kernels::specialized(&gpu.inner, k, t, &consts, &[], false, None)?;
    Ok(Some(Last {
        pipeline,
        cores_per_group: None,
        name: t.1,
        subgroups: false,
        joined: true,
    }))
}

/// The fused last stage with a workgroup of `threads` per item of the stage before
/// (`lastw.wgsl`, [`LastStage::Tile`]): lanes and columns per lane as `last1.wgsl`, reduced in
/// workgroup memory.
fn compile_tile(
    gpu: &Gpu,
    k: &Kernels,
    blocks: &[[u32; 4]],
    threads: u32,
) -> Result<Last, GpuError> {
    let [nl, _, _, pl] = blocks[blocks.len() - 1];
    let tpc = pl.next_power_of_two().min(threads).min(32);
    let jc = pl.div_ceil(tpc).min(LAST_CHUNK);
    let mut consts = lane_constants(blocks, threads, tpc, jc);
    consts.push(("TILE", nl * pl));
    let t = (include_str!("lastw.wgsl"), "lastw");
    let replace = [
        ("REDUCE", kernels::REDUCE_MEMORY),
        ("CORE_ROWS", kernels::CORE_ROWS),
        ("ROW_ITEM", "col[e]"),
        ("ROW_VALUES", "tile"),
    ];
    let pipeline = kernels::specialized(&gpu.inner, k, t, &consts, &replace, false, None)?;
    Ok(Last {
        pipeline,
        cores_per_group: None,
        name: t.1,
        subgroups: false,
        joined: false,
    })
}
