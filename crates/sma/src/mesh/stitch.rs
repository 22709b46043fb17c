//! Stitching the base mesh's T-junctions (DESIGN.md §4): a corner of one face lying inside an
//! edge of another (the lintels of bracara's gateways sit with their corners on the jambs of the
//! walls beside them: 86 edges; 212 in Sponza) is a crack of the scene itself. The two faces share no edge, so
//! refinement never splits one for the other, and each drawing rounds the corner and the edge
//! apart: through the thin gap between them a viewer shows the background, here and there a
//! pixel. The SMA therefore splits such an edge's faces at every corner lying inside it: its
//! base triangles are the scene's, cut into pieces where needed, and the mesh is conforming from
//! the start. Each piece keeps its scene triangle for shading (vertices are shaded on a scene
//! triangle, DESIGN.md §8).

use std::collections::HashMap;

use glam::{I64Vec3, Vec3};

use super::fast_hash::FastHash;
use super::{MeshVertex, NodeId, SubdivisionMesh, VertexId, pair_key};

/// The scene triangle each base triangle lies in, where the two differ.
#[derive(Clone, Debug, Default)]
pub(super) struct SceneTriangles {
    /// Base triangles `0..scene_count` are the scene's triangles (the first piece of a cut
    /// one); the ones after are further pieces, of these scene triangles.
    scene_count: u32,
    more_pieces_of: Vec<u32>,
    /// The corners of each cut scene triangle (its first piece has others).
    cut_corners: HashMap<u32, [VertexId; 3], FastHash>,
}

impl SceneTriangles {
    pub(super) fn heap_bytes(&self) -> usize {
        self.more_pieces_of.capacity() * 4 + self.cut_corners.capacity() * 17
    }
}

impl SubdivisionMesh {
    /// The scene triangle base triangle `base` lies in, and that triangle's corners: where its
    /// vertices are shaded (DESIGN.md §8).
    pub(super) fn scene_triangle_of(&self, base: NodeId) -> (u32, [Vec3; 3]) {
        let st = &self.scene_triangles;
        let scene = match base.checked_sub(st.scene_count) {
            Some(i) => st.more_pieces_of[i as usize],
            None => base,
        };
        let corners = match st.cut_corners.get(&scene) {
            Some(v) => v.map(|v| self.vertex(v).position),
            None => self.leaf_positions(scene),
        };
        (scene, corners)
    }

    /// The scene triangle leaf `id` lies in, and its corners' barycentric weights there
    /// (vertices 1 and 2): where its texture coordinates are read (DESIGN.md §5). A corner
    /// shaded on another scene triangle (shared with it) is placed by its position.
    pub fn leaf_in_scene_triangle(&self, id: NodeId) -> (u32, [[f32; 2]; 3]) {
        let (scene, corners) = self.scene_triangle_of(self.base_of(id));
        let bary = self.node(id).vertices.map(|v| {
            let vertex = self.vertex(v);
            if vertex.base_triangle == scene {
                vertex.bary
            } else {
                super::refine::barycentric(corners, vertex.position)
            }
        });
        (scene, bary)
    }
}

/// The base triangles of `mesh`, as vertex ids: its triangles, each cut where corners of other
/// faces lie inside its edges, with a vertex of its own at each such corner (pushed onto
/// `vertices` and `vertex_point`, whose points are the weld's `points`).
pub(super) fn base_triangles(
    mesh: &scene::Mesh,
    vertices: &mut Vec<MeshVertex>,
    vertex_point: &mut Vec<u32>,
    points: &[Vec3],
    tolerance: f32,
) -> (Vec<[VertexId; 3]>, SceneTriangles) {
    let scene: Vec<[u32; 3]> = mesh.triangles.iter().map(|t| t.vertices).collect();
    let mut bases = scene.clone();
    let mut st = SceneTriangles {
        scene_count: scene.len() as u32,
        ..SceneTriangles::default()
    };
    for (t, cut) in pieces(&scene, vertex_point, points, tolerance) {
        let corners = scene[t as usize];
        let mut made: HashMap<u32, VertexId> = HashMap::new();
        let mut ids = cut.iter().map(|piece| {
            piece.map(|corner| match corner {
                Corner::Vertex(v) => v,
                Corner::Inside { point, edge, t: s } => *made.entry(point).or_insert_with(|| {
                    vertices.push(inside_vertex(
                        vertices,
                        corners,
                        t,
                        edge,
                        s,
                        points[point as usize],
                    ));
                    vertex_point.push(point);
                    vertices.len() as VertexId - 1
                }),
            })
        });
        bases[t as usize] = ids.next().expect("a cut triangle has pieces");
        for piece in ids {
            bases.push(piece);
            st.more_pieces_of.push(t);
        }
        st.cut_corners.insert(t, corners);
    }
    (bases, st)
}

