//! The compute pipelines of `block.wgsl` and `diff.wgsl`, their parameters, and how a pass is
//! dispatched over a linear range of threads.

use crate::context::Context;
use crate::error::GpuError;

/// Threads per workgroup of every kernel (`WG` in the shaders).
pub(crate) const WG: u32 = 64;
/// Blocks the shaders' parameter arrays hold (`MAX_BLOCKS`).
pub(crate) const MAX_BLOCKS: usize = 8;
/// Bytes between two dispatches' parameters in the uniform buffer (the dynamic-offset
/// alignment every adapter accepts, 256, times two: `Params` takes 320 bytes).
pub(crate) const PARAM_STRIDE: u64 = 512;
/// Workgroups along x before a dispatch spills into y.
const MAX_X: u32 = 32768;

/// One dispatch's parameters (`Params` in `block.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct Params {
    pub b: u32,
    pub count: u32,
    pub lo: u32,
    pub out_lo: u32,
    pub mode: u32,
    pub n_joint: u32,
    pub has_map: u32,
    pub reward_table: u32,
    pub has_goal: u32,
    pub zero: u32,
    pub gamma: f32,
    pub shift: f32,
    pub goal_lo: u32,
    pub n_blocks: u32,
    pub len: u32,
    pub part_c0: u32,
    pub blocks: [[u32; 4]; MAX_BLOCKS],
    pub rows: [[u32; 4]; MAX_BLOCKS],
}

/// The parameters of `diff.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct DiffParams {
    pub len: u32,
    pub per_wg: u32,
    pub zero: u32,
    pub pad: u32,
}

/// The entry points of `block.wgsl`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Entry {
    ReduceRows,
    Rewards,
    Shift,
    Sub,
    Max,
    FmaProbe,
    /// `stagec.wgsl` or `stagem.wgsl`, compiled per problem and stage (not in [`Entry::ALL`]).
    StageConst,
    /// The fused last stage, `last1.wgsl` or `lastm.wgsl`, compiled per problem (not in
    /// [`Entry::ALL`]).
    Last,
    /// Policy evaluation, generated and compiled per problem ([`evaluation_source`]; not in
    /// [`Entry::ALL`]).
    Evaluate,
}

impl Entry {
    const ALL: [Entry; 6] = [
        Entry::ReduceRows,
        Entry::Rewards,
        Entry::Shift,
        Entry::Sub,
        Entry::Max,
        Entry::FmaProbe,
    ];

    fn name(self) -> &'static str {
        match self {
            Entry::ReduceRows => "reduce_rows",
            Entry::Evaluate => "evaluate",
            Entry::Rewards => "rewards_pass",
            Entry::Shift => "shift_pass",
            Entry::Sub => "sub_pass",
            Entry::Max => "max_pass",
            Entry::FmaProbe => "fma_probe",
            Entry::StageConst => "stage_c",
            Entry::Last => "last",
        }
    }
}

/// The pipelines and their layouts.
pub(crate) struct Kernels {
    pub layout: wgpu::BindGroupLayout,
    pipelines: Vec<wgpu::ComputePipeline>,
    /// Group 1's layout for a `V` in one part ([`crate::parts::ONE_PART`]): the same for
    /// every such problem.
    pub one_part: wgpu::BindGroupLayout,
    /// `diff.wgsl`, where the adapter has `f64`.
    pub diff: Option<(wgpu::BindGroupLayout, wgpu::ComputePipeline)>,
}

fn storage(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform(binding: u32, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

/// The layout of group 1 of the kernels that read `V` at other cores: its `parts`
/// read-only parts (`vp0..`, [`crate::parts::Parts::reader`]).
pub(crate) fn parts_layout(gpu: &Context, parts: usize) -> wgpu::BindGroupLayout {
    group1_layout(gpu, (0..parts).map(|_| true))
}

/// A layout of group 1: storage bindings `0..`, each read-only or not (`read_only`).
pub(crate) fn group1_layout(
    gpu: &Context,
    read_only: impl Iterator<Item = bool>,
) -> wgpu::BindGroupLayout {
    let entries: Vec<_> = read_only
        .enumerate()
        .map(|(k, r)| storage(k as u32, r))
        .collect();
    gpu.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("parts"),
            entries: &entries,
        })
}

