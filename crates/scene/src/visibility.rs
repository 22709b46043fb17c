//! A CPU estimate of which base triangles a viewpoint sees (issue 2, `scene info`): one ray
//! through each pixel centre, closest hit, like the SMA's ID-buffer pass (DESIGN.md §3 step 2)
//! without a GPU. The camera follows the system's one convention (`protocol::camera`: looks
//! down -Z of its frame, pixel (0, 0) at the top left, centres at +0.5), restated here because
//! the scene crate knows nothing of the wire.

use std::time::Duration;

use glam::{Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle as BvhTriangle;
use rayon::prelude::*;

use crate::model::Scene;
use crate::settings::ViewpointSetting;

/// How many base triangles `view` sees at `width` × `height` (builds an estimator for one view;
/// keep a [`VisibilityEstimator`] to ask about several).
pub fn visible_base_triangles(
    scene: &Scene,
    view: &ViewpointSetting,
    width: u32,
    height: u32,
) -> usize {
    VisibilityEstimator::new(scene).count_visible(view, width, height)
}

pub struct VisibilityEstimator {
    triangles: Vec<BvhTriangle>,
    bvh: CwBvh,
}

impl VisibilityEstimator {
    pub fn new(scene: &Scene) -> VisibilityEstimator {
        let triangles: Vec<BvhTriangle> = (0..scene.mesh.triangles.len())
            .map(|t| {
                let [v0, v1, v2] = scene.mesh.triangle_positions(t).map(Vec3A::from);
                BvhTriangle { v0, v1, v2 }
            })
            .collect();
        let bvh = build_cwbvh_from_tris(
            &triangles,
            BvhBuildParams::fast_build(),
            &mut Duration::default(),
        );
        VisibilityEstimator { triangles, bvh }
    }

    /// The base triangle seen through each pixel centre (row by row from the top), `None` where
    /// the ray escapes.
    pub fn id_buffer(&self, view: &ViewpointSetting, width: u32, height: u32) -> Vec<Option<u32>> {
        let camera = PinholeCamera::new(view, width, height);
        (0..width * height)
            .into_par_iter()
            .map(|i| self.first_hit(camera.eye, camera.direction(i % width, i / width)))
            .collect()
    }

    /// How many distinct base triangles cover at least one pixel centre.
    pub fn count_visible(&self, view: &ViewpointSetting, width: u32, height: u32) -> usize {
        let mut seen = vec![false; self.triangles.len()];
        for id in self.id_buffer(view, width, height).into_iter().flatten() {
            seen[id as usize] = true;
        }
        seen.iter().filter(|s| **s).count()
    }

    fn first_hit(&self, origin: Vec3, direction: Vec3) -> Option<u32> {
        let ray = Ray::new_inf(origin.into(), direction.into());
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |ray, id| {
                self.triangles[self.bvh.primitive_indices[id] as usize].intersect(ray)
            })
            .then(|| self.bvh.primitive_indices[hit.primitive_id as usize])
    }
}

struct PinholeCamera {
    eye: Vec3,
    right: Vec3,
    up: Vec3,
    forward: Vec3,
    width: u32,
    height: u32,
}

impl PinholeCamera {
    fn new(view: &ViewpointSetting, width: u32, height: u32) -> PinholeCamera {
        let eye = Vec3::from(view.eye);
        let forward = (Vec3::from(view.target) - eye).normalize();
        let right = forward.cross(Vec3::from(view.up)).normalize();
        let up = right.cross(forward);
        let half_height = (0.5 * view.fov_y_deg.to_radians()).tan();
        let aspect = width as f32 / height as f32;
        PinholeCamera {
            eye,
            right: right * half_height * aspect,
            up: up * half_height,
            forward,
            width,
            height,
        }
    }

    fn direction(&self, x: u32, y: u32) -> Vec3 {
        let sx = 2.0 * (x as f32 + 0.5) / self.width as f32 - 1.0;
        let sy = 1.0 - 2.0 * (y as f32 + 0.5) / self.height as f32;
        (self.forward + sx * self.right + sy * self.up).normalize()
    }
}
