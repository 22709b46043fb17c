//! The hierarchical subdivision mesh of the SMA (thesis §4.2, DESIGN.md §4).
//!
//! Every triangle ever made is a [`Node`]; the base triangles are nodes `0..base_count` and the
//! leaves (nodes without children) form the current triangulation. Refinement is **red–green**
//! (Bank–Sherman–Weiser): a selected leaf is split 1:4 at its edge midpoints (red, Loop's dyadic
//! split of §4.2); a neighbour left with one midpoint on its edges is bisected (green); one left
//! with two or three is split red as well, and so on until no hanging vertex remains. A green
//! triangle is never split further: when it must be, its parent's green closure is undone and the
//! parent is split red instead. Hence:
//!
//! - **Angles.** Red children are similar to their parent, so every red or base node has exactly
//!   the angles of its base triangle; greens are one median bisection of such a node. The
//!   smallest angle of any leaf is therefore at least [`angle_bound`] of its base triangle: the
//!   smallest angle among the base triangle and its three median bisections (exact, not an
//!   estimate; the property tests check it).
//! - **Termination.** Closure only splits a leaf that has a finer neighbour, and never a leaf
//!   finer than its neighbours, so it stops at the finest level already present.
//! - **Conformity** holds after every step: the leaves meet edge to edge.
//!
//! Adjacency is by *position*: base vertices are welded into points with a tolerance relative to
//! the scene size (DESIGN.md §4), across material and crease seams, and an edge is a pair of
//! points, so any number of faces may share one (non-manifold edges). The copies of a point all
//! take its position, so that leaves meeting there share bit-identical corners, and a face with
//! another's corner inside an edge is cut there (`stitch`). An edge midpoint gets one vertex per
//! pair of vertex copies, i.e. one per side of a seam, at one shared position (DESIGN.md §5).
//! Coarsening (thesis §6, future work) undoes red splits when no neighbour is finer along the
//! parents' edges, re-greening or un-greening what closure then needs; parents that block each
//! other (a uniformly refined patch) go together in one step, so coarsening everything, one
//! level per call, gives back the base mesh.
//!
//! The thesis's own neighbour rule (§4.2: a neighbour is split 1:4 when the split edge is shorter
//! than its height on it) is an option, [`NeighbourRule::Thesis`], applied inside this closure
//! with a bound on its propagation (`neighbour_rule`); red–green is the default.

mod adjacency;
mod angles;
mod changed;
mod coarsen;
mod compact;
pub(crate) mod fast_hash;
mod free_nodes;
#[cfg(any(test, feature = "testing"))]
mod grid;
mod memory;
mod neighbour_rule;
mod refine;
mod step;
mod stitch;
mod weld;

#[cfg(test)]
mod hard_cases;
#[cfg(test)]
pub(crate) mod invariants;
#[cfg(test)]
pub(crate) mod test_meshes;

use std::collections::HashMap;

use glam::Vec3;

pub use angles::{SplitShapes, angle_bound, min_angle};
use fast_hash::FastHash;
#[cfg(any(test, feature = "testing"))]
pub use grid::grid_mesh;
pub use memory::MeshMemory;
pub(crate) use memory::{set_bytes, table_bytes};
pub use neighbour_rule::{NeighbourRule, NeighbourStats};
pub use step::RefinementStep;

/// Any triangle of the hierarchy. A removed node stays as a dead entry until the caller
/// recycles removed nodes ([`SubdivisionMesh::recycle_removed`]); later splits then reuse it.
pub type NodeId = u32;
/// A mesh vertex: the scene's vertices first (same indices), then edge midpoints.
pub type VertexId = u32;