/// A bind group of a group 1 layout ([`group1_layout`]) binding `parts` in order.
pub(crate) fn parts_group(
    gpu: &Context,
    layout: &wgpu::BindGroupLayout,
    parts: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<_> = parts
        .iter()
        .enumerate()
        .map(|(k, b)| wgpu::BindGroupEntry {
            binding: k as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("parts"),
        layout,
        entries: &entries,
    })
}

fn pipeline(
    gpu: &Context,
    layouts: &[&wgpu::BindGroupLayout],
    module: &wgpu::ShaderModule,
    entry: &str,
) -> wgpu::ComputePipeline {
    let layouts: Vec<_> = layouts.iter().map(|&l| Some(l)).collect();
    let pl = gpu
        .device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(entry),
            bind_group_layouts: &layouts,
            immediate_size: 0,
        });
    gpu.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pl),
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                zero_initialize_workgroup_memory: gpu.checks.zero_workgroup,
                ..Default::default()
            },
            cache: None,
        })
}

/// The shader module of WGSL `source`, compiled with `gpu`'s runtime checks ([`Checks`](crate::Checks)).
pub(crate) fn shader(gpu: &Context, label: &str, source: String) -> wgpu::ShaderModule {
    let desc = wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    };
    let c = gpu.checks;
    if c.loops && c.division && c.bounds {
        return gpu.device.create_shader_module(desc);
    }
    let checks = wgpu::ShaderRuntimeChecks {
        bounds_checks: c.bounds,
        force_loop_bounding: c.loops,
        int_div_checks: c.division,
        ..wgpu::ShaderRuntimeChecks::checked()
    };
    // SAFETY: wgpu's checks guard code it cannot trust; this crate's kernels need none of
    // them (the crate docs, "Runtime checks", and `Checks`): every loop is counted to a
    // bound, every divisor is a nonzero constant or size, and every index stays within its
    // array or binding. The tests run every kernel without them (the default) and with them,
    // and compare the results bit for bit.
    #[allow(unsafe_code)]
    unsafe {
        gpu.device.create_shader_module_trusted(desc, checks)
    }
}

impl Kernels {
    /// Compiles the shaders for `gpu`'s device.
    pub fn new(gpu: &Context) -> Result<Self, GpuError> {
        let device = &gpu.device;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = shader(gpu, "block.wgsl", include_str!("block.wgsl").into());
        let mut entries = vec![uniform(0, true)];
        for (b, read_only) in [
            (1, true),
            (2, true),
            (3, true),
            (4, true),
            (5, false),
            (6, false),
            (7, true),
            (8, true),
            (9, true),
            (10, true),
        ] {
            entries.push(storage(b, read_only));
        }
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("block"),
            entries: &entries,
        });
        let pipelines = Entry::ALL
            .iter()
            .map(|e| pipeline(gpu, &[&layout], &module, e.name()))
            .collect();
        let one_part = parts_layout(gpu, 1);
        let diff = gpu.summary.f64.then(|| {
            let module = shader(gpu, "diff.wgsl", include_str!("diff.wgsl").into());
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("diff"),
                entries: &[
                    uniform(0, false),
                    storage(1, true),
                    storage(2, true),
                    storage(3, false),
                ],
            });
            let p = pipeline(gpu, &[&layout], &module, "diff_range");
            (layout, p)
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Failed(format!(
                "the shaders did not compile: {e}"
            )));
        }
        Ok(Self {
            layout,
            pipelines,
            one_part,
            diff,
        })
    }

    pub fn pipeline(&self, e: Entry) -> &wgpu::ComputePipeline {
        let i = Entry::ALL
            .iter()
            .position(|&x| x == e)
            .expect("every entry");
        &self.pipelines[i]
    }
}

