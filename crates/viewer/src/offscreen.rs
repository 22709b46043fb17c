//! Offscreen drawing: the window's pass into textures, read back as a tone-mapped sRGB image and a
//! linear radiance image. Headless snapshots, tests and the end-to-end benchmark draw through here.

use anyhow::{Context, anyhow};
use protocol::viewer_link::{Camera, ShownTriangle};

use crate::direct_image::DirectImage;
use crate::direct_texture::GpuDirect;
use crate::draw::{DrawSettings, Drawer, Output, depth_range, depth_texture, texture_2d};
use crate::gpu::Gpu;
use crate::looks::Looks;
use crate::looks_texture::GpuLooks;
use crate::table::TriangleTable;
use crate::update::TableOp;
use crate::vertex_buffer::GpuTriangles;

/// The display image's format (what draws over it must match).
pub const DISPLAY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// Linear radiance in full float where the adapter can draw into it; GL (downlevel) cannot, and
/// gets half floats (11-bit mantissa: 0.05 % relative error, below any sample's noise).
const LINEAR_FORMATS: [wgpu::TextureFormat; 2] = [
    wgpu::TextureFormat::Rgba32Float,
    wgpu::TextureFormat::Rgba16Float,
];

/// What a picture draws: the triangles, the direct tiles of its camera if any, and the scene's
/// materials and textures.
pub type Layers<'a> = (&'a GpuTriangles, Option<&'a GpuDirect>, &'a GpuLooks);

/// Drawing recorded over the display image, given as a target view and its size in pixels.
pub type PaintOver<'a> = dyn FnMut(&mut wgpu::CommandEncoder, (&wgpu::TextureView, [u32; 2])) + 'a;

/// One snapshot of the viewer's image.
pub struct Snapshot {
    /// Tone-mapped, sRGB-encoded (what the window shows).
    pub display: image::RgbaImage,
    /// Linear radiance, row-major from the top-left pixel; the sky where no geometry is seen.
    pub linear: Vec<[f32; 3]>,
    /// Whether each pixel sees geometry (the linear target's alpha: the sky writes 0). The
    /// convergence metric leaves out pixels that see none (DESIGN.md §10); the EXR carries it as
    /// alpha.
    pub covered: Vec<bool>,
    pub width: u32,
    pub height: u32,
}

struct Target {
    view: wgpu::TextureView,
    texture: wgpu::Texture,
    drawer: Drawer,
    bytes_per_pixel: u32,
}

pub struct Offscreen {
    width: u32,
    height: u32,
    display: Target,
    linear: Target,
    depth: wgpu::TextureView,
}

impl Offscreen {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> Offscreen {
        let target = |format: wgpu::TextureFormat, output| {
            let texture = texture_2d(
                &gpu.device,
                "offscreen colour",
                (width, height),
                format,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            );
            Target {
                view: texture.create_view(&Default::default()),
                texture,
                drawer: Drawer::new(&gpu.device, format, output),
                bytes_per_pixel: format.block_copy_size(None).unwrap_or(4),
            }
        };
        Offscreen {
            width,
            height,
            display: target(DISPLAY_FORMAT, Output::Display),
            linear: target(linear_format(&gpu.adapter), Output::Linear),
            depth: depth_texture(&gpu.device, width, height),
        }
    }

    /// Draws one tone-mapped frame and waits for the GPU to finish it (frame-time benchmark).
    pub fn draw_frame(
        &self,
        gpu: &Gpu,
        layers: Layers,
        camera: &Camera,
        depth: (f32, f32),
        settings: &DrawSettings,
    ) -> anyhow::Result<()> {
        self.draw_into(gpu, &[&self.display], layers, camera, depth, settings);
        gpu.wait_idle()
    }

    /// Draws both images and reads them back, with `direct`'s tiles where it holds some of this
    /// picture. The camera's own size is ignored: the target's is used (a camera sent to the SMA
    /// carries the same size anyway).
    pub fn snapshot(
        &self,
        gpu: &Gpu,
        layers: Layers,
        camera: &Camera,
        depth: (f32, f32),
        settings: &DrawSettings,
    ) -> anyhow::Result<Snapshot> {
        self.snapshot_painted(gpu, layers, camera, depth, settings, &mut |_, _| {})
    }

    /// [`Offscreen::snapshot`], with `paint` recording more drawing over the display image
    /// (the panel of `--overlay`; the linear image stays clean).
    pub fn snapshot_painted(
        &self,
        gpu: &Gpu,
        layers: Layers,
        camera: &Camera,
        depth: (f32, f32),
        settings: &DrawSettings,
        paint: &mut PaintOver,
    ) -> anyhow::Result<Snapshot> {
        self.draw_into(
            gpu,
            &[&self.display, &self.linear],
            layers,
            camera,
            depth,
            settings,
        );
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        paint(
            &mut encoder,
            (&self.display.view, [self.width, self.height]),
        );
        gpu.queue.submit([encoder.finish()]);
        let display = self.read(gpu, &self.display)?;
        let linear = self.read(gpu, &self.linear)?;
        let display = image::RgbaImage::from_raw(self.width, self.height, display)
            .ok_or_else(|| anyhow!("display readback has the wrong size"))?;
        let (linear, covered) = linear_rgba(&linear, self.linear.bytes_per_pixel)
            .into_iter()
            .map(|[r, g, b, a]| ([r, g, b], a > 0.5))
            .unzip();
        Ok(Snapshot {
            display,
            linear,
            covered,
            width: self.width,
            height: self.height,
        })
    }

