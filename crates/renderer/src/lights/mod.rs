//! Lights for next-event estimation (DESIGN.md §7): the sun (a disc of finite angular size), a
//! uniform sky and emissive triangles (MTL `Ke`). One file per light, pbrt-v4 style.

pub mod area;
pub mod sky;
pub mod sun;

use glam::Vec3;
use scene::Scene;

use crate::counters::RayKind;

/// Incident light sampled at a point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction toward the light.
    pub dir: Vec3,
    /// Distance to the sampled point of the light; infinite for distant lights.
    pub distance: f32,
    /// Incident radiance divided by the solid-angle density of `dir`.
    pub radiance_over_pdf: Vec3,
}

pub trait Light: Send + Sync {
    /// Samples a direction toward the light from `p`, whose shaded side has unit normal `n`;
    /// `None` when this sample brings nothing (below the horizon, behind a one-sided emitter).
    fn sample(&self, p: Vec3, n: Vec3, u: [f32; 3]) -> Option<LightSample>;

    /// The counter its shadow rays go to.
    fn shadow_kind(&self) -> RayKind;

    /// Whether rays leaving the scene see this light ([`Lights::escaped_radiance`]), so a path's
    /// continuation ray can stand in for its next-event sample (the sky).
    fn seen_by_escaping_rays(&self) -> bool {
        false
    }
}

/// The lights a scene calls for (its effects analysis), and what an escaping ray sees.
pub struct Lights {
    pub lights: Vec<Box<dyn Light>>,
    /// What a ray leaving the scene sees: the sky always; the sun's disc only through a mirror
    /// (other rays reach the sun by next-event estimation only, so nothing is counted twice).
    sun: Option<sun::SunLight>,
    sky: Option<sky::UniformSky>,
}

impl Lights {
    pub fn from_scene(scene: &Scene) -> Lights {
        let mut lights: Vec<Box<dyn Light>> = Vec::new();
        let sun = if scene.effects.sun {
            scene.settings.sun.as_ref().and_then(sun::SunLight::new)
        } else {
            None
        };
        if let Some(sun) = sun {
            lights.push(Box::new(sun));
        }
        let sky = if scene.effects.sky {
            sky::UniformSky::from_settings(&scene.settings.sky)
        } else {
            None
        };
        if let Some(sky) = sky {
            lights.push(Box::new(sky));
        }
        if scene.effects.area_lights
            && let Some(area) = area::AreaLights::new(scene)
        {
            lights.push(Box::new(area));
        }
        Lights { lights, sun, sky }
    }

    /// Radiance arriving along `dir` from outside the scene: the sky, plus the sun's disc when
    /// `with_sun` (a mirror ray, or a camera ray).
    pub fn escaped_radiance(&self, dir: Vec3, with_sun: bool) -> Vec3 {
        let sun = if with_sun {
            self.sun.map_or(Vec3::ZERO, |s| s.radiance_toward(dir))
        } else {
            Vec3::ZERO
        };
        let sky = self.sky.map_or(Vec3::ZERO, |s| s.radiance(dir));
        sun + sky
    }
}
