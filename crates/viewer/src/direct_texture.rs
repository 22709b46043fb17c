//! The GPU copy of the [`DirectImage`]: an `Rgba32Float` texture of the camera's size that
//! `draw.wgsl` reads with `textureLoad` (bind group 1). Full floats need no filtering, which GL
//! (llvmpipe through EGL) and Vulkan both allow for a sampled texture; a tile's texels are written
//! with `queue.write_texture` as they arrive, straight from the image's rows.

use crate::direct_image::{DirectImage, DirectTexel};
use crate::draw::texture_2d;
use crate::gpu::Gpu;

const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const TEXEL_BYTES: u32 = std::mem::size_of::<DirectTexel>() as u32;

/// The layout of bind group 1 of the drawing pass: the direct texture.
pub fn layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("direct tiles"),
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        }],
    })
}

/// The direct texture and its bind group.
pub struct GpuDirect {
    texture: wgpu::Texture,
    bind_group: wgpu::BindGroup,
    /// The image generation (`DirectImage::generation`) whose tiles the texture holds, up to
    /// the last upload.
    holds: Option<u64>,
}

impl GpuDirect {
    /// A 1×1 texture until an image with tiles is uploaded.
    pub fn new(device: &wgpu::Device) -> GpuDirect {
        let (texture, bind_group) = create(device, (1, 1));
        GpuDirect {
            texture,
            bind_group,
            holds: None,
        }
    }

    /// The texture's size in pixels.
    pub fn size(&self) -> (u32, u32) {
        (self.texture.width(), self.texture.height())
    }

    /// Whether the texture holds tiles for a picture of `width × height`.
    pub fn shows(&self, (width, height): (u32, u32)) -> bool {
        self.holds.is_some() && self.size() == (width, height)
    }

    pub fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }

    /// Brings the texture up to `image`: the tiles that arrived since the last call (the window,
    /// which keeps one image), or the whole image when its size or camera changed.
    pub fn sync(&mut self, gpu: &Gpu, image: &mut DirectImage) {
        let dirty = image.take_dirty();
        let Some(size) = image.size() else {
            self.holds = None;
            return;
        };
        if self.holds != Some(image.generation()) || size != self.size() {
            self.upload(gpu, image);
            return;
        }
        for rect in dirty {
            write(
                gpu,
                &self.texture,
                image,
                [rect.x, rect.y],
                [rect.width, rect.height],
            );
        }
    }

    /// Writes all of `image` (a snapshot's copy).
    pub fn upload(&mut self, gpu: &Gpu, image: &DirectImage) {
        let Some(size) = image.size() else {
            self.holds = None;
            return;
        };
        if size != self.size() {
            (self.texture, self.bind_group) = create(&gpu.device, size);
        }
        write(gpu, &self.texture, image, [0, 0], [size.0, size.1]);
        self.holds = Some(image.generation());
    }
}

fn create(device: &wgpu::Device, size: (u32, u32)) -> (wgpu::Texture, wgpu::BindGroup) {
    let texture = texture_2d(
        device,
        "direct tiles",
        size,
        FORMAT,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    let view = texture.create_view(&Default::default());
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("direct tiles"),
        layout: &layout(device),
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::TextureView(&view),
        }],
    });
    (texture, bind_group)
}

/// Writes the rectangle at `origin` of `extent` pixels from the image's rows.
fn write(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    image: &DirectImage,
    origin: [u32; 2],
    extent: [u32; 2],
) {
    let Some((width, _)) = image.size() else {
        return;
    };
    let offset = (origin[1] as u64 * width as u64 + origin[0] as u64) * TEXEL_BYTES as u64;
    gpu.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: origin[0],
                y: origin[1],
                z: 0,
            },
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(image.texels()),
        wgpu::TexelCopyBufferLayout {
            offset,
            bytes_per_row: Some(width * TEXEL_BYTES),
            rows_per_image: None,
        },
        wgpu::Extent3d {
            width: extent[0],
            height: extent[1],
            depth_or_array_layers: 1,
        },
    );
}
