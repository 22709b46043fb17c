//! One refinement or coarsening step and its whole closure: the unit the SMA sends to a viewer
//! in one update (DESIGN.md §4), so the viewer never shows a T-junction or a hole.

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
    /// For a bulk step (`SubdivisionMesh::split_red_all`), which touches too many nodes for the
    /// scan: per node id, [`UNTOUCHED`], [`WAS_INNER`] or [`WAS_LEAF`], in place of `touched`.
    bulk: Option<Vec<u8>>,
}

const UNTOUCHED: u8 = 0;
const WAS_INNER: u8 = 1;
const WAS_LEAF: u8 = 2;

impl StepRecorder {
    pub(super) fn bulk() -> StepRecorder {
        StepRecorder {
            bulk: Some(Vec::new()),
            ..StepRecorder::default()
        }
    }

    /// Call before changing whether `id` is a leaf.
    pub(super) fn before_change(&mut self, mesh: &SubdivisionMesh, id: NodeId) {
        let was_leaf = || (id as usize) < mesh.nodes.len() && mesh.is_leaf(id);
        match &mut self.bulk {
            Some(states) => {
                let i = id as usize;
                if i >= states.len() {
                    states.resize(mesh.nodes.len().max(i + 1), UNTOUCHED);
                }
                if states[i] == UNTOUCHED {
                    states[i] = if was_leaf() { WAS_LEAF } else { WAS_INNER };
                }
            }
            None => {
                if !self.touched.iter().any(|&(t, _)| t == id) {
                    self.touched.push((id, was_leaf()));
                }
            }
        }
    }

    pub(super) fn finish(mut self, mesh: &SubdivisionMesh) -> RefinementStep {
        if let Some(states) = self.bulk.take() {
            // Already in id order: no sort.
            self.touched = (0..states.len() as NodeId)
                .filter(|&id| states[id as usize] != UNTOUCHED)
                .map(|id| (id, states[id as usize] == WAS_LEAF))
                .collect();
        } else {
            self.touched.sort_unstable();
        }
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
