//! The mesh's memory by part, what a split may add to it, and recycling removed nodes: what the
//! SMA's memory budget reads and does (DESIGN.md §4, §5).

use std::collections::{HashMap, HashSet};

use super::{EdgeSplit, MeshVertex, Node, SubdivisionMesh};

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
                + self.vertex_point.capacity() * size_of::<u32>(),
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
        if grows(self.vertices.len(), self.vertices.capacity(), 3 * steps) {
            bytes += lean(self.vertices.len()).max(3 * steps)
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
