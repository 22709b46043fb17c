//! The ID pass (DESIGN.md §3 steps 2–3): triangles drawn into an R32Uint target with a depth
//! test; each pixel holds `index + 1` of the triangle it sees (0: nothing). The index comes from
//! `@builtin(primitive_index)` where [`Gpu`] chose it, else from the vertex index: triangles are
//! drawn unindexed, three vertices each, so vertex `v` belongs to triangle `v / 3`. Either way a
//! vertex is its position alone (12 bytes), relative to its buffer's origin (`view`).

use conventions::camera::relative_to;
use glam::{DVec3, Mat4, Vec3};

use super::gpu::{Gpu, GpuError, MatrixUniform, OffscreenTarget};
use super::view::View;

// Each fragment writes its own depth, z / w of its perspective-interpolated clip position, rather
// than leave it to the fixed function: wgpu's GL backend remaps clip z from WebGPU's 0..1 to GL's
// -1..1 (z' = 2z - w) before the fixed function divides by w, and that round trip through -1..1
// throws away the precision reversed Z keeps near 0, far from the eye. Far surfaces then fought in
// the depth test on GL and not on Vulkan, and the two backends saw different leaves. A fragment's
// own depth bypasses the remap on every backend (DESIGN.md §3 steps 2–3).
const SHADER_PRIMITIVE_INDEX: &str = r#"
enable primitive_index;
@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;
struct Out { @builtin(position) pos: vec4<f32>, @location(0) zw: vec2<f32> };
struct Fragment { @builtin(frag_depth) depth: f32, @location(0) id: u32 };
@vertex fn vs_main(@location(0) p: vec3<f32>) -> Out {
    let clip = view_proj * vec4<f32>(p, 1.0);
    return Out(clip, clip.zw);
}
@fragment fn fs_main(v: Out, @builtin(primitive_index) i: u32) -> Fragment {
    return Fragment(v.zw.x / v.zw.y, i + 1u);
}
"#;

const SHADER_VERTEX_INDEX: &str = r#"
@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;
struct Out {
    @builtin(position) pos: vec4<f32>,
    @location(0) @interpolate(flat) id: u32,
    @location(1) zw: vec2<f32>,
};
struct Fragment { @builtin(frag_depth) depth: f32, @location(0) id: u32 };
@vertex fn vs_main(@location(0) p: vec3<f32>, @builtin(vertex_index) v: u32) -> Out {
    let clip = view_proj * vec4<f32>(p, 1.0);
    return Out(clip, v / 3u + 1u, clip.zw);
}
@fragment fn fs_main(v: Out) -> Fragment {
    return Fragment(v.zw.x / v.zw.y, v.id);
}
"#;

/// Maps depth z to w - z: the same pixels as `Camera::view_projection`, with reversed Z.
pub fn reversed_z(view_proj: Mat4) -> Mat4 {
    let flip = Mat4::from_cols_array(&[
        1.0, 0.0, 0.0, 0.0, //
        0.0, 1.0, 0.0, 0.0, //
        0.0, 0.0, -1.0, 0.0, //
        0.0, 0.0, 1.0, 1.0,
    ]);
    flip * view_proj
}

/// Triangles on the device, ready to draw, relative to an origin.
#[derive(Default)]
pub struct TriangleBuffer {
    buffer: Option<wgpu::Buffer>,
    count: u32,
    origin: DVec3,
}

impl TriangleBuffer {
    /// Uploads triangles as `p - origin` (see `view`); triangle `i` of `triangles` gets id
    /// `i + 1` in the image. The origin should lie near the eyes that will look at them: the eye
    /// itself for a buffer drawn once, a point of the scene for one drawn from many cameras.
    pub fn upload(&mut self, gpu: &Gpu, triangles: &[[Vec3; 3]], origin: DVec3) {
        let positions: Vec<[f32; 3]> = triangles
            .iter()
            .flatten()
            .map(|&p| relative_to(p, origin).to_array())
            .collect();
        gpu.upload_into(&mut self.buffer, bytemuck::cast_slice(&positions));
        self.count = triangles.len() as u32;
        self.origin = origin;
    }

