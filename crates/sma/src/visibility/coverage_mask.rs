//! Which pixels a set of triangles covers, seen from a camera with the SMA's near and far planes:
//! the coverage of one ID pass, for checks that what a viewer shows covers what the scene does.

use glam::Vec3;
use protocol::viewer_link::Camera;

use super::gpu::{Gpu, GpuError};
use super::id_pass::{IdPass, TriangleBuffer};
use super::levels::scene_view;

/// Per pixel, row-major from the top left: whether one of `triangles` is seen there, for a scene
/// of `bounds`.
pub fn coverage(
    gpu: &Gpu,
    triangles: &[[Vec3; 3]],
    camera: &Camera,
    bounds: (Vec3, Vec3),
) -> Result<Vec<bool>, GpuError> {
    let view = scene_view(camera, bounds);
    let mut pass = IdPass::new(gpu);
    let mut buffer = TriangleBuffer::default();
    buffer.upload(gpu, triangles, view.eye());
    let image = pass.render(gpu, &buffer, &view)?;
    Ok(image.ids.iter().map(|&id| id != 0).collect())
}
