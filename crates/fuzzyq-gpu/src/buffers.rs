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

/// A storage buffer holding `data`, like [`with_data`], but staged a piece of at most
/// [`STAGING_BYTES`] at a time ([`write_pieces`]): for per-core data (a robots' rewards:
/// 150 MB), which `with_data` would stage whole.
pub(crate) fn filled<T: bytemuck::Pod>(
    gpu: &Context,
    label: &str,
    data: &[T],
) -> Result<wgpu::Buffer, GpuError> {
    if (size_of_val(data) as u64) <= STAGING_BYTES {
        return Ok(with_data(gpu, label, data));
    }
    let buffer = zeroed(gpu, label, size_of_val(data) as u64);
    write_pieces(gpu, &buffer, data, staged::<T>())?;
    Ok(buffer)
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

/// Most bytes of one staging buffer of a read ([`read_pieces`]).
pub(crate) const STAGING_BYTES: u64 = 32 << 20;

/// The first `len` values of `buffer`, read back to the host through staging buffers the
/// host maps ([`read_pieces`]), each piece copied once from the mapping into the result.
pub(crate) fn read_as<T: bytemuck::Pod>(
    gpu: &Context,
    buffer: &wgpu::Buffer,
    len: usize,
) -> Result<Vec<T>, GpuError> {
    let mut out = Vec::with_capacity(len);
    read_pieces(gpu, buffer, len, staged::<T>(), &mut |_, values: &[T]| {
        out.extend_from_slice(values);
    })?;
    Ok(out)
}

/// The first `len` values of `buffer` read back `piece` values at a time (the last piece may
/// hold fewer), each handed to `each(first, values)` in order from a staging buffer of a
/// piece's size. Two staging buffers take turns: while the host hands over one piece, the
/// device copies the next into the other (so the host holds at most two pieces beyond what
/// `each` keeps, and the staging memory is allocated once per read, not per piece: pinning
/// host memory costs time in proportion to its size).
pub(crate) fn read_pieces<T: bytemuck::Pod>(
    gpu: &Context,
    buffer: &wgpu::Buffer,
    len: usize,
    piece: usize,
    each: &mut dyn FnMut(usize, &[T]),
) -> Result<(), GpuError> {
    let t = size_of::<T>() as u64;
    let piece = piece.clamp(1, len.max(1));
    // Copies and mappings run in whole words (`wgpu::COPY_BUFFER_ALIGNMENT`).
    let words = |n: usize| (n as u64 * t).max(4).next_multiple_of(4);
    let firsts: Vec<usize> = (0..len).step_by(piece).collect();
    let device = &gpu.device;
    let staging: Vec<wgpu::Buffer> = (0..firsts.len().min(2))
        .map(|_| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: words(piece),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        })
        .collect();
    type Mapped = std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>;
    // Piece `k` copied into staging buffer `k % 2` and its mapping asked for.
    let copy = |k: usize| -> (wgpu::SubmissionIndex, Mapped) {
        let first = firsts[k];
        let size = words(piece.min(len - first));
        let into = &staging[k % 2];
        let mut enc = device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(buffer, first as u64 * t, into, 0, size);
        let index = gpu.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        into.map_async(wgpu::MapMode::Read, ..size, move |r| {
            let _ = tx.send(r);
        });
        (index, rx)
    };
    let failed = |e: String| GpuError::Failed(e);
    let mut values = Vec::new();
    let mut next = (!firsts.is_empty()).then(|| copy(0));
    for (k, &first) in firsts.iter().enumerate() {
        let Some((index, mapped)) = next.take() else {
            break;
        };
        // Staging buffer `(k + 1) % 2` was unmapped when piece `k - 1` was handed over.
        if k + 1 < firsts.len() {
            next = Some(copy(k + 1));
        }
        device
            .poll(wgpu::PollType::Wait {
                submission_index: Some(index),
                timeout: None,
            })
            .map_err(|e| failed(e.to_string()))?;
        mapped
            .recv()
            .map_err(|e| failed(e.to_string()))?
            .map_err(|e| failed(e.to_string()))?;
        let n = piece.min(len - first);
        let bytes = n * t as usize;
        let from = &staging[k % 2];
        let view = from
            .get_mapped_range(..words(n))
            .map_err(|e| failed(e.to_string()))?;
        // Mappings are aligned for any `T` here; a copy only where one is not.
        match bytemuck::try_cast_slice::<u8, T>(&view[..bytes]) {
            Ok(mapped) => each(first, mapped),
            Err(_) => {
                values.resize(n, T::zeroed());
                bytemuck::cast_slice_mut::<T, u8>(&mut values).copy_from_slice(&view[..bytes]);
                each(first, &values);
            }
        }
        drop(view);
        from.unmap();
    }
    Ok(())
}

/// Values of `T` in one staging buffer of [`STAGING_BYTES`].
pub(crate) fn staged<T>() -> usize {
    (STAGING_BYTES / size_of::<T>() as u64).max(1) as usize
}

