//! A uniform sky: constant radiance over the upper hemisphere (+Y), black below the horizon.
//! Sampled with a cosine lobe about the surface normal, which is exact importance sampling for a
//! Lambertian surface under an unoccluded sky.

use glam::Vec3;
use scene::Sky;

use super::{Light, LightSample};
use crate::counters::RayKind;
use crate::sampling::{cosine_hemisphere, cosine_pdf};

#[derive(Clone, Copy, Debug)]
pub struct UniformSky {
    radiance: Vec3,
}

impl UniformSky {
    pub fn from_settings(sky: &Sky) -> Option<UniformSky> {
        match sky {
            Sky::None => None,
            Sky::Uniform { radiance } => {
                let radiance = Vec3::from(*radiance).max(Vec3::ZERO);
                (radiance.is_finite() && radiance.max_element() > 0.0)
                    .then_some(UniformSky { radiance })
            }
        }
    }

    /// Radiance arriving from direction `dir` (a ray that escaped the scene).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        if dir.y > 0.0 {
            self.radiance
        } else {
            Vec3::ZERO
        }
    }
}

impl Light for UniformSky {
    fn sample(&self, _p: Vec3, n: Vec3, u: [f32; 3]) -> Option<LightSample> {
        let dir = cosine_hemisphere(n, [u[0], u[1]]);
        let pdf = cosine_pdf(dir.dot(n));
        (dir.y > 0.0 && pdf > 0.0).then(|| LightSample {
            dir,
            distance: f32::INFINITY,
            radiance_over_pdf: self.radiance / pdf,
        })
    }

    fn shadow_kind(&self) -> RayKind {
        RayKind::ShadowSky
    }

    fn seen_by_escaping_rays(&self) -> bool {
        true
    }
}