/// The vertex of scene triangle `t` (corners `corners`) at `position`, inside its edge `edge` at
/// `s` from the edge's start: shaded there on `t`, its normal halfway along the edge between the
/// ends' (as an edge midpoint's is), or the face's where those cancel.
fn inside_vertex(
    vertices: &[MeshVertex],
    corners: [VertexId; 3],
    t: u32,
    edge: u8,
    s: f32,
    position: Vec3,
) -> MeshVertex {
    const CORNER_BARY: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    let (k, next) = (edge as usize, (edge as usize + 1) % 3);
    let [a, b] = [corners[k], corners[next]].map(|v| &vertices[v as usize]);
    let normal = ((1.0 - s) * a.normal + s * b.normal)
        .try_normalize()
        .unwrap_or_else(|| {
            let [p, q, r] = corners.map(|v| vertices[v as usize].position);
            let face = (q - p).cross(r - p).normalize_or(a.normal);
            if face.dot(a.normal) < 0.0 {
                -face
            } else {
                face
            }
        });
    MeshVertex {
        position,
        normal,
        base_triangle: t,
        bary: std::array::from_fn(|i| (1.0 - s) * CORNER_BARY[k][i] + s * CORNER_BARY[next][i]),
    }
}

/// A corner of a base triangle piece: a scene vertex, or a point lying inside edge `edge` of the
/// scene triangle at `t` (from the edge's start, 0..1), for which the piece needs a vertex of
/// its own (the point's vertices belong to other faces).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Corner {
    Vertex(u32),
    Inside { point: u32, edge: u8, t: f32 },
}

/// The pieces of the scene triangles that have corners of other faces inside their edges, by
/// scene triangle, each counter-clockwise like its triangle. `triangles` are the scene's, as
/// vertex ids, and `vertex_point`, `points` the weld's.
pub(super) fn pieces(
    triangles: &[[u32; 3]],
    vertex_point: &[u32],
    points: &[Vec3],
    tolerance: f32,
) -> Vec<(u32, Vec<[Corner; 3]>)> {
    let inside = points_inside_edges(triangles, vertex_point, points, tolerance);
    if inside.is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    for (t, v) in triangles.iter().enumerate() {
        let p = v.map(|v| vertex_point[v as usize]);
        let lists: [Vec<Corner>; 3] = std::array::from_fn(|k| {
            let (from, to) = (p[k], p[(k + 1) % 3]);
            let Some(found) = inside.get(&pair_key(from, to)) else {
                return Vec::new();
            };
            // Stored from the lower point id; this edge may run the other way.
            let forward = from < to;
            let mut list: Vec<Corner> = found
                .iter()
                .filter(|&&(_, q)| !p.contains(&q))
                .map(|&(t, q)| Corner::Inside {
                    point: q,
                    edge: k as u8,
                    t: if forward { t } else { 1.0 - t },
                })
                .collect();
            if !forward {
                list.reverse();
            }
            list
        });
        if lists.iter().all(Vec::is_empty) {
            continue;
        }
        let mut cut = Vec::new();
        split(v.map(Corner::Vertex), lists, &mut cut);
        out.push((t as u32, cut));
    }
    out
}

/// Cuts a triangle at the corners inside its edges (`lists[k]`: inside edge k, in order from
/// corner k): at the middle one of the longest list, towards the opposite corner, and so on in
/// each half, so that pieces stay as fat as the corners allow.
fn split(corners: [Corner; 3], mut lists: [Vec<Corner>; 3], out: &mut Vec<[Corner; 3]>) {
    let Some(k) = (0..3)
        .filter(|&k| !lists[k].is_empty())
        .max_by_key(|&k| lists[k].len())
    else {
        out.push(corners);
        return;
    };
    let (a, b, c) = (corners[k], corners[(k + 1) % 3], corners[(k + 2) % 3]);
    let mut before = std::mem::take(&mut lists[k]);
    let after = before.split_off(before.len() / 2);
    let (h, after) = (after[0], after[1..].to_vec());
    let from_b = std::mem::take(&mut lists[(k + 1) % 3]);
    let to_a = std::mem::take(&mut lists[(k + 2) % 3]);
    split([a, h, c], [before, Vec::new(), to_a], out);
    split([h, b, c], [after, from_b, Vec::new()], out);
}

