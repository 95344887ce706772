//! GPU buffers made the one way every pass makes them.
//!
//! # How it works
//! [`storage`] creates a buffer and writes its contents through the queue rather than mapping it at creation:
//! on a lost device that is an error the device records (and the frame pipeline reports), never a panic. The
//! renderer's passes, the ray grids and the depth of field all upload through it.

/// A buffer of `usage` holding `contents`, written through the queue (on a lost device this is an error the
/// device records, not a panic as a buffer mapped at creation would be).
pub(crate) fn storage(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    let size = (contents.len() as u64).max(16).next_multiple_of(4);
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage: usage | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    queue.write_buffer(&buffer, 0, contents);
    buffer
}

