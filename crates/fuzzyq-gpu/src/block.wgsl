// The block backup's passes (see `fuzzyq_core::solver::BlockPlan` for the contraction and
// `sweeps.rs` for how a pass is dispatched). Every sum runs over a row's entries in order with
// `fma` from 0, as the CPU kernels do; `r + gamma m` is rounded as two operations (`unfused`).
// Each dispatch reads its own `Params` (a dynamic offset into one uniform buffer).

const WG: u32 = 64u;
const MAX_BLOCKS: u32 = 8u;

struct Params {
    // The stage (the block of `stagec.wgsl`, `stagem.wgsl`, `last1.wgsl`, `lastm.wgsl`).
    b: u32,
    // Threads (or items) of this dispatch.
    count: u32,
    // A stage's first item (a prefix of block cores, `batches.rs`; for the last stage a
    // core), counted from the first child of the first item of the stage before it that `src`
    // holds; and where the dispatch's first core is in its part of `V` (`parts.rs`).
    lo: u32,
    out_lo: u32,
    // The reduction: 0: maximum of the expected values; 1: and the argument; 2: the argument
    // only; 3: maximum of the absolute values (written per core, for `max_pass`).
    mode: u32,
    // Joint actions, and whether `map` renumbers them to product actions.
    n_joint: u32,
    has_map: u32,
    // 0: rewards per core; 1: rewards per (core, joint action).
    reward_table: u32,
    has_goal: u32,
    // A runtime zero: `unfused` XORs products with it, so that no compiler fuses them.
    zero: u32,
    gamma: f32,
    shift: f32,
    // Where the part's goal bits start (words), and blocks.
    goal_lo: u32,
    n_blocks: u32,
    // Elements of the buffers a generic pass covers (a part's cores).
    len: u32,
    // The part's first slab (policy evaluation, `kernels::evaluation_source`).
    part_c0: u32,
    // Per block (contraction order): (cores, actions, R, P).
    blocks: array<vec4<u32>, MAX_BLOCKS>,
    // Per block: (first row start in `ptr`, 0, 0, 0).
    rows: array<vec4<u32>, MAX_BLOCKS>,
}

@group(0) @binding(0) var<uniform> prm: Params;
@group(0) @binding(1) var<storage, read> row_ptr: array<u32>;
@group(0) @binding(2) var<storage, read> col: array<u32>;
@group(0) @binding(3) var<storage, read> weight: array<f32>;
@group(0) @binding(4) var<storage, read> src: array<f32>;
@group(0) @binding(5) var<storage, read_write> dst: array<f32>;
@group(0) @binding(6) var<storage, read_write> aux: array<u32>;
@group(0) @binding(7) var<storage, read> rewards: array<f32>;
// Goal cores, one bit each: core `c` is bit `c % 32` of word `c / 32`.
@group(0) @binding(8) var<storage, read> goal: array<u32>;
@group(0) @binding(9) var<storage, read> joint_map: array<u32>;
@group(0) @binding(10) var<storage, read> src2: array<f32>;

var<workgroup> best_v: array<f32, WG>;
var<workgroup> best_i: array<u32, WG>;

// The dispatch's linear thread index (workgroups laid out in x, then y).
fn linear(gid: vec3<u32>, wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return wid.y * nwg.x * WG + gid.x;
}

// `a * b` rounded to f32 on its own: the XOR with a value the compiler cannot know keeps any
// later addition from fusing with the product.
fn unfused(a: f32, b: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(a * b) ^ prm.zero);
}

fn blk(b: u32) -> vec4<u32> {
    return prm.blocks[b];
}

// Item `q` of a dispatch at a stage of `n` block cores: its block core, and where its parent's
// output starts in `src` in items of this stage's input (`(c, base)`). The first stage's
// parent is the root, whose output is `V`.
fn core_of(q: u32, n: u32) -> vec2<u32> {
    let g = prm.lo + q;
    return vec2<u32>(g % n, (g / n) * n);
}

// Whether core `core` of the dispatch's part is a goal core (of a run with goal cores: an
// absorbing goal).
fn goal_at(core: u32) -> bool {
    if prm.has_goal == 0u {
        return false;
    }
    return ((goal[prm.goal_lo + (core >> 5u)] >> (core & 31u)) & 1u) != 0u;
}

// `V` of core `core` from the maximum `m` of its expected values (state-only reward).
fn finish(core: u32, m: f32) -> f32 {
    let r = rewards[core];
    if goal_at(core) {
        return r;
    }
    return r + unfused(prm.gamma, m);
}

