// One policy-evaluation sweep over a part of `V` (`parts.rs`), one thread per core, compiled
// with the parts of the `V` it reads (`v_at`, group 1): the expected value of the core's
// action in `aux`, the sums nested as the stages nest them (block 0 innermost), then `finish`.

@compute @workgroup_size(64)
fn evaluate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>,
            @builtin(num_workgroups) nwg: vec3<u32>) {
    let core = linear(gid, wid, nwg);
    if core >= prm.len {
        return;
    }
    let nb = prm.n_blocks;
    let pol = aux[core];
    var start: array<u32, MAX_BLOCKS>;
    var end: array<u32, MAX_BLOCKS>;
    var e: array<u32, MAX_BLOCKS>;
    var acc: array<f32, MAX_BLOCKS>;
    // The core's block cores, c_{B-1} fastest; c_0 from the part's first slab.
    let r0 = blk(0u).z;
    var rest = core % r0;
    for (var i = 0u; i < nb; i++) {
        let b = nb - 1u - i;
        let bl = blk(b);
        var c = rest % bl.x;
        rest = rest / bl.x;
        if b == 0u {
            c = prm.part_c0 + core / r0;
        }
        let a = (pol / bl.w) % bl.y;
        let row = prm.rows[b].x + c * bl.y + a;
        start[b] = row_ptr[row];
        end[b] = row_ptr[row + 1u];
        e[b] = start[b];
        acc[b] = 0.0;
    }
    var result = 0.0;
    var empty = false;
    for (var b = 1u; b < nb; b++) {
        empty = empty || start[b] == end[b];
    }
    loop {
        if empty {
            break;
        }
        var off = 0u;
        for (var b = 1u; b < nb; b++) {
            off += col[e[b]] * blk(b).z;
        }
        var s = 0.0;
        for (var i = start[0]; i < end[0]; i++) {
            s = fma(weight[i], v_at(col[i], off), s);
        }
        var val = s;
        var b = 1u;
        var done = false;
        loop {
            if b >= nb {
                done = true;
                break;
            }
            acc[b] = fma(weight[e[b]], val, acc[b]);
            e[b] += 1u;
            if e[b] < end[b] {
                break;
            }
            val = acc[b];
            acc[b] = 0.0;
            e[b] = start[b];
            b += 1u;
        }
        if done {
            result = val;
            break;
        }
    }
    dst[core] = finish(core, result);
}
