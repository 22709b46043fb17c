//! The GPU copy of the [`Looks`] (bind group 2 of the drawing pass, DESIGN.md §5): the material
//! table, one `Rgba32Float` texel per material read with `textureLoad` in the vertex shader, and
//! every texture in one `texture_2d_array` of sRGB texels with its full mip chain, sampled
//! trilinearly, repeating, anisotropically where the adapter offers it (Vulkan on lavapipe
//! does; GL on llvmpipe may not). Rebuilt when the looks change, which is when a texture
//! arrives: before the session's first triangle.

use crate::gpu::Gpu;
use crate::looks::{Layers, Looks, MaterialTexel, chain_bytes, layer_side, mip_levels};

/// Materials per row of the material table.
pub const MATERIALS_PER_ROW: u32 = 256;
/// The most memory the texture array may take: larger sets are drawn at a smaller side.
const TEXTURE_BUDGET_BYTES: u64 = 256 << 20;
/// The most a layer's side may be (the SMA sends at most this; `MAX_SENT_TEXTURE_SIDE`).
const MAX_LAYER_SIDE: u32 = protocol::texture::MAX_SENT_TEXTURE_SIDE;
/// Anisotropy asked for where a hardware adapter filters anisotropically. A software rasteriser
/// (Mesa's llvmpipe and lavapipe) pays for every extra tap in CPU time: there 16× took a frame of
/// 100 k textured triangles from 1.18× to 1.56× the untextured frame (docs/bench/textures.md),
/// so it filters trilinearly, as a walkthrough on a CPU needs its frame rate more than oblique
/// floors need their sharpness.
const ANISOTROPY: u16 = 16;

/// The layout of bind group 2: material table, texture array, sampler.
pub fn layout(device: &wgpu::Device) -> wgpu::BindGroupLayout {
    let texture = |binding, visibility, filterable, view_dimension| wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension,
            multisampled: false,
        },
        count: None,
    };
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("looks"),
        entries: &[
            texture(
                0,
                wgpu::ShaderStages::VERTEX,
                false,
                wgpu::TextureViewDimension::D2,
            ),
            texture(
                1,
                wgpu::ShaderStages::FRAGMENT,
                true,
                wgpu::TextureViewDimension::D2Array,
            ),
            wgpu::BindGroupLayoutEntry {
                binding: 2,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            },
        ],
    })
}

/// The material table and texture array on the GPU, and the looks they hold.
pub struct GpuLooks {
    bind_group: wgpu::BindGroup,
    sampler: wgpu::Sampler,
    /// The looks generation held (`Looks::generation`); `None`: the empty looks of no scene.
    holds: Option<u64>,
    /// Bytes of the texture array and the material table.
    bytes: u64,
}

impl GpuLooks {
    /// No materials (every triangle's factor one, layer 0 white) until [`Self::sync`].
    pub fn new(gpu: &Gpu) -> GpuLooks {
        let anisotropic = gpu.adapter.get_info().device_type != wgpu::DeviceType::Cpu
            && gpu
                .adapter
                .get_downlevel_capabilities()
                .flags
                .contains(wgpu::DownlevelFlags::ANISOTROPIC_FILTERING);
        let sampler = gpu.device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("albedo"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            anisotropy_clamp: if anisotropic { ANISOTROPY } else { 1 },
            ..Default::default()
        });
        let (bind_group, bytes) = create(gpu, &sampler, &Layers::build(&[], 1), &[]);
        GpuLooks {
            bind_group,
            sampler,
            holds: None,
            bytes,
        }
    }

    pub fn bind_group(&self) -> &wgpu::BindGroup {
        &self.bind_group
    }

    /// Bytes the textures and the material table take on the GPU.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Makes the GPU copy hold `looks`; whether it was rebuilt.
    pub fn sync(&mut self, gpu: &Gpu, looks: &Looks) -> bool {
        if self.holds == Some(looks.generation()) {
            return false;
        }
        // One layer kept free for the padding `create` may add.
        let max_layers = gpu
            .device
            .limits()
            .max_texture_array_layers
            .saturating_sub(1);
        let (drawn, layer_of) = looks.drawn(max_layers);
        let max_side = MAX_LAYER_SIDE.min(gpu.device.limits().max_texture_dimension_2d);
        let side = layer_side(&drawn, max_side, TEXTURE_BUDGET_BYTES);
        let layers = Layers::build(&drawn, side);
        let (bind_group, bytes) = create(
            gpu,
            &self.sampler,
            &layers,
            &looks.material_texels(&layer_of),
        );
        if !drawn.is_empty() {
            tracing::debug!(
                textures = drawn.len(),
                side,
                mib = format!("{:.1}", bytes as f64 / f64::from(1 << 20)),
                "textures on the GPU"
            );
        }
        (self.bind_group, self.bytes) = (bind_group, bytes);
        self.holds = Some(looks.generation());
        true
    }
}

/// The bind group of `layers` and `materials`, and the bytes its textures take.
fn create(
    gpu: &Gpu,
    sampler: &wgpu::Sampler,
    layers: &Layers,
    materials: &[MaterialTexel],
) -> (wgpu::BindGroup, u64) {
    let side = layers.side;
    let count = layers.levels.len() as u32;
    // wgpu's GL backend guesses a texture's view dimension from its layers: one is a plain 2D
    // texture, a multiple of six a cube (array). Pad with copies of the last layer to avoid both.
    let mut array_layers = count.max(2);
    if array_layers.is_multiple_of(6) {
        array_layers += 1;
    }
    let array = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("albedo textures"),
        size: wgpu::Extent3d {
            width: side,
            height: side,
            depth_or_array_layers: array_layers,
        },
        mip_level_count: mip_levels(side),
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for layer in 0..array_layers {
        let chain = &layers.levels[(layer as usize).min(layers.levels.len() - 1)];
        for (mip, texels) in chain.iter().enumerate() {
            let s = (side >> mip).max(1);
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &array,
                    mip_level: mip as u32,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: 0,
                        z: layer,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(texels),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(4 * s),
                    rows_per_image: Some(s),
                },
                wgpu::Extent3d {
                    width: s,
                    height: s,
                    depth_or_array_layers: 1,
                },
            );
        }
    }
    let rows = (materials.len() as u32).div_ceil(MATERIALS_PER_ROW).max(1);
    // Unlisted materials (past the scene's) read as factor one, layer 0: white.
    let mut table = vec![[1.0f32, 1.0, 1.0, 0.0]; (rows * MATERIALS_PER_ROW) as usize];
    table[..materials.len()].copy_from_slice(materials);
    let material_table = crate::draw::texture_2d(
        &gpu.device,
        "material table",
        (MATERIALS_PER_ROW, rows),
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    gpu.queue.write_texture(
        material_table.as_image_copy(),
        bytemuck::cast_slice(&table),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(16 * MATERIALS_PER_ROW),
            rows_per_image: Some(rows),
        },
        material_table.size(),
    );
    let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("looks"),
        layout: &layout(&gpu.device),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(
                    &material_table.create_view(&Default::default()),
                ),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: wgpu::BindingResource::TextureView(&array.create_view(
                    &wgpu::TextureViewDescriptor {
                        dimension: Some(wgpu::TextureViewDimension::D2Array),
                        ..Default::default()
                    },
                )),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: wgpu::BindingResource::Sampler(sampler),
            },
        ],
    });
    let bytes = u64::from(array_layers) * chain_bytes(side) + table.len() as u64 * 16;
    (bind_group, bytes)
}
