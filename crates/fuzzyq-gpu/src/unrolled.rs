//! Kernels with a block's rows compiled in: the stages before the last (`stage_u`,
//! [`Gpu::with_unrolled_stages`](crate::Gpu::with_unrolled_stages)), the fused last stage
//! (`lastu`, [`LastStage::Unrolled`](crate::LastStage::Unrolled)), and the last stage that
//! computes the stage before it too (`lastj`, [`LastStage::Joined`](crate::LastStage::Joined)).
//!
//! A block's table is the same for every item of the stage before (a run of the earlier
//! blocks' cores), and small: 45 cores x 5 actions x at most 4 entries on the paper's grid.
//! So instead of reading each row's columns and weights from buffers, the kernels are
//! generated with them as constants: for each core, the values of the columns its rows read
//! are loaded once, and each row is a straight chain of `fma`s with constant weights (their
//! exact bits). A stage before the last gives a thread each element of an item of the stage
//! before and runs every core of the block below it ([`stage_source`]).
//!
//! The last stage ([`source`]) gives a workgroup of `LANES` threads each item; lane `l` takes
//! the product-action columns `p = l + LANES (JC ch + j)`, `JC` at a time as the components
//! of one vector (so neighbouring lanes read neighbouring values), in `NCH` chunks.
//!
//! Each lane keeps, per component, the largest of its actions' sums by a strict `>` in
//! increasing index order (the lowest index among equals), then folds its components and
//! chunks with `beats`. The cores of the item then reduce over the lanes a chunk of cores at
//! a time by halving: at each step a lane keeps half of the chunk's cores and sends the other
//! half to its partner (`lane ^ m`), so a chunk of 16 cores costs 16 exchanges over 32 lanes
//! where a reduction per core would cost 80. Exchanges are subgroup shuffles where the
//! workgroup is one subgroup, else go through workgroup memory.
//!
//! Each core's rows are a function of their own (`core{c}`, called once from the entry
//! point), whatever the kernel: Naga's WGSL front end types a function's expressions in time
//! that grows with the square of their count, and the paper grid's last stage written as one
//! function (23,114 expressions) took 0.17 s of a Zen 4 core to parse, 0.03 s so. Drivers
//! inline the calls: lavapipe's full backups take the same time either way.
//!
//! The same sums in the same order as `last1.wgsl` (and the CPU), and the maximum at the
//! lowest index: the same bits. One case differs from `beats`: a lane whose every candidate
//! is `-inf` or NaN keeps no index there, where `beats` takes the first `-inf`; its sums
//! come from a finite `V` and finite weights, so that needs a `V` that is not finite.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use fuzzyq_core::solver::PlanTable;

/// Most columns a lane takes at once (the components of a vector).
const MAX_JC: u32 = 4;

/// Most cores reduced over the lanes at once (two registers each per lane; at most the
/// lanes, so that the halving leaves each lane one core).
const CHUNK: usize = 16;

/// Most terms the kernel may hold (row entries times the vector chunks), so that its text
/// stays within what a driver compiles quickly (the paper's grid: 824 entries).
pub(crate) const MAX_TERMS: usize = 16_384;

/// Most cores of a block compiled in: each is a branch of the kernel, and a compiler's time
/// grows faster than their count (Khepera's coarse start, 1,089 cores in under 16,384 terms:
/// minutes on lavapipe and on NVIDIA's driver, against 0.04 s for the kernels reading tables).
pub(crate) const MAX_CORES: usize = 128;

/// Whether `table`'s rows, `chunks` times over, are small enough to compile in.
fn compiles_in(table: &PlanTable<'_, f32>, chunks: usize) -> bool {
    table.n_cores <= MAX_CORES && table.col.len() * chunks <= MAX_TERMS
}

/// The kernel's layout for a last block of `pl` product actions before it over `lanes`
/// lanes: `(JC, NCH)`.
fn lane_columns(pl: u32, lanes: u32) -> (u32, u32) {
    let jc = pl.div_ceil(lanes).clamp(1, MAX_JC);
    (jc, pl.div_ceil(lanes * jc))
}

/// Most entries of a row of the stage before the last that the joined kernel (`lastj`) takes.
const MAX_BEFORE_ENTRIES: u32 = 16;

/// The stage before the last, where the kernel computes it itself (`lastj`,
/// [`LastStage::Joined`](crate::LastStage::Joined)): its block's cores, actions and product
/// actions before it, and the most entries of its rows. Its rows are read from the tables
/// (block `LAST - 1`), as its block core is the workgroup's; each lane's values of an item
/// are computed where a core of the last block first reads them, from the stage before it
/// (`src`), instead of being read from a buffer that stage wrote.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Before {
    pub n: u32,
    pub a: u32,
    pub p: u32,
    pub max_entries: u32,
}

