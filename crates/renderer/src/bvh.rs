//! Ray tracing core over the scene's triangles: a closest-hit query and an early-exit occlusion
//! query (DESIGN.md §7). obvhs builds the tree, a compressed wide BVH (CWBVH); the queries run
//! one of two traversals of it ([`Traversal`]):
//! - **wide** (the default on x86-64): the tree decoded into full-precision eight-wide nodes
//!   (`wide_bvh`), traversed nearest child first with eight boxes per vector step and four
//!   triangles per leaf test (`wide_traversal`);
//! - **compressed**: obvhs's own `traverse!` loop over the CWBVH nodes, the intersection passed
//!   in as a closure, obvhs style (the only one elsewhere, and the comparison in benchmarks).
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

/// The deepest tree the wide traversal runs.
pub const WIDE_MAX_DEPTH: usize = 36;

/// The closest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index into the scene's triangles.
    pub triangle: u32,
    pub t: f32,
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
    use super::{Hit, Query, Ray, RtTriangle, SceneBvh, WideBvh, wide_traversal};

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
}

#[cfg(test)]
mod tests {
    use super::*;
    use scene::Triangle;

    fn quad_mesh(y: f32) -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(-1.0, y, -1.0),
                Vec3::new(1.0, y, -1.0),
                Vec3::new(1.0, y, 1.0),
                Vec3::new(-1.0, y, 1.0),
            ],
            normals: vec![Vec3::Y; 4],
            triangles: vec![
                Triangle {
                    vertices: [0, 2, 1],
                    material: 0,
                },
                Triangle {
                    vertices: [0, 3, 2],
                    material: 0,
                },
            ],
        }
    }

    #[test]
    fn closest_hit_finds_the_nearer_plane_and_its_distance() {
        let mut mesh = quad_mesh(0.0);
        let upper = quad_mesh(2.0);
        let base = mesh.positions.len() as u32;
        mesh.positions.extend(upper.positions);
        mesh.normals.extend(upper.normals);
        mesh.triangles
            .extend(upper.triangles.iter().map(|t| Triangle {
                vertices: t.vertices.map(|v| v + base),
                material: 0,
            }));
        for preset in [BuildPreset::Fast, BuildPreset::Medium, BuildPreset::Slow] {
            let bvh = SceneBvh::build(&mesh, preset);
            let hit = bvh
                .closest_hit(Vec3::new(0.3, 5.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
                .unwrap();
            assert!((hit.t - 3.0).abs() < 1e-5);
            assert!(hit.triangle >= 2, "upper plane is triangles 2 and 3");
            let hit = bvh
                .closest_hit(Vec3::new(0.3, 1.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
                .unwrap();
            assert!((hit.t - 1.0).abs() < 1e-5 && hit.triangle < 2);
            assert!(
                bvh.closest_hit(Vec3::new(3.0, 1.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
                    .is_none()
            );
        }
    }

    #[test]
    fn occlusion_respects_the_segment_length() {
        let bvh = SceneBvh::build(&quad_mesh(0.0), BuildPreset::Slow);
        let o = Vec3::new(0.1, 1.0, 0.1);
        assert!(bvh.occluded(o, Vec3::NEG_Y, 2.0));
        assert!(!bvh.occluded(o, Vec3::NEG_Y, 0.5));
        assert!(!bvh.occluded(o, Vec3::Y, 10.0));
    }

    #[test]
    fn an_occluder_found_blocks_its_segment_and_not_a_shorter_one() {
        let bvh = SceneBvh::build(&quad_mesh(0.0), BuildPreset::Slow);
        let o = Vec3::new(0.1, 1.0, 0.1);
        let prim = bvh.occluder(o, Vec3::NEG_Y, 2.0).expect("the quad blocks");
        assert!(bvh.blocks(prim, o, Vec3::NEG_Y, 2.0));
        assert!(!bvh.blocks(prim, o, Vec3::NEG_Y, 0.5));
        assert!(!bvh.blocks(prim, o, Vec3::Y, 10.0));
        assert_eq!(bvh.occluder(o, Vec3::Y, 10.0), None);
    }

    /// A crumpled sheet of triangles over several scales, for comparing traversals.
    fn crumpled_mesh() -> Mesh {
        let n = 40;
        let mut mesh = Mesh::default();
        for i in 0..=n {
            for j in 0..=n {
                let (x, z) = (i as f32 * 0.25, j as f32 * 0.25);
                let y = (x * 1.7).sin() * (z * 1.3).cos() + ((i * 31 + j * 17) % 7) as f32 * 0.02;
                mesh.positions.push(Vec3::new(x, y, z));
                mesh.normals.push(Vec3::Y);
            }
        }
        let at = |i: usize, j: usize| (i * (n + 1) + j) as u32;
        for i in 0..n {
            for j in 0..n {
                for vertices in [
                    [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                    [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                ] {
                    mesh.triangles.push(Triangle {
                        vertices,
                        material: 0,
                    });
                }
            }
        }
        mesh
    }

    #[test]
    fn both_traversals_give_the_same_answers_at_every_level() {
        let mesh = crumpled_mesh();
        let mut rng = crate::sampling::stream(7, 0);
        let rays: Vec<(Vec3, Vec3, f32)> = (0..4000)
            .map(|k| {
                let u = crate::sampling::uniform2(&mut rng);
                let v = crate::sampling::uniform2(&mut rng);
                let origin = Vec3::new(u[0] * 10.0, 2.5 * v[0] - 0.5, u[1] * 10.0);
                let w = crate::sampling::uniform2(&mut rng);
                // A cone of half-angle π is the whole sphere.
                let dir = crate::sampling::uniform_cone(Vec3::Y, 2.0, w);
                // Some axis-parallel rays and some short segments too.
                let dir = if k % 10 == 0 { Vec3::NEG_Y } else { dir };
                let tmax = if k % 3 == 0 { 1.5 } else { f32::INFINITY };
                (origin, dir, tmax)
            })
            .collect();
        for preset in [BuildPreset::Medium, BuildPreset::Slow] {
            let mut bvh = SceneBvh::build(&mesh, preset);
            assert_eq!(bvh.traversal(), Traversal::Wide, "x86-64 runs the wide one");
            for level in [VectorLevel::Baseline, VectorLevel::V3] {
                if !level.available() {
                    continue;
                }
                bvh.set_vector_level(level);
                let mut hits = 0;
                for &(o, d, tmax) in &rays {
                    bvh.set_traversal(Traversal::Compressed);
                    let (expected, blocked) =
                        (bvh.closest_hit(o, d, tmax), bvh.occluded(o, d, tmax));
                    bvh.set_traversal(Traversal::Wide);
                    let got = bvh.closest_hit(o, d, tmax);
                    assert_eq!(got.map(|h| h.t), expected.map(|h| h.t), "{o} {d} {tmax}");
                    assert_eq!(bvh.occluded(o, d, tmax), blocked, "{o} {d} {tmax}");
                    if let Some(prim) = bvh.occluder(o, d, tmax) {
                        assert!(bvh.blocks(prim, o, d, tmax));
                    }
                    hits += usize::from(got.is_some());
                }
                assert!(
                    hits > 1000 && hits < 3900,
                    "{hits} of 4000 rays hit: a poor test set"
                );
            }
        }
    }

    #[test]
    fn empty_mesh_hits_nothing() {
        let bvh = SceneBvh::build(&Mesh::default(), BuildPreset::Slow);
        assert!(
            bvh.closest_hit(Vec3::ZERO, Vec3::X, f32::INFINITY)
                .is_none()
        );
        assert!(!bvh.occluded(Vec3::ZERO, Vec3::X, 1.0));
    }
}
