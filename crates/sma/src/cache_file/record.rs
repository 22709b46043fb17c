//! One base triangle's record: its refinement subtree and the samples of its vertices
//! (DESIGN.md §5). Node and vertex ids are the mesh's own and change from run to run, so the
//! record names neither: the subtree is its shape, one code per node in pre-order, and a vertex
//! is named by its place in that shape (`synthetic_corners`), which a mesh rebuilt with the same
//! splits gives back (`restore`).

use std::collections::HashMap;

use glam::Vec3;
use protocol::renderer_link::{Quality, SampleKey};
use protocol::{SampleParts, Side};
use serde::{Deserialize, Serialize};

use crate::cache::{CachedSample, ShadingCache};
use crate::mesh::{NodeId, Split, SubdivisionMesh, VertexId};

/// A node's split in a record's shape: a leaf, red (four children follow), or green along an
/// edge (two children follow).
pub const LEAF: u8 = 0;
pub const RED: u8 = 1;
/// `GREEN_ALONG + e` for a bisection of edge `e`.
pub const GREEN_ALONG: u8 = 2;

/// A sample as stored: `CachedSample` less what belongs to this run (when it was last seen, the
/// indirect part as the object-space filter showed it): its parts as the renderers answered them.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StoredSample {
    pub parts: SampleParts,
    pub paths: u32,
    pub bounces: Option<u32>,
    /// The eye of a view-dependent sample; None for the others.
    pub eye: Option<[f32; 3]>,
    pub view_dependent: bool,
}

impl StoredSample {
    /// `sample` with `answered`, its parts unfiltered (`ShadingCache::answered`).
    fn of(sample: &CachedSample, answered: SampleParts) -> StoredSample {
        StoredSample {
            parts: answered,
            paths: sample.quality.paths,
            bounces: sample.quality.bounces,
            eye: sample.eye.map(|e| e.to_array()),
            view_dependent: sample.view_dependent,
        }
    }

    /// The sample as the cache takes it, seen at no frame yet.
    pub fn cached(&self) -> CachedSample {
        CachedSample {
            parts: self.parts,
            quality: Quality {
                paths: self.paths,
                bounces: self.bounces,
            },
            view_dependent: self.view_dependent,
            eye: self.eye.map(Vec3::from),
            last_seen: 0,
        }
    }
}

/// One base triangle's record.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BaseRecord {
    /// The subtree's nodes in pre-order: [`LEAF`], [`RED`] or `GREEN_ALONG + edge`.
    pub shape: Vec<u8>,
    /// Per vertex of the shape (`synthetic_corners`' numbering), its front and back samples.
    pub samples: Vec<[Option<StoredSample>; 2]>,
}

/// A shape that does not describe a tree.
#[derive(Debug, thiserror::Error)]
#[error("a subtree's shape is malformed: {0}")]
pub struct BadShape(&'static str);

/// The corners of every node of `shape`, in pre-order, as vertex numbers of the shape itself:
/// the base triangle's corners are 0, 1, 2, and each edge midpoint gets the next number the
/// first time a split cuts that edge. Within one base triangle a vertex pair has one midpoint
/// (`mesh::refine`'s `split_edge`), so these numbers stand for the mesh's vertices one for one.
/// Also returns how many vertices the shape has.
pub fn synthetic_corners(shape: &[u8]) -> Result<(Vec<[u32; 3]>, u32), BadShape> {
    let mut corners = Vec::with_capacity(shape.len());
    let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
    let mut next = 3u32;
    let mut mid = |a: u32, b: u32| {
        *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
            next += 1;
            next - 1
        })
    };
    // Children wait on a stack, last child on top, so they come off in pre-order.
    let mut stack = vec![[0, 1, 2]];
    for &code in shape {
        let v = stack.pop().ok_or(BadShape("more codes than nodes"))?;
        corners.push(v);
        let [a, b, c] = v;
        match code {
            LEAF => {}
            RED => {
                let m = [mid(a, b), mid(b, c), mid(c, a)];
                let children = [[a, m[0], m[2]], [m[0], b, m[1]], [m[2], m[1], c], m];
                stack.extend(children.into_iter().rev());
            }
            g if (GREEN_ALONG..GREEN_ALONG + 3).contains(&g) => {
                let s = usize::from(g - GREEN_ALONG);
                let (p, q, o) = (v[s], v[(s + 1) % 3], v[(s + 2) % 3]);
                let m = mid(p, q);
                stack.extend([[m, q, o], [p, m, o]]);
            }
            _ => return Err(BadShape("unknown split code")),
        }
    }
    if !stack.is_empty() {
        return Err(BadShape("fewer codes than nodes"));
    }
    Ok((corners, next))
}