impl Before {
    /// The stage before the last of `table`'s block (`None` where a row holds more than
    /// [`MAX_BEFORE_ENTRIES`] entries).
    pub(crate) fn of(table: &PlanTable<'_, f32>) -> Option<Self> {
        let max_entries = most_entries(table);
        (max_entries <= MAX_BEFORE_ENTRIES).then(|| Before {
            n: table.n_cores as u32,
            a: table.n_actions as u32,
            p: table.p_len as u32,
            max_entries: max_entries.max(1),
        })
    }
}

/// The most entries a row of `table` holds (0 for a table without rows).
pub(crate) fn most_entries(table: &PlanTable<'_, f32>) -> u32 {
    table.ptr.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0)
}

/// The kernel's text (after `block.wgsl`'s declarations and the constants `LAST`, `NL`,
/// `AL`, `PL`), for the last block's `table`, `pl` product actions before it, a workgroup of
/// `lanes` threads exchanging by subgroup shuffles (`subgroups`) or through workgroup memory,
/// reading the stage before's output (`lastu`) or computing it (`before`, `lastj`); `None`
/// where the table holds more terms than [`MAX_TERMS`] or more cores than [`MAX_CORES`].
pub(crate) fn source(
    table: &PlanTable<'_, f32>,
    pl: u32,
    lanes: u32,
    subgroups: bool,
    before: Option<Before>,
) -> Option<String> {
    let (jc, nch) = lane_columns(pl, lanes);
    if !compiles_in(table, nch as usize) {
        return None;
    }
    let g = Gen {
        t: table,
        pl,
        lanes,
        jc,
        nch,
        padded: lanes * jc * nch > pl,
        subgroups,
        before,
    };
    Some(g.kernel())
}

struct Gen<'a, 'o> {
    t: &'a PlanTable<'o, f32>,
    pl: u32,
    lanes: u32,
    jc: u32,
    nch: u32,
    /// Whether some lane's columns run past `PL` (then masked).
    padded: bool,
    subgroups: bool,
    before: Option<Before>,
}

/// The joined kernel's rows of the stage before the last: `row1` reads the row of product
/// column `q` (its action `q / P1` of block core `c1`; the entries' weights and where each
/// reads the stage before it, less the last block's core), `xs` sums it at the last block's
/// core `k`, in the row's order from 0, as `stagec.wgsl` does.
const BEFORE_FNS: &str = "
struct Row1 {
    w: array<f32, ME>,
    o: array<u32, ME>,
    n: u32,
}

fn row1(q: u32, c1: u32, base1: u32) -> Row1 {
    let row = prm.rows[LAST - 1u].x + c1 * A1 + q / P1;
    let e0 = row_ptr[row];
    var r: Row1;
    r.n = row_ptr[row + 1u] - e0;
    for (var e = 0u; e < ME; e++) {
        let i = e0 + min(e, max(r.n, 1u) - 1u);
        r.w[e] = weight[i];
        r.o[e] = (base1 + col[i]) * NL * P1 + q % P1;
    }
    return r;
}

fn xs(r: Row1, k: u32) -> f32 {
    var t = bitcast<f32>(prm.zero);
    for (var e = 0u; e < ME; e++) {
        if e < r.n {
            t = fma(r.w[e], src[r.o[e] + k * P1], t);
        }
    }
    return t;
}
";

/// A WGSL `f32` constant with exactly `w`'s bits.
fn weight_text(w: f32) -> String {
    format!("bitcast<f32>({:#010x}u)", w.to_bits())
}

impl Gen<'_, '_> {
    /// The vector types of a lane's columns: values, indices, flags.
    fn vf(&self) -> String {
        self.vec("f32")
    }

    fn vu(&self) -> String {
        self.vec("u32")
    }

    fn vec(&self, t: &str) -> String {
        match self.jc {
            1 => t.to_owned(),
            n => format!("vec{n}<{t}>"),
        }
    }

    /// Component `j` of a lane's vector `v`.
    fn comp(&self, v: &str, j: u32) -> String {
        match self.jc {
            1 => v.to_owned(),
            _ => format!("{v}[{j}]"),
        }
    }

