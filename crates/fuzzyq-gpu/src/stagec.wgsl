// Stage SB of a full backup with the problem's constants (`compile.rs`: SB, SN cores, SA
// actions, SR, SP), so that every index is arithmetic on constants. The first stage of a
// contraction of several blocks reads `V` through `v_at` (its parts, `parts.rs`): SRC_AT is
// `v_at(col[e], r)` there and `src[...]` (the stage before) elsewhere, or `s_at(...)` where the
// stage before is in parts; `put(o, x)` writes element `o` of the output (`dst`, or its parts:
// `sweeps.rs`, `Shape::stage_cut`).

@compute @workgroup_size(64)
fn stage_c(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
           @builtin(num_workgroups) nwg: vec3<u32>) {
    let o = linear(gid, wid, nwg);
    if o >= prm.count {
        return;
    }
    let p = o % SP;
    var t = o / SP;
    let a = t % SA;
    t = t / SA;
    let r = t % SR;
    let q = t / SR;
    let cb = core_of(q, SN);
    let c = cb.x;
    let base = cb.y;
    let row = prm.rows[SB].x + c * SA + a;
    let e1 = row_ptr[row + 1u];
    var acc = 0.0;
    for (var e = row_ptr[row]; e < e1; e++) {
        acc = fma(weight[e], SRC_AT, acc);
    }
    put(o, acc);
}
