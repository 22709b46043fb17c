//! A tile of a camera's direct light per pixel (DESIGN.md §3 step 8; §5, "samples in parts"): while a
//! viewer rests, the SMA asks for the sharp part of its picture pixel by pixel, and the viewer
//! adds the vertices' interpolated indirect part to it.
//!
//! Each sample is a camera ray jittered over its pixel (a box filter, `reference::jittered_ray`)
//! and, where it hits, the first vertex's direct light as the vertices' direct part counts it
//! (`estimator::PathParts`), as radiance: the albedo at the hit times the direct illumination
//! of one path of bounce depth 0 (every light by next-event estimation, the sky's included) with
//! [`DirectLights::All`], so that a tile and the vertices' interpolated rest (albedo × indirect
//! illumination, plus the view-dependent part, which holds the emission and the glossy and
//! mirror lobes) sum to the picture. The other selections trace only their lights' shadow rays,
//! through the diffuse lobe.
//! A ray that misses the scene brings nothing: the viewer draws the sky itself.

use std::time::Instant;

use glam::Vec3;
use protocol::direct_tile::{DirectLights, TileAnswer, TileRequest};
use rayon::prelude::*;

use crate::counters::{RayCounts, RayKind};
use crate::estimator::{path_radiance, shadow_rays};
use crate::reference::jittered_ray;
use crate::sampling::{Rng, stream};
use crate::shade::PartSum;
use crate::texture_lod::Footprint;
use crate::world::{Surface, World};

/// Depth 0: the first vertex's direct light only.
const DIRECT_ONLY: Option<u32> = Some(0);

/// Traces one pass over the request's tile, rows on the current rayon pool. Pixel (x, y) of the
/// image draws from stream `y · width + x` of a seed made of the camera's sequence number and the
/// pass, so a pass is reproducible and passes differ.
pub fn trace_tile(world: &World, request: &TileRequest) -> (TileAnswer, RayCounts) {
    let started = Instant::now();
    let rect = request.rect;
    let camera = &request.camera;
    let seed = camera.seq.rotate_left(32) ^ u64::from(request.pass);
    let spp = request.samples_per_pixel.max(1);
    let rows: Vec<_> = (rect.y..rect.y + rect.height)
        .into_par_iter()
        .map(|y| {
            crate::subnormals::flush_on_this_thread();
            let mut counts = RayCounts::default();
            let row: Vec<_> = (rect.x..rect.x + rect.width)
                .map(|x| {
                    let index = u64::from(y) * u64::from(camera.width) + u64::from(x);
                    let mut rng = stream(seed, index);
                    let mut sum = PartSum::default();
                    for _ in 0..spp {
                        let dir = jittered_ray(camera, x, y, &mut rng);
                        let l = sample(world, request, dir, &mut rng, &mut counts);
                        // As a batch's paths: a bad value counts as black (DESIGN.md §5).
                        sum.add(if l.is_finite() {
                            l.max(Vec3::ZERO)
                        } else {
                            Vec3::ZERO
                        });
                    }
                    sum.estimate(spp, Vec3::ZERO)
                })
                .collect();
            (row, counts)
        })
        .collect();
    let mut counts = RayCounts::default();
    let mut pixels = Vec::with_capacity(rect.pixels());
    for (row, c) in rows {
        counts += c;
        pixels.extend(row);
    }
    let answer = TileAnswer {
        tile_id: request.tile_id,
        camera_seq: camera.seq,
        rect,
        pass: request.pass,
        samples_per_pixel: spp,
        pixels,
        micros: started.elapsed().as_micros() as u64,
    };
    (answer, counts)
}

/// One camera ray's direct light along unit `dir`.
fn sample(
    world: &World,
    request: &TileRequest,
    dir: Vec3,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Vec3 {
    let origin = world.to_local(request.camera.eye_vec());
    let Some(hit) = world.trace(origin, dir, RayKind::Camera, counts) else {
        return Vec3::ZERO;
    };
    let surface = world.surface_at(origin, dir, hit);
    match request.lights {
        DirectLights::All => {
            world.albedo_at(&surface)
                * path_radiance(world, surface, -dir, DIRECT_ONLY, None, rng, counts).direct
        }
        DirectLights::Sun => shadowed(world, &surface, -dir, &[RayKind::ShadowSun], rng, counts),
        DirectLights::SunSky => shadowed(
            world,
            &surface,
            -dir,
            &[RayKind::ShadowSun, RayKind::ShadowSky],
            rng,
            counts,
        ),
    }
}

/// Next-event estimation at `s` toward the lights whose shadow rays are of `kinds`.
fn shadowed(
    world: &World,
    s: &Surface,
    wo: Vec3,
    kinds: &[RayKind],
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Vec3 {
    let bsdf = world.bsdf_at(s, Footprint::POINT);
    let origin = world.offset.origin(s.position, s.normal);
    let mut direct = Vec3::ZERO;
    shadow_rays(world, s, origin, wo, &bsdf, true, rng, |ray| {
        if kinds.contains(&ray.kind) && !world.occluded(origin, ray.dir, ray.tmax, ray.kind, counts)
        {
            direct += ray.contribution.diffuse;
        }
    });
    direct
}