    fn kernel(&self) -> String {
        let mut s = String::new();
        let lanes = self.lanes;
        let _ = writeln!(s, "const LANES: u32 = {lanes}u;");
        let _ = writeln!(s, "const NONE: u32 = 0xffffffffu;");
        // A core's largest value so far and its index ([`Gen::core_fn`]).
        s.push_str("struct Held {\n    v: f32,\n    n: u32,\n}\n");
        let mut fns = String::new();
        if !self.subgroups {
            s.push_str(
                "var<workgroup> xf: array<f32, LANES>;\n\
                 var<workgroup> xu: array<u32, LANES>;\n\
                 fn shuf_f(x: f32, m: u32, lane: u32) -> f32 {\n\
                 \x20   workgroupBarrier();\n    xf[lane] = x;\n    workgroupBarrier();\n\
                 \x20   return xf[lane ^ m];\n}\n\
                 fn shuf_u(x: u32, m: u32, lane: u32) -> u32 {\n\
                 \x20   workgroupBarrier();\n    xu[lane] = x;\n    workgroupBarrier();\n\
                 \x20   return xu[lane ^ m];\n}\n",
            );
        }
        if let Some(b) = self.before {
            let _ = writeln!(
                s,
                "const N1: u32 = {}u;\nconst A1: u32 = {}u;\nconst P1: u32 = {}u;\n\
                 const ME: u32 = {}u;",
                b.n, b.a, b.p, b.max_entries
            );
            s.push_str(BEFORE_FNS);
        }
        let lane_param = if self.subgroups {
            ", @builtin(subgroup_invocation_id) sid: u32"
        } else {
            ""
        };
        let entry = self.entry();
        let _ = writeln!(
            s,
            "@compute @workgroup_size(LANES)\n\
             fn {entry}(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,\n\
             \x20        @builtin(local_invocation_index) li: u32{lane_param}) {{"
        );
        let lane = if self.subgroups { "sid" } else { "li" };
        let (vf, vu) = (self.vf(), self.vu());
        let _ = writeln!(
            s,
            "    let lane = {lane};\n\
             \x20   let item = prm.lo / NL + wid.y * nwg.x + wid.x;\n\
             \x20   let c_lo = max(prm.lo, item * NL);\n\
             \x20   let c_hi = min(prm.lo + prm.count, item * NL + NL);\n\
             \x20   let z = {vf}(bitcast<f32>(prm.zero));\n\
             \x20   let ab = prm.mode == 3u;\n\
             \x20   let ninf = bitcast<f32>(0xff800000u ^ prm.zero);"
        );
        let offsets: Vec<String> = (0..self.jc).map(|j| format!("{}u", lanes * j)).collect();
        let _ = writeln!(s, "    let steps = {vu}({});", offsets.join(", "));
        if self.before.is_some() {
            s.push_str("    let c1 = item % N1;\n    let base1 = item - c1;\n");
        }
        // One chunk of columns: set up once, and the values of the stage before computed
        // once for every core.
        let mut defined = BTreeSet::new();
        if self.nch == 1 {
            s.push_str("    let ch = 0u;\n");
            self.columns_setup(&mut s, "    ");
        }
        // At most one core per lane at the end of the halving.
        let chunk = CHUNK.min(self.lanes as usize);
        let n = self.t.n_cores;
        for first in (0..n).step_by(chunk) {
            let end = (first + chunk).min(n);
            if self.nch == 1 {
                for c in first..end {
                    self.define(&mut s, c, &mut defined, "    ");
                }
            }
            self.chunk(&mut s, &mut fns, first..end);
        }
        s.push_str("}\n");
        fns + &s
    }

