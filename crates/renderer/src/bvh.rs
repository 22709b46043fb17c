//! Ray tracing core: an obvhs compressed wide BVH (CWBVH) over the scene's triangles, a closest-hit
//! query and an early-exit occlusion query (DESIGN.md §7). Intersection is passed to obvhs as a
//! closure, obvhs style.

use std::time::{Duration, Instant};

use glam::Vec3;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::rt_triangle::RtTriangle;
use scene::Mesh;
pub use scene::bvh::BuildPreset;
use scene::bvh::{build_cwbvh, bvh_triangles};

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
    build_time: Duration,
}

impl SceneBvh {
    pub fn build(mesh: &Mesh, preset: BuildPreset) -> SceneBvh {
        let start = Instant::now();
        let tris = bvh_triangles(mesh);
        let bvh = build_cwbvh(&tris, preset);
        let prim_triangle = bvh.primitive_indices.clone();
        let prims = prim_triangle
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        SceneBvh {
            bvh,
            prims,
            prim_triangle,
            build_time: start.elapsed(),
        }
    }

    /// Wall time of `build`, triangle conversion included.
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Closest hit along `origin + t dir`, t in (0, tmax). `dir` need not be unit length; `t` is in
    /// its units.
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<Hit> {
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        let mut hit = RayHit::none();
        if self
            .bvh
            .ray_traverse(ray, &mut hit, |ray, id| self.prims[id].intersect(ray))
        {
            Some(Hit {
                triangle: self.prim_triangle[hit.primitive_id as usize],
                t: hit.t,
            })
        } else {
            None
        }
    }

    /// True when something lies on the segment `origin + t dir`, t in (0, tmax); stops at the
    /// first hit found (obvhs' `ray_traverse_miss` returns true on a miss).
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmax: f32) -> bool {
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        !self
            .bvh
            .ray_traverse_miss(ray, |ray, id| self.prims[id].intersect(ray))
    }

    /// Number of BVH primitive references (more than triangles when the preset splits).
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
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
    fn empty_mesh_hits_nothing() {
        let bvh = SceneBvh::build(&Mesh::default(), BuildPreset::Slow);
        assert!(
            bvh.closest_hit(Vec3::ZERO, Vec3::X, f32::INFINITY)
                .is_none()
        );
        assert!(!bvh.occluded(Vec3::ZERO, Vec3::X, 1.0));
    }
}
