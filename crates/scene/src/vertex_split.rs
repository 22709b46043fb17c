//! Vertex splitting and canonical normals (thesis §4.1; DESIGN.md §4, §5).
//!
//! A vertex is shared only by faces that could share a shading sample: faces of the same material
//! that meet across an edge at less than the crease angle. Every other meeting (a material seam,
//! a crease such as the corner of a sunlit and a shaded wall, faces touching only at a point)
//! gets its own copy of the vertex, at the bit-identical position, so geometry stays crack-free.
//!
//! Angles between faces are measured between *undirected* face normals, because Sponza and the
//! thesis's model have inconsistent winding (§2.4.2): two coplanar faces wound oppositely are
//! one smooth surface, not a 180° fold.

use glam::Vec3;

use crate::model::{Mesh, Triangle};

pub struct SplitMesh {
    pub mesh: Mesh,
    /// Copies added because faces of different materials met at a vertex.
    pub material_splits: usize,
    /// Copies added because faces of one material met at a crease (or only at a point).
    pub crease_splits: usize,
}

/// Splits the vertices of `triangles` (indices into `positions`, no degenerate triangles) and
/// renumbers them in order of first use, so the result does not depend on how the input
/// numbered its vertices.
pub fn split_vertices(
    positions: &[Vec3],
    triangles: &[Triangle],
    crease_angle_deg: f32,
) -> SplitMesh {
    let face_normals: Vec<Vec3> = triangles
        .iter()
        .map(|t| face_normal(positions, t))
        .collect();
    let incident = Incidence::new(positions.len(), triangles);
    let cos_crease = crease_angle_deg.clamp(0.0, 180.0).to_radians().cos();
    let mut groups = UnionFind::new(triangles.len() * 3);
    let mut material_splits = 0;
    let mut crease_splits = 0;
    for v in 0..positions.len() {
        let corners = incident.corners(v);
        if corners.is_empty() {
            continue;
        }
        join_smooth_neighbours(
            v as u32,
            corners,
            triangles,
            &face_normals,
            cos_crease,
            &mut groups,
        );
        let materials = count_distinct(corners.iter().map(|&c| triangles[c as usize / 3].material));
        let copies = count_distinct(corners.iter().map(|&c| groups.find(c)));
        material_splits += materials - 1;
        crease_splits += copies - materials;
    }
    let mesh = renumber(positions, triangles, &face_normals, &mut groups);
    SplitMesh {
        mesh,
        material_splits,
        crease_splits,
    }
}

/// Unnormalised normal (length = 2 × area), counter-clockwise.
fn face_normal(positions: &[Vec3], t: &Triangle) -> Vec3 {
    let [a, b, c] = t.vertices.map(|i| positions[i as usize]);
    (b - a).cross(c - a)
}

/// Corners (3 × triangle + k) around each vertex, in compressed rows.
struct Incidence {
    start: Vec<u32>,
    corners: Vec<u32>,
}

