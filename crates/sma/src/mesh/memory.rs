//! The mesh's memory by part, what a split may add to it, recycling removed nodes and freeing
//! unused midpoint vertices: what the SMA's memory budget reads and does (DESIGN.md §4, §5).

use std::collections::{HashMap, HashSet};

use super::fast_hash::FastHash;
use super::{EdgeSplit, MeshVertex, Node, SEAM_VERTEX, SubdivisionMesh, VertexId, pair_key};

/// `MeshVertex::base_triangle` of a freed midpoint vertex.
const FREE_VERTEX: u32 = u32::MAX - 1;

/// The mesh's memory by part, counted by capacity (`SubdivisionMesh::memory`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeshMemory {
    /// Nodes, their free lists, and the base triangles' adjacency and pieces.
    pub nodes: usize,
    /// Vertices and their welded points.
    pub vertices: usize,
    /// Split edges and seam midpoints.
    pub edge_tables: usize,
}

impl MeshMemory {
    pub fn total(&self) -> usize {
        self.nodes + self.vertices + self.edge_tables
    }
}

/// Heap bytes of a hash table by capacity: hashbrown keeps it at 7/8 of a power-of-two bucket
/// count, with one control byte per bucket.
pub(crate) fn table_bytes<K, V, S>(t: &HashMap<K, V, S>) -> usize {
    buckets_bytes(t.capacity(), size_of::<(K, V)>())
}

/// [`table_bytes`] of a hash set.
pub(crate) fn set_bytes<K, S>(t: &HashSet<K, S>) -> usize {
    buckets_bytes(t.capacity(), size_of::<K>())
}

fn buckets_bytes(capacity: usize, entry: usize) -> usize {
    if capacity == 0 {
        return 0;
    }
    (capacity * 8 / 7).next_power_of_two() * (entry + 1)
}

impl SubdivisionMesh {
    /// Heap bytes held by the mesh structures (nodes, vertices, points, edge tables), for the
    /// memory figures of BENCHMARKS.md.
    pub fn heap_bytes(&self) -> usize {
        self.memory().total()
    }

    /// The mesh's memory by part, by capacity.
    pub fn memory(&self) -> MeshMemory {
        MeshMemory {
            nodes: self.nodes.capacity() * size_of::<Node>()
                + self.degenerate.capacity()
                + self.adjacency.heap_bytes()
                + self.scene_triangles.heap_bytes()
                + self.free_nodes.heap_bytes(),
            vertices: self.vertices.capacity() * size_of::<MeshVertex>()
                + self.vertex_point.capacity() * size_of::<u32>()
                + self.free_vertices.capacity() * size_of::<VertexId>(),
            edge_tables: table_bytes(&self.edge_splits) + table_bytes(&self.seam_midpoints),
        }
    }

    /// Bytes the mesh's arrays and tables may grow by over `steps` more splits (a split makes at
    /// most four nodes, three vertices and three split edges): each one that would fill takes its
    /// next reservation (a quarter more for the arrays, twice the buckets for a table). Nodes
    /// come from the recycled ones first. What a caller keeping a budget checks before refining.
    pub fn growth_bytes(&self, steps: usize) -> usize {
        let grows = |len: usize, capacity: usize, more: usize| len + more > capacity;
        let nodes_needed = (4 * steps).saturating_sub(self.free_nodes.free_slots());
        let lean = |len: usize| len / 4 + 16;
        let mut bytes = 0;
        if grows(self.nodes.len(), self.nodes.capacity(), nodes_needed) {
            bytes += lean(self.nodes.len()).max(nodes_needed) * size_of::<Node>();
        }
        let vertices_needed = (3 * steps).saturating_sub(self.free_vertices.len());
        if grows(
            self.vertices.len(),
            self.vertices.capacity(),
            vertices_needed,
        ) {
            bytes += lean(self.vertices.len()).max(vertices_needed)
                * (size_of::<MeshVertex>() + size_of::<u32>());
        }
        for (len, capacity, table) in [
            (
                self.edge_splits.len(),
                self.edge_splits.capacity(),
                table_bytes(&self.edge_splits),
            ),
            (
                self.seam_midpoints.len(),
                self.seam_midpoints.capacity(),
                table_bytes(&self.seam_midpoints),
            ),
        ] {
            if grows(len, capacity, 3 * steps) {
                bytes += table.max(3 * steps * (size_of::<u64>() + size_of::<EdgeSplit>() + 1));
            }
        }
        bytes
    }

    /// Makes the nodes removed so far reusable by later splits, and gives back the node array's
    /// free end (`compact`: live nodes near the end move down, so their ids change too). Call
    /// only where nothing outside the mesh names a node any more but a shown table, which
    /// tells a triangle by its corners (see `free_nodes`); returns whether any was removed.
    pub(crate) fn recycle_removed(&mut self) -> bool {
        if !self.free_nodes.recycle() {
            return false;
        }
        self.compact_nodes();
        true
    }

