// The range of `a - b` in f64 (NaN differences skipped), per workgroup: `out[2 g]` the
// minimum and `out[2 g + 1]` the maximum of workgroup `g`'s stretch of `per_wg` values. The
// host takes the range of the workgroups' ranges (exact in any order) and finishes it as the
// CPU's `diff_stats` does. Needs the adapter's f64 (`SHADER_F64`).

const WG: u32 = 64u;

struct DiffParams {
    len: u32,
    per_wg: u32,
    zero: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> prm: DiffParams;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read_write> out: array<f64>;

var<workgroup> lo_s: array<f64, WG>;
var<workgroup> hi_s: array<f64, WG>;

@compute @workgroup_size(64)
fn diff_range(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
              @builtin(local_invocation_index) li: u32) {
    let g = wid.y * nwg.x + wid.x;
    let first = g * prm.per_wg;
    // +inf and -inf, made at run time (constant infinities are refused).
    let inf = f64(bitcast<f32>(0x7f800000u ^ prm.zero));
    var lo = inf;
    var hi = -inf;
    for (var i = first + li; i < min(first + prm.per_wg, prm.len); i += WG) {
        let d = f64(a[i]) - f64(b[i]);
        if d == d {
            if d < lo {
                lo = d;
            }
            if d > hi {
                hi = d;
            }
        }
    }
    lo_s[li] = lo;
    hi_s[li] = hi;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if li < s {
            if lo_s[li + s] < lo_s[li] {
                lo_s[li] = lo_s[li + s];
            }
            if hi_s[li + s] > hi_s[li] {
                hi_s[li] = hi_s[li + s];
            }
        }
        workgroupBarrier();
    }
    if li == 0u {
        out[2u * g] = lo_s[0];
        out[2u * g + 1u] = hi_s[0];
    }
}
