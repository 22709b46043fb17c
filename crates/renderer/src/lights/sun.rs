//! The sun: a disc of finite angular size and uniform radiance, sampled uniformly over its cone.
//! Its irradiance at normal incidence is radiance × solid angle (the analytic test of `tests/analytic.rs` checks it).
//! Like the sky, it gives no light from below the horizon (y = 0, DESIGN.md §7): a sun on the
//! horizon lights with the part of its disc above it, one under it not at all, so an open scene
//! is never lit from underneath.

use glam::Vec3;
use scene::Sun;

use super::{Light, LightSample};
use crate::counters::RayKind;
use crate::sampling::uniform_cone;

#[derive(Clone, Copy, Debug)]
pub struct SunLight {
    dir: Vec3,
    radiance: Vec3,
    /// 1 - cos(half angle), kept apart for precision (a 0.53° sun: about 1e-5).
    one_minus_cos: f32,
}

impl SunLight {
    /// `None` for a sun that lights nothing: zero direction, non-positive radiance, or wholly
    /// below the horizon.
    pub fn new(sun: &Sun) -> Option<SunLight> {
        if !sun.is_above_horizon() {
            return None;
        }
        let dir = Vec3::from(sun.direction).try_normalize()?;
        let radiance = Vec3::from(sun.radiance).max(Vec3::ZERO);
        if radiance.max_element() <= 0.0 || !radiance.is_finite() {
            return None;
        }
        // A zero-size sun would be a delta light; keep a tiny disc so the sampling stays uniform.
        let half = (0.5 * sun.angular_diameter_deg.to_radians()).clamp(1e-5, 0.5);
        let one_minus_cos = 2.0 * (0.5 * half).sin().powi(2);
        Some(SunLight {
            dir,
            radiance,
            one_minus_cos,
        })
    }

    /// Radiance seen along unit `dir`: the disc's where `dir` falls inside it, above the horizon.
    pub fn radiance_toward(&self, dir: Vec3) -> Vec3 {
        if dir.y > 0.0 && 1.0 - dir.dot(self.dir) <= self.one_minus_cos {
            self.radiance
        } else {
            Vec3::ZERO
        }
    }

    /// Solid angle of the disc.
    pub fn solid_angle(&self) -> f32 {
        2.0 * std::f32::consts::PI * self.one_minus_cos
    }
}

impl Light for SunLight {
    fn sample(&self, _p: Vec3, n: Vec3, u: [f32; 3]) -> Option<LightSample> {
        let dir = uniform_cone(self.dir, self.one_minus_cos, [u[0], u[1]]);
        (dir.dot(n) > 0.0 && dir.y > 0.0).then(|| LightSample {
            dir,
            distance: f32::INFINITY,
            radiance_over_pdf: self.radiance * self.solid_angle(),
        })
    }

    fn shadow_kind(&self) -> RayKind {
        RayKind::ShadowSun
    }
}
