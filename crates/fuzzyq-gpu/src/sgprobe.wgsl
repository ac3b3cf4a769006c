// Probe: whether a workgroup of WGS threads is one subgroup whose lanes `subgroupShuffleXor`
// exchanges, as `last1.wgsl` relies on (the body below takes the last stage's reduction,
// from `kernels.rs`): every cluster of TPC lanes reduces `src` to its
// largest value at the lowest index, each lane writing the result at its own element.

@compute @workgroup_size(WGS)
fn sg_probe(@builtin(workgroup_id) wid: vec3<u32>, @builtin(subgroup_invocation_id) sid: u32) {
    let g = wid.x * WGS + sid;
    var bv = src[g];
    var bi = g;
    REDUCE
    dst[g] = bv;
    aux[g] = bi;
}
