//! Shading requests: one `ShadePoint` at a quality, and whole batches spread over rayon. Each point
//! draws from its own random stream, seeded by (batch seed, point index) only, so an answer does
//! not depend on thread scheduling.

use std::time::Instant;

use glam::Vec3;
use protocol::renderer_link::{Quality, Radiance, ShadeBatch, ShadePoint, point_flags};
use rayon::prelude::*;

use crate::counters::RayCounts;
use crate::estimator::path_radiance;
use crate::point::locate;
use crate::sampling::{Rng, stream};
use crate::world::{Surface, World};

/// The answer for one point: an estimate with its uncertainty (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shaded {
    /// The mean of the paths, plus the point's own emission.
    pub rgb: Vec3,
    /// The sample variance of the paths' luminance (0 with fewer than two paths).
    pub luminance_variance: f32,
    /// Paths averaged; 0 when the point could not be shaded.
    pub paths: u32,
    /// `protocol::renderer_link::point_flags` bits.
    pub flags: u8,
}

/// Outgoing radiance of `p` toward its eye (or its normal, for a diffuse material), averaged over
/// `quality.paths` paths, plus the point's own emission on its emitting side.
pub fn shade_point(
    world: &World,
    p: &ShadePoint,
    quality: Quality,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Shaded {
    let located = match locate(world, p, counts) {
        Ok(l) => l,
        Err(_) => {
            return Shaded {
                rgb: Vec3::ZERO,
                luminance_variance: 0.0,
                paths: 0,
                flags: point_flags::INVALID_POINT,
            };
        }
    };
    let s = located.surface;
    let mut flags = if located.moved {
        point_flags::MOVED_OFF_HIDDEN
    } else {
        0
    };
    let material = world.scene.material_of(s.triangle as usize);
    if material.is_view_dependent() {
        flags |= point_flags::VIEW_DEPENDENT;
    }
    let wo = outgoing_direction(&s, p.eye.map(|e| world.to_local(Vec3::from(e))));
    let paths = quality.paths.max(1);
    let mut sum = Vec3::ZERO;
    let mut luminance = PathLuminance::default();
    for _ in 0..paths {
        let l = path_radiance(world, s, wo, quality.bounces, rng, counts);
        if l.is_finite() && l.min_element() >= 0.0 {
            sum += l;
            luminance.add(conventions::luminance(l.to_array()));
        } else {
            // Counted as a black path, so the mean stays over `paths`.
            luminance.add(0.0);
            flags |= point_flags::NON_FINITE_DISCARDED;
        }
    }
    let emitted = world.emission(s.triangle, -s.normal);
    Shaded {
        rgb: emitted + sum / paths as f32,
        luminance_variance: luminance.variance(),
        paths,
        flags,
    }
}

/// Running sum and sum of squares of path luminances, in f64 so that 1,000 paths of a bright
/// point do not cancel into a negative variance.
#[derive(Default)]
struct PathLuminance {
    n: u32,
    sum: f64,
    sum_sq: f64,
}

impl PathLuminance {
    fn add(&mut self, l: f32) {
        let l = f64::from(l);
        self.n += 1;
        self.sum += l;
        self.sum_sq += l * l;
    }

    /// The unbiased sample variance.
    fn variance(&self) -> f32 {
        if self.n < 2 {
            return 0.0;
        }
        let n = f64::from(self.n);
        ((self.sum_sq - self.sum * self.sum / n) / (n - 1.0)).max(0.0) as f32
    }
}

/// Toward the eye when it is on the shaded side; otherwise along the normal (a diffuse surface
/// looks the same from everywhere, and a point seen edge-on has no better choice).
fn outgoing_direction(s: &Surface, eye: Option<Vec3>) -> Vec3 {
    eye.and_then(|e| (e - s.position).try_normalize())
        .filter(|wo| wo.dot(s.normal) > 1e-4)
        .unwrap_or(s.normal)
}

/// Shades a whole batch on the current rayon pool. Returns the reply and the rays traced.
pub fn shade_batch(world: &World, batch: &ShadeBatch) -> (Radiance, RayCounts) {
    let start = Instant::now();
    let results: Vec<(Shaded, RayCounts)> = batch
        .points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let mut counts = RayCounts::default();
            let mut rng = stream(batch.seed, i as u64);
            (
                shade_point(world, p, batch.quality, &mut rng, &mut counts),
                counts,
            )
        })
        .collect();
    let mut counts = RayCounts::default();
    for (_, c) in &results {
        counts += *c;
    }
    let radiance = Radiance {
        batch_id: batch.batch_id,
        quality: batch.quality,
        rgb: results.iter().map(|(s, _)| s.rgb.to_array()).collect(),
        luminance_variance: results.iter().map(|(s, _)| s.luminance_variance).collect(),
        paths: results.iter().map(|(s, _)| s.paths).collect(),
        flags: results.iter().map(|(s, _)| s.flags).collect(),
        micros: start.elapsed().as_micros() as u64,
    };
    (radiance, counts)
}