    /// The kernel's entry point.
    fn entry(&self) -> &'static str {
        if self.before.is_some() {
            "lastj"
        } else {
            "lastu"
        }
    }

    /// The columns `pj` of chunk `ch` of the lane, where they are read (`q`), which are past
    /// the end (`ok`), and for the joined kernel, each column's row of the stage before.
    fn columns_setup(&self, s: &mut String, ind: &str) {
        let vu = self.vu();
        let _ = writeln!(
            s,
            "{ind}let pj = lane + LANES * {jc}u * ch + steps;",
            jc = self.jc
        );
        if self.before.is_none() {
            let _ = writeln!(s, "{ind}let q = item * NL * PL + min(pj, {vu}(PL - 1u));");
        }
        if self.padded {
            let _ = writeln!(s, "{ind}let ok = pj < {vu}(PL);");
        }
        if self.before.is_some() {
            for j in 0..self.jc {
                let p = self.comp("pj", j);
                let _ = writeln!(s, "{ind}let r{j} = row1(min({p}, PL - 1u), c1, base1);");
            }
        }
    }

    /// For the joined kernel, the lane's values `x{k}` that core `c`'s rows read and that are
    /// not yet `defined`, computed from the stage before's rows.
    fn define(&self, s: &mut String, c: usize, defined: &mut BTreeSet<u32>, ind: &str) {
        if self.before.is_none() {
            return;
        }
        let vf = self.vf();
        for k in read_columns(self.t, c) {
            if defined.insert(k) {
                let parts: Vec<String> = (0..self.jc).map(|j| format!("xs(r{j}, {k}u)")).collect();
                let _ = writeln!(s, "{ind}let x{k} = {vf}({});", parts.join(", "));
            }
        }
    }

    /// Cores `cores` of the item: their largest values over the lane's columns, reduced over
    /// the lanes, written.
    fn chunk(&self, s: &mut String, fns: &mut String, cores: core::ops::Range<usize>) {
        s.push_str("    {\n");
        for c in cores.clone() {
            let _ = writeln!(s, "        var v{c} = ninf;\n        var n{c} = NONE;");
        }
        // Several chunks of columns: each set up, and the values of the stage before computed,
        // per chunk of cores.
        let chunked = self.nch > 1;
        let mut defined = BTreeSet::new();
        if chunked {
            let _ = writeln!(s, "        for (var ch = 0u; ch < {}u; ch++) {{", self.nch);
            self.columns_setup(s, "            ");
        }
        for c in cores.clone() {
            if chunked {
                self.define(s, c, &mut defined, "            ");
            }
            self.core(s, fns, c);
        }
        if chunked {
            s.push_str("        }\n");
        }
        self.reduce(s, cores);
        s.push_str("    }\n");
    }

    /// Core `c`'s rows over the lane's columns `pj` (of this chunk), folded into `v{c}`,
    /// `n{c}`: a function of its own in `fns` ([`Gen::core_fn`]), called here.
    fn core(&self, s: &mut String, fns: &mut String, c: usize) {
        let columns = read_columns(self.t, c);
        // The joined kernel has the values its rows read; the other reads them itself.
        let mut args: Vec<String> = match self.before {
            Some(_) => columns.iter().map(|k| format!("x{k}")).collect(),
            None => vec!["q".into()],
        };
        args.extend(["pj", "z", "ab", "ninf"].map(String::from));
        if self.padded {
            args.push("ok".into());
        }
        let _ = writeln!(
            s,
            "            let h{c} = core{c}({}, Held(v{c}, n{c}));\n\
             \x20           v{c} = h{c}.v;\n            n{c} = h{c}.n;",
            args.join(", ")
        );
        self.core_fn(fns, c, &columns);
    }

    /// Core `c`'s function `core{c}` in `fns`: the values of the columns its rows read
    /// (`x{k}`, `columns`: loaded once from the stage before's output at the lane's `q`, or
    /// given by the joined kernel), each action's row a chain of `fma`s with constant
    /// weights, the largest sum per component by a strict `>` in action order, folded into
    /// the core's largest so far (`Held`) with `beats`. A function per core keeps each of the
    /// kernel's functions small: Naga's WGSL front end types a function's expressions in time
    /// that grows with the square of their count (`Typifier::grow` walks past every
    /// expression typed before at each call: the paper grid's last stage in one function,
    /// 23,114 expressions, took 0.17 s of a Zen 4 core to parse, against 0.02 s so).
    fn core_fn(&self, fns: &mut String, c: usize, columns: &[u32]) {
        let (vf, vu) = (self.vf(), self.vu());
        let mut params: Vec<String> = match self.before {
            Some(_) => columns.iter().map(|k| format!("x{k}: {vf}")).collect(),
            None => vec![format!("q: {vu}")],
        };
        params.extend([
            format!("pj: {vu}"),
            format!("z: {vf}"),
            "ab: bool".into(),
            "ninf: f32".into(),
        ]);
        if self.padded {
            params.push(format!("ok: {}", self.vec("bool")));
        }
        let _ = writeln!(
            fns,
            "fn core{c}({}, held: Held) -> Held {{",
            params.join(", ")
        );
        if self.before.is_none() {
            for &k in columns {
                let parts: Vec<String> = (0..self.jc)
                    .map(|j| format!("src[{} + {}u]", self.comp("q", j), k * self.pl))
                    .collect();
                let _ = writeln!(fns, "    let x{k} = {vf}({});", parts.join(", "));
            }
        }
        let _ = writeln!(fns, "    var bv = {vf}(ninf);\n    var bk = {vu}(NONE);");
        let t = self.t;
        for (a, e) in rows(t, c).enumerate() {
            fns.push_str("    {\n        var s = z;\n");
            for i in e {
                let _ = writeln!(
                    fns,
                    "        s = fma({vf}({}), x{}, s);",
                    weight_text(t.weight[i]),
                    t.col[i]
                );
            }
            fns.push_str("        var y = select(s, abs(s), ab);\n");
            if self.padded {
                let _ = writeln!(fns, "        y = select({vf}(ninf), y, ok);");
            }
            let _ = writeln!(
                fns,
                "        let t = y > bv;\n        bv = select(bv, y, t);\n\
                 \x20       bk = select(bk, {vu}({a}u), t);\n    }}"
            );
        }
        // The components (and chunks) in turn: any order gives the lowest index.
        fns.push_str("    var h = held;\n");
        for j in 0..self.jc {
            let (v, k, p) = (self.comp("bv", j), self.comp("bk", j), self.comp("pj", j));
            let _ = writeln!(
                fns,
                "    {{\n\
                 \x20       let i = select(NONE, {k} * PL + {p}, {k} != NONE);\n\
                 \x20       if beats({v}, i, h.v, h.n) {{\n\
                 \x20           h = Held({v}, i);\n        }}\n    }}"
            );
        }
        fns.push_str("    return h;\n}\n");
    }

    /// The chunk's cores reduced over the lanes by halving ([`halving`]), then written by the
    /// lane that holds each.
    fn reduce(&self, s: &mut String, cores: core::ops::Range<usize>) {
        let c0 = cores.start;
        let n = cores.len();
        let (sf, su) = if self.subgroups {
            ("subgroupShuffleXor", "subgroupShuffleXor")
        } else {
            ("shuf_f", "shuf_u")
        };
        let extra = if self.subgroups { "" } else { ", lane" };
        let mut held: Vec<(String, String)> = cores
            .clone()
            .map(|c| (format!("v{c}"), format!("n{c}")))
            .collect();
        // `off`: the chunk's core at the lane's first held place; `live`: how many of its
        // held places are cores (the others padding, which must not be written: a padded
        // place's `off` can name a core that another lane holds).
        let _ = writeln!(s, "        var off = 0u;\n        var live = {n}u;");
        let mut copies = 0u32;
        for (step, &(m, half)) in halving(n, self.lanes).iter().enumerate() {
            let _ = writeln!(s, "        let u{step} = (lane & {m}u) != 0u;");
            let mut next = Vec::new();
            if let Some(h) = half {
                let _ = writeln!(
                    s,
                    "        off += select(0u, {h}u, u{step});\n\
                     \x20       live = select(min(live, {h}u), max(live, {h}u) - {h}u, u{step});"
                );
                for i in 0..h {
                    let (lv, li) = &held[i];
                    let (hv, hi) = held
                        .get(h + i)
                        .cloned()
                        .unwrap_or(("ninf".into(), "NONE".into()));
                    let (kv, ki) = (format!("k{step}_{i}v"), format!("k{step}_{i}i"));
                    let _ = writeln!(
                        s,
                        "        let {kv}0 = select({lv}, {hv}, u{step});\n\
                         \x20       let {ki}0 = select({li}, {hi}, u{step});\n\
                         \x20       let {kv}r = {sf}(select({hv}, {lv}, u{step}), {m}u{extra});\n\
                         \x20       let {ki}r = {su}(select({hi}, {li}, u{step}), {m}u{extra});\n\
                         \x20       let {kv}t = beats({kv}r, {ki}r, {kv}0, {ki}0);\n\
                         \x20       let {kv} = select({kv}0, {kv}r, {kv}t);\n\
                         \x20       let {ki} = select({ki}0, {ki}r, {kv}t);"
                    );
                    next.push((kv, ki));
                }
            } else {
                // One core left: the partners hold the same one (a butterfly).
                copies |= m;
                let (lv, li) = &held[0];
                let (kv, ki) = (format!("k{step}_0v"), format!("k{step}_0i"));
                let _ = writeln!(
                    s,
                    "        let {kv}r = {sf}({lv}, {m}u{extra});\n\
                     \x20       let {ki}r = {su}({li}, {m}u{extra});\n\
                     \x20       let {kv}t = beats({kv}r, {ki}r, {lv}, {li});\n\
                     \x20       let {kv} = select({lv}, {kv}r, {kv}t);\n\
                     \x20       let {ki} = select({li}, {ki}r, {kv}t);"
                );
                next.push((kv, ki));
            }
            held = next;
        }
        assert_eq!(held.len(), 1, "a chunk of at most one core per lane");
        let (v, i) = &held[0];
        let _ = writeln!(
            s,
            "        let g = item * NL + {c0}u + off;\n\
             \x20       if live > 0u && (lane & {copies}u) == 0u && g >= c_lo && g < c_hi {{\n\
             \x20           write_best(prm.out_lo + (g - prm.lo), {v}, {i});\n        }}"
        );
    }
}

