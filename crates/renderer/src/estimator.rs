//! Path tracing with next-event estimation (DESIGN.md §7): the outgoing radiance of a surface point
//! toward a direction. The sun and emitters are reached by next-event estimation at every vertex;
//! a mirror bounce instead sees what it hits (emitters, the sun's disc), so every light path is
//! counted exactly once. Bounce depth counts diffuse and glossy bounces; mirror
//! bounces are free up to `MAX_MIRROR_CHAIN` so a mirror still shows its reflection at the
//! direct-light-only quality.
//!
//! Two schedules of the same estimator share every step below: [`path_radiance`] follows one path
//! at a time; `wavefront` advances a batch of paths together, one stream of rays at a time. Which
//! one runs is [`Estimator`], a field of the [`World`].

use glam::Vec3;

use crate::bvh::Hit;
use crate::counters::{RayCounts, RayKind};
use crate::material::{Bsdf, BsdfSample, Lobes};
use crate::sampling::{Rng, uniform2, uniform3};
use crate::texture_lod::Footprint;
use crate::wavefront::{Start, trace_paths};
use crate::world::{Surface, World};
use rand::RngExt;

/// Russian roulette starts after this many bounces.
const ROULETTE_AFTER: u32 = 3;
/// Longest chain of mirror reflections followed (two facing mirrors would loop forever).
const MAX_MIRROR_CHAIN: u32 = 8;
/// Safety cap on unbounded paths; roulette ends them long before in any scene with albedo < 1.
pub(crate) const MAX_DEPTH: u32 = 1024;

/// How the paths of a batch are scheduled (DESIGN.md §7): the answers are the same in
/// distribution, only the order of the work differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Estimator {
    /// One path at a time, each ray traced as soon as it is known.
    #[default]
    Path,
    /// Paths advanced together: every path's shadow rays as one stream, then its continuation
    /// rays as another (`wavefront`).
    Wavefront,
}

impl Estimator {
    pub const ALL: [Estimator; 2] = [Estimator::Path, Estimator::Wavefront];

    pub fn name(self) -> &'static str {
        match self {
            Estimator::Path => "path",
            Estimator::Wavefront => "wavefront",
        }
    }
}

/// One path's estimate in parts (DESIGN.md §5, "Parts, and textures"). The first vertex's
/// diffuse lobe is taken with a unit albedo, so `direct` and `indirect` are **illumination**,
/// which that vertex's albedo multiplies on display ([`PathParts::radiance`]); what leaves the
/// first vertex over its glossy or mirror lobe stays radiance, `view_dependent`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathParts {
    /// Illumination arriving at the first vertex straight from a light: its shadow rays, and its
    /// diffuse continuation ray where that escapes to the sky.
    pub direct: Vec3,
    /// Illumination arriving at the first vertex over further vertices.
    pub indirect: Vec3,
    /// Radiance the first vertex's glossy or mirror lobe reflects toward the eye, from lights
    /// and from everything behind it (the point's own emission is added per point, `shade`).
    pub view_dependent: Vec3,
}

impl PathParts {
    /// The path's radiance, with `albedo`, the first vertex's diffuse albedo, multiplying its
    /// illumination.
    pub fn radiance(&self, albedo: Vec3) -> Vec3 {
        albedo * (self.direct + self.indirect) + self.view_dependent
    }

    /// Adds what the lights bring at a vertex on `route` (already weighted by the path's
    /// throughput), lobe by lobe at the first vertex.
    pub(crate) fn add_light(&mut self, route: Route, l: Lobes) {
        match route {
            Route::FirstVertex => {
                self.direct += l.diffuse;
                self.view_dependent += l.specular;
            }
            Route::Indirect => self.indirect += l.total(),
            Route::ViewDependent => self.view_dependent += l.total(),
        }
    }

    /// Adds `l`, what a continuation ray of `kind` leaving a vertex on `route` sees (weighted by
    /// the path's throughput): a diffuse ray's under the diffuse lobe, others' the specular.
    pub(crate) fn add_seen(&mut self, route: Route, kind: RayKind, l: Vec3) {
        let lobes = if kind == RayKind::Bounce {
            Lobes {
                diffuse: l,
                specular: Vec3::ZERO,
            }
        } else {
            Lobes {
                diffuse: Vec3::ZERO,
                specular: l,
            }
        };
        self.add_light(route, lobes);
    }
}

