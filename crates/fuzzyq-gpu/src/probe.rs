//! Start-up probes of an adapter: whether its `fma` is fused, and whether a workgroup of one
//! subgroup's size reduces by shuffles as the last stage needs.

use wgpu::util::DeviceExt;

use crate::buffers::{read_as, with_data, zeroed};
use crate::context::Context;
use crate::error::GpuError;
use crate::kernels::{Entry, Kernels, Params, bind_group};

/// Whether `fma` is fused on this adapter: `fma(x, x, -1)` for `x = 1 + 2^-12` is
/// `2^-11 + 2^-24` in one rounding and `2^-11` with the product rounded first.
pub(crate) fn fused_fma(gpu: &Context, k: &Kernels) -> Result<bool, GpuError> {
    let x = 1.0f32 + f32::powi(2.0, -12);
    let out = run_probe(gpu, k, &[x], &[-1.0])?;
    let fused = x.mul_add(x, -1.0);
    Ok(out[0].to_bits() == fused.to_bits())
}

/// The subgroup probe's substitution: the last stage's reduction.
const SG_PROBE_REPLACE: [(&str, &str); 1] = [("REDUCE", crate::kernels::REDUCE_SUBGROUP)];

/// The subgroup probe's constants for workgroups of `wgs` threads (`WGS`, and `TPC` lanes
/// per cluster).
fn sg_probe_consts(wgs: u32) -> [(&'static str, u32); 2] {
    [("WGS", wgs), ("TPC", wgs.min(32))]
}

/// Whether subgroup shuffles reduce clusters of lanes as the last stage needs, on workgroups
/// of `wgs` threads (the adapter's subgroup size): the probe's result against the host's.
pub(crate) fn subgroups_work(gpu: &Context, k: &Kernels, wgs: u32) -> Result<bool, GpuError> {
    let consts = sg_probe_consts(wgs);
    let t = (include_str!("sgprobe.wgsl"), "sg_probe");
    let Ok(pipeline) =
        crate::kernels::specialized(gpu, k, t, &consts, &SG_PROBE_REPLACE, true, None)
    else {
        return Ok(false);
    };
    let groups = 64u32;
    let n = (groups * wgs) as usize;
    // Values with ties (multiples of 1/4 in a small range), so that the lowest index counts.
    let x: Vec<f32> = (0..n).map(|i| ((i * 37 + 11) % 13) as f32 * 0.25).collect();
    let device = &gpu.device;
    let ubuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("probe params"),
        contents: bytemuck::bytes_of(&Params::default()),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let src = with_data(gpu, "x", &x);
    let dst = zeroed(gpu, "max", 4 * n as u64);
    let aux = zeroed(gpu, "arg", 4 * n as u64);
    let dr = zeroed(gpu, "dummy", 4);
    let bufs: [&wgpu::Buffer; 11] = [&ubuf, &dr, &dr, &dr, &src, &dst, &aux, &dr, &dr, &dr, &dr];
    let bind = bind_group(gpu, &k.layout, &bufs);
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[0]);
        pass.dispatch_workgroups(groups, 1, 1);
    }
    gpu.queue.submit([enc.finish()]);
    let (m, a): (Vec<f32>, Vec<u32>) = (read_as(gpu, &dst, n)?, read_as(gpu, &aux, n)?);
    let [_, (_, tpc)] = consts;
    let tpc = tpc as usize;
    Ok((0..n).all(|g| {
        let cluster = g / tpc * tpc..g / tpc * tpc + tpc;
        let best = cluster
            .clone()
            .fold(cluster.start, |b, i| if x[i] > x[b] { i } else { b });
        m[g].to_bits() == x[best].to_bits() && a[g] as usize == best
    }))
}

/// Runs `fma_probe` on `x`, `c`: `fma(x, x, c)` per element.
pub(crate) fn run_probe(
    gpu: &Context,
    k: &Kernels,
    x: &[f32],
    c: &[f32],
) -> Result<Vec<f32>, GpuError> {
    let device = &gpu.device;
    let params = Params {
        len: x.len() as u32,
        ..Params::default()
    };
    let ubuf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("probe params"),
        contents: bytemuck::bytes_of(&params),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let (src, src2) = (with_data(gpu, "x", x), with_data(gpu, "c", c));
    let dst = zeroed(gpu, "out", 4 * x.len() as u64);
    let (dr, dw) = (zeroed(gpu, "dummy", 4), zeroed(gpu, "dummy", 4));
    let bufs: [&wgpu::Buffer; 11] = [&ubuf, &dr, &dr, &dr, &src, &dst, &dw, &dr, &dr, &dr, &src2];
    let bind = bind_group(gpu, &k.layout, &bufs);
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(k.pipeline(Entry::FmaProbe));
        pass.set_bind_group(0, &bind, &[0]);
        let (gx, gy) = crate::kernels::grid(x.len() as u64);
        pass.dispatch_workgroups(gx, gy, 1);
    }
    gpu.queue.submit([enc.finish()]);
    read_as(gpu, &dst, x.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_subgroup_probe_is_valid_wgsl() {
        // A probe that does not compile reads as an adapter whose subgroups do not reduce,
        // and turns subgroups off everywhere without a word (its header comment once named
        // the placeholder it substitutes, which put the loop in the comment's place).
        for wgs in [8, 32, 64] {
            let consts = sg_probe_consts(wgs);
            let text = crate::kernels::source_text(
                include_str!("sgprobe.wgsl"),
                &consts,
                &SG_PROBE_REPLACE,
                None,
            );
            let _ = crate::kernels::check_wgsl(&text).unwrap();
        }
    }
}