/// The steps that reduce a chunk of `n` cores (at most `lanes`) over `lanes` lanes, one per
/// lane bit `m` from the highest: `(m, Some(h))` where a lane keeps `h` of its held places
/// (the first `h` where bit `m` is clear, the rest, padded to `h`, where it is set) and its
/// partner `lane ^ m` the others; `(m, None)` where one place is left, which partners share.
fn halving(n: usize, lanes: u32) -> Vec<(u32, Option<usize>)> {
    let mut steps = Vec::new();
    let (mut held, mut m) = (n, lanes / 2);
    while m > 0 {
        if held > 1 {
            let h = held.div_ceil(2);
            steps.push((m, Some(h)));
            held = h;
        } else {
            steps.push((m, None));
        }
        m /= 2;
    }
    steps
}

/// The text of a stage before the last with its block's rows compiled in (`stage_u`, after
/// `block.wgsl`'s declarations, the stage's constants `SN`, `SA`, `SR`, `SP`, and `put`):
/// a thread per element `(r, p)` of an item of the stage before, taking every core of the
/// block that the dispatch covers below that item, and for each, the values its rows read
/// (`at(k)`: the expression of column `k`'s value at the thread's `(r, p)`) loaded once and
/// each row a chain of `fma`s with constant weights, written as `stagec.wgsl` writes it.
/// `None` where the table holds more than [`MAX_TERMS`] entries or [`MAX_CORES`] cores.
pub(crate) fn stage_source(
    table: &PlanTable<'_, f32>,
    at: impl Fn(u32) -> String,
) -> Option<String> {
    if !compiles_in(table, 1) {
        return None;
    }
    let mut s = String::from(
        "@compute @workgroup_size(64)\n\
         fn stage_u(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,\n\
         \x20          @builtin(num_workgroups) nwg: vec3<u32>) {\n\
         \x20   let o = linear(gid, wid, nwg);\n\
         \x20   let items = prm.count / (SR * SA * SP);\n\
         \x20   let base = (prm.lo / SN + o / (SR * SP)) * SN;\n\
         \x20   let r = (o % (SR * SP)) / SP;\n\
         \x20   let p = o % SP;\n\
         \x20   let lo = max(prm.lo, base) - base;\n\
         \x20   let hi = min(prm.lo + items, base + SN);\n\
         \x20   if hi <= base {\n\
         \x20       return;\n\
         \x20   }\n\
         \x20   let z = bitcast<f32>(prm.zero);\n",
    );
    // A function per core, as in the last stage ([`Gen::core_fn`]: Naga's time).
    let mut fns = String::new();
    for c in 0..table.n_cores {
        let _ = writeln!(
            s,
            "    if {c}u >= lo && base + {c}u < hi {{\n        core{c}(base, r, p, z);\n    }}"
        );
        let _ = writeln!(fns, "fn core{c}(base: u32, r: u32, p: u32, z: f32) {{");
        for k in read_columns(table, c) {
            let _ = writeln!(fns, "    let x{k} = {};", at(k));
        }
        let _ = writeln!(
            fns,
            "    let out = ((base + {c}u - prm.lo) * SR + r) * (SA * SP) + p;"
        );
        for (a, e) in rows(table, c).enumerate() {
            fns.push_str("    {\n        var s = z;\n");
            for i in e {
                let _ = writeln!(
                    fns,
                    "        s = fma({}, x{}, s);",
                    weight_text(table.weight[i]),
                    table.col[i]
                );
            }
            let _ = writeln!(fns, "        put(out + {a}u * SP, s);\n    }}");
        }
        fns.push_str("}\n");
    }
    s.push_str("}\n");
    Some(fns + &s)
}