/// Policy evaluation's kernel (`evaluate`) for a sweep over `blocks` (`[cores, actions, R, P]`
/// in contraction order) that runs their first `stages` stages of a full backup first: a
/// thread per core sums its action's rows of blocks `stages..`, nested as the stages nest
/// them (block `stages` innermost, each level a chain of `fma`s from 0 over its row's entries
/// in order, the depth written out), then `finish`es. With no stages the innermost sums read
/// `V` through its parts (`v_at`, group 1, `parts.rs`); else the output of the last stage run
/// (`src`), which holds the sums over the blocks before for every action of the core's item
/// `q` of that stage: read at the column of the innermost block, the later blocks' columns
/// `off` and the product of the core's action's earlier blocks' actions `pp`. The dispatch
/// covers `prm.count` cores from `prm.out_lo` in its part of the per-core buffers, from
/// `prm.lo` counted from the first core below the source's first item (0 and the part's cores
/// without stages: `c_0` then comes from the part's first slab).
pub(crate) fn evaluation_source(blocks: &[[u32; 4]], stages: usize) -> String {
    let (nb, first) = (blocks.len(), stages);
    let mut s = String::from(
        "@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = linear(gid, wid, nwg);
    if t >= prm.count {
        return;
    }
    let core = prm.out_lo + t;
    let pol = aux[core];
    var rest = prm.lo + t;
",
    );
    // Each block's core (the last fastest) and its action's row.
    for b in (first..nb).rev() {
        let [n, a, r, p] = blocks[b];
        if b == 0 {
            s += &format!("    let c0 = prm.part_c0 + core / {r}u;\n");
        } else {
            s += &format!("    let c{b} = rest % {n}u;\n    rest = rest / {n}u;\n");
        }
        s += &format!(
            "    let row{b} = prm.rows[{b}u].x + c{b} * {a}u + (pol / {p}u) % {a}u;
    let s{b} = row_ptr[row{b}];
    let n{b} = row_ptr[row{b} + 1u];
"
        );
    }
    // The innermost read at the outer levels' offset.
    let off = if first + 1 < nb {
        format!("o{}", first + 1)
    } else {
        "0u".to_owned()
    };
    let at = if first == 0 {
        format!("v_at(col[e], {off})")
    } else {
        let [n, _, r, p] = blocks[first];
        s += &format!("    let q = rest;\n    let pp = pol % {p}u;\n");
        format!("src[((q * {n}u + col[e]) * {r}u + {off}) * {p}u + pp]")
    };
    let mut pad = String::from("    ");
    for b in (first + 1..nb).rev() {
        let outer = if b + 1 < nb {
            format!("o{} + ", b + 1)
        } else {
            String::new()
        };
        let r = blocks[b][2];
        s += &format!(
            "{pad}var a{b} = 0.0;
{pad}for (var e{b} = s{b}; e{b} < n{b}; e{b}++) {{
{pad}    let o{b} = {outer}col[e{b}] * {r}u;
"
        );
        pad += "    ";
    }
    s += &format!(
        "{pad}var a{first} = 0.0;
{pad}for (var e = s{first}; e < n{first}; e++) {{
{pad}    a{first} = fma(weight[e], {at}, a{first});
{pad}}}
"
    );
    for b in first + 1..nb {
        pad.truncate(pad.len() - 4);
        s += &format!(
            "{pad}    a{b} = fma(weight[e{b}], a{}, a{b});
{pad}}}
",
            b - 1
        );
    }
    s += &format!("    dst[core] = finish(core, a{});\n}}\n", nb - 1);
    s
}

/// The text of a kernel of `template` ([`specialized`]): the constants `consts`, then
/// `block.wgsl`'s declarations and `reader` (group 1's, if any), then `template` with its
/// `replace` pairs substituted.
pub(crate) fn source_text(
    template: &str,
    consts: &[(&str, u32)],
    replace: &[(&str, &str)],
    reader: Option<&str>,
) -> String {
    let mut source = String::new();
    for (name, v) in consts {
        source.push_str(&format!("const {name}: u32 = {v}u;\n"));
    }
    source.push_str(include_str!("block.wgsl"));
    source.push_str(reader.unwrap_or(""));
    let mut body = template.to_owned();
    for (from, to) in replace {
        body = body.replace(from, to);
    }
    source.push_str(&body);
    source
}