// Offers expected value `x` of product action `i` (its absolute value in mode 3) to a lane's
// largest (`bv` at `bi`; the fused last stage): taken where it beats it, so the lowest index
// among equals wins whatever the order of the offers.
fn offer(x: f32, i: u32, bv: ptr<function, f32>, bi: ptr<function, u32>) {
    var y = x;
    if prm.mode == 3u {
        y = abs(x);
    }
    if beats(y, i, *bv, *bi) {
        *bv = y;
        *bi = i;
    }
}

// Writes core `core`'s largest value `bv`, at product action `bi`, as `prm.mode` says (the
// fused last stage: `last1.wgsl`, `lastm.wgsl`).
fn write_best(core: u32, bv: f32, bi: u32) {
    let is_goal = goal_at(core);
    switch prm.mode {
        case 0u: {
            dst[core] = finish(core, bv);
        }
        case 1u: {
            dst[core] = finish(core, bv);
            aux[core] = select(bi, 0u, is_goal);
        }
        case 2u: {
            aux[core] = select(bi, 0u, is_goal);
        }
        default: {
            dst[core] = select(bv, 0.0, is_goal);
        }
    }
}

// Whether (v, i) beats (bv, bi): larger, or equal at a lower index.
fn beats(v: f32, i: u32, bv: f32, bi: u32) -> bool {
    return v > bv || (v == bv && i < bi);
}

// Expected value of joint action `u` in a core's row of product actions.
fn at(row: u32, u: u32) -> f32 {
    if prm.has_map != 0u {
        return src[row + joint_map[u]];
    }
    return src[row + u];
}

// The reduction of full rows (`src`: one row of product actions per core of the batch, the
// last stage's output), one thread per core, over the joint actions in order, as the CPU's
// `Operator::reduce`; modes as `last1.wgsl`.
@compute @workgroup_size(64)
fn reduce_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let local = linear(gid, wid, nwg);
    if local >= prm.count {
        return;
    }
    let core = prm.out_lo + local;
    let width = prm.len;
    let row = local * width;
    let m = prm.n_joint;
    let is_goal = goal_at(core);
    if prm.mode == 3u {
        var best = 0.0;
        if !is_goal {
            for (var u = 0u; u < m; u++) {
                let x = abs(at(row, u));
                if !(best >= x) {
                    best = x;
                }
            }
        }
        dst[core] = best;
        return;
    }
    var best = 0.0;
    var arg = 0u;
    if prm.reward_table == 0u {
        let r = rewards[core];
        if is_goal {
            best = r;
        } else {
            var e = at(row, 0u);
            for (var u = 1u; u < m; u++) {
                let x = at(row, u);
                if x > e {
                    e = x;
                    arg = u;
                }
            }
            best = r + unfused(prm.gamma, e);
        }
    } else {
        for (var u = 0u; u < m; u++) {
            let r = rewards[core * m + u];
            var theta = r;
            if !is_goal {
                theta = r + unfused(prm.gamma, at(row, u));
            }
            if u == 0u || theta > best {
                best = theta;
                arg = u;
            }
        }
    }
    if prm.mode != 2u {
        dst[core] = best;
    }
    if prm.mode != 0u {
        aux[core] = arg;
    }
}

// `dst = rho + gamma 0` per core: the backup of `V = 0` (state-only rewards).
@compute @workgroup_size(64)
fn rewards_pass(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
                @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, wid, nwg);
    if i < prm.len {
        dst[i] = finish(i, 0.0);
    }
}

// `dst += shift` (the extrapolation's shift).
@compute @workgroup_size(64)
fn shift_pass(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
              @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, wid, nwg);
    if i < prm.len {
        dst[i] = dst[i] + prm.shift;
    }
}

// `dst = src - src2` (the change `exact_delta` contracts).
@compute @workgroup_size(64)
fn sub_pass(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, wid, nwg);
    if i < prm.len {
        dst[i] = src[i] - src2[i];
    }
}

// Per workgroup, the maximum of its stretch of `src` (`len` values, `prm.count` values per
// workgroup), from 0 as `T::max_of` folds: into `dst[workgroup]`.
@compute @workgroup_size(64)
fn max_pass(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) li: u32) {
    let g = wid.y * nwg.x + wid.x;
    let first = g * prm.count;
    var m = 0.0;
    for (var i = first + li; i < min(first + prm.count, prm.len); i += WG) {
        let x = src[i];
        if !(m >= x) {
            m = x;
        }
    }
    best_v[li] = m;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if li < s {
            let x = best_v[li + s];
            if !(best_v[li] >= x) {
                best_v[li] = x;
            }
        }
        workgroupBarrier();
    }
    if li == 0u {
        dst[g] = best_v[0];
    }
}

// Probe: `dst[i] = fma(src[i], src[i], src2[i])`, which tells whether the adapter fuses.
@compute @workgroup_size(64)
fn fma_probe(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
             @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = linear(gid, wid, nwg);
    if i < prm.len {
        dst[i] = fma(src[i], src[i], src2[i]);
    }
}
