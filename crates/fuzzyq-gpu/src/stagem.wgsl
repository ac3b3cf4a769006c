// Stage SB of a full backup as `stagec.wgsl`, a thread taking all SA actions of one
// element `(q, r, p)`: the rows of the stage's block core merged by column (`last.rs`,
// `MergedAt`: step `s` for `s` in `row_ptr[MP + c] .. row_ptr[MP + c + 1]` reads column
// `col[MC + s]`, and action `a` takes it where bit `a` of `col[MM + s]` is set, with weight
// `weight[MW + s SA + a]`). Each value of the stage before is read once per step and feeds
// every action whose row has that column, where `stage_c` reads it once per row; each row's
// entries still meet its sum in the row's order: the same bits. Neighbouring threads take
// neighbouring `(r, p)` of one block core, so they read one run of the stage before and
// share each step. SRC_AT and `put` as in `stagec.wgsl`, with the step's column `k`.

@compute @workgroup_size(64)
fn stage_m(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
           @builtin(num_workgroups) nwg: vec3<u32>) {
    let o = linear(gid, wid, nwg);
    if o >= prm.count / SA {
        return;
    }
    let p = o % SP;
    let t = o / SP;
    let r = t % SR;
    let q = t / SR;
    let cb = core_of(q, SN);
    let base = cb.y;
    var acc: array<f32, SA>;
    for (var a = 0u; a < SA; a++) {
        acc[a] = 0.0;
    }
    let s1 = row_ptr[MP + cb.x + 1u];
    for (var s = row_ptr[MP + cb.x]; s < s1; s++) {
        let k = col[MC + s];
        let m = col[MM + s];
        let x = SRC_AT;
        for (var a = 0u; a < SA; a++) {
            if ((m >> a) & 1u) != 0u {
                acc[a] = fma(weight[MW + s * SA + a], x, acc[a]);
            }
        }
    }
    let out = (q * SR + r) * SA * SP + p;
    for (var a = 0u; a < SA; a++) {
        put(out + a * SP, acc[a]);
    }
}
