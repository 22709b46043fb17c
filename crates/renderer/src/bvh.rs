//! Ray tracing core over the scene's triangles: a closest-hit query and an early-exit occlusion
//! query (DESIGN.md §7). obvhs builds the tree, a compressed wide BVH (CWBVH); the queries run
//! one of two traversals of it ([`Traversal`]):
//! - **wide** (the default on x86-64): the tree decoded into full-precision eight-wide nodes
//!   (`wide_bvh`), traversed nearest child first with eight boxes per vector step, a node's leaf
//!   children tested as soon as it is visited (`wide_traversal`);
//! - **compressed**: obvhs's own `traverse!` loop over the CWBVH nodes, the intersection passed
//!   in as a closure, obvhs style (the only one elsewhere, and the comparison in benchmarks).
//!
//! Coherent rays (a pixel tile's camera rays, shadow rays toward the sun) may also be traced as
//! packets of up to eight rays of one direction octant (`packet_traversal`, over the wide nodes);
//! each ray gets the answer its one-ray query gives.
//!
//! Each query exists once per [`VectorLevel`]. Target features do not reach into a function that
//! is not inlined, so both traversals are `#[inline(always)]` bodies compiled inside one entry
//! point per level.

use std::time::{Duration, Instant};

use glam::{UVec2, Vec3};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use scene::Mesh;
pub use scene::bvh::BuildPreset;
use scene::bvh::{build_cwbvh, bvh_triangles};

#[cfg(target_arch = "x86_64")]
use crate::packet_traversal::{self, PACKET, Packet};
use crate::vector_level::VectorLevel;
#[cfg(target_arch = "x86_64")]
use crate::wide_bvh::WideBvh;
#[cfg(target_arch = "x86_64")]
use crate::wide_traversal::{self, Query};

/// Which traversal of the tree the queries run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Traversal {
    /// Full-precision eight-wide nodes, nearest child first (`wide_traversal`; x86-64 only).
    Wide,
    /// obvhs's traversal of its compressed nodes.
    Compressed,
}

impl Traversal {
    pub const ALL: [Traversal; 2] = [Traversal::Wide, Traversal::Compressed];

    pub fn name(self) -> &'static str {
        match self {
            Traversal::Wide => "wide",
            Traversal::Compressed => "compressed",
        }
    }
}

/// Rays per packet of the packet queries ([`SceneBvh::closest_hit_packet`]): one AVX register
/// of lanes.
pub const PACKET_RAYS: usize = 8;

/// The deepest tree the wide traversal runs.
pub const WIDE_MAX_DEPTH: usize = 36;

/// The closest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index into the scene's triangles.
    pub triangle: u32,
    pub t: f32,
}

/// The rays of a packet query: `origins[k] + t dirs[k]`, t in (0, tmaxs[k]).
struct Rays<'a> {
    origins: &'a [Vec3],
    dirs: &'a [Vec3],
    tmaxs: &'a [f32],
}

impl<'a> Rays<'a> {
    /// Panics unless the slices, and the `answers` the query writes, are equally long.
    fn new(origins: &'a [Vec3], dirs: &'a [Vec3], tmaxs: &'a [f32], answers: usize) -> Rays<'a> {
        assert!(
            dirs.len() == origins.len() && tmaxs.len() == origins.len(),
            "one direction and one tmax per origin"
        );
        assert_eq!(answers, origins.len(), "one answer per ray");
        Rays {
            origins,
            dirs,
            tmaxs,
        }
    }

    /// `answers[k]` for each ray: runs of [`PACKET_RAYS`] consecutive rays offered to
    /// `as_packet` (which says whether it traced them), the rays of a run it declines to `single`.
    fn by_packets<T>(
        &self,
        answers: &mut [T],
        as_packet: impl Fn(&[Vec3], &[Vec3], &[f32], &mut [T]) -> bool,
        single: impl Fn(Vec3, Vec3, f32) -> T,
    ) {
        for (k, answers) in answers.chunks_mut(PACKET_RAYS).enumerate() {
            let run = k * PACKET_RAYS..k * PACKET_RAYS + answers.len();
            let o = &self.origins[run.clone()];
            let (d, t) = (&self.dirs[run.clone()], &self.tmaxs[run]);
            if !as_packet(o, d, t, answers) {
                for (k, answer) in answers.iter_mut().enumerate() {
                    *answer = single(o[k], d[k], t[k]);
                }
            }
        }
    }
}

pub struct SceneBvh {
    bvh: CwBvh,
    /// Triangles in BVH primitive order (a triangle split by the builder appears once per
    /// reference), so a leaf test reads memory in traversal order without an indirection.
    prims: Vec<RtTriangle>,
    /// Scene triangle of each BVH primitive.
    prim_triangle: Vec<u32>,
    /// The tree decoded for the wide traversal; None off x86-64 or for a degenerate, too deep
    /// tree (`wide_bvh::MAX_DEPTH`).
    #[cfg(target_arch = "x86_64")]
    wide: Option<WideBvh>,
    traversal: Traversal,
    preset: BuildPreset,
    build_time: Duration,
    /// Only ever a level the CPU has (`set_vector_level` checks it).
    level: VectorLevel,
}

impl SceneBvh {
    pub fn build(mesh: &Mesh, preset: BuildPreset) -> SceneBvh {
        let start = Instant::now();
        let tris = bvh_triangles(mesh);
        let bvh = build_cwbvh(&tris, preset);
        let prim_triangle = bvh.primitive_indices.clone();
        let prims: Vec<RtTriangle> = prim_triangle
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        #[cfg(target_arch = "x86_64")]
        let wide = WideBvh::from_cwbvh(&bvh);
        #[cfg(target_arch = "x86_64")]
        let traversal = if wide.is_some() {
            Traversal::Wide
        } else {
            Traversal::Compressed
        };
        #[cfg(not(target_arch = "x86_64"))]
        let traversal = Traversal::Compressed;
        SceneBvh {
            bvh,
            prims,
            prim_triangle,
            #[cfg(target_arch = "x86_64")]
            wide,
            traversal,
            preset,
            build_time: start.elapsed(),
            level: VectorLevel::selected(),
        }
    }

    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    /// Whether the wide traversal can run this tree (x86-64, and at most [`WIDE_MAX_DEPTH`]
    /// levels deep).
    pub fn wide_available(&self) -> bool {
        #[cfg(target_arch = "x86_64")]
        return self.wide.is_some();
        #[cfg(not(target_arch = "x86_64"))]
        return false;
    }

