//! Coarsening: undoing a red split that is no longer needed (the thesis's future work, §6;
//! DESIGN.md §4), keeping the leaves conforming.

use super::step::StepRecorder;
use super::{NodeId, NodeKind, RefinementStep, Split, SubdivisionMesh};

impl SubdivisionMesh {
    /// Removes the four red children of `parent` when all are leaves and no neighbour is finer
    /// along the parent's edges; the parent becomes a leaf again, or is bisected green if exactly
    /// one neighbour is still split along one of its edges. Green closures of neighbours that only
    /// this split needed are undone too. `None` when not allowed (the mesh is unchanged).
    pub fn coarsen(&mut self, parent: NodeId) -> Option<RefinementStep> {
        let node = *self.node(parent);
        let Split::Red { first_child } = node.split else {
            return None;
        };
        if !node.alive || !(first_child..first_child + 4).all(|c| self.is_leaf(c)) {
            return None;
        }
        if (0..3).any(|k| self.half_edges_split(first_child, k)) {
            return None;
        }
        // Per edge: the green closures across it, and whether anything else still splits it.
        let greens = [0, 1, 2].map(|k| self.greens_across(parent, k));
        let mut still_split = (0..3)
            .filter(|&k| self.splits_of(self.edge_key(parent, k)) as usize > 1 + greens[k].len());
        let hanging = still_split.next();
        if still_split.next().is_some() {
            return None;
        }
        let mut step = StepRecorder::default();
        self.remove_children(parent, &mut step);
        for (k, greens) in greens.into_iter().enumerate() {
            if Some(k) == hanging {
                self.green_split(parent, k, &mut step, &mut Vec::new());
            } else {
                greens
                    .into_iter()
                    .for_each(|g| self.remove_children(g, &mut step));
            }
        }
        Some(step.finish(self))
    }

    /// Whether a neighbour splits either half of the parent's edge `k` (held by the red corner
    /// children `k` and `k + 1`, see `refine::red_children`).
    fn half_edges_split(&self, first_child: NodeId, k: usize) -> bool {
        let first_half = self.edge_key(first_child + k as NodeId, k);
        let second_half = self.edge_key(first_child + ((k + 1) % 3) as NodeId, k);
        self.splits_of(first_half) > 0 || self.splits_of(second_half) > 0
    }

    /// The nodes across edge `k` of `id` that are bisected green along that very edge.
    fn greens_across(&self, id: NodeId, k: usize) -> Vec<NodeId> {
        let key = self.edge_key(id, k);
        let mut across = Vec::new();
        self.leaves_across(id, k, &mut across);
        let mut greens: Vec<NodeId> = across
            .into_iter()
            .filter(|&leaf| self.node(leaf).kind == NodeKind::Green)
            .filter_map(|leaf| self.node(leaf).parent)
            .filter(|&p| {
                matches!(self.node(p).split, Split::Green { edge, .. } if self.edge_key(p, edge as usize) == key)
            })
            .collect();
        greens.sort_unstable();
        greens.dedup();
        greens
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;
    use crate::mesh::test_meshes::square;

    #[test]
    fn coarsening_a_single_split_restores_the_base_mesh() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        mesh.refine(&[0], &|_| false);
        let step = mesh.coarsen(0).expect("allowed");
        assert_eq!(step.new_leaves, vec![0, 1]);
        assert_eq!(step.replaced_leaves.len(), 6);
        assert_eq!(mesh.leaf_count(), 2);
        assert_eq!(mesh.leaves().collect::<Vec<_>>(), vec![0, 1]);
    }

    #[test]
    fn a_parent_with_finer_neighbours_keeps_its_children() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        mesh.refine(&[0], &|_| false);
        // Split the corner child of 0 at the shared diagonal's end, then its neighbours.
        let children: Vec<_> = mesh.node(0).children().collect();
        mesh.refine(&[children[2]], &|_| false);
        let leaves: Vec<_> = mesh.leaves().collect();
        assert!(mesh.coarsen(0).is_none(), "child 2 is split");
        assert_eq!(mesh.leaves().collect::<Vec<_>>(), leaves, "unchanged");
    }

    #[test]
    fn re_refining_after_coarsening_reuses_the_midpoint_vertices() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        let first = mesh.refine(&[0], &|_| false).remove(0);
        mesh.coarsen(0).unwrap();
        let again = mesh.refine(&[0], &|_| false).remove(0);
        assert!(again.new_vertices.is_empty());
        assert_eq!(mesh.vertex_count(), 4 + first.new_vertices.len());
    }
}
