//! One refinement or coarsening step and its whole closure: the unit the SMA sends to a viewer
//! in one update (DESIGN.md §4), so the viewer never shows a T-junction or a hole.

use std::collections::HashSet;

use super::fast_hash::FastHash;
use super::{NodeId, SubdivisionMesh, VertexId};

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RefinementStep {
    /// Leaves after the step that were not leaves before it, ascending.
    pub new_leaves: Vec<NodeId>,
    /// Leaves before the step that are not leaves after it, ascending.
    pub replaced_leaves: Vec<NodeId>,
    /// Vertices the step created (they need samples), ascending.
    pub new_vertices: Vec<VertexId>,
}

/// Records each node's leaf state the first time the step changes it. A step touches tens of
/// nodes, so a linear scan beats a hash set (and its allocation) here.
#[derive(Default)]
pub(super) struct StepRecorder {
    touched: Vec<(NodeId, bool)>,
    pub(super) new_vertices: Vec<VertexId>,
    /// The nodes touched, for a bulk step (`SubdivisionMesh::split_red_all`) that touches too
    /// many for the scan.
    bulk: Option<HashSet<NodeId, FastHash>>,
}

impl StepRecorder {
    pub(super) fn bulk() -> StepRecorder {
        StepRecorder {
            bulk: Some(HashSet::default()),
            ..StepRecorder::default()
        }
    }

    /// Call before changing whether `id` is a leaf.
    pub(super) fn before_change(&mut self, mesh: &SubdivisionMesh, id: NodeId) {
        let first = match &mut self.bulk {
            Some(seen) => seen.insert(id),
            None => !self.touched.iter().any(|&(t, _)| t == id),
        };
        if first {
            let was_leaf = (id as usize) < mesh.nodes.len() && mesh.is_leaf(id);
            self.touched.push((id, was_leaf));
        }
    }

    pub(super) fn finish(mut self, mesh: &SubdivisionMesh) -> RefinementStep {
        self.touched.sort_unstable();
        self.new_vertices.sort_unstable();
        let (mut new_leaves, mut replaced_leaves) = (Vec::new(), Vec::new());
        for (id, was_leaf) in self.touched {
            match (was_leaf, mesh.is_leaf(id)) {
                (false, true) => new_leaves.push(id),
                (true, false) => replaced_leaves.push(id),
                _ => {}
            }
        }
        RefinementStep {
            new_leaves,
            replaced_leaves,
            new_vertices: self.new_vertices,
        }
    }
}
