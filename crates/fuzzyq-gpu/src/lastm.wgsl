// The last stage fused with the reduction as `last1.wgsl`, a core's rows merged by column
// (`PlanTable::merged_steps`, laid out by `sweeps.rs` after the tables: step `s` of the last
// block's core `c` for `s` in `row_ptr[MP + c] .. row_ptr[MP + c + 1]` reads column
// `col[MC + s]`, and action `a` takes it where bit `a` of `col[MM + s]` is set, with weight
// `weight[MW + s AL + a]`). Each value of the stage before is read once per core and step
// and feeds the multiply-adds of every action whose row has that column, where `last1` reads
// it once per row; each row's entries still meet its sum in the row's order, so the sums and
// the maximum (at the lowest index, whatever the order) are the same bits.
// Constants as `last1.wgsl`, JC columns of all AL actions at a time (AL JC sums); and CR
// cores in turn per group of TPC lanes, so that neighbouring cores, whose columns are mostly
// the same, find them in the first-level cache: round `r` of workgroup `g` takes cores
// `(g CR + r) CPW .. + CPW`.

var<workgroup> tv: array<f32, WGS>;
var<workgroup> ti: array<u32, WGS>;

@compute @workgroup_size(WGS)
fn lastm(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32 LANE_PARAM) {
    let t = LANE_EXPR;
    let lane = t % TPC;
    let g = wid.y * nwg.x + wid.x;
    for (var r = 0u; r < CR; r++) {
        let local = (g * CR + r) * CPW + t / TPC;
        let valid = local < prm.count;
        var bv = bitcast<f32>(0xff800000u ^ prm.zero);
        var bi = 0xffffffffu;
        if valid {
            let cb = core_of(local, NL);
            let s0 = row_ptr[MP + cb.x];
            let s1 = row_ptr[MP + cb.x + 1u];
            for (var ch = 0u; ch < NCH; ch++) {
                let p0 = lane + TPC * JC * ch;
                var acc: array<array<f32, JC>, AL>;
                for (var a = 0u; a < AL; a++) {
                    for (var j = 0u; j < JC; j++) {
                        acc[a][j] = 0.0;
                    }
                }
                for (var s = s0; s < s1; s++) {
                    let k = (cb.y + col[MC + s]) * PL;
                    let m = col[MM + s];
                    var x: array<f32, JC>;
                    for (var j = 0u; j < JC; j++) {
                        x[j] = src[k + min(p0 + TPC * j, PL - 1u)];
                    }
                    for (var a = 0u; a < AL; a++) {
                        if ((m >> a) & 1u) != 0u {
                            let w = weight[MW + s * AL + a];
                            for (var j = 0u; j < JC; j++) {
                                acc[a][j] = fma(w, x[j], acc[a][j]);
                            }
                        }
                    }
                }
                for (var a = 0u; a < AL; a++) {
                    for (var j = 0u; j < JC; j++) {
                        let p = p0 + TPC * j;
                        if p < PL {
                            offer(acc[a][j], a * PL + p, &bv, &bi);
                        }
                    }
                }
            }
        }
        REDUCE
        if valid && lane == 0u {
            write_best(prm.out_lo + local, bv, bi);
        }
    }
}