    /// Frees the midpoint vertices of edges no live node splits any more, with their split-edge
    /// and seam entries, for later splits to reuse: a re-split then makes them, and their
    /// samples, afresh. Edges with a vertex `named` elsewhere (a shown triangle's corner, a
    /// sample asked for) are kept, for a later call. Returns the freed vertices, whose samples
    /// the caller drops. Call where a recycle may run (no refinement step pending).
    pub(crate) fn free_unused_midpoints(
        &mut self,
        named: &dyn Fn(VertexId) -> bool,
    ) -> Vec<VertexId> {
        let mut unused: HashMap<u64, Vec<VertexId>, FastHash> = self
            .edge_splits
            .iter()
            .filter(|(_, e)| e.splits == 0)
            .map(|(&key, e)| (key, vec![e.mid_vertex]))
            .collect();
        let vertex_point = &self.vertex_point;
        let point_key = |pair: u64| {
            let point = |v: u64| vertex_point[(v & u64::from(u32::MAX)) as usize] & !SEAM_VERTEX;
            pair_key(point(pair >> 32), point(pair))
        };
        for (&pair, &v) in &self.seam_midpoints {
            if let Some(vertices) = unused.get_mut(&point_key(pair)) {
                vertices.push(v);
            }
        }
        unused.retain(|_, vertices| {
            vertices.sort_unstable();
            vertices.dedup();
            !vertices.iter().any(|&v| named(v))
        });
        // A seam entry that stays is keyed by its ends' vertex ids: those must not be reused
        // while it stays (point ids never are, so split-edge keys need no such care).
        loop {
            let staying: HashSet<VertexId, FastHash> = self
                .seam_midpoints
                .keys()
                .filter(|&&pair| !unused.contains_key(&point_key(pair)))
                .flat_map(|&pair| [(pair >> 32) as VertexId, pair as VertexId])
                .collect();
            let before = unused.len();
            unused.retain(|_, vertices| !vertices.iter().any(|v| staying.contains(v)));
            if unused.len() == before {
                break;
            }
        }
        self.seam_midpoints
            .retain(|&pair, _| !unused.contains_key(&point_key(pair)));
        let mut freed = Vec::new();
        for (key, vertices) in unused {
            self.edge_splits.remove(&key);
            freed.extend(vertices);
        }
        freed.sort_unstable();
        for &v in &freed {
            self.vertices[v as usize].base_triangle = FREE_VERTEX;
        }
        self.free_vertices.extend(freed.iter().rev());
        self.edge_splits.shrink_to_fit();
        self.seam_midpoints.shrink_to_fit();
        freed
    }

    /// Whether vertex `v` was freed (`free_unused_midpoints`) and not reused since.
    pub(crate) fn is_free_vertex(&self, v: VertexId) -> bool {
        self.vertices[v as usize].base_triangle == FREE_VERTEX
    }

    /// How many times removed nodes were recycled: a node id held from before a later recycle
    /// may name another triangle now.
    pub fn recycles(&self) -> u64 {
        self.free_nodes.recycles()
    }

    /// Node slots removed and not yet recycled.
    pub(crate) fn retired_nodes(&self) -> usize {
        self.free_nodes.retired_slots()
    }
}

#[cfg(test)]
mod tests {
    use crate::mesh::test_meshes::grid;
    use crate::mesh::{MeshParams, NodeId, SubdivisionMesh, invariants};

    fn refine_all(mesh: &mut SubdivisionMesh, levels: usize) {
        for _ in 0..levels {
            let leaves: Vec<NodeId> = mesh.leaves().collect();
            mesh.refine(&leaves, &|_| false);
        }
    }

    fn coarsen_all(mesh: &mut SubdivisionMesh) {
        while !mesh
            .coarsen_many(&(0..mesh.node_count() as NodeId).collect::<Vec<_>>())
            .is_empty()
        {}
    }

    #[test]
    fn midpoints_freed_after_a_collapse_are_reused_and_their_tables_given_back() {
        let scene = grid(4);
        let mut mesh = SubdivisionMesh::new(&scene, MeshParams::default());
        let base_vertices = mesh.vertex_count();
        refine_all(&mut mesh, 2);
        let (vertices, memory) = (mesh.vertex_count(), mesh.memory());
        // Collapsed: every midpoint is unused, one is named elsewhere.
        coarsen_all(&mut mesh);
        assert!(mesh.recycle_removed());
        let named = base_vertices as u32 + 1;
        let freed = mesh.free_unused_midpoints(&|v| v == named);
        assert!(!freed.contains(&named), "a named vertex stays");
        assert_eq!(
            freed.len() + 1,
            vertices - base_vertices,
            "all but the named one"
        );
        assert!(freed.iter().all(|&v| mesh.is_free_vertex(v)));
        assert!(
            mesh.memory().edge_tables < memory.edge_tables,
            "tables shrank"
        );
        invariants::check(&mesh, &scene).unwrap();
        // The same refinement again takes the freed vertices first: the array does not grow.
        refine_all(&mut mesh, 2);
        assert_eq!(mesh.vertex_count(), vertices);
        assert!(freed.iter().all(|&v| !mesh.is_free_vertex(v)), "all reused");
        invariants::check(&mesh, &scene).unwrap();
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        for leaf in leaves {
            // Every corner of a leaf is a live vertex at its place: no stale midpoint.
            let [a, b, c] = mesh.leaf_positions(leaf);
            assert!((b - a).cross(c - a).length() > 0.0, "leaf {leaf}");
        }
        // Nothing named: every midpoint goes.
        coarsen_all(&mut mesh);
        assert!(mesh.recycle_removed());
        assert_eq!(
            mesh.free_unused_midpoints(&|_| false).len(),
            vertices - base_vertices
        );
    }
}