/// Below this fraction of the scene's extent an edge is not split: midpoints of shorter edges
/// would lie within a few hundred f32 ulps of their ends, so positions would start to collide.
const MIN_EDGE_FRACTION_OF_EXTENT: f32 = 1e-5;
/// Nor below this many f32 ulps of the scene's largest coordinate: far from the origin (1e5,
/// where the spacing is about 0.008, DESIGN.md §7) the extent says nothing of the spacing, and a
/// midpoint rounds by up to half an ulp, a sixteenth of such an edge.
const MIN_EDGE_ULPS: f32 = 8.0;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshParams {
    /// No red split of a triangle whose longest edge is shorter than twice this (scene units), so
    /// no child edge drops below it (no split below a set edge length). Closure splits
    /// ignore it: conformity comes first. Raised to [`MIN_EDGE_FRACTION_OF_EXTENT`] of the scene
    /// extent and [`MIN_EDGE_ULPS`] of its largest coordinate at least.
    pub min_edge_length: f32,
    /// Weld tolerance as a fraction of the scene's bounding-box diagonal: base vertices closer
    /// than this are one point for adjacency. 1e-6 is ten f32 ulps of a scene coordinate, so it
    /// only absorbs rounding in exported files, never merges distinct modelled corners.
    pub weld_tolerance_rel: f32,
    /// How closure splits a neighbour with one split edge: red–green's bisection, or the
    /// thesis's 1:4 split of a neighbour tall on that edge (§4.2, fig. 4.7; `neighbour_rule`).
    pub neighbour_rule: NeighbourRule,
}

impl Default for MeshParams {
    fn default() -> Self {
        // The pixel veto of the caller (`refine`'s `too_small`) is the working limit; this one
        // only guards scenes in metres against refining below a millimetre.
        MeshParams {
            min_edge_length: 1e-3,
            weld_tolerance_rel: 1e-6,
            // Red–green bounds angles and propagation by itself (DESIGN.md §4); the thesis's
            // rule is there to be measured beside it.
            neighbour_rule: NeighbourRule::RedGreen,
        }
    }
}

/// One vertex of the subdivision mesh, with where a renderer should shade it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshVertex {
    pub position: Vec3,
    /// Canonical unit normal; sides of samples are relative to it (DESIGN.md §5).
    pub normal: Vec3,
    /// A scene triangle the vertex lies on, where renderers shade it (`u32::MAX` for a scene
    /// vertex no triangle uses); the scene triangle of a base triangle that is a piece of one
    /// (`stitch`).
    pub base_triangle: u32,
    /// Barycentric weights of that triangle's vertices 1 and 2.
    pub bary: [f32; 2],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeKind {
    Base,
    /// A child of a 1:4 split.
    Red,
    /// A child of a closure bisection; never split itself.
    Green,
}

/// How a node is split, if it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    None,
    /// Four children `first..first + 4`: the corners at vertices 0, 1, 2, then the middle one.
    Red {
        first_child: NodeId,
    },
    /// Two children `first..first + 2` bisecting edge `edge` (vertices `edge`, `edge + 1`).
    Green {
        first_child: NodeId,
        edge: u8,
    },
}

/// 20 bytes: nodes are most of the mesh's memory (target: <= 100 bytes per leaf all included, BENCHMARKS.md),
/// so the hierarchy links carry the node's state in their spare bits (read it through the
/// accessors), and the base triangle is found by climbing ([`SubdivisionMesh::base_of`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Counter-clockwise like the base triangle; edge `k` runs from vertex `k` to `k + 1`.
    pub vertices: [VertexId; 3],
    /// Parent id, [`NO_PARENT`] for a base triangle; [`GREEN_CHILD`] set for a green child.
    parent: u32,
    /// First child id in the low [`CHILD_BITS`] bits, the state ([`LEAF`], [`RED`], ...) above.
    child_state: u32,
}

const _: () = assert!(size_of::<Node>() == 20);

/// Bit of `Node::parent` marking a child of a green split.
const GREEN_CHILD: u32 = 1 << 31;
const NO_PARENT: u32 = u32::MAX;
/// Node ids fit in this many bits (536 million nodes, 12 GiB of them).
const CHILD_BITS: u32 = 29;
const CHILD_MASK: u32 = (1 << CHILD_BITS) - 1;

/// What `Node::child_state` holds above the first child: a live leaf, split red, split green
/// along edge `e` (`GREEN_ALONG + e`), or dead.
const LEAF: u32 = 0;
const RED: u32 = 1;
const GREEN_ALONG: u32 = 2;
const DEAD: u32 = 5;

impl Node {
    fn new(vertices: [VertexId; 3], parent: Option<NodeId>, kind: NodeKind) -> Node {
        let parent = match (parent, kind) {
            (None, _) => NO_PARENT,
            (Some(p), NodeKind::Green) => p | GREEN_CHILD,
            (Some(p), _) => p,
        };
        Node {
            vertices,
            parent,
            child_state: LEAF << CHILD_BITS,
        }
    }

    fn state(&self) -> u32 {
        self.child_state >> CHILD_BITS
    }