impl Incidence {
    fn new(vertex_count: usize, triangles: &[Triangle]) -> Incidence {
        let mut start = vec![0u32; vertex_count + 1];
        for t in triangles {
            for v in t.vertices {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..vertex_count {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut corners = vec![0u32; triangles.len() * 3];
        for (ti, t) in triangles.iter().enumerate() {
            for (k, v) in t.vertices.iter().enumerate() {
                corners[fill[*v as usize] as usize] = (ti * 3 + k) as u32;
                fill[*v as usize] += 1;
            }
        }
        Incidence { start, corners }
    }

    fn corners(&self, v: usize) -> &[u32] {
        &self.corners[self.start[v] as usize..self.start[v + 1] as usize]
    }
}

/// Joins the corners at `v` whose faces share an edge (v, w), have the same material and meet
/// at no more than the crease angle. A non-manifold edge (more than two faces) joins every
/// qualifying pair.
fn join_smooth_neighbours(
    v: u32,
    corners: &[u32],
    triangles: &[Triangle],
    face_normals: &[Vec3],
    cos_crease: f32,
    groups: &mut UnionFind,
) {
    let mut edges: Vec<(u32, u32)> = corners
        .iter()
        .flat_map(|&c| {
            let t = triangles[c as usize / 3].vertices;
            t.into_iter().filter(move |&w| w != v).map(move |w| (w, c))
        })
        .collect();
    edges.sort_unstable();
    for run in edges.chunk_by(|a, b| a.0 == b.0) {
        for (i, &(_, a)) in run.iter().enumerate() {
            for &(_, b) in &run[i + 1..] {
                let (ta, tb) = (a as usize / 3, b as usize / 3);
                if triangles[ta].material == triangles[tb].material
                    && within_crease(face_normals[ta], face_normals[tb], cos_crease)
                {
                    groups.union(a, b);
                }
            }
        }
    }
}

fn within_crease(a: Vec3, b: Vec3, cos_crease: f32) -> bool {
    a.dot(b).abs() >= cos_crease * a.length() * b.length()
}

fn count_distinct(items: impl Iterator<Item = u32>) -> usize {
    let mut v: Vec<u32> = items.collect();
    v.sort_unstable();
    v.dedup();
    v.len()
}

/// One output vertex per corner group, numbered in order of first use, with its canonical
/// normal (DESIGN.md §5): the sum of its faces' area-weighted normals, each first flipped into
/// the hemisphere of the group's largest face, so mixed winding cannot cancel them.
fn renumber(
    positions: &[Vec3],
    triangles: &[Triangle],
    face_normals: &[Vec3],
    groups: &mut UnionFind,
) -> Mesh {
    let corner_count = triangles.len() * 3;
    let mut vertex_of_group = vec![u32::MAX; corner_count];
    let mut out = Mesh {
        positions: Vec::new(),
        normals: Vec::new(),
        triangles: Vec::with_capacity(triangles.len()),
    };
    let mut reference: Vec<Vec3> = Vec::new();
    for (ti, t) in triangles.iter().enumerate() {
        let mut vertices = [0u32; 3];
        for k in 0..3 {
            let root = groups.find((ti * 3 + k) as u32) as usize;
            if vertex_of_group[root] == u32::MAX {
                vertex_of_group[root] = out.positions.len() as u32;
                out.positions.push(positions[t.vertices[k] as usize]);
                reference.push(Vec3::ZERO);
            }
            let id = vertex_of_group[root];
            let n = face_normals[ti];
            if n.length_squared() > reference[id as usize].length_squared() {
                reference[id as usize] = n;
            }
            vertices[k] = id;
        }
        out.triangles.push(Triangle {
            vertices,
            material: t.material,
        });
    }
    let mut sums = vec![Vec3::ZERO; out.positions.len()];
    for (ti, t) in out.triangles.iter().enumerate() {
        let n = face_normals[ti];
        for v in t.vertices {
            let r = reference[v as usize];
            sums[v as usize] += if n.dot(r) < 0.0 { -n } else { n };
        }
    }
    out.normals = sums
        .iter()
        .zip(&reference)
        .map(|(s, r)| s.try_normalize().unwrap_or(r.normalize()))
        .collect();
    out
}

struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    fn new(n: usize) -> UnionFind {
        UnionFind {
            parent: (0..n as u32).collect(),
        }
    }

    fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        // The smaller root wins, so numbering by first use stays deterministic.
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(vertices: [u32; 3], material: u32) -> Triangle {
        Triangle { vertices, material }
    }

    /// Two triangles sharing the edge (0, 1); the second one's far vertex is lifted to make the
    /// given dihedral bend between them.
    fn hinge(bend_deg: f32, materials: [u32; 2], flip_second: bool) -> SplitMesh {
        let b = bend_deg.to_radians();
        let positions = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.5, 0.0, -1.0),
            Vec3::new(0.5, b.sin(), b.cos()),
        ];
        let second = if flip_second { [1, 0, 3] } else { [0, 1, 3] };
        split_vertices(
            &positions,
            &[tri([0, 2, 1], materials[0]), tri(second, materials[1])],
            45.0,
        )
    }

    #[test]
    fn flat_hinge_shares_its_edge_vertices() {
        let s = hinge(0.0, [0, 0], false);
        assert_eq!(s.mesh.positions.len(), 4);
        assert_eq!((s.material_splits, s.crease_splits), (0, 0));
    }

    #[test]
    fn mixed_winding_does_not_split_or_cancel_normals() {
        let s = hinge(10.0, [0, 0], true);
        assert_eq!(s.mesh.positions.len(), 4);
        let shared = s.mesh.triangles[0].vertices[0] as usize;
        assert!(
            s.mesh.normals[shared].y.abs() > 0.99,
            "{}",
            s.mesh.normals[shared]
        );
    }

    #[test]
    fn crease_splits_the_edge_vertices() {
        let s = hinge(60.0, [0, 0], false);
        assert_eq!(s.mesh.positions.len(), 6);
        assert_eq!((s.material_splits, s.crease_splits), (0, 2));
        // Copies keep bit-identical positions.
        let copies: Vec<_> = s.mesh.positions.iter().filter(|p| **p == Vec3::X).collect();
        assert_eq!(copies.len(), 2);
    }

    #[test]
    fn material_seam_splits_even_when_flat() {
        let s = hinge(0.0, [0, 1], false);
        assert_eq!(s.mesh.positions.len(), 6);
        assert_eq!((s.material_splits, s.crease_splits), (2, 0));
    }

    #[test]
    fn numbering_follows_first_use_not_input_order() {
        let a = hinge(20.0, [0, 0], false);
        let positions = [
            Vec3::new(0.5, 20f32.to_radians().sin(), 20f32.to_radians().cos()),
            Vec3::new(0.5, 0.0, -1.0),
            Vec3::X,
            Vec3::ZERO,
        ];
        let b = split_vertices(&positions, &[tri([3, 1, 2], 0), tri([3, 2, 0], 0)], 45.0);
        assert_eq!(a.mesh.positions, b.mesh.positions);
        assert_eq!(a.mesh.triangles, b.mesh.triangles);
    }
}
