//! A reference image's feature images (DESIGN.md §10, the denoised per-pixel competitor): the
//! albedo and the normal first seen through each pixel, box-filtered over jittered camera rays
//! like the colour, so that a denoiser (Intel Open Image Denoise takes both) can tell texture
//! and geometry from noise. The albedo is the diffuse one plus the view-dependent lobe's (clamped
//! to 1, as OIDN asks of glossy and mirror surfaces); a ray that escapes counts as black and no
//! normal. Normals are world-space (the local frame is only translated).

use std::path::{Path, PathBuf};

use glam::Vec3;
use protocol::viewer_link::Camera;
use rayon::prelude::*;

use crate::counters::{RayCounts, RayKind};
use crate::material::Specular;
use crate::sampling::{stream, uniform2};
use crate::texture_lod::Footprint;
use crate::world::World;

/// Camera rays per pixel for the features: their edges need antialiasing like the colour's, but
/// the first hit has no other noise, so a few rays are enough.
pub const FEATURE_RAYS: u32 = 8;

/// The albedo and normal images, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Features {
    pub albedo: Vec<Vec3>,
    pub normal: Vec<Vec3>,
}

/// The features of a `width` × `height` image of `camera`.
pub fn render_features(
    world: &World,
    camera: &Camera,
    width: u32,
    height: u32,
    seed: u64,
) -> Features {
    let rows: Vec<Vec<(Vec3, Vec3)>> = (0..height)
        .into_par_iter()
        .map(|y| {
            crate::subnormals::flush_on_this_thread();
            (0..width)
                .map(|x| pixel_features(world, camera, x, y, seed ^ u64::from(y * width + x)))
                .collect()
        })
        .collect();
    let (albedo, normal) = rows.into_iter().flatten().unzip();
    Features { albedo, normal }
}

/// Where the feature `name` of the colour image `out` is written: `<stem>-<name>.exr` beside it.
pub fn beside(out: &Path, name: &str) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    out.with_file_name(format!("{stem}-{name}.exr"))
}

fn pixel_features(world: &World, camera: &Camera, x: u32, y: u32, key: u64) -> (Vec3, Vec3) {
    let mut rng = stream(key, 0x6665_6174);
    let origin = world.to_local(camera.eye_vec());
    let mut counts = RayCounts::default();
    let (mut albedo, mut normal) = (Vec3::ZERO, Vec3::ZERO);
    for _ in 0..FEATURE_RAYS {
        let [jx, jy] = uniform2(&mut rng);
        let dir = camera.ray_direction(x as f32 + jx, y as f32 + jy);
        if let Some(hit) = world.trace(origin, dir, RayKind::Camera, &mut counts) {
            let surface = world.surface_at(origin, dir, hit);
            albedo += first_hit_albedo(world, &surface);
            normal += surface.normal;
        }
    }
    let n = FEATURE_RAYS as f32;
    (albedo / n, normal.normalize_or_zero())
}

fn first_hit_albedo(world: &World, surface: &crate::world::Surface) -> Vec3 {
    let bsdf = world.bsdf_at(surface, Footprint::POINT);
    let ks = match bsdf.specular {
        Specular::None => Vec3::ZERO,
        Specular::Glossy { ks, .. } | Specular::Mirror { ks } => ks,
    };
    (bsdf.kd + ks).min(Vec3::ONE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::camera_for;

    /// Cornell's back wall is white and faces the camera: the middle pixel's albedo is its Kd
    /// and its normal points back at the eye.
    #[test]
    fn the_middle_of_cornell_shows_the_back_walls_albedo_and_normal() {
        let world = World::new(scene::load("cornell").unwrap());
        let view = world.scene.settings.viewpoints[0].name.clone();
        let camera = camera_for(&world, &view, 32, 32).unwrap();
        let f = render_features(&world, &camera, 32, 32, 1);
        assert_eq!((f.albedo.len(), f.normal.len()), (32 * 32, 32 * 32));
        let middle = 16 * 32 + 16;
        let toward_eye = -camera.ray_direction(16.5, 16.5);
        assert!(
            f.normal[middle].dot(toward_eye) > 0.9,
            "{}",
            f.normal[middle]
        );
        let a = f.albedo[middle];
        assert!(
            a.min_element() > 0.3 && (a.max_element() - a.min_element()) < 0.05,
            "{a}"
        );
    }
}
