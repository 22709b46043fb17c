//! What one viewer should be shown of its visible set (DESIGN.md §3 step 6, §4): the display's
//! targets, which the viewer's sync brings it to (`shown`). A refinement or coarsening step
//! swaps in whole, once every visible new leaf is shaded, so the viewer never sees a hole or a
//! T-junction.

use std::collections::HashSet;

use glam::Vec3;
use protocol::Side;

use super::pending::PendingRefinement;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visibility::{LeafView, side_facing};

/// The nodes to show for a visible set: each visible leaf, except that a new leaf of a pending
/// refinement group stands for the leaves the group replaced (seen from the eye's side), so the
/// closure swaps in only when complete.
pub fn targets(
    view: &LeafView,
    pending: &PendingRefinement,
    mesh: &SubdivisionMesh,
    eye: Vec3,
) -> Vec<(NodeId, Side)> {
    let mut seen_groups = HashSet::new();
    let mut out = Vec::with_capacity(view.visible.leaves.len());
    for v in &view.visible.leaves {
        match pending.group_of(v.leaf) {
            None => out.push((v.leaf, v.side)),
            Some(g) if seen_groups.insert(g) => {
                let group = pending.group(g).expect("a leaf's group is pending");
                out.extend(
                    group
                        .replaced_leaves
                        .iter()
                        .map(|&r| (r, side_facing(mesh, r, eye))),
                );
            }
            Some(_) => {}
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::grid_mesh;
    use crate::visible_set::VisibleSet;

    fn view_of(leaves: &[NodeId]) -> LeafView {
        LeafView {
            visible: VisibleSet::of_front_leaves(leaves),
            ..Default::default()
        }
    }

    #[test]
    fn a_pending_steps_new_leaves_stand_for_the_leaves_it_replaced_until_it_is_committed() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let steps = mesh.refine(&[0], &|_| false);
        let mut pending = PendingRefinement::default();
        pending.add(steps);
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        let view = view_of(&leaves);
        assert!(leaves.len() > mesh.base_count(), "refined");
        let mut shown: Vec<NodeId> = targets(&view, &pending, &mesh, eye)
            .into_iter()
            .map(|(node, _)| node)
            .collect();
        shown.sort_unstable();
        let bases: Vec<NodeId> = (0..mesh.base_count() as NodeId).collect();
        assert_eq!(shown, bases, "the base mesh, as before the step");
        for id in pending.ids() {
            pending.commit(id);
        }
        let shown = targets(&view, &pending, &mesh, eye);
        assert_eq!(shown.len(), view.visible.leaves.len(), "every leaf itself");
    }
}