/// The entries of block core `c`'s rows in `table`, one range per action.
fn rows<'t>(
    table: &'t PlanTable<'_, f32>,
    c: usize,
) -> impl Iterator<Item = core::ops::Range<usize>> + 't {
    let na = table.n_actions;
    (c * na..(c + 1) * na).map(|r| table.ptr[r] as usize..table.ptr[r + 1] as usize)
}

/// The columns block core `c`'s rows in `table` read, in order, each once.
fn read_columns(table: &PlanTable<'_, f32>, c: usize) -> Vec<u32> {
    let mut cols: Vec<u32> = rows(table, c).flat_map(|e| table.col[e].to_vec()).collect();
    cols.sort_unstable();
    cols.dedup();
    cols
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_columns_cover_the_product_actions() {
        assert_eq!(lane_columns(125, 32), (4, 1));
        assert_eq!(lane_columns(243, 32), (4, 2));
        assert_eq!(lane_columns(5, 32), (1, 1));
        assert_eq!(lane_columns(3125, 32), (4, 25));
        for (pl, lanes) in [(125, 32), (243, 32), (5, 8), (3125, 64), (64, 16)] {
            let (jc, nch) = lane_columns(pl, lanes);
            assert!(lanes * jc * nch >= pl);
            assert!(
                lanes * jc * (nch - 1) < pl,
                "no chunk wholly past the columns"
            );
        }
    }

    /// A table of `n` cores and 2 actions, each row two entries (its core and the next).
    fn table(n: usize) -> (Vec<u32>, Vec<u32>, Vec<f32>) {
        let ptr = (0..=2 * n as u32).map(|r| 2 * r).collect();
        let col = (0..2 * n)
            .flat_map(|r| [(r / 2) as u32, ((r / 2 + 1) % n) as u32])
            .collect();
        let weight = (0..4 * n).map(|i| i as f32 / 8.0).collect();
        (ptr, col, weight)
    }

    /// The block table of `t` ([`table`]) with `p_len` product actions before it.
    fn plan(t: &(Vec<u32>, Vec<u32>, Vec<f32>), p_len: usize) -> PlanTable<'_, f32> {
        PlanTable {
            n_cores: (t.0.len() - 1) / 2,
            n_actions: 2,
            r_len: 1,
            p_len,
            ptr: &t.0,
            col: &t.1,
            weight: &t.2,
        }
    }

    #[test]
    fn a_chunk_of_cores_reduces_in_as_many_exchanges() {
        // 16 cores over 32 lanes: 8 + 4 + 2 + 1 exchanges halving them, then 1 between lanes
        // holding the same core; each exchange shuffles a value and an index.
        let tab = table(16);
        let t = plan(&tab, 125);
        let text = source(&t, 125, 32, true, None).unwrap();
        assert_eq!(text.matches("subgroupShuffleXor(").count(), 2 * 16);
        assert!(text.contains("fn lastu("));
        // Every row's weights, in order, with their bits.
        for w in &tab.2 {
            assert!(text.contains(&weight_text(*w)), "{w}");
        }
        // Through workgroup memory, the same exchanges.
        let text = source(&t, 125, 32, false, None).unwrap();
        assert_eq!(text.matches("= shuf_f(").count(), 16);
        assert_eq!(text.matches("= shuf_u(").count(), 16);
        // The stage before joined in: its rows read where a core first needs a value.
        let before = Before {
            n: 3,
            a: 5,
            p: 25,
            max_entries: 4,
        };
        let text = source(&t, 125, 32, true, Some(before)).unwrap();
        assert!(text.contains("fn lastj("));
        assert_eq!(
            text.matches("let x").count(),
            16,
            "each value computed once"
        );
    }

    #[test]
    fn the_generated_kernels_are_valid_wgsl() {
        // Every variant through naga's parser and validator, as wgpu runs them: one chunk of
        // columns and several, lanes of 8 and 32 exchanging by shuffles or in memory, the
        // stage before joined in or not; and a stage before the last.
        let tab = table(16);
        let t = |p_len| plan(&tab, p_len);
        let before = Before {
            n: 3,
            a: 5,
            p: 25,
            max_entries: 4,
        };
        for (pl, lanes, subgroups, joined) in [
            (125u32, 32, true, false),
            (125, 32, false, false),
            (125, 8, true, true),
            (243, 32, true, true),
            (243, 32, false, true),
            (5, 32, false, false),
        ] {
            let text = source(
                &t(pl as usize),
                pl,
                lanes,
                subgroups,
                joined.then_some(before),
            )
            .unwrap();
            let consts = [("LAST", 3), ("NL", 16), ("AL", 2), ("PL", pl)];
            let text = crate::kernels::source_text(&text, &consts, &[], None);
            let _ = crate::kernels::check_wgsl(&text)
                .unwrap_or_else(|e| panic!("{pl} {lanes} {subgroups} {joined}: {e}"));
        }
        let stage = stage_source(&t(25), |k| {
            format!("src[((base + {k}u) * SR + r) * SP + p]")
        })
        .unwrap();
        let consts = [("SB", 1), ("SN", 16), ("SA", 2), ("SR", 45), ("SP", 25)];
        let put = "fn put(o: u32, x: f32) {\n    dst[o] = x;\n}\n";
        let text = crate::kernels::source_text(&(put.to_owned() + &stage), &consts, &[], None);
        let _ = crate::kernels::check_wgsl(&text).unwrap();
    }

    #[test]
    fn each_core_is_a_function_of_its_own() {
        // Naga types a function's expressions in time that grows with the square of their
        // count: the paper grid's last stage (45 cores x 5 actions, 125 product actions) as
        // one function held 23,114 expressions and took 0.17 s to parse, 0.03 s a function
        // per core. A table of that size (rows of 4 entries) keeps every function small, in
        // the last stage (read or joined) and in a stage before it.
        let (n, na, ne) = (45usize, 5usize, 4usize);
        let ptr: Vec<u32> = (0..=n * na).map(|r| (r * ne) as u32).collect();
        let col: Vec<u32> = (0..n * na)
            .flat_map(|r| (0..ne).map(move |e| ((r / na + e) % n) as u32))
            .collect();
        let weight: Vec<f32> = (0..n * na * ne).map(|i| i as f32 / 1024.0).collect();
        let t = |p_len| PlanTable {
            n_cores: n,
            n_actions: na,
            r_len: 1,
            p_len,
            ptr: &ptr,
            col: &col,
            weight: &weight,
        };
        let before = Before {
            n: 3,
            a: 5,
            p: 25,
            max_entries: 4,
        };
        let most = 4_096;
        for joined in [None, Some(before)] {
            let text = source(&t(125), 125, 32, true, joined).unwrap();
            let consts = [
                ("LAST", 3),
                ("NL", n as u32),
                ("AL", na as u32),
                ("PL", 125),
            ];
            let text = crate::kernels::source_text(&text, &consts, &[], None);
            let largest = crate::kernels::check_wgsl(&text).unwrap();
            assert!(
                largest <= most,
                "{joined:?}: {largest} expressions in one function"
            );
        }
        let stage = stage_source(&t(25), |k| {
            format!("src[((base + {k}u) * SR + r) * SP + p]")
        })
        .unwrap();
        let consts = [
            ("SB", 1),
            ("SN", n as u32),
            ("SA", na as u32),
            ("SR", 45),
            ("SP", 25),
        ];
        let put = "fn put(o: u32, x: f32) {\n    dst[o] = x;\n}\n";
        let text = crate::kernels::source_text(&(put.to_owned() + &stage), &consts, &[], None);
        let largest = crate::kernels::check_wgsl(&text).unwrap();
        assert!(
            largest <= most,
            "stage_u: {largest} expressions in one function"
        );
    }

    #[test]
    fn fewer_lanes_than_a_chunk_take_chunks_of_their_count() {
        // Subgroups of 8 (lavapipe's): 16 cores in two chunks of 8, each 4 + 2 + 1
        // exchanges; a chunk of 16 would leave each lane two cores, one never written.
        let tab = table(16);
        let t = plan(&tab, 125);
        let text = source(&t, 125, 8, true, None).unwrap();
        assert_eq!(text.matches("subgroupShuffleXor(").count(), 2 * 2 * 7);
        assert_eq!(text.matches("write_best(").count(), 2);
    }

    /// Each lane's places through [`halving`] as the kernel moves them (`Some(core)` or
    /// padding), then which lanes write which core, as the kernel decides from `off` and
    /// `live`.
    fn writers(n: usize, lanes: u32) -> Vec<Vec<u32>> {
        let steps = halving(n, lanes);
        let mut held: Vec<Vec<Option<usize>>> = vec![(0..n).map(Some).collect(); lanes as usize];
        let (mut off, mut live) = (vec![0; lanes as usize], vec![n; lanes as usize]);
        let mut copies = 0;
        for &(m, half) in &steps {
            let before = held.clone();
            for l in 0..lanes as usize {
                let u = l as u32 & m != 0;
                let partner = &before[l ^ m as usize];
                let Some(h) = half else {
                    copies |= m;
                    assert_eq!(before[l][0], partner[0], "a butterfly shares its core");
                    continue;
                };
                let at = |v: &Vec<Option<usize>>, i: usize| v.get(i).copied().flatten();
                let kept: Vec<Option<usize>> = (0..h)
                    .map(|i| {
                        let (own, theirs) = if u {
                            (at(&before[l], h + i), at(partner, h + i))
                        } else {
                            (at(&before[l], i), at(partner, i))
                        };
                        assert_eq!(own, theirs, "partners merge the same core");
                        own
                    })
                    .collect();
                held[l] = kept;
                if u {
                    off[l] += h;
                    live[l] = live[l].max(h) - h;
                } else {
                    live[l] = live[l].min(h);
                }
            }
        }
        let mut by_core = vec![Vec::new(); n];
        for l in 0..lanes as usize {
            assert_eq!(held[l].len(), 1);
            assert_eq!(
                live[l] > 0,
                held[l][0].is_some(),
                "lane {l}: live counts its core"
            );
            if live[l] > 0 && l as u32 & copies == 0 {
                assert_eq!(
                    held[l][0],
                    Some(off[l]),
                    "lane {l} holds the core it writes"
                );
                by_core[off[l]].push(l as u32);
            }
        }
        by_core
    }

    /// Regression: a chunk of cores not a power of two (9 of a block of 9 over 32 lanes,
    /// 13 of the paper's 45) left lanes holding only padding whose `off` named another
    /// lane's core; they wrote `-inf` over it, which NVIDIA's warps (not lavapipe's lanes of
    /// 8, taking chunks of 8) let win.
    #[test]
    fn every_core_of_a_chunk_is_written_by_one_lane() {
        for lanes in [8u32, 16, 32, 64] {
            for n in 1..=CHUNK.min(lanes as usize) {
                for (core, w) in writers(n, lanes).iter().enumerate() {
                    assert_eq!(
                        w.len(),
                        1,
                        "{n} cores over {lanes} lanes: core {core} by {w:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_table_too_large_is_not_compiled_in() {
        let n = MAX_TERMS / 4 + 1;
        let tab = table(n);
        let t = plan(&tab, 5);
        assert!(source(&t, 5, 32, true, None).is_none());
        assert!(stage_source(&t, |k| format!("v{k}")).is_none());
        // Regression: too many cores, within the terms (Khepera's coarse start: 1,089 cores,
        // minutes to compile).
        let tab = table(MAX_CORES + 1);
        let t = plan(&tab, 5);
        assert!(4 * t.n_cores <= MAX_TERMS);
        assert!(source(&t, 5, 32, true, None).is_none());
        assert!(stage_source(&t, |k| format!("v{k}")).is_none());
        let tab = table(MAX_CORES);
        assert!(stage_source(&plan(&tab, 5), |k| format!("v{k}")).is_some());
    }

    #[test]
    fn a_weight_keeps_its_bits() {
        assert_eq!(weight_text(1.0), "bitcast<f32>(0x3f800000u)");
        assert_eq!(weight_text(f32::from_bits(1)), "bitcast<f32>(0x00000001u)");
    }
}
