//! Buffers on the device: made from host data, zeroed, and read back.

use wgpu::util::DeviceExt;

use crate::error::GpuError;
use crate::gpu::Gpu;
use crate::kernels::{Entry, Kernels, PARAM_STRIDE, Params};

/// Usages of every storage buffer: bound in shaders, written from the host, read back.
const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_DST)
    .union(wgpu::BufferUsages::COPY_SRC);

/// A storage buffer holding `data` (at least 4 bytes: empty data gets one zero word).
pub(crate) fn with_data<T: bytemuck::Pod>(gpu: &Gpu, label: &str, data: &[T]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    let zero = [0u8; 4];
    gpu.inner
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: if bytes.is_empty() { &zero } else { bytes },
            usage: STORAGE,
        })
}

/// A zeroed storage buffer of `bytes` bytes (at least 4).
pub(crate) fn zeroed(gpu: &Gpu, label: &str, bytes: u64) -> wgpu::Buffer {
    gpu.inner.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(4).next_multiple_of(4),
        usage: STORAGE,
        mapped_at_creation: false,
    })
}

/// Waits for every submitted command.
pub(crate) fn wait(gpu: &Gpu) -> Result<(), GpuError> {
    gpu.inner
        .device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| GpuError::Failed(e.to_string()))
}

/// The first `bytes` bytes of `buffer`, read back to the host.
pub(crate) fn read(gpu: &Gpu, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, GpuError> {
    let device = &gpu.inner.device;
    let size = bytes.max(4).next_multiple_of(4);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    gpu.inner.queue.submit([enc.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    wait(gpu)?;
    rx.recv()
        .map_err(|e| GpuError::Failed(e.to_string()))?
        .map_err(|e| GpuError::Failed(e.to_string()))?;
    let view = staging
        .get_mapped_range(..)
        .map_err(|e| GpuError::Failed(e.to_string()))?;
    let out = view[..bytes as usize].to_vec();
    drop(view);
    staging.unmap();
    Ok(out)
}

/// `bytes` read back as values of `T`.
pub(crate) fn read_as<T: bytemuck::Pod>(
    gpu: &Gpu,
    buffer: &wgpu::Buffer,
    len: usize,
) -> Result<Vec<T>, GpuError> {
    let bytes = read(gpu, buffer, (len * size_of::<T>()) as u64)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Runs `fma_probe` on `x`, `c`: `fma(x, x, c)` per element.
pub(crate) fn run_probe(
    gpu: &Gpu,
    k: &Kernels,
    x: &[f32],
    c: &[f32],
) -> Result<Vec<f32>, GpuError> {
    let device = &gpu.inner.device;
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
    let bufs: [&wgpu::Buffer; 11] = [
        &ubuf, &dr, &dr, &dr, &src, &dst, &dw, &dr, &dr, &dr, &src2,
    ];
    let bind = bind_group(gpu, &k.layout, &bufs);
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(k.pipeline(Entry::FmaProbe));
        pass.set_bind_group(0, &bind, &[0]);
        let (gx, gy) = crate::kernels::grid(x.len() as u64);
        pass.dispatch_workgroups(gx, gy, 1);
    }
    gpu.inner.queue.submit([enc.finish()]);
    read_as(gpu, &dst, x.len())
}

/// A bind group of `layout` binding `bufs[i]` at binding `i` (binding 0 a uniform window of
/// one dispatch's parameters).
pub(crate) fn bind_group(
    gpu: &Gpu,
    layout: &wgpu::BindGroupLayout,
    bufs: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = bufs
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: if i == 0 {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: b,
                    offset: 0,
                    size: wgpu::BufferSize::new(size_of::<Params>() as u64),
                })
            } else {
                b.as_entire_binding()
            },
        })
        .collect();
    gpu.inner
        .device
        .create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout,
            entries: &entries,
        })
}

/// The parameters of `n` dispatches, `PARAM_STRIDE` bytes apart.
pub(crate) fn params_bytes(params: &[Params]) -> Vec<u8> {
    let mut out = vec![0u8; params.len() * PARAM_STRIDE as usize];
    for (i, p) in params.iter().enumerate() {
        let at = i * PARAM_STRIDE as usize;
        out[at..at + size_of::<Params>()].copy_from_slice(bytemuck::bytes_of(p));
    }
    out
}
