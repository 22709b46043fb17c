//! The estimator of `estimator` scheduled as ray streams (DESIGN.md §7): a wave of paths (those
//! of a few shading points, or of a few pixels) advances one vertex at a time, and each step
//! traces its rays as two streams: first every path's shadow rays, then every path's
//! continuation ray. The paths' state lives in flat arrays indexed by path.
//!
//! The streams are there to make rays of one kind, and the rays of one shading point (which share
//! an origin), follow one another through the BVH; shadow rays also try the triangle that blocked
//! the previous one first (`World::occluded_after`), and the sun shadow rays of a point's paths,
//! which share an origin and nearly one direction, go eight at a time as packets
//! (`World::packets`). With obvhs's one-ray-at-a-time traversal
//! that alone buys little: docs/bench/renderer.md measures both schedules side by side, and
//! `Estimator::default` is the one that measured faster. Every step is `estimator`'s own, so the
//! answers are the same in distribution.
//!
//! Each path draws from its start's random stream, in an order fixed by the starts alone: an
//! answer depends only on the starts and the seeds, never on thread scheduling.

use glam::Vec3;

use crate::bvh::PACKET_RAYS;
use crate::counters::{RayCounts, RayKind};
use crate::estimator::{
    Depth, MAX_DEPTH, PathParts, Route, ShadowRay, arrive, continuation, shadow_rays,
};
use crate::material::Lobes;
use crate::ray_order::RayOrder;
use crate::sampling::{Rng, uniform2};
use crate::strata::Strata;
use crate::texture_lod::Footprint;
use crate::world::{Surface, World};

/// Paths advanced together: the 64 paths of 64 points at the interactive quality. A wave's state
/// is about 100 bytes a path, so a wave stays in the L2 cache.
pub(crate) const WAVE_PATHS: usize = 4096;

/// `paths` paths leaving `surface` toward `wo`, drawing from random stream `stream`; their first
/// bounces take points `first_index..` of `strata` where there are strata (as `path_radiance`'s
/// `first_bounce`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Start {
    pub(crate) surface: Surface,
    pub(crate) wo: Vec3,
    pub(crate) paths: u32,
    pub(crate) stream: usize,
    pub(crate) strata: Option<Strata>,
    pub(crate) first_index: u32,
}

/// Traces every path of `starts` in waves of at most [`WAVE_PATHS`] and hands each path's
/// radiance in parts (without the start's own emission) to `done`, with the index of its start,
/// in the order of the starts.
pub(crate) fn trace_paths(
    world: &World,
    starts: &[Start],
    max_bounces: Option<u32>,
    rngs: &mut [Rng],
    counts: &mut RayCounts,
    mut done: impl FnMut(usize, PathParts),
) {
    let mut wave = Wave::default();
    let mut streams = Streams::default();
    for (i, start) in starts.iter().enumerate() {
        for k in 0..start.paths {
            wave.push(i, start, k);
            if wave.len() == WAVE_PATHS {
                wave.run(world, max_bounces, rngs, &mut streams, counts);
                wave.drain(&mut done);
            }
        }
    }
    if wave.len() > 0 {
        wave.run(world, max_bounces, rngs, &mut streams, counts);
        wave.drain(&mut done);
    }
}

/// The state of a wave's paths, structure of arrays, indexed by path.
#[derive(Default)]
struct Wave {
    start: Vec<u32>,
    stream: Vec<u32>,
    radiance: Vec<PathParts>,
    /// Which part what arrives at the path's current vertex belongs to.
    route: Vec<Route>,
    throughput: Vec<Vec3>,
    surface: Vec<Surface>,
    wo: Vec<Vec3>,
    depth: Vec<Depth>,
    /// The width of the path's cone at its current vertex (`texture_lod`).
    footprint: Vec<Footprint>,
    /// The first continuation's direction sample, until the first vertex takes it.
    first_bounce: Vec<Option<[f32; 2]>>,
}

/// Cells per axis of the origins' grid by which continuation rays are regrouped, as a power of
/// two: with the direction's octant, 512 buckets for a wave of 4096 rays.
const ORDER_BITS_PER_AXIS: u32 = 2;

/// The rays of one step, and which paths are still going: buffers kept from wave to wave.
#[derive(Default)]
struct Streams {
    active: Vec<u32>,
    shadow: ShadowStream,
    bounce: BounceStream,
    /// Continuation rays are traced in this order (`ray_order`), made once per world.
    order: Option<RayOrder>,
    sequence: Vec<u32>,
}

#[derive(Default)]
struct ShadowStream {
    path: Vec<u32>,
    origin: Vec<Vec3>,
    /// Contributions already weighted by the path's throughput.
    ray: Vec<ShadowRay>,
}

