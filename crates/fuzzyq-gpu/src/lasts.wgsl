// The last stage fused with the reduction and with the stage before it (`LastStage::Staged`),
// compiled with the problem's constants (`last.rs`): LAST (the block), NL cores, AL actions,
// PL product actions before it, ML most entries of its rows; N1 cores, A1 actions, P1
// product actions before it and ME most entries of the rows of the block before it
// (LAST - 1); a workgroup of WGS threads per item of the stage before.
//
// 1. The item's values of the stage before (TILE = NL x PL of them: the stage's block core
//    `c1` of the item, for each core `k` of the last block and column `q`), computed from the
//    stage before that (`src`) into workgroup memory: thread `t` takes column `q = t % QT`
//    (and every QT-th after it), holds that column's row (block core `c1`, action `q / P1`)
//    in registers and runs it for cores `k = t / QT`, `+ KG`, ...
// 2. The item's cores of the dispatch, CPW at a time in ROUNDS rounds: J lanes per core, lane
//    `j` taking the columns `p = j, j + J, ...`; for each action the core's row held in
//    registers and run over the lane's columns from workgroup memory, each sum offered to
//    the lane's largest; then the core's first lane folds its J lanes' largest (in
//    workgroup memory) and writes.
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
    // 1. The stage before, from its item's parent in `src`.
    let c1 = item % N1;
    let base1 = item - c1;
    if li < QT * KG {
        for (var q = li % QT; q < PL; q += QT) {
            let row = prm.rows[LAST - 1u].x + c1 * A1 + q / P1;
            let e0 = row_ptr[row];
            let n = row_ptr[row + 1u] - e0;
            var w: array<f32, ME>;
            var o: array<u32, ME>;
            for (var e = 0u; e < ME; e++) {
                let i = e0 + min(e, max(n, 1u) - 1u);
                w[e] = weight[i];
                o[e] = (base1 + col[i]) * NL * P1 + q % P1;
            }
            for (var k = li / QT; k < NL; k += KG) {
                var t = zero;
                for (var e = 0u; e < ME; e++) {
                    if e < n {
                        t = fma(w[e], src[o[e] + k * P1], t);
                    }
                }
                tile[k * PL + q] = t;
            }
        }
    }
    workgroupBarrier();
    // 2. The last stage over the item's values.
    let j = li % J;
    for (var round = 0u; round < ROUNDS; round++) {
        let g = c_lo + round * CPW + li / J;
        let valid = li < CPW * J && g < c_hi;
        var bv = bitcast<f32>(0xff800000u ^ prm.zero);
        var bi = 0xffffffffu;
        if valid {
            let c = g - item * NL;
            for (var a = 0u; a < AL; a++) {
                let row = prm.rows[LAST].x + c * AL + a;
                let e0 = row_ptr[row];
                let n = row_ptr[row + 1u] - e0;
                var w: array<f32, ML>;
                var o: array<u32, ML>;
                for (var e = 0u; e < ML; e++) {
                    let i = e0 + min(e, max(n, 1u) - 1u);
                    w[e] = weight[i];
                    o[e] = col[i] * PL;
                }
                for (var p = j; p < PL; p += J) {
                    var t = zero;
                    for (var e = 0u; e < ML; e++) {
                        if e < n {
                            t = fma(w[e], tile[o[e] + p], t);
                        }
                    }
                    offer(t, a * PL + p, &bv, &bi);
                }
            }
        }
        fold_v[li] = bv;
        fold_i[li] = bi;
        workgroupBarrier();
        if valid && j == 0u {
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
