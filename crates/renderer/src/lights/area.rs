//! Emissive triangles (MTL `Ke`). Each emits uniformly, on the side its counter-clockwise winding
//! faces only (DESIGN.md §7, as in pbrt and Mitsuba). A triangle is chosen with probability
//! proportional to area × luminance of `Ke`, then a point uniformly on it.

use glam::Vec3;
use scene::Scene;

use super::{Light, LightSample};
use crate::counters::RayKind;
use crate::sampling::{luminance, uniform_triangle};

#[derive(Clone, Copy, Debug)]
struct Emitter {
    corners: [Vec3; 3],
    /// Unit counter-clockwise normal: the emitting side.
    normal: Vec3,
    area: f32,
    ke: Vec3,
}

pub struct AreaLights {
    emitters: Vec<Emitter>,
    /// Cumulative selection weights, last = `total`.
    cdf: Vec<f32>,
    total: f32,
}

impl AreaLights {
    /// `None` when the scene has no emitting triangle of positive area.
    pub fn new(scene: &Scene) -> Option<AreaLights> {
        let emitters: Vec<Emitter> = (0..scene.mesh.triangles.len())
            .filter_map(|t| {
                let ke = scene.material_of(t).ke;
                let face = scene.mesh.face_normal(t);
                let area = 0.5 * face.length();
                (ke.max_element() > 0.0 && ke.is_finite() && area > 0.0).then(|| Emitter {
                    corners: scene.mesh.triangle_positions(t),
                    normal: face / (2.0 * area),
                    area,
                    ke,
                })
            })
            .collect();
        let mut total = 0.0;
        let cdf: Vec<f32> = emitters
            .iter()
            .map(|e| {
                total += e.area * luminance(e.ke).max(1e-12);
                total
            })
            .collect();
        (total > 0.0).then_some(AreaLights {
            emitters,
            cdf,
            total,
        })
    }

    fn pick(&self, u: f32) -> (usize, f32) {
        let target = u * self.total;
        let i = self
            .cdf
            .partition_point(|&c| c <= target)
            .min(self.emitters.len() - 1);
        let below = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        (i, (self.cdf[i] - below) / self.total)
    }
}

impl Light for AreaLights {
    fn sample(&self, p: Vec3, n: Vec3, u: [f32; 3]) -> Option<LightSample> {
        let (i, p_pick) = self.pick(u[2]);
        let e = &self.emitters[i];
        let [b1, b2] = uniform_triangle([u[0], u[1]]);
        let q = e.corners[0] * (1.0 - b1 - b2) + e.corners[1] * b1 + e.corners[2] * b2;
        let to_light = q - p;
        let dist2 = to_light.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let distance = dist2.sqrt();
        let dir = to_light / distance;
        let cos_light = -dir.dot(e.normal);
        if cos_light <= 0.0 || dir.dot(n) <= 0.0 {
            return None;
        }
        // Area density p_pick / area, turned into solid angle: * dist^2 / cos_light.
        let radiance_over_pdf = e.ke * (cos_light * e.area / (dist2 * p_pick));
        Some(LightSample {
            dir,
            distance,
            radiance_over_pdf,
        })
    }

    fn shadow_kind(&self) -> RayKind {
        RayKind::ShadowArea
    }
}