    /// Runs `traversal` from now on (benchmarks and `--traversal` compare them on one tree).
    /// Panics where the wide traversal is not available.
    pub fn set_traversal(&mut self, traversal: Traversal) {
        assert!(
            traversal == Traversal::Compressed || self.wide_available(),
            "the wide traversal is not available for this tree"
        );
        self.traversal = traversal;
    }

    pub fn vector_level(&self) -> VectorLevel {
        self.level
    }

    /// Runs the queries at `level` from now on (benchmarks and tests compare levels on one BVH).
    /// Panics when the CPU lacks it.
    pub fn set_vector_level(&mut self, level: VectorLevel) {
        assert!(level.available(), "this CPU lacks {}", level.name());
        self.level = level;
    }

    /// The preset the tree was built with.
    pub fn preset(&self) -> BuildPreset {
        self.preset
    }

    /// Wall time of `build`, triangle conversion included.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Closest hit along `origin + t dir`, t in (0, tmax). `dir` need not be unit length; `t` is in
    /// its units.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if let (Traversal::Wide, Some(wide)) = (self.traversal, &self.wide) {
            let q = Query::new(origin, dir, tmax);
            let prims = &self.prims;
            let hit = match self.level {
                // SAFETY: `level` is V3 only where the CPU has every feature of `x86_64_v3`.
                VectorLevel::V3 => unsafe { x86_64_v3::wide_closest(wide, prims, &q) },
                // SAFETY: SSE is part of x86-64.
                VectorLevel::Baseline => unsafe {
                    wide_traversal::closest::<wide_traversal::Sse>(wide, prims, &q)
                },
            };
            return hit.map(|(prim, t)| Hit {
                triangle: self.prim_triangle[prim as usize],
                t,
            });
        }
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        match self.level {
            // SAFETY: as above.
            #[cfg(target_arch = "x86_64")]
            VectorLevel::V3 => unsafe { x86_64_v3::closest_hit(self, ray) },
            _ => self.closest_hit_inline(ray),
        }
    }

    /// True when something lies on the segment `origin + t dir`, t in (0, tmax); stops at the
    /// first hit found.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmax: f32) -> bool {
        self.occluder(origin, dir, tmax).is_some()
    }

    /// A primitive (BVH order) on the segment `origin + t dir`, t in (0, tmax): the first one
    /// found, not the nearest.
    pub(crate) fn occluder(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<u32> {
        #[cfg(target_arch = "x86_64")]
        if let (Traversal::Wide, Some(wide)) = (self.traversal, &self.wide) {
            let q = Query::new(origin, dir, tmax);
            let prims = &self.prims;
            return match self.level {
                // SAFETY: as in `closest_hit`.
                VectorLevel::V3 => unsafe { x86_64_v3::wide_any(wide, prims, &q) },
                // SAFETY: SSE is part of x86-64.
                VectorLevel::Baseline => unsafe {
                    wide_traversal::any::<wide_traversal::Sse>(wide, prims, &q)
                },
            };
        }
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        match self.level {
            // SAFETY: as in `closest_hit`.
            #[cfg(target_arch = "x86_64")]
            VectorLevel::V3 => unsafe { x86_64_v3::occluder(self, ray) },
            _ => self.occluder_inline(ray),
        }
    }

    /// [`closest_hit`](Self::closest_hit) of each ray `origins[k] + t dirs[k]`, t in
    /// (0, tmaxs[k]), into `hits[k]`. Consecutive rays go eight at a time as packets
    /// (`packet_traversal`): worth it for coherent rays, such as a pixel tile's from one eye.
    /// Eight rays not all of one direction octant, or a tree the wide traversal cannot run, are
    /// traced one by one. Panics unless the four slices are equally long.
    pub fn closest_hit_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
        hits: &mut [Option<Hit>],
    ) {
        let rays = Rays::new(origins, dirs, tmaxs, hits.len());
        rays.by_packets(
            hits,
            |o, d, t, hits| self.closest_hit_as_packet(o, d, t, hits),
            |o, d, t| self.closest_hit(o, d, t),
        );
    }

    /// [`occluded`](Self::occluded) for each ray, into `blocked[k]`, eight rays at a time as in
    /// [`closest_hit_packet`](Self::closest_hit_packet): worth it for shadow rays toward the sun,
    /// which share nearly one direction.
    pub fn occluded_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
        blocked: &mut [bool],
    ) {
        let rays = Rays::new(origins, dirs, tmaxs, blocked.len());
        let as_packet = |o: &[Vec3], d: &[Vec3], t: &[f32], blocked: &mut [bool]| {
            let mut occluders = [None; PACKET_RAYS];
            let occluders = &mut occluders[..blocked.len()];
            let traced = self.occluder_as_packet(o, d, t, occluders);
            for (b, o) in blocked.iter_mut().zip(occluders.iter()) {
                *b = o.is_some();
            }
            traced
        };
        rays.by_packets(blocked, as_packet, |o, d, t| self.occluded(o, d, t));
    }

    /// [`occluder`](Self::occluder) for each ray, into `occluders[k]`, eight rays at a time as
    /// in [`closest_hit_packet`](Self::closest_hit_packet).
    pub(crate) fn occluder_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
        occluders: &mut [Option<u32>],
    ) {
        let rays = Rays::new(origins, dirs, tmaxs, occluders.len());
        rays.by_packets(
            occluders,
            |o, d, t, occluders| self.occluder_as_packet(o, d, t, occluders),
            |o, d, t| self.occluder(o, d, t),
        );
    }

    /// The wide tree and up to [`PACKET_RAYS`] rays as one packet, where the wide traversal runs
    /// and the rays make one: more than one ray (a packet of one costs more than the one-ray
    /// query), all of one direction octant.
    #[cfg(target_arch = "x86_64")]
    fn as_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
    ) -> Option<(&WideBvh, Packet)> {
        let (Traversal::Wide, Some(wide)) = (self.traversal, &self.wide) else {
            return None;
        };
        if origins.len() < 2 {
            return None;
        }
        Some((wide, Packet::new(origins, dirs, tmaxs)?))
    }

    /// Up to [`PACKET_RAYS`] rays' closest hits as one packet (`as_packet`); false, nothing
    /// written, where they make none.
    fn closest_hit_as_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
        hits: &mut [Option<Hit>],
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some((wide, packet)) = self.as_packet(origins, dirs, tmaxs) {
            let mut found = [None; PACKET];
            let prims = &self.prims;
            match self.level {
                // SAFETY: `level` is V3 only where the CPU has every feature of `x86_64_v3`.
                VectorLevel::V3 => unsafe {
                    x86_64_v3::packet_closest(wide, prims, &packet, &mut found)
                },
                // SAFETY: SSE is part of x86-64.
                VectorLevel::Baseline => unsafe {
                    packet_traversal::closest::<wide_traversal::Sse>(
                        wide, prims, &packet, &mut found,
                    )
                },
            }
            for (hit, found) in hits.iter_mut().zip(found) {
                *hit = found.map(|(prim, t)| Hit {
                    triangle: self.prim_triangle[prim as usize],
                    t,
                });
            }
            return true;
        }
        let _ = (origins, dirs, tmaxs, hits);
        false
    }

    /// Up to [`PACKET_RAYS`] rays' occluders as one packet; false as in
    /// `closest_hit_as_packet`.
    fn occluder_as_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        tmaxs: &[f32],
        occluders: &mut [Option<u32>],
    ) -> bool {
        #[cfg(target_arch = "x86_64")]
        if let Some((wide, packet)) = self.as_packet(origins, dirs, tmaxs) {
            let mut found = [None; PACKET];
            let prims = &self.prims;
            match self.level {
                // SAFETY: as in `closest_hit_as_packet`.
                VectorLevel::V3 => unsafe {
                    x86_64_v3::packet_any(wide, prims, &packet, &mut found)
                },
                // SAFETY: SSE is part of x86-64.
                VectorLevel::Baseline => unsafe {
                    packet_traversal::any::<wide_traversal::Sse>(wide, prims, &packet, &mut found)
                },
            }
            occluders.copy_from_slice(&found[..occluders.len()]);
            return true;
        }
        let _ = (origins, dirs, tmaxs, occluders);
        false
    }

    /// Whether primitive `prim` (an [`occluder`](Self::occluder)) lies on the segment: the
    /// traversal's own triangle test, so a segment it blocks is one the traversal finds blocked.
    pub(crate) fn blocks(&self, prim: u32, origin: Vec3, dir: Vec3, tmax: f32) -> bool {
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        self.prims[prim as usize].intersect(&ray) < tmax
    }

    /// `closest_hit`'s body, inlined into each level's entry point: obvhs's `traverse!` loop over
    /// its CWBVH nodes, as in `CwBvh::ray_traverse`.
    #[inline(always)]
    fn closest_hit_inline(&self, ray: Ray) -> Option<Hit> {
        let mut traverse_ray = ray;
        let mut hit = RayHit::none();
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        obvhs::traverse!(
            self.bvh,
            node,
            state,
            node.intersect_ray(&traverse_ray, state.oct_inv4),
            {
                let t = self.prims[state.primitive_id as usize].intersect(&traverse_ray);
                if t < traverse_ray.tmax {
                    hit.primitive_id = state.primitive_id;
                    hit.t = t;
                    traverse_ray.tmax = t;
                }
            }
        );
        (hit.t < ray.tmax).then(|| Hit {
            triangle: self.prim_triangle[hit.primitive_id as usize],
            t: hit.t,
        })
    }

    /// `occluder`'s body, inlined like `closest_hit_inline`; stops at the first hit, as in
    /// `CwBvh::ray_traverse_miss`.
    #[inline(always)]
    fn occluder_inline(&self, ray: Ray) -> Option<u32> {
        let mut state = self.bvh.new_traversal(ray.direction);
        let mut node;
        let mut occluder = None;
        'traversal: {
            obvhs::traverse!(
                self.bvh,
                node,
                state,
                node.intersect_ray(&ray, state.oct_inv4),
                {
                    if self.prims[state.primitive_id as usize].intersect(&ray) < ray.tmax {
                        occluder = Some(state.primitive_id);
                        break 'traversal;
                    }
                }
            );
        }
        occluder
    }

    /// Number of BVH primitive references (more than triangles when the preset splits).
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
    }
}