/// The mesh vertex behind each of the shape's vertex numbers, from the mesh nodes that stand for
/// the shape's nodes (`node_of[i]` for the shape's node `i`, None where the mesh has none).
pub fn vertex_map(
    mesh: &SubdivisionMesh,
    corners: &[[u32; 3]],
    vertex_count: u32,
    node_of: impl Fn(usize) -> Option<NodeId>,
) -> Vec<Option<VertexId>> {
    let mut map = vec![None; vertex_count as usize];
    for (i, synthetic) in corners.iter().enumerate() {
        if let Some(id) = node_of(i) {
            for (s, v) in synthetic.iter().zip(mesh.node(id).vertices) {
                map[*s as usize] = Some(v);
            }
        }
    }
    map
}

/// Which mesh vertices one snapshot has numbered already: a stamp per vertex, so a snapshot on
/// the schedule's thread costs a lookup per split rather than a hash of every midpoint
/// (DESIGN.md §3: the schedule may pause at most 20 ms for a save). Kept across snapshots.
#[derive(Default)]
pub struct Numbering {
    stamp: Vec<u32>,
    serial: u32,
}

impl Numbering {
    /// Starts a snapshot's numbering of a mesh of `vertex_count` vertices: none numbered yet.
    fn begin(&mut self, vertex_count: usize) {
        if self.stamp.len() < vertex_count {
            self.stamp.resize(vertex_count, 0);
        }
        self.serial = self.serial.wrapping_add(1);
        if self.serial == 0 {
            self.stamp.fill(0);
            self.serial = 1;
        }
    }

    /// Numbers `vertex`; whether it had no number yet.
    fn number(&mut self, vertex: VertexId) -> bool {
        let stamp = &mut self.stamp[vertex as usize];
        let new = *stamp != self.serial;
        *stamp = self.serial;
        new
    }
}

impl BaseRecord {
    /// `base`'s subtree and the cached samples of its vertices, now; also the mesh vertices it
    /// covers, in the shape's numbering (`synthetic_corners`). The subtree is walked once in
    /// pre-order, and each split numbers the midpoints it made as `synthetic_corners` does
    /// (a red split's in the order of its middle child's corners, a green split's one), taken
    /// from the mesh's children, whose corners are laid out as that function's.
    pub fn snapshot(
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
        base: u32,
        numbering: &mut Numbering,
    ) -> (BaseRecord, Vec<VertexId>) {
        numbering.begin(mesh.vertex_count());
        let mut shape = Vec::new();
        // The base triangle's corners are 0, 1 and 2 whatever they are.
        let mut vertices = mesh.node(base).vertices.to_vec();
        for &v in &vertices {
            numbering.number(v);
        }
        let mut stack = vec![base];
        while let Some(id) = stack.pop() {
            let node = mesh.node(id);
            match node.split() {
                Split::None => shape.push(LEAF),
                Split::Red { first_child } => {
                    shape.push(RED);
                    let midpoints = mesh.node(first_child + 3).vertices;
                    vertices.extend(midpoints.into_iter().filter(|&m| numbering.number(m)));
                }
                Split::Green { edge, first_child } => {
                    shape.push(GREEN_ALONG + edge);
                    let midpoint = mesh.node(first_child).vertices[1];
                    if numbering.number(midpoint) {
                        vertices.push(midpoint);
                    }
                }
            }
            stack.extend(node.children().rev());
        }
        let samples = vertices
            .iter()
            .map(|&vertex| {
                [Side::Front, Side::Back].map(|side| {
                    let key = SampleKey { vertex, side };
                    let (sample, (answered, _)) = cache.get(key).zip(cache.answered(key))?;
                    Some(StoredSample::of(&sample, answered.parts))
                })
            })
            .collect();
        (BaseRecord { shape, samples }, vertices)
    }

