//! The luminance pass for `nld-is` (DESIGN.md §6): the triangles a viewer shows, Gouraud-shaded
//! with their vertex luminances, into an image of f32 (0 where nothing is seen). The floats are
//! written as their bits into R32Uint: R32Float is not renderable on every adapter (llvmpipe
//! through GL refuses it), R32Uint is, and without blending the bits pass through unchanged.

use conventions::camera::relative_to;
use glam::Vec3;

use super::gpu::{Gpu, GpuError};
use super::id_pass::R32UintPass;
use super::view::View;

// Depth written per fragment, as in the ID pass (see `id_pass`): the same pixels on every backend.
const SHADER: &str = r#"
@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;
struct Out { @builtin(position) pos: vec4<f32>, @location(0) lum: f32, @location(1) zw: vec2<f32> };
struct Fragment { @builtin(frag_depth) depth: f32, @location(0) bits: u32 };
@vertex fn vs_main(@location(0) p: vec3<f32>, @location(1) lum: f32) -> Out {
    let clip = view_proj * vec4<f32>(p, 1.0);
    return Out(clip, lum, clip.zw);
}
@fragment fn fs_main(v: Out) -> Fragment {
    return Fragment(v.zw.x / v.zw.y, bitcast<u32>(v.lum));
}
"#;

const ATTRS: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32];

pub struct LuminancePass {
    pass: R32UintPass,
    vertices: Option<wgpu::Buffer>,
}

impl LuminancePass {
    pub fn new(gpu: &Gpu) -> Self {
        let layout = wgpu::VertexBufferLayout {
            array_stride: 16,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &ATTRS,
        };
        LuminancePass {
            pass: R32UintPass::new(gpu, SHADER, layout),
            vertices: None,
        }
    }

    /// Draws triangles given as (positions, vertex luminances) seen through `view`, relative to
    /// its eye (`view`), and reads the image back.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        triangles: &[([Vec3; 3], [f32; 3])],
        view: &View,
    ) -> Result<Vec<f32>, GpuError> {
        let eye = view.eye();
        let mut words: Vec<f32> = Vec::with_capacity(triangles.len() * 12);
        for (positions, lum) in triangles {
            for (&p, l) in positions.iter().zip(lum) {
                let p = relative_to(p, eye);
                words.extend([p.x, p.y, p.z, *l]);
            }
        }
        gpu.upload_into(&mut self.vertices, bytemuck::cast_slice(&words));
        let bits = self.pass.draw_and_read(
            gpu,
            self.vertices.as_ref(),
            triangles.len() as u32 * 3,
            view,
            eye,
        )?;
        Ok(bits.into_iter().map(f32::from_bits).collect())
    }
}
