//! Path tracing with next-event estimation (DESIGN.md §7): the outgoing radiance of a surface point
//! toward a direction. The sun and emitters are reached by next-event estimation at every vertex;
//! a mirror bounce instead sees what it hits (emitters, the sun's disc), so every light path is
//! counted exactly once. Bounce depth counts diffuse and glossy bounces; mirror
//! bounces are free up to `MAX_MIRROR_CHAIN` so a mirror still shows its reflection at the
//! direct-light-only quality.

use glam::Vec3;

use crate::counters::{RayCounts, RayKind};
use crate::material::{Bsdf, BsdfSample};
use crate::sampling::{Rng, uniform3};
use crate::world::{Surface, World};
use rand::RngExt;

/// Russian roulette starts after this many bounces.
const ROULETTE_AFTER: u32 = 3;
/// Longest chain of mirror reflections followed (two facing mirrors would loop forever).
const MAX_MIRROR_CHAIN: u32 = 8;
/// Safety cap on unbounded paths; roulette ends them long before in any scene with albedo < 1.
const MAX_DEPTH: u32 = 1024;

/// One path's estimate of the radiance leaving `surface` toward unit `wo`, excluding the surface's
/// own emission. `max_bounces`: `Some(0)` = direct light only, `None` = unbounded with roulette.
///
/// The sky is reached by the path's own continuation ray where there is one (for a Lambertian
/// vertex that ray is cosine-distributed, exactly the sky's next-event density, so it spares a
/// shadow ray at the same variance) and by next-event estimation at the vertex where the path
/// ends.
pub fn path_radiance(
    world: &World,
    surface: Surface,
    wo: Vec3,
    max_bounces: Option<u32>,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Vec3 {
    let mut radiance = Vec3::ZERO;
    let mut throughput = Vec3::ONE;
    let mut s = surface;
    let mut wo = wo;
    let mut depth = Depth {
        bounces: 0,
        mirror_chain: 0,
    };
    for _ in 0..MAX_DEPTH {
        let bsdf = world.bsdf(s.triangle);
        let origin = world.offset.origin(s.position, s.normal);
        let next = continuation(world, bsdf, &s, wo, max_bounces, depth, throughput, rng);
        radiance +=
            throughput * direct_light(world, &s, origin, wo, bsdf, next.is_none(), rng, counts);
        let Some((sample, next_throughput)) = next else {
            break;
        };
        throughput = next_throughput;
        let mirror = sample.kind == RayKind::Mirror;
        let Some(hit) = world.trace(origin, sample.dir, sample.kind, counts) else {
            radiance += throughput * world.lights.escaped_radiance(sample.dir, mirror);
            break;
        };
        if mirror {
            radiance += throughput * world.emission(hit.triangle, sample.dir);
            depth.mirror_chain += 1;
        } else {
            depth = Depth {
                bounces: depth.bounces + 1,
                mirror_chain: 0,
            };
        }
        s = world.surface_at(origin, sample.dir, hit);
        wo = -sample.dir;
    }
    radiance
}

/// Bounces taken so far: diffuse and glossy ones count against the quality's depth, mirror ones
/// against `MAX_MIRROR_CHAIN`.
#[derive(Clone, Copy)]
struct Depth {
    bounces: u32,
    mirror_chain: u32,
}

/// The ray that continues the path from `s`, with the throughput after it, or `None` where the
/// path ends: no lobe sampled, depth exhausted, an effect the scene does not call for, or
/// Russian roulette.
#[allow(clippy::too_many_arguments)]
fn continuation(
    world: &World,
    bsdf: &Bsdf,
    s: &Surface,
    wo: Vec3,
    max_bounces: Option<u32>,
    depth: Depth,
    throughput: Vec3,
    rng: &mut Rng,
) -> Option<(BsdfSample, Vec3)> {
    let sample = bsdf.sample(s.normal, wo, uniform3(rng))?;
    let budget_left = if sample.kind == RayKind::Mirror {
        depth.mirror_chain < MAX_MIRROR_CHAIN
    } else {
        max_bounces.is_none_or(|max| depth.bounces < max)
    };
    if !budget_left || !world.simulates(sample.kind) {
        return None;
    }
    let mut next = throughput * sample.weight;
    if depth.bounces >= ROULETTE_AFTER {
        let survive = next.max_element().min(0.95);
        if survive <= 0.0 || rng.random::<f32>() >= survive {
            return None;
        }
        next /= survive;
    }
    (next.max_element() > 0.0).then_some((sample, next))
}

/// Next-event estimation: one sample of each light, each with its shadow ray; the sky only when
/// `sky_here` (no continuation ray will see it).
#[allow(clippy::too_many_arguments)]
fn direct_light(
    world: &World,
    s: &Surface,
    origin: Vec3,
    wo: Vec3,
    bsdf: &Bsdf,
    sky_here: bool,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for light in &world.lights.lights {
        if light.seen_by_escaping_rays() && !sky_here {
            continue;
        }
        let Some(ls) = light.sample(origin, s.normal, uniform3(rng)) else {
            continue;
        };
        let f = bsdf.eval(s.normal, wo, ls.dir);
        if f.max_element() <= 0.0 {
            continue;
        }
        // Stop short of the light's own surface by its rounding margin.
        let tmax = if ls.distance.is_finite() {
            ls.distance - 2.0 * world.offset.margin(origin + ls.dir * ls.distance)
        } else {
            f32::INFINITY
        };
        if tmax <= 0.0 || world.occluded(origin, ls.dir, tmax, light.shadow_kind(), counts) {
            continue;
        }
        sum += f * s.normal.dot(ls.dir) * ls.radiance_over_pdf;
    }
    sum
}