#[derive(Default)]
struct BounceStream {
    path: Vec<u32>,
    origin: Vec<Vec3>,
    dir: Vec<Vec3>,
    kind: Vec<RayKind>,
}

impl Wave {
    fn len(&self) -> usize {
        self.start.len()
    }

    /// Path `k` of `start`.
    fn push(&mut self, start_index: usize, start: &Start, k: u32) {
        self.start.push(start_index as u32);
        self.stream.push(start.stream as u32);
        self.radiance.push(PathParts::default());
        self.route.push(Route::FirstVertex);
        self.throughput.push(Vec3::ONE);
        self.surface.push(start.surface);
        self.wo.push(start.wo);
        self.depth.push(Depth::START);
        self.footprint.push(Footprint::POINT);
        self.first_bounce
            .push(start.strata.map(|s| s.point(start.first_index + k)));
    }

    /// Advances every path to its end, one vertex per step (the same cap as `path_radiance`).
    fn run(
        &mut self,
        world: &World,
        max_bounces: Option<u32>,
        rngs: &mut [Rng],
        s: &mut Streams,
        counts: &mut RayCounts,
    ) {
        s.active.clear();
        s.active.extend(0..self.len() as u32);
        for _ in 0..MAX_DEPTH {
            if s.active.is_empty() {
                break;
            }
            s.shadow.clear();
            s.bounce.clear();
            for &p in &s.active {
                self.shade_vertex(world, p, max_bounces, rngs, &mut s.shadow, &mut s.bounce);
            }
            self.trace_shadows(world, &s.shadow, counts);
            s.active.clear();
            let order = s
                .order
                .get_or_insert_with(|| RayOrder::new(world.bounds(), ORDER_BITS_PER_AXIS));
            let bounce = &s.bounce;
            order.order(
                bounce.path.len(),
                |k| (bounce.origin[k], bounce.dir[k]),
                &mut s.sequence,
            );
            self.trace_bounces(world, bounce, &s.sequence, &mut s.active, counts);
        }
    }

    /// One vertex of path `p`: its continuation sampled, its shadow rays and continuation ray
    /// queued (`path_radiance`'s loop body up to the traces).
    fn shade_vertex(
        &mut self,
        world: &World,
        p: u32,
        max_bounces: Option<u32>,
        rngs: &mut [Rng],
        shadow: &mut ShadowStream,
        bounce: &mut BounceStream,
    ) {
        let i = p as usize;
        let (s, wo, throughput) = (self.surface[i], self.wo[i], self.throughput[i]);
        let rng = &mut rngs[self.stream[i] as usize];
        let bsdf = &self.route[i].bsdf_at(world, &s, self.footprint[i]);
        let origin = world.offset.origin(s.position, s.normal);
        let u = self.first_bounce[i].take().unwrap_or_else(|| uniform2(rng));
        let next = continuation(
            world,
            bsdf,
            &s,
            wo,
            max_bounces,
            self.depth[i],
            throughput,
            u,
            rng,
        );
        shadow_rays(world, &s, origin, wo, bsdf, next.is_none(), rng, |ray| {
            shadow.path.push(p);
            shadow.origin.push(origin);
            shadow.ray.push(ShadowRay {
                contribution: ray.contribution.scaled(throughput),
                ..ray
            });
        });
        if let Some((sample, next_throughput)) = next {
            self.throughput[i] = next_throughput;
            bounce.path.push(p);
            bounce.origin.push(origin);
            bounce.dir.push(sample.dir);
            bounce.kind.push(sample.kind);
        }
    }

    fn trace_shadows(&mut self, world: &World, shadow: &ShadowStream, counts: &mut RayCounts) {
        // The blocker of the last blocked ray toward each kind of light: the next rays of the
        // same point toward it (same origin, nearly the same direction for the sun) are most
        // often blocked by it too.
        let mut last = [None; 3];
        let mut sun = SunPacket::default();
        for (k, ((&p, &origin), ray)) in shadow
            .path
            .iter()
            .zip(&shadow.origin)
            .zip(&shadow.ray)
            .enumerate()
        {
            let slot = light_slot(ray.kind);
            if world.packets && ray.kind == RayKind::ShadowSun {
                counts.count(ray.kind);
                let blocked = last[slot]
                    .is_some_and(|prim| world.bvh.blocks(prim, origin, ray.dir, ray.tmax));
                if blocked {
                    continue;
                }
                // Only rays from one origin (the paths of one point at their first vertex) make
                // a packet: later vertices' rays start all over the scene and measured slower
                // as packets than one by one.
                if sun.len > 0 && shadow.origin[sun.rays[0]] != origin {
                    self.trace_sun_packet(world, shadow, &mut sun, &mut last[slot]);
                }
                if sun.push(k) {
                    self.trace_sun_packet(world, shadow, &mut sun, &mut last[slot]);
                }
                continue;
            }
            if !world.occluded_after(origin, ray.dir, ray.tmax, ray.kind, &mut last[slot], counts) {
                self.add(p as usize, ray.contribution);
            }
        }
        self.trace_sun_packet(
            world,
            shadow,
            &mut sun,
            &mut last[light_slot(RayKind::ShadowSun)],
        );
    }