    pub fn parent(&self) -> Option<NodeId> {
        (self.parent != NO_PARENT).then_some(self.parent & !GREEN_CHILD)
    }

    pub fn kind(&self) -> NodeKind {
        match self.parent {
            NO_PARENT => NodeKind::Base,
            p if p & GREEN_CHILD != 0 => NodeKind::Green,
            _ => NodeKind::Red,
        }
    }

    pub fn split(&self) -> Split {
        let first_child = self.child_state & CHILD_MASK;
        match self.state() {
            RED => Split::Red { first_child },
            s @ GREEN_ALONG..DEAD => Split::Green {
                first_child,
                edge: (s - GREEN_ALONG) as u8,
            },
            _ => Split::None,
        }
    }

    /// False once removed by coarsening or by undoing a green closure.
    pub fn is_alive(&self) -> bool {
        self.state() != DEAD
    }

    fn is_leaf(&self) -> bool {
        self.state() == LEAF
    }

    fn set_split(&mut self, split: Split) {
        let (state, first_child) = match split {
            Split::None => (LEAF, 0),
            Split::Red { first_child } => (RED, first_child),
            Split::Green { first_child, edge } => (GREEN_ALONG + u32::from(edge), first_child),
        };
        assert!(first_child <= CHILD_MASK, "more than 2^29 mesh nodes");
        self.child_state = (state << CHILD_BITS) | first_child;
    }

    fn kill(&mut self) {
        self.child_state = DEAD << CHILD_BITS;
    }

    pub fn children(&self) -> std::ops::Range<NodeId> {
        match self.split() {
            Split::None => 0..0,
            Split::Red { first_child } => first_child..first_child + 4,
            Split::Green { first_child, .. } => first_child..first_child + 2,
        }
    }
}

/// A split edge, keyed by its (welded) end points.
#[derive(Clone, Copy, Debug)]
struct EdgeSplit {
    /// The first midpoint vertex made on the edge; its point is the midpoint's, shared by every
    /// face on the edge, and, unless an end is a seam vertex, it is the only midpoint vertex.
    mid_vertex: VertexId,
    /// Live nodes whose split cut this edge; a leaf edge with a count above zero has a hanging
    /// vertex.
    splits: u32,
}

#[derive(Clone, Debug)]
pub struct SubdivisionMesh {
    min_split_edge: f32,
    neighbour_rule: NeighbourRule,
    neighbour_stats: NeighbourStats,
    split_shapes: SplitShapes,
    nodes: Vec<Node>,
    vertices: Vec<MeshVertex>,
    /// Welded point of each vertex, with [`SEAM_VERTEX`] set where the point may have other
    /// vertices: adjacency goes by points, shading by vertices.
    vertex_point: Vec<u32>,
    /// Points so far: the welded base points, then one per split edge.
    point_count: u32,
    base_count: usize,
    /// Base triangles with two corners welded into one point: never split, no neighbours.
    degenerate: Vec<bool>,
    adjacency: adjacency::BaseAdjacency,
    /// Where base triangles are pieces of the scene's (`stitch`).
    scene_triangles: stitch::SceneTriangles,
    /// Keyed by point pair; kept when the count drops to zero so a re-split reuses the point.
    edge_splits: HashMap<u64, EdgeSplit, FastHash>,
    /// Keyed by vertex pair: one midpoint vertex per side of a seam, for edges with a seam vertex
    /// at an end (the others find theirs in `edge_splits`); kept, unless memory is pressed, so a re-split finds the
    /// vertex, and its cached samples, again.
    seam_midpoints: HashMap<u64, VertexId, FastHash>,
    leaf_count: usize,
    /// Triangle splits so far (see [`SubdivisionMesh::split_count`]).
    splits: u64,
    /// Base triangles whose subtree changed since the cache file last asked.
    changed: changed::ChangedBases,
    /// Removed children, reused by later splits once recycled.
    free_nodes: free_nodes::FreeNodes,
    /// Midpoint vertices freed under memory pressure (`memory`), reused by later splits.
    free_vertices: Vec<VertexId>,
}

/// Flag in `vertex_point` of a vertex whose point may hold other vertices (a seam side, or a
/// midpoint of an edge with such an end): only those need `seam_midpoints`.
const SEAM_VERTEX: u32 = 1 << 31;

