//! The GPU copy of the triangle table. Between frames only the slots the last updates touched are
//! sent: runs of neighbouring slots (new triangles appended at the end) with `queue.write_buffer`,
//! and scattered single slots (a removal fills its hole with the last triangle, a recolour hits
//! any slot) packed into one list that a compute pass (`scatter.wgsl`) writes into place — one
//! buffer write per scattered slot would cost more than the data. The whole table is sent only
//! when the buffer grows, which doubling makes rare (amortised O(1) per triangle).
//!
//! Positions go up relative to an origin, a point of the scene fixed for the table's life, and
//! the drawing's matrix is built for it (`conventions::camera`): far from the world origin (1e5,
//! where f32 spacing is about 0.008) the picture is that of a centred scene (DESIGN.md §7). The
//! origin is not the eye itself, or every camera move would re-send the whole table; a point of
//! the scene is as close to the eye as the scene is large, and that is all the precision needs.

use conventions::camera::relative_to;
use glam::DVec3;

use crate::gpu::Gpu;
use crate::table::{Extent, TRIANGLE_BYTES, TriangleTable, Vertex};

const MIN_CAPACITY: u64 = 4096;
/// Runs at least this long go through `write_buffer`; shorter ones are scattered.
const LONG_RUN_SLOTS: u32 = 32;
/// Without the compute pass: slots closer than this are written as one range (rewriting up to 64
/// unchanged triangles, 4.5 KiB, costs less than another staging copy).
const MERGE_GAP_SLOTS: u32 = 64;
/// A patch: the slot, then its three vertices' words (`scatter.wgsl` reads the same count).
const PATCH_WORDS: usize = 1 + 3 * std::mem::size_of::<Vertex>() / 4;
const WORKGROUP: u32 = 64;

pub struct GpuTriangles {
    buffer: wgpu::Buffer,
    capacity: u64,
    /// Triangles to draw (the table's length, capped by the capacity the device allows).
    count: u32,
    /// None where the adapter has no compute shaders (or the buffer outgrew a storage binding).
    scatter: Option<Scatter>,
    /// The table outgrew the device's largest buffer at the last sync.
    truncated: bool,
    /// What positions are relative to: the centre of the table's extent at the first sync that
    /// found triangles; chosen again after a sync that found none.
    origin: Option<DVec3>,
}

/// What one `sync` sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Upload {
    pub bytes: u64,
    /// `write_buffer` calls.
    pub writes: u32,
    /// Slots written by the compute pass.
    pub scattered: u32,
    pub full: bool,
}

