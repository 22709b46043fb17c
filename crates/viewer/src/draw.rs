//! The drawing pass: Gouraud-interpolated vertex illumination times each pixel's albedo (the
//! material's factor and texture, `looks_texture`) plus the view-dependent radiance, tone-mapped
//! in the shader (`draw.wgsl`), with an optional wireframe overlay to see the refinement mesh,
//! and where a resting camera's per-pixel direct tiles have arrived, their direct part in place
//! of the vertices' (`direct_texture`).
//! The same pass draws into a window surface and into offscreen targets.

use bytemuck::{Pod, Zeroable};
use conventions::ToneMap;
use glam::Vec3;
use protocol::viewer_link::{Camera, SkyInfo};

use crate::direct_texture::{self, GpuDirect};
use crate::looks_texture::{self, GpuLooks};
use crate::table::{Extent, Vertex};
use crate::vertex_buffer::GpuTriangles;

pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// What a drawing pass writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// Tone-mapped colour for display (PNG snapshots, the window).
    Display,
    /// Linear radiance, untouched (EXR snapshots).
    Linear,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DrawSettings {
    pub tone_map: ToneMap,
    /// The smallest luminance mapped to pure white, as the SMA last sent it (thesis §2.3).
    pub l_white: f32,
    pub wireframe: bool,
    /// Drawn behind the geometry; the default is black (a scene without a sky).
    pub sky: SkyInfo,
}

