// The last stage fused with the reduction, compiled with the problem's constants
// (`sweeps.rs`): LAST (the block), NL cores, AL actions, PL product actions before it; TPC
// lanes per core, each taking J of the core's PL columns (p = lane + TPC j), so that a row
// entry's weight and column feed several multiply-adds: JC at a time, in NCH chunks (JC J's
// up to 8, so that the accumulators stay in registers where PL is large, as with 15,625 joint
// actions); CPW cores per workgroup of WGS threads.
// With SG the workgroup is one subgroup and a core's lanes reduce by `subgroupShuffleXor`
// (no workgroup memory, no barrier); without, in workgroup memory. The same sums in the same
// order as `last_fused`, and the same maximum at the lowest index: the same bits.

var<workgroup> tv: array<f32, WGS>;
var<workgroup> ti: array<u32, WGS>;

@compute @workgroup_size(WGS)
fn last1(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32 LANE_PARAM) {
    let t = LANE_EXPR;
    let local = (wid.y * nwg.x + wid.x) * CPW + t / TPC;
    let lane = t % TPC;
    let valid = local < prm.count;
    var bv = bitcast<f32>(0xff800000u ^ prm.zero);
    var bi = 0xffffffffu;
    if valid {
        let cb = core_of(local, NL);
        let c = cb.x;
        let base = cb.y;
        CORE_ROWS
    }
    REDUCE
    if !valid || lane != 0u {
        return;
    }
    write_best(prm.out_lo + local, bv, bi);
}