    pub fn len(&self) -> usize {
        self.count as usize
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// What one triangle covers in an ID image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Coverage {
    pub pixels: u32,
    /// Sums of pixel coordinates, for the centroid (priority: near the centre first).
    pub sum_x: u64,
    pub sum_y: u64,
}

impl Coverage {
    /// Centroid in pixels (pixel centres at +0.5).
    pub fn centroid(&self) -> (f32, f32) {
        let n = self.pixels.max(1) as f64;
        (
            (self.sum_x as f64 / n + 0.5) as f32,
            (self.sum_y as f64 / n + 0.5) as f32,
        )
    }
}

/// A read-back ID image, row-major from the top-left.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IdImage {
    pub width: u32,
    pub height: u32,
    /// `index + 1` of the triangle seen at each pixel, 0 for none.
    pub ids: Vec<u32>,
}

impl IdImage {
    /// Coverage of each of `triangles` submitted triangles (index = submission order). Row by
    /// row, so pixel coordinates need no division.
    pub fn coverage(&self, triangles: usize) -> Vec<Coverage> {
        let mut cov = vec![Coverage::default(); triangles];
        for (y, row) in self.ids.chunks_exact(self.width as usize).enumerate() {
            for (x, &id) in row.iter().enumerate() {
                if let Some(c) = id.checked_sub(1).and_then(|t| cov.get_mut(t as usize)) {
                    c.pixels += 1;
                    c.sum_x += x as u64;
                    c.sum_y += y as u64;
                }
            }
        }
        cov
    }
}

/// A pipeline drawing into an R32Uint target with reversed Z, and that target, reused while the
/// image size stays the same.
pub(super) struct R32UintPass {
    uniform: MatrixUniform,
    pipeline: wgpu::RenderPipeline,
    target: Option<OffscreenTarget>,
}

impl R32UintPass {
    pub fn new(gpu: &Gpu, shader: &str, layout: wgpu::VertexBufferLayout<'_>) -> Self {
        let uniform = MatrixUniform::new(gpu);
        let pipeline = uniform.pipeline(gpu, shader, layout, wgpu::TextureFormat::R32Uint);
        R32UintPass {
            uniform,
            pipeline,
            target: None,
        }
    }

    /// Draws `vertex_count` vertices of `vertices`, positions relative to `origin`, seen through
    /// `view`, and reads the image back.
    pub fn draw_and_read(
        &mut self,
        gpu: &Gpu,
        vertices: Option<&wgpu::Buffer>,
        vertex_count: u32,
        view: &View,
        origin: DVec3,
    ) -> Result<Vec<u32>, GpuError> {
        self.uniform.set(gpu, view.matrix_from(origin));
        let target = fitted_target(
            &mut self.target,
            gpu,
            wgpu::TextureFormat::R32Uint,
            view.width(),
            view.height(),
        );
        target.draw_and_read::<u32>(
            gpu,
            &self.pipeline,
            &self.uniform.bind_group,
            vertices,
            vertex_count,
        )
    }
}

/// The ID pipeline and its reusable target.
pub struct IdPass {
    pass: R32UintPass,
}

const POSITION_ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];

impl IdPass {
    pub fn new(gpu: &Gpu) -> Self {
        let shader = if gpu.primitive_index {
            SHADER_PRIMITIVE_INDEX
        } else {
            SHADER_VERTEX_INDEX
        };
        let layout = wgpu::VertexBufferLayout {
            array_stride: 12,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &POSITION_ATTRS,
        };
        IdPass {
            pass: R32UintPass::new(gpu, shader, layout),
        }
    }

    /// Draws `triangles` seen through `view` and reads back.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        triangles: &TriangleBuffer,
        view: &View,
    ) -> Result<IdImage, GpuError> {
        let ids = self.pass.draw_and_read(
            gpu,
            triangles.buffer.as_ref(),
            triangles.count * 3,
            view,
            triangles.origin,
        )?;
        Ok(IdImage {
            width: view.width(),
            height: view.height(),
            ids,
        })
    }
}

/// The target in `slot`, recreated when the image size changed.
fn fitted_target<'a>(
    slot: &'a mut Option<OffscreenTarget>,
    gpu: &Gpu,
    format: wgpu::TextureFormat,
    width: u32,
    height: u32,
) -> &'a OffscreenTarget {
    if slot
        .as_ref()
        .is_none_or(|t| t.width != width || t.height != height)
    {
        *slot = Some(OffscreenTarget::new(gpu, format, width, height));
    }
    slot.as_ref().expect("just filled")
}
