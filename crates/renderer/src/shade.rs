//! Shading requests: one `ShadePoint` at a quality, and whole batches spread over rayon, one point
//! per task or, with the wavefront estimator, one wave of points per task. Each point draws from
//! its own random stream, seeded by (batch seed, point index) only, so an answer does not depend
//! on thread scheduling.

use std::time::Instant;

use glam::Vec3;
use protocol::renderer_link::{Quality, Radiance, ShadeBatch, ShadePoint, point_flags};
use protocol::{PartEstimate, SampleParts};
use rayon::prelude::*;

use crate::counters::RayCounts;
use crate::estimator::{Estimator, PathParts, for_each_path};
use crate::point::locate;
use crate::sampling::{Rng, stream};
use crate::wavefront::{Start, WAVE_PATHS, trace_paths};
use crate::world::{Surface, World};

/// The answer for one point: an estimate with its uncertainty, in parts (DESIGN.md §5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shaded {
    /// The radiance: the mean of the paths with the point's albedo multiplying their
    /// illumination, plus the point's own emission (`parts.radiance(albedo)`).
    pub rgb: Vec3,
    /// Per part the mean of the paths and the sample variance of their luminance (0 with fewer
    /// than two paths). The point's own emission is exact, arrives at no vertex, is never
    /// filtered and is not multiplied by an albedo, so it goes with the view-dependent part.
    pub parts: SampleParts,
    /// Paths averaged; 0 when the point could not be shaded.
    pub paths: u32,
    /// `protocol::renderer_link::point_flags` bits.
    pub flags: u8,
}

