//! Buffers on the device: made from host data, zeroed, and read back.

use wgpu::util::DeviceExt;

use crate::context::Context;
use crate::error::GpuError;

/// Usages of every storage buffer: bound in shaders, written from the host, read back.
const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_DST)
    .union(wgpu::BufferUsages::COPY_SRC);

/// A storage buffer holding `data` (at least 4 bytes: empty data gets one zero word).
pub(crate) fn with_data<T: bytemuck::Pod>(gpu: &Context, label: &str, data: &[T]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    let zero = [0u8; 4];
    gpu.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: if bytes.is_empty() { &zero } else { bytes },
            usage: STORAGE,
        })
}

/// A zeroed storage buffer of `bytes` bytes (at least 4).
pub(crate) fn zeroed(gpu: &Context, label: &str, bytes: u64) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(4).next_multiple_of(4),
        usage: STORAGE,
        mapped_at_creation: false,
    })
}

/// Waits for every submitted command.
pub(crate) fn wait(gpu: &Context) -> Result<(), GpuError> {
    gpu.device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| GpuError::Failed(e.to_string()))
}

/// The first `len` values of `buffer`, read back to the host: copied on the device into a
/// staging buffer the host maps, then once from the mapping into the result (a run's `V` is
/// 150 MB on the robots' grid, so no copy beyond that one).
pub(crate) fn read_as<T: bytemuck::Pod>(
    gpu: &Context,
    buffer: &wgpu::Buffer,
    len: usize,
) -> Result<Vec<T>, GpuError> {
    let bytes = (len * size_of::<T>()) as u64;
    let device = &gpu.device;
    let size = bytes.max(4).next_multiple_of(4);
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    gpu.queue.submit([enc.finish()]);
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
    let mut out = vec![T::zeroed(); len];
    bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&view[..bytes as usize]);
    drop(view);
    staging.unmap();
    Ok(out)
}
