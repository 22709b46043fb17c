//! The headless wgpu device and an offscreen target with readback, shared by the ID pass and the
//! luminance pass (DESIGN.md §3 steps 2–3). Without a GPU wgpu finds Mesa (lavapipe through Vulkan
//! or llvmpipe through GL/EGL); `WGPU_BACKEND` picks one (DEPENDENCY-NOTES.md).

use std::sync::mpsc;

use thiserror::Error;

#[derive(Debug, Error)]
pub enum GpuError {
    #[error(
        "no graphics adapter found (no GPU, and no Mesa llvmpipe/lavapipe through GL/EGL or Vulkan): {0}"
    )]
    NoAdapter(String),
    #[error("could not open the graphics device: {0}")]
    Device(String),
    #[error("reading back the image failed: {0}")]
    Readback(String),
}

/// One device and queue, with what the adapter offers.
#[derive(Clone)]
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter: wgpu::AdapterInfo,
    /// The ID pass uses `@builtin(primitive_index)` (WGSL `enable primitive_index;`), else the
    /// vertex index.
    pub primitive_index: bool,
}

impl Gpu {
    /// The first adapter wgpu prefers (a real GPU when there is one), honouring `WGPU_BACKEND`.
    /// Triangle ids come from `@builtin(primitive_index)` on a GPU that offers it, from the vertex
    /// index on a software adapter (Mesa's lavapipe or llvmpipe): llvmpipe supplies
    /// `primitive_index` through an extra primitive-assembly stage that made the 1M-triangle pass
    /// 15–20% slower (DESIGN.md §3 step 2). A software adapter also tunes the process's allocator
    /// (`keep_pass_memory`).
    pub fn new() -> Result<Gpu, GpuError> {
        Self::open(None, None)
    }

    /// As [`Gpu::new`], but `primitive_index` says whether to use `@builtin(primitive_index)`
    /// where the adapter offers it (so tests can check both id paths on one adapter).
    pub fn with_primitive_index(primitive_index: bool) -> Result<Gpu, GpuError> {
        Self::open(Some(primitive_index), None)
    }

    /// As [`Gpu::new`], but on `backends` only, whatever `WGPU_BACKEND` says, so that one process
    /// can hold a GL and a Vulkan device side by side and compare their answers.
    pub fn on_backends(backends: wgpu::Backends) -> Result<Gpu, GpuError> {
        Self::open(None, Some(backends))
    }

