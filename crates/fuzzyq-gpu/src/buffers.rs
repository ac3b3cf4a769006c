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

/// Submits what the queue has staged (buffer writes, buffers made with data) and waits for
/// it, so that the host's staging memory is freed before more is staged.
pub(crate) fn settle(gpu: &Context) -> Result<(), GpuError> {
    gpu.queue.submit([]);
    wait(gpu)
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
    let mut out = vec![T::zeroed(); len];
    read_pieces(gpu, buffer, len, len, &mut |first, piece: &[T]| {
        out[first..first + piece.len()].copy_from_slice(piece);
    })?;
    Ok(out)
}

/// The first `len` values of `buffer` read back `piece` values at a time (the last piece may
/// hold fewer), each handed to `each(first, values)` from one staging buffer of a piece's
/// size: the host never holds more than a piece beyond what `each` keeps.
pub(crate) fn read_pieces<T: bytemuck::Pod>(
    gpu: &Context,
    buffer: &wgpu::Buffer,
    len: usize,
    piece: usize,
    each: &mut dyn FnMut(usize, &[T]),
) -> Result<(), GpuError> {
    let t = size_of::<T>() as u64;
    let piece = piece.clamp(1, len.max(1));
    let device = &gpu.device;
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: (piece as u64 * t).max(4).next_multiple_of(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut values = Vec::new();
    for first in (0..len).step_by(piece) {
        let n = piece.min(len - first);
        let bytes = n as u64 * t;
        // Copies and mappings run in whole words (`wgpu::COPY_BUFFER_ALIGNMENT`).
        let size = bytes.max(4).next_multiple_of(4);
        let mut enc = device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, first as u64 * t, &staging, 0, size);
        gpu.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, ..size, move |r| {
            let _ = tx.send(r);
        });
        wait(gpu)?;
        rx.recv()
            .map_err(|e| GpuError::Failed(e.to_string()))?
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        let view = staging
            .get_mapped_range(..size)
            .map_err(|e| GpuError::Failed(e.to_string()))?;
        // Mappings are aligned for any `T` here; a copy only where one is not.
        match bytemuck::try_cast_slice::<u8, T>(&view[..bytes as usize]) {
            Ok(mapped) => each(first, mapped),
            Err(_) => {
                values.resize(n, T::zeroed());
                bytemuck::cast_slice_mut::<T, u8>(&mut values)
                    .copy_from_slice(&view[..bytes as usize]);
                each(first, &values);
            }
        }
        drop(view);
        staging.unmap();
    }
    Ok(())
}