impl GpuTriangles {
    pub fn new(gpu: &Gpu) -> Self {
        let compute = gpu
            .adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::COMPUTE_SHADERS)
            && gpu.device.limits().max_storage_buffers_per_shader_stage >= 2;
        GpuTriangles {
            buffer: create(&gpu.device, MIN_CAPACITY),
            capacity: MIN_CAPACITY,
            count: 0,
            scatter: compute.then(|| Scatter::new(&gpu.device)),
            truncated: false,
            origin: None,
        }
    }

    /// The point positions on the GPU are relative to.
    pub fn origin(&self) -> DVec3 {
        self.origin.unwrap_or(DVec3::ZERO)
    }

    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    pub fn count(&self) -> u32 {
        self.count
    }

    /// Brings the GPU copy in line with `table`.
    pub fn sync(&mut self, gpu: &Gpu, table: &mut TriangleTable) -> Upload {
        let len = table.len() as u64;
        // Every live slot was written since a sync that found none, so all go up relative to
        // the new origin.
        self.place_origin(len, table.extent());
        let origin = self.origin();
        let grow = self.grow_for(gpu, len);
        // A table larger than the largest buffer the device allows is drawn as a prefix; changes
        // past it are dropped, so the first sync that fits again sends everything.
        let refill = self.truncated && len <= self.capacity;
        self.truncated = len > self.capacity;
        if self.truncated {
            tracing::warn!(
                len,
                capacity = self.capacity,
                "device buffer limit: drawing a prefix"
            );
        }
        if grow || refill {
            self.count = len.min(self.capacity) as u32;
            table.clear_dirty();
            let bytes = write(
                &gpu.queue,
                &self.buffer,
                table.vertices(),
                0..self.count,
                origin,
            );
            return Upload {
                bytes,
                writes: 1,
                scattered: 0,
                full: true,
            };
        }
        self.count = len.min(self.capacity) as u32;
        let storage_fits =
            self.capacity * TRIANGLE_BYTES <= gpu.device.limits().max_storage_buffer_binding_size;
        let scatter = self.scatter.as_mut().filter(|_| storage_fits);
        let gap = if scatter.is_some() {
            0
        } else {
            MERGE_GAP_SLOTS
        };
        let mut upload = Upload::default();
        let mut patches: Vec<u32> = Vec::new();
        for range in table.take_dirty_ranges(gap) {
            let range = range.start..range.end.min(self.count);
            if range.is_empty() {
                continue;
            }
            if scatter.is_some() && range.len() < LONG_RUN_SLOTS as usize {
                for slot in range {
                    patches.push(slot);
                    patches.extend_from_slice(bytemuck::cast_slice(&relative_vertices(
                        table.vertices(),
                        slot..slot + 1,
                        origin,
                    )));
                }
            } else {
                upload.bytes += write(&gpu.queue, &self.buffer, table.vertices(), range, origin);
                upload.writes += 1;
            }
        }
        if let Some(scatter) = scatter
            && !patches.is_empty()
        {
            upload.scattered = (patches.len() / PATCH_WORDS) as u32;
            upload.bytes += 4 * patches.len() as u64;
            scatter.run(gpu, &self.buffer, &patches);
        }
        upload
    }

    /// Makes the GPU copy hold exactly `vertices` (three per triangle) at once, as a whole: for
    /// a copy of the table taken elsewhere (a headless snapshot), which no dirty slots describe.
    pub fn replace(&mut self, gpu: &Gpu, vertices: &[Vertex], extent: Option<Extent>) -> Upload {
        let len = (vertices.len() / 3) as u64;
        self.place_origin(len, extent);
        self.grow_for(gpu, len);
        self.truncated = len > self.capacity;
        self.count = len.min(self.capacity) as u32;
        let bytes = write(
            &gpu.queue,
            &self.buffer,
            vertices,
            0..self.count,
            self.origin(),
        );
        Upload {
            bytes,
            writes: 1,
            scattered: 0,
            full: true,
        }
    }

    /// No origin while the table is empty; the centre of its extent once it holds triangles.
    fn place_origin(&mut self, len: u64, extent: Option<Extent>) {
        if len == 0 {
            self.origin = None;
        } else if self.origin.is_none() {
            self.origin = extent.map(|e| {
                0.5 * (glam::Vec3::from(e.min).as_dvec3() + glam::Vec3::from(e.max).as_dvec3())
            });
        }
    }

    /// Doubles the buffer (a fresh, empty one) until `len` triangles fit or the device's limit
    /// is reached; whether it did.
    fn grow_for(&mut self, gpu: &Gpu, len: u64) -> bool {
        let max = gpu.device.limits().max_buffer_size / TRIANGLE_BYTES;
        let grow = len > self.capacity && self.capacity < max;
        if grow {
            self.capacity = len.next_power_of_two().clamp(MIN_CAPACITY, max);
            self.buffer = create(&gpu.device, self.capacity);
            if let Some(s) = &mut self.scatter {
                s.bind_group = None;
            }
        }
        grow
    }
}

fn write(
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    vertices: &[Vertex],
    slots: std::ops::Range<u32>,
    origin: DVec3,
) -> u64 {
    let vertices = relative_vertices(vertices, slots.clone(), origin);
    let bytes: &[u8] = bytemuck::cast_slice(&vertices);
    if !bytes.is_empty() {
        queue.write_buffer(buffer, slots.start as u64 * TRIANGLE_BYTES, bytes);
    }
    bytes.len() as u64
}