/// For each edge (point pair key) with points strictly inside it, those points with their
/// parameter from the edge's lower point id, in order. A point is inside when within
/// `tolerance` of the segment and farther than that from both ends.
fn points_inside_edges(
    triangles: &[[u32; 3]],
    vertex_point: &[u32],
    points: &[Vec3],
    tolerance: f32,
) -> HashMap<u64, Vec<(f32, u32)>, FastHash> {
    let (lo, hi) = points
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    if points.is_empty() || tolerance <= 0.0 {
        return HashMap::default();
    }
    // Cells of about a 256th of the extent (a few points each), never below the tolerance.
    let cell = ((hi - lo).max_element() / 256.0).max(4.0 * tolerance);
    let cell_of = |p: Vec3| ((p - lo) / cell).floor().as_i64vec3();
    let mut grid: HashMap<I64Vec3, Vec<u32>, FastHash> = HashMap::default();
    for (i, &p) in points.iter().enumerate() {
        grid.entry(cell_of(p)).or_default().push(i as u32);
    }
    let mut seen: std::collections::HashSet<u64, FastHash> = Default::default();
    let mut inside: HashMap<u64, Vec<(f32, u32)>, FastHash> = HashMap::default();
    let mut near = Vec::new();
    for v in triangles {
        let p = v.map(|v| vertex_point[v as usize]);
        for k in 0..3 {
            let (a, b) = (p[k].min(p[(k + 1) % 3]), p[k].max(p[(k + 1) % 3]));
            if a == b || !seen.insert(pair_key(a, b)) {
                continue;
            }
            let (pa, pb) = (points[a as usize], points[b as usize]);
            let d = pb - pa;
            let length = d.length();
            // Pieces of the segment no longer than a cell: each one's box, widened by the
            // tolerance, spans a few cells at most.
            let steps = (length / cell).ceil().max(1.0) as u32;
            near.clear();
            for s in 0..steps {
                let (from, to) = (
                    pa + d * (s as f32 / steps as f32),
                    pa + d * ((s + 1) as f32 / steps as f32),
                );
                let (c0, c1) = (
                    cell_of(from.min(to) - tolerance),
                    cell_of(from.max(to) + tolerance),
                );
                for x in c0.x..=c1.x {
                    for y in c0.y..=c1.y {
                        for z in c0.z..=c1.z {
                            if let Some(list) = grid.get(&I64Vec3::new(x, y, z)) {
                                near.extend_from_slice(list);
                            }
                        }
                    }
                }
            }
            near.sort_unstable();
            near.dedup();
            let mut found: Vec<(f32, u32)> = near
                .iter()
                .filter(|&&q| q != a && q != b)
                .filter_map(|&q| {
                    let t = (points[q as usize] - pa).dot(d) / (length * length);
                    let along = t * length;
                    let off = (pa + t * d).distance(points[q as usize]);
                    (off <= tolerance && along > tolerance && length - along > tolerance)
                        .then_some((t, q))
                })
                .collect();
            if !found.is_empty() {
                found.sort_by(|x, y| x.0.total_cmp(&y.0));
                inside.insert(pair_key(a, b), found);
            }
        }
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wall with a gateway: the left and right parts, two quads floor to top, and the lintel
    /// over the gateway, whose lower corners lie inside the parts' jambs (bracara's gateways).
    fn gateway() -> (Vec<[u32; 3]>, Vec<Vec3>) {
        let p = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        let points = vec![
            p(-3.0, 0.0),
            p(-1.0, 0.0),
            p(-1.0, 4.0),
            p(-3.0, 4.0),
            p(1.0, 0.0),
            p(3.0, 0.0),
            p(3.0, 4.0),
            p(1.0, 4.0),
            p(-1.0, 3.0),
            p(1.0, 3.0),
        ];
        let triangles = vec![
            [0, 1, 2],
            [0, 2, 3],
            [4, 5, 6],
            [4, 6, 7],
            [8, 9, 7],
            [8, 7, 2],
        ];
        (triangles, points)
    }

    #[test]
    fn a_corner_inside_an_edge_is_found_once_per_edge() {
        let (triangles, points) = gateway();
        let vertex_point: Vec<u32> = (0..points.len() as u32).collect();
        let inside = points_inside_edges(&triangles, &vertex_point, &points, 1e-5);
        assert_eq!(inside.len(), 2, "{inside:?}");
        assert_eq!(inside[&pair_key(1, 2)], vec![(0.75, 8)]);
        assert_eq!(inside[&pair_key(4, 7)], vec![(0.75, 9)]);
    }

    #[test]
    fn faces_with_a_corner_inside_an_edge_are_cut_there() {
        let (triangles, points) = gateway();
        let vertex_point: Vec<u32> = (0..points.len() as u32).collect();
        let cut = pieces(&triangles, &vertex_point, &points, 1e-5);
        let cut_triangles: Vec<u32> = cut.iter().map(|(t, _)| *t).collect();
        assert_eq!(cut_triangles, vec![0, 3]);
        // (0, 1, 2): its edge 1 runs from point 1 to point 2, the lintel's corner a quarter
        // of the way down from 2.
        let inside = Corner::Inside {
            point: 8,
            edge: 1,
            t: 0.75,
        };
        assert_eq!(
            cut[0].1,
            vec![
                [Corner::Vertex(1), inside, Corner::Vertex(0)],
                [inside, Corner::Vertex(2), Corner::Vertex(0)],
            ]
        );
        // (4, 6, 7): edge 2 runs from point 7 down to point 4.
        let [first, second] = [&cut[1].1[0], &cut[1].1[1]];
        assert_eq!(first[0], Corner::Vertex(7));
        assert_eq!(second[1], Corner::Vertex(4));
        assert!(matches!(first[1], Corner::Inside { point: 9, edge: 2, t } if t == 0.25));
    }

    /// The gateway as a scene mesh, refined all over a few times: no leaf has a corner at a
    /// dyadic point inside another's edge (no T-junction, at the lintel's corners either), and
    /// the vertices made for the cuts are shaded where they lie.
    #[test]
    fn a_mesh_with_t_junctions_refines_conforming() {
        use crate::mesh::{MeshParams, SubdivisionMesh};

        let (triangles, positions) = gateway();
        let mesh = scene::Mesh {
            normals: vec![Vec3::Z; positions.len()],
            positions,
            triangles: triangles
                .iter()
                .map(|&vertices| scene::Triangle {
                    vertices,
                    material: 0,
                })
                .collect(),
        };
        let mut sma = SubdivisionMesh::new(&mesh, MeshParams::default());
        assert_eq!(
            sma.base_count(),
            triangles.len() + 2,
            "two faces cut in two"
        );
        for v in mesh.positions.len()..sma.vertex_count() {
            let vertex = sma.vertex(v as VertexId);
            let corners = mesh.triangle_positions(vertex.base_triangle as usize);
            let [u, w] = vertex.bary;
            let at = (1.0 - u - w) * corners[0] + u * corners[1] + w * corners[2];
            assert!(at.distance(vertex.position) < 1e-6, "{vertex:?}");
        }
        for _ in 0..3 {
            let leaves: Vec<NodeId> = sma.leaves().collect();
            sma.refine(&leaves, &|_| false);
        }
        let bits = |p: Vec3| p.to_array().map(f32::to_bits);
        let leaves: Vec<[Vec3; 3]> = sma.leaves().map(|l| sma.leaf_positions(l)).collect();
        let corners: std::collections::HashSet<[u32; 3]> =
            leaves.iter().flatten().map(|&p| bits(p)).collect();
        for p in &leaves {
            for k in 0..3 {
                let (a, b) = (p[k], p[(k + 1) % 3]);
                let m = 0.5 * (a + b);
                for x in [m, 0.5 * (a + m), 0.5 * (m + b)] {
                    assert!(
                        !corners.contains(&bits(x)),
                        "a corner inside {a}-{b} at {x}"
                    );
                }
            }
        }
    }

    #[test]
    fn several_corners_inside_edges_make_a_piece_per_gap() {
        let mut out = Vec::new();
        let inside = |point, edge, t| Corner::Inside { point, edge, t };
        split(
            [Corner::Vertex(0), Corner::Vertex(1), Corner::Vertex(2)],
            [
                vec![inside(3, 0, 0.25), inside(4, 0, 0.5), inside(5, 0, 0.75)],
                vec![inside(6, 1, 0.5)],
                Vec::new(),
            ],
            &mut out,
        );
        // Four gaps on edge 0, two on edge 1: five pieces.
        assert_eq!(out.len(), 5, "{out:?}");
    }
}