/// Pushes onto a vector grown by a quarter when full rather than doubled: the node and vertex
/// arrays are most of the mesh's memory (target: <= 100 bytes per leaf all included, BENCHMARKS.md), and the
/// allocator moves a large block by remapping its pages, so the extra moves cost little.
pub(crate) fn push_lean<T>(v: &mut Vec<T>, x: T) {
    if v.len() == v.capacity() {
        v.reserve_exact(v.len() / 4 + 16);
    }
    v.push(x);
}

/// Key of an unordered pair of ids.
fn pair_key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (u64::from(lo) << 32) | u64::from(hi)
}

impl SubdivisionMesh {
    pub fn new(mesh: &scene::Mesh, params: MeshParams) -> Self {
        let (lo, hi) = mesh.bounds();
        let extent = if mesh.positions.is_empty() {
            0.0
        } else {
            (hi - lo).length()
        };
        let tolerance = params.weld_tolerance_rel * extent;
        let (mut vertex_point, point_positions) = weld::weld(&mesh.positions, tolerance);
        let mut vertices = base_vertices(mesh);
        // Copies welded into one point take the point's position: leaves on either side of a
        // seam then send bit-identical corners, and a viewer draws the seam without a crack
        // (DESIGN.md §4). They move by at most the weld tolerance (a millionth of the extent).
        for (vertex, &point) in vertices.iter_mut().zip(&vertex_point) {
            vertex.position = point_positions[point as usize];
        }
        let (bases, scene_triangles) = stitch::base_triangles(
            mesh,
            &mut vertices,
            &mut vertex_point,
            &point_positions,
            tolerance,
        );
        let nodes: Vec<Node> = bases
            .into_iter()
            .map(|vertices| Node::new(vertices, None, NodeKind::Base))
            .collect();
        let degenerate: Vec<bool> = nodes
            .iter()
            .map(|n| {
                let [a, b, c] = n.vertices.map(|v| vertex_point[v as usize]);
                a == b || b == c || c == a
            })
            .collect();
        let adjacency = adjacency::BaseAdjacency::new(&nodes, &vertex_point, &degenerate);
        let mut vertices_at = vec![0u32; point_positions.len()];
        vertex_point
            .iter()
            .for_each(|&p| vertices_at[p as usize] += 1);
        let vertex_point = vertex_point
            .into_iter()
            .map(|p| {
                if vertices_at[p as usize] > 1 {
                    p | SEAM_VERTEX
                } else {
                    p
                }
            })
            .collect();
        let base_count = nodes.len();
        SubdivisionMesh {
            min_split_edge: 2.0
                * params
                    .min_edge_length
                    .max(MIN_EDGE_FRACTION_OF_EXTENT * extent)
                    .max(MIN_EDGE_ULPS * ulp(lo.abs().max(hi.abs()).max_element())),
            neighbour_rule: params.neighbour_rule,
            neighbour_stats: NeighbourStats::default(),
            split_shapes: SplitShapes::default(),
            leaf_count: nodes.len(),
            base_count: nodes.len(),
            nodes,
            vertices,
            vertex_point,
            point_count: point_positions.len() as u32,
            degenerate,
            adjacency,
            scene_triangles,
            edge_splits: HashMap::default(),
            seam_midpoints: HashMap::default(),
            splits: 0,
            changed: changed::ChangedBases::new(base_count),
            free_nodes: free_nodes::FreeNodes::default(),
            free_vertices: Vec::new(),
        }
    }

    /// The base triangles whose subtree was split or coarsened since the last call (the cache
    /// file's incremental save).
    pub(crate) fn take_changed_bases(&mut self) -> Vec<u32> {
        self.changed.take()
    }

    /// Base triangles are nodes `0..base_count`.
    pub fn base_count(&self) -> usize {
        self.base_count
    }