/// The vertices of `slots` as the GPU holds them: positions relative to `origin`.
fn relative_vertices(
    vertices: &[Vertex],
    slots: std::ops::Range<u32>,
    origin: DVec3,
) -> Vec<Vertex> {
    vertices[3 * slots.start as usize..3 * slots.end as usize]
        .iter()
        .map(|v| Vertex {
            position: relative_to(glam::Vec3::from(v.position), origin).to_array(),
            ..*v
        })
        .collect()
}

fn create(device: &wgpu::Device, capacity: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("triangle table"),
        size: capacity * TRIANGLE_BYTES,
        usage: wgpu::BufferUsages::VERTEX
            | wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// The compute pass that writes scattered slots, with its patch list buffer.
struct Scatter {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    patches: wgpu::Buffer,
    /// Bound to the current patch and vertex buffers; rebuilt when either is replaced.
    bind_group: Option<wgpu::BindGroup>,
}

impl Scatter {
    fn new(device: &wgpu::Device) -> Scatter {
        let shader = device.create_shader_module(wgpu::include_wgsl!("scatter.wgsl"));
        let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("scatter"),
            entries: &[
                storage(0, true),
                storage(1, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("scatter"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("scatter"),
            layout: Some(&pipeline_layout),
            module: &shader,
            entry_point: Some("scatter"),
            compilation_options: Default::default(),
            cache: None,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("scatter params"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let patches = patch_buffer(device, 1024);
        Scatter {
            pipeline,
            layout,
            params,
            patches,
            bind_group: None,
        }
    }

    fn run(&mut self, gpu: &Gpu, vertices: &wgpu::Buffer, patches: &[u32]) {
        let bytes: &[u8] = bytemuck::cast_slice(patches);
        if self.patches.size() < bytes.len() as u64 {
            self.patches = patch_buffer(
                &gpu.device,
                (patches.len() / PATCH_WORDS).next_power_of_two(),
            );
            self.bind_group = None;
        }
        let count = (patches.len() / PATCH_WORDS) as u32;
        let max_x = gpu
            .device
            .limits()
            .max_compute_workgroups_per_dimension
            .max(1);
        let groups = count.div_ceil(WORKGROUP);
        let (x, y) = (groups.min(max_x), groups.div_ceil(max_x));
        gpu.queue.write_buffer(&self.patches, 0, bytes);
        gpu.queue.write_buffer(
            &self.params,
            0,
            bytemuck::cast_slice(&[count, x * WORKGROUP, 0, 0]),
        );
        let bind_group = self.bind_group.get_or_insert_with(|| {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("scatter"),
                layout: &self.layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: self.patches.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: vertices.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: self.params.as_entire_binding(),
                    },
                ],
            })
        });
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &*bind_group, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        gpu.queue.submit([encoder.finish()]);
    }
}

fn patch_buffer(device: &wgpu::Device, patches: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("scatter patches"),
        size: (patches.max(1) * PATCH_WORDS * 4) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

#[cfg(test)]
mod tests {
    use protocol::texture::Texcoords;
    use protocol::viewer_link::{CornerShading, DirectShare, Recolour, ShownTriangle};

    use super::*;
    use crate::gpu::headless_or_skip;
    use crate::update::TableOp;

    fn triangle(id: u64) -> ShownTriangle {
        let v = id as f32;
        ShownTriangle {
            id,
            positions: [[v, 1.0, 2.0], [3.0, v, 4.0], [5.0, 6.0, v]],
            material: id as u16,
            texcoords: Texcoords::encode([[v, 0.0], [v + 0.5, 0.0], [v, 0.5]], false),
            shading: CornerShading {
                illumination: [[v * 0.5; 3], [1.0, v, 2.0], [v, 0.25, 0.125]],
                direct_share: [DirectShare(id as u8); 3],
                view_dependent: Some([[v; 3]; 3]),
            },
        }
    }

    fn read_back(gpu: &Gpu, buffer: &wgpu::Buffer, bytes: u64) -> Vec<u8> {
        let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes.max(4),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        staging
            .slice(..)
            .map_async(wgpu::MapMode::Read, |r| r.unwrap());
        gpu.wait_idle().unwrap();
        staging.get_mapped_range(..bytes).unwrap().to_vec()
    }

    /// Random inserts, removes and recolours, synced after each batch, leave the GPU copy equal
    /// to the table, with and without the compute scatter.
    #[test]
    fn gpu_copy_follows_the_table() {
        let Some(gpu) = headless_or_skip("gpu_copy_follows_the_table").unwrap() else {
            return;
        };
        for use_scatter in [true, false] {
            let mut gpu_triangles = GpuTriangles::new(&gpu);
            if !use_scatter {
                gpu_triangles.scatter = None;
            }
            let mut table = TriangleTable::new();
            let mut state = 12345u64;
            let mut next = move |n: u64| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (state >> 33) % n
            };
            let mut scattered = 0;
            for batch in 0..12u64 {
                let inserts = (0..3000).map(|i| triangle(batch * 10_000 + i)).collect();
                let held = table.ids().to_vec();
                let removes = (0..800)
                    .filter_map(|_| held.get(next(held.len().max(1) as u64) as usize))
                    .copied()
                    .collect();
                let recolours = (0..500)
                    .filter_map(|_| {
                        let id = *held.get(next(held.len().max(1) as u64) as usize)?;
                        Some(Recolour {
                            id,
                            shading: CornerShading {
                                illumination: [[next(100) as f32; 3]; 3],
                                ..CornerShading::default()
                            },
                        })
                    })
                    .collect();
                table.apply(&[
                    TableOp::Insert(inserts),
                    TableOp::Remove(removes),
                    TableOp::Recolour(recolours),
                ]);
                scattered += gpu_triangles.sync(&gpu, &mut table).scattered;
                let bytes = table.len() as u64 * TRIANGLE_BYTES;
                let on_gpu = read_back(&gpu, gpu_triangles.buffer(), bytes);
                let origin = gpu_triangles.origin();
                let want: Vec<Vertex> = table
                    .vertices()
                    .iter()
                    .map(|v| Vertex {
                        position: (glam::Vec3::from(v.position).as_dvec3() - origin)
                            .as_vec3()
                            .to_array(),
                        ..*v
                    })
                    .collect();
                assert!(
                    on_gpu == bytemuck::cast_slice::<Vertex, u8>(&want),
                    "batch {batch}, scatter {use_scatter}"
                );
                assert_eq!(gpu_triangles.count() as usize, table.len());
            }
            assert_eq!(
                scattered > 0,
                use_scatter && gpu_triangles.scatter.is_some()
            );
        }
    }

    /// A whole copy replaces what the GPU held, however much it was, and keeps the origin a
    /// synced table chose.
    #[test]
    fn a_replaced_copy_holds_exactly_the_given_vertices() {
        let Some(gpu) =
            headless_or_skip("a_replaced_copy_holds_exactly_the_given_vertices").unwrap()
        else {
            return;
        };
        let mut big = TriangleTable::new();
        big.apply(&[TableOp::Insert((0..5000).map(triangle).collect())]);
        let mut gpu_triangles = GpuTriangles::new(&gpu);
        gpu_triangles.sync(&gpu, &mut big);
        let origin = gpu_triangles.origin();
        let mut small = TriangleTable::new();
        small.apply(&[TableOp::Insert((7..10).map(triangle).collect())]);
        let upload = gpu_triangles.replace(&gpu, small.vertices(), small.extent());
        assert!(upload.full);
        assert_eq!(gpu_triangles.count(), 3);
        assert_eq!(gpu_triangles.origin(), origin);
        let on_gpu = read_back(&gpu, gpu_triangles.buffer(), 3 * TRIANGLE_BYTES);
        let want = relative_vertices(small.vertices(), 0..3, origin);
        assert!(on_gpu == bytemuck::cast_slice::<Vertex, u8>(&want));
        gpu_triangles.replace(&gpu, &[], None);
        assert_eq!(gpu_triangles.count(), 0);
        assert_eq!(
            gpu_triangles.origin(),
            DVec3::ZERO,
            "an empty copy has no origin"
        );
    }
}