/// The queries compiled for `x86-64-v3`. The feature list is `vector_level::v3_detected`'s.
#[cfg(target_arch = "x86_64")]
mod x86_64_v3 {
    use super::{
        Hit, PACKET, Packet, Query, Ray, RtTriangle, SceneBvh, WideBvh, packet_traversal,
        wide_traversal,
    };

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn closest_hit(bvh: &SceneBvh, ray: Ray) -> Option<Hit> {
        bvh.closest_hit_inline(ray)
    }

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn occluder(bvh: &SceneBvh, ray: Ray) -> Option<u32> {
        bvh.occluder_inline(ray)
    }

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn wide_closest(
        bvh: &WideBvh,
        prims: &[RtTriangle],
        q: &Query,
    ) -> Option<(u32, f32)> {
        // SAFETY: this function's features include AVX.
        unsafe { wide_traversal::closest::<wide_traversal::Avx2>(bvh, prims, q) }
    }

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn wide_any(bvh: &WideBvh, prims: &[RtTriangle], q: &Query) -> Option<u32> {
        // SAFETY: as in `wide_closest`.
        unsafe { wide_traversal::any::<wide_traversal::Avx2>(bvh, prims, q) }
    }

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn packet_closest(
        bvh: &WideBvh,
        prims: &[RtTriangle],
        packet: &Packet,
        hits: &mut [Option<(u32, f32)>; PACKET],
    ) {
        // SAFETY: as in `wide_closest`.
        unsafe { packet_traversal::closest::<wide_traversal::Avx2>(bvh, prims, packet, hits) }
    }

    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt,movbe,f16c")]
    pub(super) unsafe fn packet_any(
        bvh: &WideBvh,
        prims: &[RtTriangle],
        packet: &Packet,
        occluders: &mut [Option<u32>; PACKET],
    ) {
        // SAFETY: as in `wide_closest`.
        unsafe { packet_traversal::any::<wide_traversal::Avx2>(bvh, prims, packet, occluders) }
    }
}

#[cfg(test)]
mod tests;