/// `data` written to `buffer` from its start, `piece` values at a time (the last piece may
/// hold fewer) through two staging buffers that take turns, as [`read_pieces`] reads: the host fills one
/// while the device copies the other, each is allocated once, and a staging buffer is filled
/// again once its last copy has run. Returns once every copy is submitted; later commands on
/// the queue see the data.
pub(crate) fn write_pieces<T: bytemuck::Pod>(
    gpu: &Context,
    buffer: &wgpu::Buffer,
    data: &[T],
    piece: usize,
) -> Result<(), GpuError> {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    // Whole words, as copies and mappings run (`T` is 4 or 8 bytes: no piece is cut short).
    let piece = (piece.max(1) * size_of::<T>())
        .min(bytes.len())
        .next_multiple_of(4);
    let device = &gpu.device;
    let failed = |e: String| GpuError::Failed(e);
    let mut staging: Vec<(wgpu::Buffer, Option<wgpu::SubmissionIndex>)> = Vec::new();
    for (k, chunk) in bytes.chunks(piece.max(4)).enumerate() {
        let size = (chunk.len() as u64).next_multiple_of(4);
        if staging.len() < 2 {
            let b = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("upload"),
                size: piece as u64,
                usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: true,
            });
            staging.push((b, None));
        }
        let (into, last_copy) = &mut staging[k % 2];
        if let Some(index) = last_copy.take() {
            // Mapped again once the copy out of it has run.
            let (tx, rx) = std::sync::mpsc::channel();
            into.map_async(wgpu::MapMode::Write, .., move |r| {
                let _ = tx.send(r);
            });
            device
                .poll(wgpu::PollType::Wait {
                    submission_index: Some(index),
                    timeout: None,
                })
                .map_err(|e| failed(e.to_string()))?;
            rx.recv()
                .map_err(|e| failed(e.to_string()))?
                .map_err(|e| failed(e.to_string()))?;
        }
        {
            let mut view = into
                .get_mapped_range_mut(..size)
                .map_err(|e| failed(e.to_string()))?;
            view.slice(..chunk.len()).copy_from_slice(chunk);
        }
        into.unmap();
        let mut enc = device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(into, 0, buffer, (k * piece) as u64, size);
        *last_copy = Some(gpu.queue.submit([enc.finish()]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A buffer read back and written in pieces of every size, the two staging buffers
    /// taking turns (pieces of one value, pieces that do not divide it, one piece, a piece
    /// larger than it): its values in order, each once; `read_as` and `filled` (over one
    /// staging buffer's size) the same. Skipped without an
    /// adapter unless `FUZZYQ_REQUIRE_GPU` is set.
    #[test]
    fn pieces_of_any_size_keep_the_values_in_order() {
        let gpu = match crate::Gpu::new() {
            Ok(g) => g,
            Err(e) => {
                assert!(
                    std::env::var_os("FUZZYQ_REQUIRE_GPU").is_none(),
                    "FUZZYQ_REQUIRE_GPU is set but no adapter opened: {e}"
                );
                eprintln!("skipped: needs an adapter ({e})");
                return;
            }
        };
        let ctx = &gpu.inner;
        let data: Vec<u32> = (0..5_003u32)
            .map(|i| i.wrapping_mul(2_654_435_761))
            .collect();
        let buffer = with_data(ctx, "data", &data);
        for piece in [1, 3, 1_000, 5_003, 9_999] {
            let mut seen = Vec::new();
            read_pieces(
                ctx,
                &buffer,
                data.len(),
                piece,
                &mut |first, values: &[u32]| {
                    assert_eq!(first, seen.len(), "piece {piece}: in order");
                    assert!(values.len() <= piece);
                    seen.extend_from_slice(values);
                },
            )
            .unwrap();
            assert_eq!(seen, data, "pieces of {piece}");
        }
        assert_eq!(read_as::<u32>(ctx, &buffer, 4_000).unwrap(), data[..4_000]);
        assert!(read_as::<u32>(ctx, &buffer, 0).unwrap().is_empty());
        // Written in pieces of any size, the staging buffers taking turns: the same values.
        for piece in [1, 3, 1_000, 5_003, 9_999] {
            let other: Vec<u32> = data.iter().map(|x| x ^ piece as u32).collect();
            let b = zeroed(ctx, "written", 4 * other.len() as u64);
            write_pieces(ctx, &b, &other, piece).unwrap();
            assert_eq!(
                read_as::<u32>(ctx, &b, other.len()).unwrap(),
                other,
                "{piece}"
            );
        }
        let large: Vec<f32> = (0..staged::<f32>() + 5).map(|i| i as f32).collect();
        let b = filled(ctx, "large", &large).unwrap();
        assert_eq!(read_as::<f32>(ctx, &b, large.len()).unwrap(), large);
    }
}