    /// Whether the record says nothing a fresh mesh and an empty cache do not.
    pub fn is_empty(&self) -> bool {
        self.shape == [LEAF] && self.samples.iter().flatten().all(Option::is_none)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;
    use crate::mesh::test_meshes::grid;

    /// `base`'s shape, and its vertices by the shape's own numbering (`synthetic_corners` laid
    /// over the subtree's nodes): what a snapshot's single walk must agree with.
    fn by_synthetic_corners(mesh: &SubdivisionMesh, base: u32) -> (Vec<u8>, Vec<VertexId>) {
        let (mut nodes, mut shape) = (Vec::new(), Vec::new());
        let mut stack = vec![base];
        while let Some(id) = stack.pop() {
            let node = mesh.node(id);
            nodes.push(id);
            shape.push(match node.split() {
                Split::None => LEAF,
                Split::Red { .. } => RED,
                Split::Green { edge, .. } => GREEN_ALONG + edge,
            });
            stack.extend(node.children().rev());
        }
        let (corners, count) = synthetic_corners(&shape).unwrap();
        let vertices = vertex_map(mesh, &corners, count, |i| Some(nodes[i]))
            .into_iter()
            .map(|v| v.expect("every shape vertex is a corner of a node"))
            .collect();
        (shape, vertices)
    }

    #[test]
    fn a_snapshot_numbers_the_vertices_as_the_shape_does() {
        let mut mesh = SubdivisionMesh::new(&grid(4), MeshParams::default());
        // A third of the leaves, picked anew each round, split: deep subtrees, greens between.
        for round in 0..6u32 {
            let picked: Vec<NodeId> = mesh
                .leaves()
                .filter(|&l| l.wrapping_mul(2_654_435_761).wrapping_add(round) % 3 == 0)
                .collect();
            mesh.refine(&picked, &|_| false);
        }
        let cache = ShadingCache::new(usize::MAX);
        let mut numbering = Numbering::default();
        let (mut greens, mut deepest) = (0, 0);
        // Twice over: the stamps of one snapshot must not leak into the next.
        for base in (0..mesh.base_count() as u32).chain(0..mesh.base_count() as u32) {
            let (record, vertices) = BaseRecord::snapshot(&mesh, &cache, base, &mut numbering);
            let (shape, expected) = by_synthetic_corners(&mesh, base);
            assert_eq!(record.shape, shape, "base {base}");
            assert_eq!(vertices, expected, "base {base}");
            assert_eq!(record.samples.len(), vertices.len());
            greens += shape.iter().filter(|&&c| c >= GREEN_ALONG).count();
            deepest = deepest.max(shape.len());
        }
        assert!(
            greens > 0 && deepest > 50,
            "{greens} greens, {deepest} nodes at most"
        );
    }

    #[test]
    fn a_red_split_names_three_midpoints_and_its_children_share_them() {
        let (corners, count) = synthetic_corners(&[RED, LEAF, LEAF, LEAF, LEAF]).unwrap();
        assert_eq!(count, 6);
        assert_eq!(corners[0], [0, 1, 2]);
        assert_eq!(corners[1], [0, 3, 5]);
        assert_eq!(
            corners[4],
            [3, 4, 5],
            "the middle child is the three midpoints"
        );
    }

    #[test]
    fn a_green_split_and_a_red_neighbour_share_the_midpoint_of_their_edge() {
        // The corner child at vertex 0, split green along its edge 1 (3–5), and the middle
        // child red, whose edge 2 (5–3) is the same edge: one midpoint between them.
        let shape = [
            RED,
            GREEN_ALONG + 1,
            LEAF,
            LEAF,
            LEAF,
            LEAF,
            RED,
            LEAF,
            LEAF,
            LEAF,
            LEAF,
        ];
        let (corners, count) = synthetic_corners(&shape).unwrap();
        assert_eq!(count, 6 + 3);
        let green_mid = corners[2][1];
        let red_middle = corners[6];
        assert_eq!(red_middle, [3, 4, 5]);
        assert!(corners[10].contains(&green_mid));
    }

    #[test]
    fn malformed_shapes_are_errors() {
        assert!(synthetic_corners(&[RED, LEAF]).is_err());
        assert!(synthetic_corners(&[LEAF, LEAF]).is_err());
        assert!(synthetic_corners(&[9]).is_err());
        assert!(synthetic_corners(&[]).is_err());
    }
}
