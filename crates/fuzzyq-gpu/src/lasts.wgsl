// The last stage fused with the reduction and with the stage before it (`LastStage::Staged`),
// compiled with the problem's constants (`last.rs`): LAST (the block), NL cores, AL actions,
// PL product actions before it, ML most entries of its rows; N1 cores, A1 actions, P1
// product actions before it and ME most entries of the rows of the block before it
// (LAST - 1); a workgroup of WGS threads per item of the stage before, taking the item's PL
// columns PC at a time (TILE = NL x PC values in workgroup memory).
//
// For each pass over columns `q0 .. q0 + w` (w = PC, or what is left):
// 1. The item's values of the stage before for those columns (the stage's block core `c1`
//    of the item, for each core `k` of the last block and column `q`), computed from the
//    stage before that (`src`) into workgroup memory: thread `t` takes column `q = t % QT`
//    (and every QT-th after it), holds that column's row (block core `c1`, action `q / P1`)
//    in registers and runs it for cores `k = t / QT`, `+ KG`, ...
// 2. The item's cores of the dispatch, CPW at a time in ROUNDS rounds: J lanes per core,
//    lane `j` taking the pass's columns `j, j + J, ...`; for each action the core's row held
//    in registers and run over the lane's columns from workgroup memory, each sum offered
//    to the lane's largest of that round.
// Then each round's core folds its J lanes' largest (in workgroup memory) and writes.
//
// Every sum is a chain over its row's entries in order, `fma` from 0, as `stagec.wgsl` and
// `last1.wgsl` (and the CPU) take them; the largest at the lowest index (`beats`, `offer`)
// whatever the order of the offers: the same bits. Workgroup `w` of a dispatch over cores
// `prm.lo .. prm.lo + prm.count` (counted from the first child of the first item of the
// stage before the stage before that `src` holds) takes item `prm.lo / NL + w`.

var<workgroup> tile: array<f32, TILE>;
var<workgroup> fold_v: array<f32, WGS>;
var<workgroup> fold_i: array<u32, WGS>;

@compute @workgroup_size(WGS)
fn lasts(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32) {
    let item = prm.lo / NL + wid.y * nwg.x + wid.x;
    let c_lo = max(prm.lo, item * NL);
    let c_hi = min(prm.lo + prm.count, item * NL + NL);
    let zero = bitcast<f32>(prm.zero);
    let c1 = item % N1;
    let base1 = item - c1;
    let j = li % J;
    var best_v: array<f32, ROUNDS>;
    var best_i: array<u32, ROUNDS>;
    for (var round = 0u; round < ROUNDS; round++) {
        best_v[round] = bitcast<f32>(0xff800000u ^ prm.zero);
        best_i[round] = 0xffffffffu;
    }
    for (var q0 = 0u; q0 < PL; q0 += PC) {
        let w = min(PC, PL - q0);
        // 1. The stage before, from its item's parent in `src`.
        if li < QT * KG {
            for (var q = li % QT; q < w; q += QT) {
                let row = prm.rows[LAST - 1u].x + c1 * A1 + (q0 + q) / P1;
                let e0 = row_ptr[row];
                let n = row_ptr[row + 1u] - e0;
                var wt: array<f32, ME>;
                var o: array<u32, ME>;
                for (var e = 0u; e < ME; e++) {
                    let i = e0 + min(e, max(n, 1u) - 1u);
                    wt[e] = weight[i];
                    o[e] = (base1 + col[i]) * NL * P1 + (q0 + q) % P1;
                }
                for (var k = li / QT; k < NL; k += KG) {
                    var t = zero;
                    for (var e = 0u; e < ME; e++) {
                        if e < n {
                            t = fma(wt[e], src[o[e] + k * P1], t);
                        }
                    }
                    tile[k * PC + q] = t;
                }
            }
        }
        workgroupBarrier();
        // 2. The last stage over the pass's values.
        for (var round = 0u; round < ROUNDS; round++) {
            let g = c_lo + round * CPW + li / J;
            if li < CPW * J && g < c_hi {
                let c = g - item * NL;
                var bv = best_v[round];
                var bi = best_i[round];
                for (var a = 0u; a < AL; a++) {
                    let row = prm.rows[LAST].x + c * AL + a;
                    let e0 = row_ptr[row];
                    let n = row_ptr[row + 1u] - e0;
                    var wt: array<f32, ML>;
                    var o: array<u32, ML>;
                    for (var e = 0u; e < ML; e++) {
                        let i = e0 + min(e, max(n, 1u) - 1u);
                        wt[e] = weight[i];
                        o[e] = col[i] * PC;
                    }
                    for (var p = j; p < w; p += J) {
                        var t = zero;
                        for (var e = 0u; e < ML; e++) {
                            if e < n {
                                t = fma(wt[e], tile[o[e] + p], t);
                            }
                        }
                        offer(t, a * PL + q0 + p, &bv, &bi);
                    }
                }
                best_v[round] = bv;
                best_i[round] = bi;
            }
        }
        // The pass's values read before the next pass writes its own.
        workgroupBarrier();
    }
    // 3. Each round's cores: their lanes folded, then written.
    for (var round = 0u; round < ROUNDS; round++) {
        let g = c_lo + round * CPW + li / J;
        var bv = best_v[round];
        var bi = best_i[round];
        fold_v[li] = bv;
        fold_i[li] = bi;
        workgroupBarrier();
        if li < CPW * J && g < c_hi && j == 0u {
            for (var m = 1u; m < J; m++) {
                if beats(fold_v[li + m], fold_i[li + m], bv, bi) {
                    bv = fold_v[li + m];
                    bi = fold_i[li + m];
                }
            }
            write_best(prm.out_lo + (g - prm.lo), bv, bi);
        }
        workgroupBarrier();
    }
}