/// Which part what arrives at a path's current vertex belongs to ([`PathParts`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Route {
    /// The first vertex: its diffuse lobe's share is direct illumination, its specular lobes'
    /// view-dependent radiance.
    FirstVertex,
    /// Past a first vertex left over its diffuse lobe.
    Indirect,
    /// Past a first vertex left over a glossy or mirror lobe.
    ViewDependent,
}

impl Route {
    /// The route once a continuation ray of `kind` left the current vertex.
    pub(crate) fn after(self, kind: RayKind) -> Route {
        match self {
            Route::FirstVertex if kind == RayKind::Bounce => Route::Indirect,
            Route::FirstVertex => Route::ViewDependent,
            later => later,
        }
    }

    /// How the surface at `s` scatters on this route: with a unit diffuse albedo at the first
    /// vertex (`World::illumination_bsdf_at`), as it is further on, its texture read over the
    /// path's `footprint` there.
    pub(crate) fn bsdf_at(self, world: &World, s: &Surface, footprint: Footprint) -> Bsdf {
        match self {
            Route::FirstVertex => world.illumination_bsdf_at(s),
            Route::Indirect | Route::ViewDependent => world.bsdf_at(s, footprint),
        }
    }
}

/// `paths` estimates of the radiance leaving `surface` toward unit `wo` (as [`path_radiance`]),
/// each handed to `f` as it completes, scheduled by the world's [`Estimator`].
#[allow(clippy::too_many_arguments)]
pub fn for_each_path(
    world: &World,
    surface: Surface,
    wo: Vec3,
    paths: u32,
    max_bounces: Option<u32>,
    rng: &mut Rng,
    counts: &mut RayCounts,
    mut f: impl FnMut(PathParts),
) {
    let strata = world.first_bounce.strata(rng);
    match world.estimator {
        Estimator::Path => {
            for k in 0..paths {
                let first_bounce = strata.map(|s| s.point(k));
                f(path_radiance(
                    world,
                    surface,
                    wo,
                    max_bounces,
                    first_bounce,
                    rng,
                    counts,
                ));
            }
        }
        Estimator::Wavefront => {
            let start = Start {
                surface,
                wo,
                paths,
                stream: 0,
                strata,
                first_index: 0,
            };
            let rngs = std::slice::from_mut(rng);
            trace_paths(world, &[start], max_bounces, rngs, counts, |_, l| f(l));
        }
    }
}

/// One path's estimate of the light leaving `surface` toward unit `wo`, in parts
/// ([`PathParts`]: illumination and view-dependent radiance), excluding the surface's own
/// emission. `max_bounces`: `Some(0)` = direct light only, `None` = unbounded with roulette.
///
/// The sky is reached by the path's own continuation ray where there is one (for a Lambertian
/// vertex that ray is cosine-distributed, exactly the sky's next-event density, so it spares a
/// shadow ray at the same variance) and by next-event estimation at the vertex where the path
/// ends.
///
/// `first_bounce` is the 2D sample of the first continuation's direction (its stratum, `strata`),
/// or `None` to draw it from `rng` like every other number.
pub(crate) fn path_radiance(
    world: &World,
    surface: Surface,
    wo: Vec3,
    max_bounces: Option<u32>,
    first_bounce: Option<[f32; 2]>,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> PathParts {
    let mut radiance = PathParts::default();
    let mut throughput = Vec3::ONE;
    let mut s = surface;
    let mut wo = wo;
    let mut depth = Depth::START;
    let mut direction_u = first_bounce;
    let mut route = Route::FirstVertex;
    let mut footprint = Footprint::POINT;
    for _ in 0..MAX_DEPTH {
        let bsdf = &route.bsdf_at(world, &s, footprint);
        let origin = world.offset.origin(s.position, s.normal);
        let u = direction_u.take().unwrap_or_else(|| uniform2(rng));
        let next = continuation(world, bsdf, &s, wo, max_bounces, depth, throughput, u, rng);
        let mut light = Lobes::default();
        shadow_rays(world, &s, origin, wo, bsdf, next.is_none(), rng, |ray| {
            if !world.occluded(origin, ray.dir, ray.tmax, ray.kind, counts) {
                light += ray.contribution;
            }
        });
        radiance.add_light(route, light.scaled(throughput));
        let Some((sample, next_throughput)) = next else {
            break;
        };
        throughput = next_throughput;
        let hit = world.trace(origin, sample.dir, sample.kind, counts);
        footprint = footprint.after(sample.kind, hit.map_or(0.0, |h| h.t));
        let arrived = arrive(world, origin, sample.dir, sample.kind, hit, depth);
        radiance.add_seen(route, sample.kind, throughput * arrived.seen);
        route = route.after(sample.kind);
        let Some((next_surface, next_depth)) = arrived.next else {
            break;
        };
        s = next_surface;
        depth = next_depth;
        wo = -sample.dir;
    }
    radiance
}

/// Bounces taken so far: diffuse and glossy ones count against the quality's depth, mirror ones
/// against `MAX_MIRROR_CHAIN`.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Depth {
    bounces: u32,
    mirror_chain: u32,
}