    /// Node slots, dead ones included (ids are `0..node_count`).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id as usize]
    }

    pub fn is_leaf(&self, id: NodeId) -> bool {
        self.nodes[id as usize].is_leaf()
    }

    /// Node `id` and its ancestors up to its base triangle.
    fn ancestry(&self, id: NodeId) -> impl Iterator<Item = NodeId> + '_ {
        std::iter::successors(Some(id), |&n| self.node(n).parent())
    }

    /// Splits between the base triangle and node `id` (red or green).
    pub fn depth(&self, id: NodeId) -> u32 {
        self.ancestry(id).count() as u32 - 1
    }

    /// The base triangle node `id` lies in: a scene triangle (the same index) or a piece of one
    /// (`stitch`).
    pub fn base_of(&self, id: NodeId) -> u32 {
        self.ancestry(id)
            .last()
            .expect("a node is its own ancestry")
    }

    /// The current leaves under base triangle `base`, depth first.
    pub fn leaves_of_base(&self, base: u32) -> Vec<NodeId> {
        let mut leaves = Vec::new();
        let mut stack = vec![base];
        while let Some(id) = stack.pop() {
            let node = self.node(id);
            match node.split() {
                Split::None => leaves.push(id),
                _ => stack.extend(node.children().rev()),
            }
        }
        leaves
    }

    /// All current leaves, in base order.
    pub fn leaves(&self) -> impl Iterator<Item = NodeId> + '_ {
        (0..self.base_count as u32).flat_map(|b| self.leaves_of_base(b))
    }

    pub fn leaf_count(&self) -> usize {
        self.leaf_count
    }

    /// Triangle splits since the mesh was made: one per triangle replaced by its children, red
    /// (four) or green (two), selected or made by closure; the unit of the split rate of
    /// BENCHMARKS.md (target: >= 1 million per second).
    pub fn split_count(&self) -> u64 {
        self.splits
    }

    pub fn vertex(&self, v: VertexId) -> &MeshVertex {
        &self.vertices[v as usize]
    }

    pub fn leaf_positions(&self, id: NodeId) -> [Vec3; 3] {
        self.node(id)
            .vertices
            .map(|v| self.vertices[v as usize].position)
    }

    /// The worst shape among the leaves splits made (see [`SplitShapes`]).
    pub fn split_shapes(&self) -> SplitShapes {
        self.split_shapes
    }

    /// The smallest angle any descendant of `base` can have (see the module documentation).
    pub fn base_angle_bound(&self, base: u32) -> f32 {
        angle_bound(self.leaf_positions(base))
    }

    fn point_of(&self, v: VertexId) -> u32 {
        self.vertex_point[v as usize] & !SEAM_VERTEX
    }

    fn is_seam(&self, v: VertexId) -> bool {
        self.vertex_point[v as usize] & SEAM_VERTEX != 0
    }

    /// Vertices of edge `k` of a node, in the node's winding.
    fn edge_vertices(&self, id: NodeId, k: usize) -> (VertexId, VertexId) {
        let v = self.node(id).vertices;
        (v[k], v[(k + 1) % 3])
    }

    /// Point-pair key of edge `k` of a node.
    fn edge_key(&self, id: NodeId, k: usize) -> u64 {
        let (a, b) = self.edge_vertices(id, k);
        pair_key(self.point_of(a), self.point_of(b))
    }

    /// Live splits of an edge by point-pair key.
    fn splits_of(&self, key: u64) -> u32 {
        self.edge_splits.get(&key).map_or(0, |e| e.splits)
    }

    /// A degenerate base triangle is never split, so only a base node can be one.
    fn is_degenerate(&self, id: NodeId) -> bool {
        self.node(id).parent().is_none() && self.degenerate[id as usize]
    }

    fn longest_edge(&self, id: NodeId) -> f32 {
        let [a, b, c] = self.leaf_positions(id);
        a.distance(b).max(b.distance(c)).max(c.distance(a))
    }
}

/// The spacing of f32 values at `x` (0 for an empty scene's infinite bounds).
fn ulp(x: f32) -> f32 {
    if x.is_finite() {
        f32::from_bits(x.abs().to_bits() + 1) - x.abs()
    } else {
        0.0
    }
}

/// The scene's vertices, each placed on the first triangle that uses it.
fn base_vertices(mesh: &scene::Mesh) -> Vec<MeshVertex> {
    let mut vertices: Vec<MeshVertex> = mesh
        .positions
        .iter()
        .zip(&mesh.normals)
        .map(|(&position, &normal)| MeshVertex {
            position,
            normal,
            base_triangle: u32::MAX,
            bary: [0.0; 2],
        })
        .collect();
    const CORNER_BARY: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
    for (t, tri) in mesh.triangles.iter().enumerate().rev() {
        for (corner, &v) in tri.vertices.iter().enumerate() {
            let vertex = &mut vertices[v as usize];
            vertex.base_triangle = t as u32;
            vertex.bary = CORNER_BARY[corner];
        }
    }
    vertices
}