    /// Draws into each of `targets`, at the targets' size, and submits the work.
    fn draw_into(
        &self,
        gpu: &Gpu,
        targets: &[&Target],
        (triangles, direct, looks): Layers,
        camera: &Camera,
        depth: (f32, f32),
        settings: &DrawSettings,
    ) {
        let camera = Camera {
            width: self.width,
            height: self.height,
            ..camera.clone()
        };
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        for target in targets {
            target.drawer.draw(
                &gpu.queue,
                &mut encoder,
                &target.view,
                &self.depth,
                triangles,
                (direct, looks),
                &camera,
                depth,
                settings,
            );
        }
        gpu.queue.submit([encoder.finish()]);
    }

    /// Copies a target into a mappable buffer and returns its rows without padding.
    fn read(&self, gpu: &Gpu, target: &Target) -> anyhow::Result<Vec<u8>> {
        let row = self.width * target.bytes_per_pixel;
        let padded_row =
            row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: padded_row as u64 * self.height as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            target.texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_row),
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
        // The mapping's callback runs once: room for its one answer.
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.wait_idle()?;
        rx.recv()
            .context("readback callback dropped")?
            .context("mapping the readback")?;
        let mapped = buffer
            .get_mapped_range(..)
            .map_err(|e| anyhow!("readback: {e:?}"))?;
        let mut pixels = Vec::with_capacity((row * self.height) as usize);
        for y in 0..self.height as usize {
            let start = y * padded_row as usize;
            pixels.extend_from_slice(&mapped[start..start + row as usize]);
        }
        Ok(pixels)
    }
}

fn linear_format(adapter: &wgpu::Adapter) -> wgpu::TextureFormat {
    let renderable = |f: &wgpu::TextureFormat| {
        let usages = adapter.get_texture_format_features(*f).allowed_usages;
        usages.contains(wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC)
    };
    LINEAR_FORMATS
        .into_iter()
        .find(renderable)
        .unwrap_or(LINEAR_FORMATS[1])
}

/// RGBA pixels of 32-bit or 16-bit floats.
fn linear_rgba(bytes: &[u8], bytes_per_pixel: u32) -> Vec<[f32; 4]> {
    if bytes_per_pixel == 16 {
        bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(bytes)
    } else {
        bytemuck::pod_collect_to_vec::<u8, [u16; 4]>(bytes)
            .into_iter()
            .map(|px| px.map(|h| exr::prelude::f16::from_bits(h).to_f32()))
            .collect()
    }
}

/// Draws `triangles` as the viewer would, seen by `camera` at the camera's image size, on `gpu`
/// (tests compare it with what a running viewer drew).
pub fn render_offscreen_with(
    gpu: &Gpu,
    triangles: &[ShownTriangle],
    camera: &Camera,
    settings: &DrawSettings,
) -> anyhow::Result<Snapshot> {
    render_offscreen_with_direct(gpu, triangles, &DirectImage::default(), camera, settings)
}

/// [`render_offscreen_with`], with the direct tiles of `direct` where a picture of `camera` shows
/// them (`DirectImage::shown_for`).
pub fn render_offscreen_with_direct(
    gpu: &Gpu,
    triangles: &[ShownTriangle],
    direct: &DirectImage,
    camera: &Camera,
    settings: &DrawSettings,
) -> anyhow::Result<Snapshot> {
    render_offscreen_with_looks(
        gpu,
        triangles,
        (&Looks::default(), direct),
        camera,
        settings,
    )
}

/// [`render_offscreen_with_direct`], with the materials and textures of `looks` (without, every
/// triangle's albedo is one).
pub fn render_offscreen_with_looks(
    gpu: &Gpu,
    triangles: &[ShownTriangle],
    (looks, direct): (&Looks, &DirectImage),
    camera: &Camera,
    settings: &DrawSettings,
) -> anyhow::Result<Snapshot> {
    let mut table = TriangleTable::new();
    table.apply(&[TableOp::Insert(triangles.to_vec())]);
    let mut gpu_triangles = GpuTriangles::new(gpu);
    gpu_triangles.sync(gpu, &mut table);
    let offscreen = Offscreen::new(gpu, camera.width.max(1), camera.height.max(1));
    let depth = depth_range(camera, table.extent());
    let mut gpu_direct = GpuDirect::new(&gpu.device);
    if direct.shown_for(camera) {
        gpu_direct.upload(gpu, direct);
    }
    let mut gpu_looks = GpuLooks::new(gpu);
    gpu_looks.sync(gpu, looks);
    offscreen.snapshot(
        gpu,
        (&gpu_triangles, Some(&gpu_direct), &gpu_looks),
        camera,
        depth,
        settings,
    )
}