impl Depth {
    pub(crate) const START: Depth = Depth {
        bounces: 0,
        mirror_chain: 0,
    };
}

/// The ray that continues the path from `s`, with the throughput after it, or `None` where the
/// path ends: no lobe sampled, depth exhausted, an effect the scene does not call for, or
/// Russian roulette. `direction_u` places the direction within the lobe; the lobe choice and
/// the roulette draw from `rng`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn continuation(
    world: &World,
    bsdf: &Bsdf,
    s: &Surface,
    wo: Vec3,
    max_bounces: Option<u32>,
    depth: Depth,
    throughput: Vec3,
    direction_u: [f32; 2],
    rng: &mut Rng,
) -> Option<(BsdfSample, Vec3)> {
    let lobe_u = rng.random::<f32>();
    let sample = bsdf.sample(s.normal, wo, [direction_u[0], direction_u[1], lobe_u])?;
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

/// A shadow ray of next-event estimation and what it brings, lobe by lobe (before the path's
/// throughput), when nothing blocks it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ShadowRay {
    pub(crate) dir: Vec3,
    pub(crate) tmax: f32,
    pub(crate) kind: RayKind,
    pub(crate) contribution: Lobes,
}

/// Next-event estimation: one sample of each light, each handed to `emit` as a shadow ray from
/// `origin`; the sky only when `sky_here` (no continuation ray will see it).
#[allow(clippy::too_many_arguments)]
pub(crate) fn shadow_rays(
    world: &World,
    s: &Surface,
    origin: Vec3,
    wo: Vec3,
    bsdf: &Bsdf,
    sky_here: bool,
    rng: &mut Rng,
    mut emit: impl FnMut(ShadowRay),
) {
    for light in &world.lights.lights {
        if light.seen_by_escaping_rays() && !sky_here {
            continue;
        }
        let Some(ls) = light.sample(origin, s.normal, uniform3(rng)) else {
            continue;
        };
        let f = bsdf.eval_lobes(s.normal, wo, ls.dir);
        if f.total().max_element() <= 0.0 {
            continue;
        }
        // Stop short of the light's own surface by its rounding margin.
        let tmax = if ls.distance.is_finite() {
            ls.distance - 2.0 * world.offset.margin(origin + ls.dir * ls.distance)
        } else {
            f32::INFINITY
        };
        if tmax > 0.0 {
            emit(ShadowRay {
                dir: ls.dir,
                tmax,
                kind: light.shadow_kind(),
                contribution: f.scaled(s.normal.dot(ls.dir) * ls.radiance_over_pdf),
            });
        }
    }
}

/// What a continuation ray found: the radiance it sees itself (before the path's throughput),
/// and the next vertex with the depth there, `None` where the path leaves the scene.
pub(crate) struct Arrival {
    pub(crate) seen: Vec3,
    pub(crate) next: Option<(Surface, Depth)>,
}

/// The continuation ray from `origin` along `dir` met `hit`: an escaping ray sees the sky (and,
/// through a mirror, the sun's disc); a mirror ray sees the emitter it hits.
pub(crate) fn arrive(
    world: &World,
    origin: Vec3,
    dir: Vec3,
    kind: RayKind,
    hit: Option<Hit>,
    depth: Depth,
) -> Arrival {
    let mirror = kind == RayKind::Mirror;
    let Some(hit) = hit else {
        return Arrival {
            seen: world.lights.escaped_radiance(dir, mirror),
            next: None,
        };
    };
    let (seen, depth) = if mirror {
        (
            world.emission(hit.triangle, dir),
            Depth {
                mirror_chain: depth.mirror_chain + 1,
                ..depth
            },
        )
    } else {
        (
            Vec3::ZERO,
            Depth {
                bounces: depth.bounces + 1,
                mirror_chain: 0,
            },
        )
    };
    Arrival {
        seen,
        next: Some((world.surface_at(origin, dir, hit), depth)),
    }
}
