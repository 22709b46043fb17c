//! Welding base vertices into points by position (DESIGN.md §4): split copies at material and
//! crease seams, and vertices an exporter duplicated, become one point, so adjacency crosses
//! seams and refinement opens no crack there.

use std::collections::HashMap;

use glam::Vec3;

/// Returns each vertex's point and the points' positions (the first vertex of each). Greedy on a
/// grid of cells `tolerance` wide: a vertex joins the first point within `tolerance` in the 27
/// cells around it.
pub(super) fn weld(positions: &[Vec3], tolerance: f32) -> (Vec<u32>, Vec<Vec3>) {
    let cell_size = tolerance.max(f32::MIN_POSITIVE);
    let cell_of = |p: Vec3| (p / cell_size).floor().as_i64vec3();
    let mut cells: HashMap<glam::I64Vec3, Vec<u32>> = HashMap::new();
    let mut points: Vec<Vec3> = Vec::new();
    let vertex_point = positions
        .iter()
        .map(|&p| {
            let cell = cell_of(p);
            let found = neighbour_cells(cell)
                .filter_map(|c| cells.get(&c))
                .flatten()
                .copied()
                .find(|&q| points[q as usize].distance(p) <= tolerance);
            found.unwrap_or_else(|| {
                let q = points.len() as u32;
                points.push(p);
                cells.entry(cell).or_default().push(q);
                q
            })
        })
        .collect();
    (vertex_point, points)
}

fn neighbour_cells(c: glam::I64Vec3) -> impl Iterator<Item = glam::I64Vec3> {
    (-1..=1).flat_map(move |x| {
        (-1..=1).flat_map(move |y| (-1..=1).map(move |z| c + glam::I64Vec3::new(x, y, z)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_within_tolerance_share_a_point_and_others_do_not() {
        let positions = [
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0 + 1e-7, 0.0, 0.0),
            Vec3::new(1.0 + 1e-3, 0.0, 0.0),
        ];
        let (vp, points) = weld(&positions, 1e-6);
        assert_eq!(vp, vec![0, 1, 0, 1, 2]);
        assert_eq!(points.len(), 3);
    }

    /// Two faces of an exported square whose shared corners were written a rounding apart:
    /// both send bit-identical corners for them, before refinement and after, on the seam's
    /// midpoints too.
    #[test]
    fn copies_of_a_point_share_its_position() {
        use crate::mesh::{MeshParams, NodeId, SubdivisionMesh};

        let mut mesh = crate::mesh::test_meshes::square();
        let nudged = |p: Vec3| p + Vec3::new(3e-7, -2e-7, 0.0);
        mesh.positions.push(nudged(mesh.positions[0]));
        mesh.positions.push(nudged(mesh.positions[2]));
        mesh.normals.extend([Vec3::Z; 2]);
        mesh.triangles[1].vertices = [4, 5, 3];
        let mut sma = SubdivisionMesh::new(&mesh, MeshParams::default());
        let corners = |sma: &SubdivisionMesh, base: NodeId| -> Vec<[u32; 3]> {
            sma.leaves_of_base(base)
                .iter()
                .flat_map(|&l| sma.leaf_positions(l))
                .map(|p| p.to_array().map(f32::to_bits))
                .collect()
        };
        for round in 0..2 {
            let (a, b) = (corners(&sma, 0), corners(&sma, 1));
            let shared = a.iter().filter(|p| b.contains(p)).count();
            assert!(
                shared >= 2 + round,
                "round {round}: {shared} shared corners"
            );
            sma.refine(&[0, 1], &|_| false);
        }
    }
}
