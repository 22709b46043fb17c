//! Numerical hard cases of the subdivision mesh (DESIGN.md §4): needle and degenerate base
//! triangles, refinement driven down to the minimum edge, and the same far from the origin.
//! Each refines every leaf, round after round, until a round splits nothing, under both
//! neighbour rules (`neighbour_rule`).

use glam::{DVec3, Vec3};
use scene::{Mesh, Triangle};

use super::test_meshes::square;
use super::{MeshParams, NeighbourRule, NodeId, NodeKind, SubdivisionMesh, min_angle};

/// More rounds than any of these meshes needs to reach its minimum edge.
const ROUNDS: usize = 16;

/// Refines all leaves until a round splits nothing, checking `each` after every round; the
/// rounds that split something.
fn refine_to_a_stop(mesh: &mut SubdivisionMesh, each: &dyn Fn(&SubdivisionMesh)) -> usize {
    for round in 0..ROUNDS {
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        if mesh.refine(&leaves, &|_| false).is_empty() {
            return round;
        }
        each(mesh);
    }
    panic!("still splitting after {ROUNDS} rounds");
}

fn params(min_edge_length: f32, neighbour_rule: NeighbourRule) -> MeshParams {
    MeshParams {
        min_edge_length,
        neighbour_rule,
        ..MeshParams::default()
    }
}

fn edges([a, b, c]: [Vec3; 3]) -> [f32; 3] {
    [a.distance(b), b.distance(c), c.distance(a)]
}

fn longest(p: [Vec3; 3]) -> f32 {
    edges(p).into_iter().fold(0.0, f32::max)
}

/// A triangle fan with needles (sines of their smallest angles 2e-5 and 1e-6) on the edges of an
/// ordinary triangle, a zero-area triangle of three distinct collinear points, and one whose
/// two corners are copies of one point (welded into one: never split).
fn needles_and_degenerates() -> Mesh {
    let positions = vec![
        Vec3::ZERO,
        Vec3::X,
        Vec3::new(0.5, 0.8, 0.0),
        Vec3::new(0.5, -1e-5, 0.0),
        Vec3::new(3.0, 0.0, 0.0),
        Vec3::new(2.0, 1e-6, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        Vec3::new(5.0, 0.0, 0.0),
        Vec3::new(5.0, 0.0, 0.0),
        Vec3::new(6.0, 1.0, 0.0),
    ];
    let triangles = [[0, 1, 2], [1, 0, 3], [1, 4, 5], [6, 7, 8], [9, 10, 11]]
        .map(|vertices| Triangle {
            vertices,
            material: 0,
        })
        .to_vec();
    Mesh {
        normals: vec![Vec3::Z; positions.len()],
        positions,
        triangles,
    }
}

/// Needles and degenerate bases refine to a stop with every vertex finite, every normal unit
/// and every vertex where its base triangle and barycentric weights place it (the renderer
/// shades it there, DESIGN.md §8): with the textbook barycentrics the needles' midpoints were
/// placed at a corner of their base triangle.
#[test]
fn needles_and_degenerate_bases_refine_to_a_stop_without_nan() {
    for rule in NeighbourRule::ALL {
        needles_and_degenerates_under(rule);
    }
}

fn needles_and_degenerates_under(rule: NeighbourRule) {
    let scene = needles_and_degenerates();
    let mut mesh = SubdivisionMesh::new(&scene, params(0.05, rule));
    let rounds = refine_to_a_stop(&mut mesh, &|_| {});
    assert!(rounds > 0, "nothing was refined");
    for v in 0..mesh.vertex_count() as u32 {
        let vertex = mesh.vertex(v);
        assert!(
            vertex.position.is_finite() && vertex.normal.is_finite(),
            "vertex {v}: {vertex:?}"
        );
        assert!((vertex.normal.length() - 1.0).abs() < 1e-5, "vertex {v}");
        let [u, w] = vertex.bary.map(f64::from);
        assert!(u.is_finite() && w.is_finite(), "vertex {v}: {vertex:?}");
        // The zero-area base has no plane to place points in: they go to its first corner,
        // where no pixel will ever see them.
        if vertex.base_triangle == 3 {
            continue;
        }
        let t = mesh
            .leaf_positions(vertex.base_triangle)
            .map(Vec3::as_dvec3);
        let placed: DVec3 = (1.0 - u - w) * t[0] + u * t[1] + w * t[2];
        let off = placed.distance(vertex.position.as_dvec3());
        assert!(
            off <= 1e-6,
            "vertex {v} on base {} is placed {off} away",
            vertex.base_triangle
        );
    }
    // Only the welded base keeps two corners at one point: it is never split.
    for leaf in mesh.leaves() {
        let p = mesh.leaf_positions(leaf);
        if leaf == 4 {
            continue;
        }
        assert!(edges(p).iter().all(|&e| e > 0.0), "leaf {leaf}: {p:?}");
        assert!(!min_angle(p).is_nan(), "leaf {leaf}: {p:?}");
    }
    assert!(mesh.is_leaf(4), "the welded base was split");
}

/// Refinement goes down to the minimum edge and stops there: no red child's longest edge is
/// below it, and every leaf that could still be split red without going below it has been.
#[test]
fn refinement_stops_at_the_minimum_edge() {
    for rule in NeighbourRule::ALL {
        stops_at_the_minimum_edge_under(rule);
    }
}

fn stops_at_the_minimum_edge_under(rule: NeighbourRule) {
    let min_edge = 0.1;
    let mut mesh = SubdivisionMesh::new(&square(), params(min_edge, rule));
    let rounds = refine_to_a_stop(&mut mesh, &|_| {});
    // The square's triangles have longest edges of sqrt 2: 0.71, 0.35, 0.18, then no further.
    assert!(rounds >= 3, "{rounds} rounds");
    for leaf in mesh.leaves() {
        if mesh.node(leaf).kind() == NodeKind::Green {
            continue;
        }
        let l = longest(mesh.leaf_positions(leaf));
        assert!(l >= min_edge, "leaf {leaf}: longest edge {l}");
        assert!(l < 2.0 * min_edge, "leaf {leaf} could still be split: {l}");
    }
    assert!(
        mesh.leaf_count() >= 2 * 4usize.pow(3),
        "{} leaves",
        mesh.leaf_count()
    );
}

/// Far from the origin (1e5, f32 spacing about 0.008, DESIGN.md §7) the minimum edge follows the
/// float spacing: refinement stops with every leaf's corners apart. With the extent alone setting
/// it (2 mm for this 25 cm square), midpoints rounded onto their ends and leaves collapsed.
#[test]
fn far_from_the_origin_the_minimum_edge_follows_the_float_spacing() {
    let mut scene = square();
    let offset = Vec3::new(1.0e5, 0.0, 1.0e5);
    for p in &mut scene.positions {
        *p = *p * 0.25 + offset;
    }
    let spacing = f32::from_bits(1.0e5f32.to_bits() + 1) - 1.0e5;
    for neighbour_rule in NeighbourRule::ALL {
        let params = MeshParams {
            neighbour_rule,
            ..MeshParams::default()
        };
        let mut mesh = SubdivisionMesh::new(&scene, params);
        let rounds = refine_to_a_stop(&mut mesh, &|mesh| {
            for leaf in mesh.leaves() {
                let p = mesh.leaf_positions(leaf);
                assert!(
                    edges(p).iter().all(|&e| e >= 2.0 * spacing),
                    "leaf {leaf} collapsed: {p:?}"
                );
            }
        });
        assert!(rounds > 0, "nothing was refined");
    }
}