/// Whether `text` is a valid WGSL module (naga's parser and validator, as wgpu runs them,
/// with subgroup operations and `f64`): for the tests of generated kernels, without an
/// adapter. The most expressions one of its functions holds.
#[cfg(test)]
pub(crate) fn check_wgsl(text: &str) -> Result<usize, String> {
    use wgpu::naga;
    let module = naga::front::wgsl::parse_str(text).map_err(|e| e.emit_to_string(text))?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(text))?;
    let functions = module.functions.iter().map(|(_, f)| f);
    let entries = module.entry_points.iter().map(|e| &e.function);
    Ok(functions
        .chain(entries)
        .map(|f| f.expressions.len())
        .max()
        .unwrap_or(0))
}

/// A kernel of `template` compiled with the problem's constants `consts` (prepended, with
/// `block.wgsl`'s declarations), its text's `replace` pairs substituted; `subgroups` when it
/// uses subgroup operations; `parts`: group 1's layout and declarations (`v_at`), for a kernel
/// that reads `V` through them.
pub(crate) fn specialized(
    gpu: &Context,
    k: &Kernels,
    (template, entry): (&str, &str),
    consts: &[(&str, u32)],
    replace: &[(&str, &str)],
    subgroups: bool,
    parts: Option<(&wgpu::BindGroupLayout, &str)>,
) -> Result<wgpu::ComputePipeline, GpuError> {
    // Naga takes subgroup operations without `enable subgroups;` (which it does not parse
    // yet) where the device has the feature; the flag only names the kernel's needs.
    let _ = subgroups;
    let source = source_text(template, consts, replace, parts.map(|p| p.1));
    let device = &gpu.device;
    // Error scopes are the calling thread's, and kernels compile on threads of their own
    // (`compile.rs`): both kinds are caught here.
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let module = shader(gpu, entry, source);
    let layouts: Vec<&wgpu::BindGroupLayout> =
        [&k.layout].into_iter().chain(parts.map(|p| p.0)).collect();
    let p = pipeline(gpu, &layouts, &module, entry);
    let memory = pollster::block_on(memory.pop());
    if let Some(e) = pollster::block_on(validation.pop()).or(memory) {
        return Err(GpuError::Failed(format!(
            "the kernel {entry} did not compile: {e}"
        )));
    }
    Ok(p)
}

/// The reduction over a core's lanes in `last1.wgsl` and `lastm.wgsl`: by subgroup shuffles,
/// or in workgroup memory.
pub(crate) const REDUCE_SUBGROUP: &str = "
    for (var m = TPC / 2u; m > 0u; m = m / 2u) {
        let ov = subgroupShuffleXor(bv, m);
        let oi = subgroupShuffleXor(bi, m);
        if beats(ov, oi, bv, bi) {
            bv = ov;
            bi = oi;
        }
    }";

/// A core's rows one at a time in `last1.wgsl` and `lastw.wgsl` (`CORE_ROWS`): for core `c` of
/// the last block, each action's row entries in order, `JC` of the lane's columns at a time,
/// each sum offered to the lane's largest. `ROW_ITEM` is where a row entry's column starts in
/// units of `PL` values of `ROW_VALUES` (the stage before's buffer, or the workgroup's tile).
pub(crate) const CORE_ROWS: &str = "
        for (var a = 0u; a < AL; a++) {
            let row = prm.rows[LAST].x + c * AL + a;
            let e0 = row_ptr[row];
            let e1 = row_ptr[row + 1u];
            for (var ch = 0u; ch < NCH; ch++) {
                let p0 = lane + TPC * JC * ch;
                var acc: array<f32, JC>;
                for (var j = 0u; j < JC; j++) {
                    acc[j] = 0.0;
                }
                for (var e = e0; e < e1; e++) {
                    let w = weight[e];
                    let k = ROW_ITEM * PL;
                    for (var j = 0u; j < JC; j++) {
                        acc[j] = fma(w, ROW_VALUES[k + min(p0 + TPC * j, PL - 1u)], acc[j]);
                    }
                }
                for (var j = 0u; j < JC; j++) {
                    let p = p0 + TPC * j;
                    if p < PL {
                        offer(acc[j], a * PL + p, &bv, &bi);
                    }
                }
            }
        }
