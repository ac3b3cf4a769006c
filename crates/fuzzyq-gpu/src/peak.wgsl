// The adapter's fused multiply-add peak: every thread runs 16 independent chains of `fma`,
// `iters` steps each, and writes their sum (so that nothing is left out).

struct PeakParams {
    iters: u32,
    m: f32,
    c: f32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> prm: PeakParams;
@group(0) @binding(1) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(256)
fn peak(@builtin(global_invocation_id) gid: vec3<u32>) {
    let m = prm.m;
    let c = prm.c;
    let x = f32(gid.x) * 1e-9;
    var a = array<f32, 16>(x, x + c, x + 2.0 * c, x + 3.0 * c, x + 4.0 * c, x + 5.0 * c,
        x + 6.0 * c, x + 7.0 * c, x + 8.0 * c, x + 9.0 * c, x + 10.0 * c, x + 11.0 * c,
        x + 12.0 * c, x + 13.0 * c, x + 14.0 * c, x + 15.0 * c);
    var s0 = a[0]; var s1 = a[1]; var s2 = a[2]; var s3 = a[3];
    var s4 = a[4]; var s5 = a[5]; var s6 = a[6]; var s7 = a[7];
    var s8 = a[8]; var s9 = a[9]; var s10 = a[10]; var s11 = a[11];
    var s12 = a[12]; var s13 = a[13]; var s14 = a[14]; var s15 = a[15];
    for (var i = 0u; i < prm.iters; i++) {
        s0 = fma(s0, m, c); s1 = fma(s1, m, c); s2 = fma(s2, m, c); s3 = fma(s3, m, c);
        s4 = fma(s4, m, c); s5 = fma(s5, m, c); s6 = fma(s6, m, c); s7 = fma(s7, m, c);
        s8 = fma(s8, m, c); s9 = fma(s9, m, c); s10 = fma(s10, m, c); s11 = fma(s11, m, c);
        s12 = fma(s12, m, c); s13 = fma(s13, m, c); s14 = fma(s14, m, c); s15 = fma(s15, m, c);
    }
    out[gid.x] = s0 + s1 + s2 + s3 + s4 + s5 + s6 + s7 + s8 + s9 + s10 + s11 + s12 + s13
        + s14 + s15;
}
