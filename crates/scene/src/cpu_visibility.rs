//! A CPU estimate of which base triangles a viewpoint sees (`scene info`): one ray through each
//! pixel centre, closest hit, like the SMA's ID-buffer pass (DESIGN.md §3 step 2) without a GPU.
//! The camera is the system's one convention (`conventions::camera`).

use conventions::camera::Pinhole;
use glam::Vec3;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle as BvhTriangle;
use rayon::prelude::*;

use crate::bvh::{BuildPreset, build_cwbvh, bvh_triangles};
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
        let triangles = bvh_triangles(&scene.mesh);
        let bvh = build_cwbvh(&triangles, BuildPreset::Fast);
        VisibilityEstimator { triangles, bvh }
    }

    /// The base triangle seen through each pixel centre (row by row from the top), `None` where
    /// the ray escapes.
    pub fn id_buffer(&self, view: &ViewpointSetting, width: u32, height: u32) -> Vec<Option<u32>> {
        let camera = Pinhole::look_at(
            Vec3::from(view.eye),
            Vec3::from(view.target),
            Vec3::from(view.up),
            view.fov_y_deg,
            [width, height],
        );
        (0..width * height)
            .into_par_iter()
            .map(|i| {
                let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
                self.first_hit(camera.eye, camera.ray_direction(x, y))
            })
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
