//! The GPU copy of the triangle table. Between frames only the slots the last updates touched are
//! written (`queue.write_buffer` per coalesced range); the whole table is sent only when the buffer
//! has to grow, which doubling makes rare (amortised O(1) per triangle).

use crate::table::{TRIANGLE_BYTES, TriangleTable};

/// Slots closer than this are uploaded as one range: writing up to 64 unchanged triangles
/// (4.5 KiB) costs less than another staging copy.
const MERGE_GAP_SLOTS: u32 = 64;
const MIN_CAPACITY: u64 = 4096;

pub struct GpuTriangles {
    buffer: wgpu::Buffer,
    capacity: u64,
    /// Triangles to draw (the table's length, capped by the capacity the device allows).
    count: u32,
}

/// What one `sync` sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Upload {
    pub bytes: u64,
    pub writes: u32,
    pub full: bool,
}

impl GpuTriangles {
    pub fn new(device: &wgpu::Device) -> Self {
        GpuTriangles { buffer: create(device, MIN_CAPACITY), capacity: MIN_CAPACITY, count: 0 }
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    pub fn count(&self) -> u32 {
        self.count
    }

    /// Brings the GPU copy in line with `table`.
    pub fn sync(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        table: &mut TriangleTable,
    ) -> Upload {
        let len = table.len() as u64;
        let max = device.limits().max_buffer_size / TRIANGLE_BYTES;
        if len > self.capacity && self.capacity < max {
            self.capacity = len.next_power_of_two().clamp(MIN_CAPACITY, max);
            self.buffer = create(device, self.capacity);
            self.count = len.min(self.capacity) as u32;
            table.clear_dirty();
            if len > self.capacity {
                tracing::warn!(len, capacity = self.capacity, "device buffer limit: drawing a prefix");
            }
            return self.write(queue, table, 0..self.count, true);
        }
        self.count = len.min(self.capacity) as u32;
        let mut upload = Upload::default();
        for range in table.take_dirty_ranges(MERGE_GAP_SLOTS) {
            let range = range.start..range.end.min(self.count);
            if !range.is_empty() {
                let u = self.write(queue, table, range, false);
                upload.bytes += u.bytes;
                upload.writes += 1;
            }
        }
        upload
    }

    fn write(
        &self,
        queue: &wgpu::Queue,
        table: &TriangleTable,
        slots: std::ops::Range<u32>,
        full: bool,
    ) -> Upload {
        let bytes = table.slot_bytes(slots.clone());
        if !bytes.is_empty() {
            queue.write_buffer(&self.buffer, slots.start as u64 * TRIANGLE_BYTES, bytes);
        }
        Upload { bytes: bytes.len() as u64, writes: 1, full }
    }
}

fn create(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("triangle table"),
        size: capacity * TRIANGLE_BYTES,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}
