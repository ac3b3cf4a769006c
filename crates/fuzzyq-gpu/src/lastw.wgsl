// The last stage fused with the reduction as `last1.wgsl`, a workgroup per item of the stage
// before (`LastStage::Tile`): its cores of the dispatch (up to NL, the last block's) share
// that item's NL x PL values, which the workgroup loads once into `tile` (TILE values) before
// its lanes read them there instead of from the stage before's buffer. Then, CPW cores at a
// time, each core's TPC lanes take J of its PL columns (JC at a time, in NCH chunks) as
// `last1.wgsl` does, and reduce in workgroup memory. The same sums in the same order, and the
// maximum at the lowest index: the same bits. Workgroup `w` of a dispatch over cores
// `prm.lo .. prm.lo + prm.count` (counted from the first child of the source's first item)
// takes item `prm.lo / NL + w`.

var<workgroup> tile: array<f32, TILE>;
var<workgroup> tv: array<f32, WGS>;
var<workgroup> ti: array<u32, WGS>;

@compute @workgroup_size(WGS)
fn lastw(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) li: u32) {
    let item = prm.lo / NL + wid.y * nwg.x + wid.x;
    let c_lo = max(prm.lo, item * NL);
    let c_hi = min(prm.lo + prm.count, item * NL + NL);
    for (var i = li; i < TILE; i += WGS) {
        tile[i] = src[item * TILE + i];
    }
    workgroupBarrier();
    let lane = li % TPC;
    for (var first = c_lo; first < c_hi; first += CPW) {
        let g = first + li / TPC;
        let valid = g < c_hi;
        var bv = bitcast<f32>(0xff800000u ^ prm.zero);
        var bi = 0xffffffffu;
        if valid {
            let c = g % NL;
            CORE_ROWS
        }
        REDUCE
        if valid && lane == 0u {
            write_best(prm.out_lo + (g - prm.lo), bv, bi);
        }
    }
}