    fn open(
        primitive_index: Option<bool>,
        backends: Option<wgpu::Backends>,
    ) -> Result<Gpu, GpuError> {
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle().with_env();
        if let Some(backends) = backends {
            descriptor.backends = backends;
        }
        let instance = wgpu::Instance::new(descriptor);
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let software = info.device_type == wgpu::DeviceType::Cpu;
        if software {
            keep_pass_memory();
        }
        let primitive_index = primitive_index.unwrap_or(!software)
            && adapter.features().contains(wgpu::Features::PRIMITIVE_INDEX);
        let required_features = if primitive_index {
            wgpu::Features::PRIMITIVE_INDEX
        } else {
            wgpu::Features::empty()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("sma visibility"),
            required_features,
            required_limits: adapter.limits(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Gpu {
            device,
            queue,
            adapter: info,
            primitive_index,
        })
    }

    /// "llvmpipe (LLVM 15.0.6, 256 bits) / Vulkan / Cpu, ids from vertex_index", for logs and
    /// benchmark tables.
    pub fn describe(&self) -> String {
        format!(
            "{} / {:?} / {:?}, ids from {}",
            self.adapter.name,
            self.adapter.backend,
            self.adapter.device_type,
            if self.primitive_index {
                "primitive_index"
            } else {
                "vertex_index"
            }
        )
    }

    /// A vertex buffer holding `bytes`, reusing `slot` when it is large enough.
    pub fn upload_into(&self, slot: &mut Option<wgpu::Buffer>, bytes: &[u8]) {
        let fits = slot
            .as_ref()
            .is_some_and(|b| b.size() >= bytes.len() as u64);
        if !fits {
            *slot = Some(
                self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("triangles"),
                    size: (bytes.len() as u64)
                        .max(16)
                        .next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
                    usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            );
        }
        if let Some(buffer) = slot.as_ref() {
            let len = bytes.len() - bytes.len() % wgpu::COPY_BUFFER_ALIGNMENT as usize;
            if len > 0 {
                self.queue.write_buffer(buffer, 0, &bytes[..len]);
            }
        }
    }
}

/// Mesa bins each pass's triangles in memory its draw thread mallocs and frees again at the end of
/// the pass; with glibc's default thresholds that memory goes back to the kernel every pass
/// (`madvise(MADV_DONTNEED)` of ~22 MB at 100k triangles) and the next pass faults it all in
/// again: about a third of a 100k-triangle ID pass (DESIGN.md §3 step 2). Pinning the thresholds
/// at the highest values glibc's own sliding rule reaches (mmap 32 MiB, trim twice that) keeps it
/// between passes. Process-wide, for every allocation.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_pass_memory() {
    // SAFETY: mallopt only sets allocator parameters, under the allocator's own lock.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 64 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_pass_memory() {}

/// Depth format of every pass. Reversed Z (cleared to 0, `Greater` wins) keeps float depth
/// precise far from the eye, so distant coplanar-ish surfaces do not fight in the ID buffer.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// A colour target of one 4-byte texel format, a depth buffer and a readback buffer, all of one
/// image size, with their views made once rather than every pass.
pub struct OffscreenTarget {
    pub width: u32,
    pub height: u32,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    readback: wgpu::Buffer,
    padded_row: u32,
}

impl OffscreenTarget {
    pub fn new(gpu: &Gpu, format: wgpu::TextureFormat, width: u32, height: u32) -> Self {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label, format, usage| {
            gpu.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let color = texture(
            "colour",
            format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let depth = texture(
            "depth",
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readback = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: padded_row as u64 * height as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        OffscreenTarget {
            width,
            height,
            color_view: color.create_view(&wgpu::TextureViewDescriptor::default()),
            depth_view: depth.create_view(&wgpu::TextureViewDescriptor::default()),
            color,
            readback,
            padded_row,
        }
    }

    /// Records one render pass that clears to zero and draws `vertex_count` vertices of
    /// `vertices` with `pipeline` and `bind_group`, then copies the colour into the readback
    /// buffer, submits, and returns the texels row by row without padding.
    pub fn draw_and_read<T: bytemuck::Pod>(
        &self,
        gpu: &Gpu,
        pipeline: &wgpu::RenderPipeline,
        bind_group: &wgpu::BindGroup,
        vertices: Option<&wgpu::Buffer>,
        vertex_count: u32,
    ) -> Result<Vec<T>, GpuError> {
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("offscreen pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(0.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let (Some(buffer), true) = (vertices, vertex_count > 0) {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind_group, &[]);
                pass.set_vertex_buffer(0, buffer.slice(..));
                pass.draw(0..vertex_count, 0..1);
            }
        }
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &self.color,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &self.readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
        gpu.queue.submit([encoder.finish()]);
        self.read_back(gpu)
    }

    fn read_back<T: bytemuck::Pod>(&self, gpu: &Gpu) -> Result<Vec<T>, GpuError> {
        let slice = self.readback.slice(..);
        // One message, the mapping's result: a channel of one slot.
        let (tx, rx) = mpsc::sync_channel(1);
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Readback(e.to_string()))?
            .map_err(|e| GpuError::Readback(e.to_string()))?;
        let mut texels = Vec::with_capacity((self.width * self.height) as usize);
        {
            let bytes = slice
                .get_mapped_range()
                .map_err(|e| GpuError::Readback(e.to_string()))?;
            let row_bytes = (self.width * 4) as usize;
            for row in bytes.chunks_exact(self.padded_row as usize) {
                texels.extend_from_slice(bytemuck::cast_slice::<u8, T>(&row[..row_bytes]));
            }
        }
        self.readback.unmap();
        Ok(texels)
    }
}

/// A uniform buffer holding one 4×4 matrix and its bind group layout entry.
pub struct MatrixUniform {
    pub buffer: wgpu::Buffer,
    pub layout: wgpu::BindGroupLayout,
    pub bind_group: wgpu::BindGroup,
}

impl MatrixUniform {
    pub fn new(gpu: &Gpu) -> Self {
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("view-projection"),
            size: 64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("view-projection"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                }],
            });
        let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view-projection"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: buffer.as_entire_binding(),
            }],
        });
        MatrixUniform {
            buffer,
            layout,
            bind_group,
        }
    }

    pub fn set(&self, gpu: &Gpu, m: glam::Mat4) {
        gpu.queue
            .write_buffer(&self.buffer, 0, bytemuck::cast_slice(&m.to_cols_array()));
    }

    /// A triangle-list pipeline writing one 4-byte `target` format, depth-tested with reversed Z,
    /// no culling (surfaces are two-sided, DESIGN.md §5).
    pub fn pipeline(
        &self,
        gpu: &Gpu,
        shader: &str,
        vertex_layout: wgpu::VertexBufferLayout<'_>,
        target: wgpu::TextureFormat,
    ) -> wgpu::RenderPipeline {
        let module = gpu
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("pass shader"),
                source: wgpu::ShaderSource::Wgsl(shader.into()),
            });
        let layout = gpu
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("pass layout"),
                bind_group_layouts: &[Some(&self.layout)],
                immediate_size: 0,
            });
        gpu.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("pass pipeline"),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(vertex_layout)],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Greater),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: target,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
    }
}