impl Default for DrawSettings {
    fn default() -> Self {
        DrawSettings {
            tone_map: ToneMap::Drago,
            l_white: 1.0,
            wireframe: false,
            sky: SkyInfo::default(),
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Uniforms {
    view_proj: [[f32; 4]; 4],
    l_white: f32,
    mode: u32,
    wireframe: u32,
    encode_srgb: u32,
    right: [f32; 4],
    up: [f32; 4],
    forward: [f32; 4],
    sky: [f32; 4],
    sun_dir: [f32; 4],
    sun_radiance: [f32; 4],
    /// 1 where the direct texture holds tiles of this picture (`direct_image`).
    tiles: u32,
    _pad: [u32; 3],
}

impl Uniforms {
    /// The eye ray basis of `draw.wgsl`'s sky: right and up scaled to the image's half extent
    /// at unit distance along the view direction.
    fn set_sky(&mut self, camera: &Camera, sky: &SkyInfo) {
        let pinhole = camera.pinhole();
        let rotation = pinhole.rotation;
        let half_height = pinhole.half_height();
        let half_width = half_height * pinhole.aspect();
        let w0 = |v: Vec3| v.extend(0.0).to_array();
        self.right = w0(rotation * Vec3::X * half_width);
        self.up = w0(rotation * Vec3::Y * half_height);
        self.forward = w0(rotation * Vec3::NEG_Z);
        self.sky = w0(Vec3::from(sky.radiance));
        if let Some(sun) = &sky.sun {
            let one_minus_cos = 1.0 - (0.5 * sun.angular_diameter_deg.to_radians()).cos();
            self.sun_dir = Vec3::from(sun.direction)
                .normalize()
                .extend(one_minus_cos)
                .to_array();
            self.sun_radiance = w0(Vec3::from(sun.radiance));
        }
    }
}

/// One pipeline for one target format, with its uniforms.
pub struct Drawer {
    pipeline: wgpu::RenderPipeline,
    sky: wgpu::RenderPipeline,
    uniforms: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    output: Output,
    encode_srgb: bool,
    /// Bound when a frame has no direct tiles.
    no_tiles: GpuDirect,
}

impl Drawer {
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat, output: Output) -> Drawer {
        let shader = device.create_shader_module(wgpu::include_wgsl!("draw.wgsl"));
        let uniforms = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("draw uniforms"),
            size: std::mem::size_of::<Uniforms>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("draw uniforms"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("draw uniforms"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniforms.as_entire_binding(),
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("draw"),
            bind_group_layouts: &[
                Some(&layout),
                Some(&direct_texture::layout(device)),
                Some(&looks_texture::layout(device)),
            ],
            immediate_size: 0,
        });
        let sky = pipeline(device, &pipeline_layout, &shader, format, Pass::Sky);
        let pipeline = pipeline(device, &pipeline_layout, &shader, format, Pass::Geometry);
        let encode_srgb = output == Output::Display && !format.is_srgb();
        Drawer {
            pipeline,
            sky,
            uniforms,
            bind_group,
            output,
            encode_srgb,
            no_tiles: GpuDirect::new(device),
        }
    }

    /// Records one frame: the sky over the whole target, then every live triangle over it, with
    /// the albedo of `looks`, and the per-pixel direct light of `direct` where it holds tiles of
    /// this picture (the caller passes it only for the camera its tiles are of:
    /// `DirectImage::shown_for`).
    #[allow(clippy::too_many_arguments)]
    pub fn draw(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        colour: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        triangles: &GpuTriangles,
        (direct, looks): (Option<&GpuDirect>, &GpuLooks),
        camera: &Camera,
        depth_range: (f32, f32),
        settings: &DrawSettings,
    ) {
        let (near, far) = depth_range;
        let mut uniforms = Uniforms {
            // Reversed Z (near -> 1, far -> 0): with a float depth buffer the precision then
            // follows the float's own, so a tiny near plane costs nothing far away. Positions
            // are relative to the buffer's origin (`vertex_buffer`), so the matrix is too.
            view_proj: camera
                .pinhole()
                .view_projection_from(triangles.origin(), far, near)
                .to_cols_array_2d(),
            l_white: settings.l_white.max(1e-6),
            mode: match (self.output, settings.tone_map) {
                (Output::Linear, _) => 0,
                (Output::Display, ToneMap::Drago) => 1,
                (Output::Display, ToneMap::Reinhard) => 2,
            },
            wireframe: u32::from(settings.wireframe),
            encode_srgb: u32::from(self.encode_srgb),
            ..Zeroable::zeroed()
        };
        let direct = direct
            .filter(|d| d.shows((camera.width, camera.height)))
            .inspect(|_| uniforms.tiles = 1)
            .unwrap_or(&self.no_tiles);
        uniforms.set_sky(camera, &settings.sky);
        queue.write_buffer(&self.uniforms, 0, bytemuck::bytes_of(&uniforms));
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("draw"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: colour,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
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
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_bind_group(1, direct.bind_group(), &[]);
        pass.set_bind_group(2, looks.bind_group(), &[]);
        pass.set_pipeline(&self.sky);
        pass.draw(0..3, 0..1);
        if triangles.count() > 0 {
            pass.set_pipeline(&self.pipeline);
            pass.set_vertex_buffer(0, triangles.buffer().slice(..));
            pass.draw(0..3 * triangles.count(), 0..1);
        }
    }
}

/// The two pipelines of a frame.
#[derive(Clone, Copy, PartialEq)]
enum Pass {
    /// Behind everything: no vertex buffer, no depth test or write.
    Sky,
    /// The triangle table, depth-tested (reversed Z: greater is nearer).
    Geometry,
}

fn pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    shader: &wgpu::ShaderModule,
    format: wgpu::TextureFormat,
    pass: Pass,
) -> wgpu::RenderPipeline {
    let geometry = pass == Pass::Geometry;
    let vertex_layout = [Some(wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &wgpu::vertex_attr_array![
            0 => Float32x3,
            1 => Float32x3,
            2 => Float32,
            3 => Float32x3,
            4 => Uint16x2,
            5 => Uint32,
        ],
    })];
    let (vertex_entry, fragment_entry) = if geometry {
        ("vs_main", "fs_main")
    } else {
        ("vs_sky", "fs_sky")
    };
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(if geometry { "draw" } else { "sky" }),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module: shader,
            entry_point: Some(vertex_entry),
            compilation_options: Default::default(),
            buffers: if geometry { &vertex_layout } else { &[] },
        },
        // Surfaces are two-sided (DESIGN.md §5): no culling.
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(geometry),
            depth_compare: Some(if geometry {
                wgpu::CompareFunction::Greater
            } else {
                wgpu::CompareFunction::Always
            }),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: shader,
            entry_point: Some(fragment_entry),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A single-sample 2D texture: the shape of every target the viewer draws into.
pub fn texture_2d(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A depth texture matching a colour target.
pub fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::TextureView {
    texture_2d(
        device,
        "depth",
        (width, height),
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    )
    .create_view(&Default::default())
}

/// Near and far planes that hold the whole scene in front of the eye: far reaches the farthest
/// corner of the box, near is a small fraction of it (reversed Z keeps 1:10⁵ well resolved).
pub fn depth_range(camera: &Camera, extent: Option<Extent>) -> (f32, f32) {
    let far = extent
        .map(|e| {
            let (lo, hi) = (Vec3::from(e.min), Vec3::from(e.max));
            let reach = (camera.eye_vec() - (lo + hi) * 0.5).abs() + (hi - lo) * 0.5;
            reach.length() * 1.01
        })
        .filter(|f| f.is_finite() && *f > 0.0)
        .unwrap_or(1000.0);
    (far * 1e-5, far)
}
