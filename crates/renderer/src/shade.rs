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

/// The answer for one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shaded {
    pub rgb: Vec3,
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
    let wo = outgoing_direction(&s, p.eye.map(Vec3::from));
    let paths = quality.paths.max(1);
    let mut sum = Vec3::ZERO;
    for _ in 0..paths {
        let l = path_radiance(world, s, wo, quality.bounces, rng, counts);
        if l.is_finite() && l.min_element() >= 0.0 {
            sum += l;
        } else {
            flags |= point_flags::NON_FINITE_DISCARDED;
        }
    }
    let emitted = world.emission(s.triangle, -s.normal);
    Shaded {
        rgb: emitted + sum / paths as f32,
        flags,
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
        flags: results.iter().map(|(s, _)| s.flags).collect(),
        micros: start.elapsed().as_micros() as u64,
    };
    (radiance, counts)
}