    /// Traces the sun shadow rays waiting in `sun` as one packet (they share nearly one
    /// direction, DESIGN.md §7), adds what the unblocked ones bring, and empties it; a blocker
    /// found becomes `last`.
    fn trace_sun_packet(
        &mut self,
        world: &World,
        shadow: &ShadowStream,
        sun: &mut SunPacket,
        last: &mut Option<u32>,
    ) {
        let rays = &sun.rays[..sun.len];
        let (mut origins, mut dirs) = ([Vec3::ZERO; PACKET_RAYS], [Vec3::ZERO; PACKET_RAYS]);
        let mut tmaxs = [0.0; PACKET_RAYS];
        for (lane, &k) in rays.iter().enumerate() {
            origins[lane] = shadow.origin[k];
            dirs[lane] = shadow.ray[k].dir;
            tmaxs[lane] = shadow.ray[k].tmax;
        }
        let mut occluders = [None; PACKET_RAYS];
        let occluders = &mut occluders[..rays.len()];
        world.bvh.occluder_packet(
            &origins[..rays.len()],
            &dirs[..rays.len()],
            &tmaxs[..rays.len()],
            occluders,
        );
        for (&k, occluder) in rays.iter().zip(occluders.iter()) {
            match occluder {
                None => self.add(shadow.path[k] as usize, shadow.ray[k].contribution),
                Some(prim) => *last = Some(*prim),
            }
        }
        sun.len = 0;
    }

    /// Traces the continuation rays in `sequence`'s order; the paths that found a next vertex
    /// go to `active`.
    fn trace_bounces(
        &mut self,
        world: &World,
        bounce: &BounceStream,
        sequence: &[u32],
        active: &mut Vec<u32>,
        counts: &mut RayCounts,
    ) {
        for k in sequence.iter().map(|&k| k as usize) {
            let (p, origin, dir, kind) = (
                bounce.path[k],
                bounce.origin[k],
                bounce.dir[k],
                bounce.kind[k],
            );
            let i = p as usize;
            let hit = world.trace(origin, dir, kind, counts);
            self.footprint[i] = self.footprint[i].after(kind, hit.map_or(0.0, |h| h.t));
            let arrived = arrive(world, origin, dir, kind, hit, self.depth[i]);
            let route = self.route[i];
            self.radiance[i].add_seen(route, kind, self.throughput[i] * arrived.seen);
            self.route[i] = route.after(kind);
            if let Some((surface, depth)) = arrived.next {
                self.surface[i] = surface;
                self.depth[i] = depth;
                self.wo[i] = -dir;
                active.push(p);
            }
        }
    }

    /// Adds `l`, what the lights bring at path `i`'s current vertex, to the parts it belongs to.
    fn add(&mut self, i: usize, l: Lobes) {
        self.radiance[i].add_light(self.route[i], l);
    }

    /// Hands every path's radiance to `done` in path order and empties the wave.
    fn drain(&mut self, done: &mut impl FnMut(usize, PathParts)) {
        for (&start, &radiance) in self.start.iter().zip(&self.radiance) {
            done(start as usize, radiance);
        }
        self.start.clear();
        self.stream.clear();
        self.radiance.clear();
        self.route.clear();
        self.throughput.clear();
        self.surface.clear();
        self.wo.clear();
        self.depth.clear();
        self.footprint.clear();
        self.first_bounce.clear();
    }
}

/// Up to [`PACKET_RAYS`] sun shadow rays of a stream (their indices) waiting to be traced
/// together.
#[derive(Default)]
struct SunPacket {
    rays: [usize; PACKET_RAYS],
    len: usize,
}

impl SunPacket {
    /// Adds ray `k`; true when the packet is full.
    fn push(&mut self, k: usize) -> bool {
        self.rays[self.len] = k;
        self.len += 1;
        self.len == PACKET_RAYS
    }
}

/// Which of `trace_shadows`' remembered blockers a shadow ray uses.
fn light_slot(kind: RayKind) -> usize {
    match kind {
        RayKind::ShadowSun => 0,
        RayKind::ShadowSky => 1,
        _ => 2,
    }
}

impl ShadowStream {
    fn clear(&mut self) {
        self.path.clear();
        self.origin.clear();
        self.ray.clear();
    }
}

impl BounceStream {
    fn clear(&mut self) {
        self.path.clear();
        self.origin.clear();
        self.dir.clear();
        self.kind.clear();
    }
}