/// Outgoing light of `p` toward its eye (or its normal, for a diffuse material), averaged over
/// `quality.paths` paths, in parts (illumination and view-dependent radiance), plus the point's
/// own emission on its emitting side.
pub fn shade_point(
    world: &World,
    p: &ShadePoint,
    quality: Quality,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> Shaded {
    let point = match prepare(world, p, counts) {
        Ok(point) => point,
        Err(invalid) => return invalid,
    };
    let mut sum = PathSum::new(point.flags);
    for_each_path(
        world,
        point.surface,
        point.wo,
        paths_of(quality),
        quality.bounces,
        rng,
        counts,
        |l| sum.add(l),
    );
    point.finish(world, sum)
}

/// Paths per point: at least one.
fn paths_of(quality: Quality) -> u32 {
    quality.paths.max(1)
}

/// A located point, ready for its paths.
struct Prepared {
    surface: Surface,
    wo: Vec3,
    /// The diffuse albedo there, which multiplies the illumination in [`Shaded::rgb`].
    albedo: Vec3,
    flags: u8,
}

/// Locates `p` (moved off a hidden spot when needed) and picks its outgoing direction; an
/// invalid point is answered at once.
fn prepare(world: &World, p: &ShadePoint, counts: &mut RayCounts) -> Result<Prepared, Shaded> {
    let located = locate(world, p, counts).map_err(|_| Shaded {
        rgb: Vec3::ZERO,
        parts: SampleParts::default(),
        paths: 0,
        flags: point_flags::INVALID_POINT,
    })?;
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
    Ok(Prepared {
        albedo: world.albedo_at(&s),
        surface: s,
        wo: outgoing_direction(&s, p.eye.map(|e| world.to_local(Vec3::from(e)))),
        flags,
    })
}

impl Prepared {
    /// The mean of the paths plus the point's own emission (in the view-dependent part).
    fn finish(&self, world: &World, sum: PathSum) -> Shaded {
        let emitted = world.emission(self.surface.triangle, -self.surface.normal);
        let paths = sum.direct.luminance.n;
        let parts = SampleParts {
            direct: sum.direct.estimate(paths, Vec3::ZERO),
            indirect: sum.indirect.estimate(paths, Vec3::ZERO),
            view_dependent: sum.view_dependent.estimate(paths, emitted),
        };
        Shaded {
            rgb: Vec3::from(parts.radiance(self.albedo.to_array())),
            parts,
            paths,
            flags: sum.flags,
        }
    }
}

/// The paths of one point as they arrive, per part.
struct PathSum {
    direct: PartSum,
    indirect: PartSum,
    view_dependent: PartSum,
    flags: u8,
}

impl PathSum {
    fn new(flags: u8) -> PathSum {
        PathSum {
            direct: PartSum::default(),
            indirect: PartSum::default(),
            view_dependent: PartSum::default(),
            flags,
        }
    }

    /// A path with a non-finite or negative value in any part counts as a black path in all,
    /// so that every mean stays over the same `paths`.
    fn add(&mut self, l: PathParts) {
        let good = |v: Vec3| v.is_finite() && v.min_element() >= 0.0;
        let l = if good(l.direct) && good(l.indirect) && good(l.view_dependent) {
            l
        } else {
            self.flags |= point_flags::NON_FINITE_DISCARDED;
            PathParts::default()
        };
        self.direct.add(l.direct);
        self.indirect.add(l.indirect);
        self.view_dependent.add(l.view_dependent);
    }
}

/// One part's running sum over a point's paths (or a pixel's samples, `direct_tile`).
#[derive(Default)]
pub(crate) struct PartSum {
    rgb: Vec3,
    luminance: PathLuminance,
}

impl PartSum {
    pub(crate) fn add(&mut self, l: Vec3) {
        self.rgb += l;
        self.luminance.add(conventions::luminance(l.to_array()));
    }

    /// The part's mean over `paths`, plus `exact` (a value without variance).
    pub(crate) fn estimate(&self, paths: u32, exact: Vec3) -> PartEstimate {
        PartEstimate {
            rgb: (exact + self.rgb / paths.max(1) as f32).to_array(),
            luminance_variance: self.luminance.variance(),
        }
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
    let (shaded, counts): (Vec<Shaded>, RayCounts) = match world.estimator {
        Estimator::Path => {
            let results: Vec<(Shaded, RayCounts)> = batch
                .points
                .par_iter()
                .enumerate()
                .map(|(i, p)| {
                    crate::subnormals::flush_on_this_thread();
                    let mut counts = RayCounts::default();
                    let mut rng = stream(batch.seed, i as u64);
                    let shaded = shade_point(world, p, batch.quality, &mut rng, &mut counts);
                    (shaded, counts)
                })
                .collect();
            let counts = sum_counts(results.iter().map(|(_, c)| *c));
            (results.into_iter().map(|(s, _)| s).collect(), counts)
        }
        Estimator::Wavefront => {
            // Whole waves per task: the chunks, not the threads, fix the order of the work.
            let chunk = (WAVE_PATHS / paths_of(batch.quality) as usize).max(1);
            let results: Vec<(Vec<Shaded>, RayCounts)> = batch
                .points
                .par_chunks(chunk)
                .enumerate()
                .map(|(k, points)| {
                    crate::subnormals::flush_on_this_thread();
                    shade_wave(world, batch, k * chunk, points)
                })
                .collect();
            let counts = sum_counts(results.iter().map(|(_, c)| *c));
            (results.into_iter().flat_map(|(s, _)| s).collect(), counts)
        }
    };
    let radiance = Radiance {
        batch_id: batch.batch_id,
        quality: batch.quality,
        parts: shaded.iter().map(|s| s.parts).collect(),
        paths: shaded.iter().map(|s| s.paths).collect(),
        flags: shaded.iter().map(|s| s.flags).collect(),
        micros: start.elapsed().as_micros() as u64,
    };
    (radiance, counts)
}

fn sum_counts(counts: impl Iterator<Item = RayCounts>) -> RayCounts {
    let mut sum = RayCounts::default();
    for c in counts {
        sum += c;
    }
    sum
}

/// Points `first..` of a batch shaded as one wave of paths (`wavefront`), each point drawing from
/// the same stream as in [`shade_point`].
fn shade_wave(
    world: &World,
    batch: &ShadeBatch,
    first: usize,
    points: &[ShadePoint],
) -> (Vec<Shaded>, RayCounts) {
    let mut counts = RayCounts::default();
    let prepared: Vec<Result<Prepared, Shaded>> = points
        .iter()
        .map(|p| prepare(world, p, &mut counts))
        .collect();
    let mut rngs: Vec<Rng> = (0..points.len())
        .map(|i| stream(batch.seed, (first + i) as u64))
        .collect();
    let starts: Vec<Start> = prepared
        .iter()
        .enumerate()
        .filter_map(|(i, p)| p.as_ref().ok().map(|p| (i, p)))
        .map(|(i, p)| Start {
            surface: p.surface,
            wo: p.wo,
            paths: paths_of(batch.quality),
            stream: i,
            // Drawn first from the point's stream, as `for_each_path` does.
            strata: world.first_bounce.strata(&mut rngs[i]),
            first_index: 0,
        })
        .collect();
    let mut sums: Vec<PathSum> = prepared
        .iter()
        .map(|p| PathSum::new(p.as_ref().map_or(0, |p| p.flags)))
        .collect();
    trace_paths(
        world,
        &starts,
        batch.quality.bounces,
        &mut rngs,
        &mut counts,
        |i, l| sums[starts[i].stream].add(l),
    );
    let shaded = prepared
        .into_iter()
        .zip(sums)
        .map(|(p, sum)| match p {
            Ok(p) => p.finish(world, sum),
            Err(invalid) => invalid,
        })
        .collect();
    (shaded, counts)
}
