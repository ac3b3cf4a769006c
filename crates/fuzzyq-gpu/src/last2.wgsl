// The last two stages of a full backup fused in one workgroup per prefix (c_0, ..., c_{B-2}):
// the stage before the last writes its slice `[k_L][p]` (`NL x PL` values) into workgroup
// memory, then the last stage reads it there, 32 lanes per core group, and the core's
// reduction takes the lanes' partial maxima. Prepended with `block.wgsl`'s declarations and
// with the problem's constants (`sweeps.rs`: NL, AL, PL, NB, AB, PB, BSTAGE, LAST, SLN, J),
// so that every index is arithmetic on constants. The same sums in the same order as
// `stage` then `last_fused`: the same bits.

var<workgroup> sl: array<f32, SLN>;
var<workgroup> part_v: array<f32, NL * 32u>;
var<workgroup> part_i: array<u32, NL * 32u>;

@compute @workgroup_size(128)
fn last2(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) t: u32) {
    let q = wid.y * nwg.x + wid.x;
    if q >= prm.count {
        return;
    }
    // Stage BSTAGE for block core `c` of prefix `q` into `sl`.
    var c: u32;
    var base: u32;
    if BSTAGE == 0u {
        c = prm.c0_lo + q;
        base = 0u;
    } else {
        c = q % NB;
        base = (q / NB) * NB;
    }
    let row0 = prm.rows[BSTAGE].x + c * AB;
    for (var o = t; o < SLN; o += 128u) {
        let p = o % PB;
        let a = (o / PB) % AB;
        let r = o / (AB * PB);
        let row = row0 + a;
        let e1 = row_ptr[row + 1u];
        var acc = 0.0;
        for (var e = row_ptr[row]; e < e1; e++) {
            acc = fma(weight[e], src[((base + col[e]) * NL + r) * PB + p], acc);
        }
        sl[o] = acc;
    }
    workgroupBarrier();
    // The last stage: group `g` takes cores g, g + 4, ...; lane `l` the actions' p = l + 32 j.
    let g = t / 32u;
    let l = t % 32u;
    let abs_mode = prm.mode == 3u;
    for (var cl = g; cl < NL; cl += 4u) {
        var bv = bitcast<f32>(0xff800000u ^ prm.zero);
        var bi = 0xffffffffu;
        for (var a = 0u; a < AL; a++) {
            let row = prm.rows[LAST].x + cl * AL + a;
            let e1 = row_ptr[row + 1u];
            var acc: array<f32, J>;
            for (var j = 0u; j < J; j++) {
                acc[j] = 0.0;
            }
            for (var e = row_ptr[row]; e < e1; e++) {
                let w = weight[e];
                let k = col[e] * PL;
                for (var j = 0u; j < J; j++) {
                    let p = min(l + 32u * j, PL - 1u);
                    acc[j] = fma(w, sl[k + p], acc[j]);
                }
            }
            for (var j = 0u; j < J; j++) {
                let p = l + 32u * j;
                var x = acc[j];
                if abs_mode {
                    x = abs(x);
                }
                if p < PL && x > bv {
                    bv = x;
                    bi = a * PL + p;
                }
            }
        }
        part_v[cl * 32u + l] = bv;
        part_i[cl * 32u + l] = bi;
    }
    workgroupBarrier();
    if t >= NL {
        return;
    }
    var m = part_v[t * 32u];
    var mi = part_i[t * 32u];
    for (var i = 1u; i < 32u; i++) {
        let v = part_v[t * 32u + i];
        let vi = part_i[t * 32u + i];
        if beats(v, vi, m, mi) {
            m = v;
            mi = vi;
        }
    }
    let core = prm.c0_lo * prm.slab + q * NL + t;
    let is_goal = prm.has_goal != 0u && goal[core] != 0u;
    switch prm.mode {
        case 0u: {
            dst[core] = finish(core, m);
        }
        case 1u: {
            dst[core] = finish(core, m);
            aux[core] = select(mi, 0u, is_goal);
        }
        case 2u: {
            aux[core] = select(mi, 0u, is_goal);
        }
        default: {
            dst[core] = select(m, 0.0, is_goal);
        }
    }
}