";

/// See [`REDUCE_SUBGROUP`].
pub(crate) const REDUCE_MEMORY: &str = "
    tv[li] = bv;
    ti[li] = bi;
    workgroupBarrier();
    for (var s = TPC / 2u; s > 0u; s = s / 2u) {
        if lane < s && beats(tv[li + s], ti[li + s], tv[li], ti[li]) {
            tv[li] = tv[li + s];
            ti[li] = ti[li + s];
        }
        workgroupBarrier();
    }
    bv = tv[li];
    bi = ti[li];";

/// Workgroups `(x, y)` covering `threads` threads (the shaders' `linear` index).
pub(crate) fn grid(threads: u64) -> (u32, u32) {
    let groups = threads.div_ceil(u64::from(WG)).max(1);
    let x = groups.min(u64::from(MAX_X)) as u32;
    let y = groups.div_ceil(u64::from(x)) as u32;
    (x, y)
}

/// Workgroups `(x, y)` for `groups` workgroups (kernels indexed per workgroup).
pub(crate) fn groups(groups: u64) -> (u32, u32) {
    let groups = groups.max(1);
    let x = groups.min(u64::from(MAX_X)) as u32;
    let y = groups.div_ceil(u64::from(x)) as u32;
    (x, y)
}

/// A bind group of `layout` binding `bufs[i]` at binding `i` (binding 0 a uniform window of
/// one dispatch's parameters).
pub(crate) fn bind_group(
    gpu: &Context,
    layout: &wgpu::BindGroupLayout,
    bufs: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = bufs
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: if i == 0 {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: b,
                    offset: 0,
                    size: wgpu::BufferSize::new(size_of::<Params>() as u64),
                })
            } else {
                b.as_entire_binding()
            },
        })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout,
        entries: &entries,
    })
}

/// The parameters of `n` dispatches, `PARAM_STRIDE` bytes apart.
pub(crate) fn params_bytes(params: &[Params]) -> Vec<u8> {
    let mut out = vec![0u8; params.len() * PARAM_STRIDE as usize];
    for (i, p) in params.iter().enumerate() {
        let at = i * PARAM_STRIDE as usize;
        out[at..at + size_of::<Params>()].copy_from_slice(bytemuck::bytes_of(p));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policy_evaluation_is_valid_wgsl_for_every_split() {
        // Three blocks of 4 cores and 2 actions: nested over `V` (one part and several), and
        // from the first and second stages' outputs.
        let blocks = [[4, 2, 16, 1], [4, 2, 4, 2], [4, 2, 1, 4]];
        let parts = crate::parts::Parts::new(4, 16, 128, 128, 100).unwrap();
        assert_eq!(parts.count(), 2);
        for (stages, reader) in [
            (0, Some(crate::parts::ONE_PART.to_owned())),
            (0, Some(parts.reader())),
            (1, None),
            (2, None),
        ] {
            let text = source_text(
                &evaluation_source(&blocks, stages),
                &[],
                &[],
                reader.as_deref(),
            );
            let _ = check_wgsl(&text).unwrap_or_else(|e| panic!("{stages} stages: {e}\n{text}"));
        }
        // Two levels nested over the second stage's output: its item, column, the outer
        // level's offset and the first two blocks' actions.
        let text = evaluation_source(&blocks, 1);
        assert!(
            text.contains("a1 = fma(weight[e], src[((q * 4u + col[e]) * 4u + o2) * 2u + pp], a1);"),
            "{text}"
        );
        assert!(text.contains("a2 = fma(weight[e2], a1, a2);"), "{text}");
        assert!(!text.contains("c0"), "{text}");
        let text = evaluation_source(&blocks, 0);
        assert!(
            text.contains("let c0 = prm.part_c0 + core / 16u;"),
            "{text}"
        );
        assert!(text.contains("v_at(col[e], o1)"), "{text}");
    }
}
