//! Coarsening: undoing a red split that is no longer needed (the thesis's future work, §6;
//! DESIGN.md §4), keeping the leaves conforming.

use std::collections::HashMap;

use super::fast_hash::FastHash;
use super::step::StepRecorder;
use super::{NodeId, NodeKind, RefinementStep, Split, SubdivisionMesh};

/// What collapsing one red parent does, decided before anything changes.
struct Collapse {
    parent: NodeId,
    /// Point-pair keys of the parent's edges.
    keys: [u64; 3],
    /// Per edge, the green closures across it that exist only because something split it.
    greens: [Vec<NodeId>; 3],
    /// The one edge still split by a node that stays: the parent is bisected green along it.
    hanging: Option<usize>,
}

impl SubdivisionMesh {
    /// [`Self::coarsen_many`] of one parent: `None` when it is not allowed alone (the mesh is
    /// unchanged), e.g. inside a uniformly refined region, where every red neighbour blocks it.
    pub fn coarsen(&mut self, parent: NodeId) -> Option<RefinementStep> {
        self.coarsen_many(&[parent]).pop()
    }

    /// Removes the four red children of as many of `parents` as can go together, keeping the
    /// leaves conforming, and returns one step per group of parents that share an edge: the
    /// smallest conforming units (DESIGN.md §4). A parent goes when its children are all leaves,
    /// no neighbour is finer along its edges, and at most one of its edges stays split by a node
    /// that is not coarsened with it (it is then bisected green along that edge). Green closures
    /// that only the removed splits needed are undone in the same step. Parents that cannot go
    /// are skipped; those one level up may go in a later call, once their children are leaves.
    ///
    /// One parent alone often cannot go: in a uniformly refined region each red parent has red
    /// neighbours on all sides, so only the whole region collapses conformingly (red–green
    /// coarsening undoes whole levels of a patch, Bank–Sherman–Weiser).
    pub fn coarsen_many(&mut self, parents: &[NodeId]) -> Vec<RefinementStep> {
        let mut plans: Vec<Collapse> = Vec::new();
        let mut ids: Vec<NodeId> = parents.to_vec();
        ids.sort_unstable();
        ids.dedup();
        for parent in ids {
            let node = *self.node(parent);
            let Split::Red { first_child } = node.split() else {
                continue;
            };
            if !node.is_alive()
                || !(first_child..first_child + 4).all(|c| self.is_leaf(c))
                || (0..3).any(|k| self.half_edges_split(first_child, k))
            {
                continue;
            }
            plans.push(Collapse {
                parent,
                keys: [0, 1, 2].map(|k| self.edge_key(parent, k)),
                greens: [0, 1, 2].map(|k| self.greens_across(parent, k)),
                hanging: None,
            });
        }
        // Drop parents left with two or more edges split by nodes that stay, until none is.
        loop {
            let mut going: HashMap<u64, u32, FastHash> = HashMap::default();
            for key in plans.iter().flat_map(|p| p.keys) {
                *going.entry(key).or_default() += 1;
            }
            let before = plans.len();
            plans.retain_mut(|plan| {
                let mut split = (0..3).filter(|&k| {
                    self.splits_of(plan.keys[k]) as usize
                        > going[&plan.keys[k]] as usize + plan.greens[k].len()
                });
                plan.hanging = split.next();
                split.next().is_none()
            });
            if plans.len() == before {
                break;
            }
        }
        group_by_shared_edge(plans)
            .into_iter()
            .map(|group| {
                let mut step = StepRecorder::default();
                for plan in &group {
                    self.remove_children(plan.parent, &mut step);
                }
                for plan in group {
                    for (k, greens) in plan.greens.into_iter().enumerate() {
                        if Some(k) == plan.hanging {
                            self.green_split(plan.parent, k, &mut step, &mut Vec::new());
                        } else {
                            // Parents on one edge list the same greens: undo each once.
                            for g in greens {
                                if matches!(self.node(g).split(), Split::Green { .. }) {
                                    self.remove_children(g, &mut step);
                                }
                            }
                        }
                    }
                }
                step.finish(self)
            })
            .collect()
    }

    /// Collapses the subdivision of the base triangles `bases` as far as conformity allows,
    /// every level, deepest first; returns the steps of all levels. A base held by a
    /// neighbour's split that stays keeps what that split needs.
    pub fn collapse_bases(&mut self, bases: &[u32]) -> Vec<RefinementStep> {
        let mut steps = Vec::new();
        loop {
            // Each call undoes the deepest red splits whose children are all leaves; the level
            // above becomes eligible in the next (coarsen_many skips green parents: their red
            // neighbour's collapse undoes them).
            let parents: Vec<NodeId> = bases
                .iter()
                .flat_map(|&b| self.leaves_of_base(b))
                .filter_map(|leaf| self.node(leaf).parent())
                .collect();
            let level = self.coarsen_many(&parents);
            if level.is_empty() {
                return steps;
            }
            steps.extend(level);
        }
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
            .filter(|&leaf| self.node(leaf).kind() == NodeKind::Green)
            .filter_map(|leaf| self.node(leaf).parent())
            .filter(|&p| {
                matches!(self.node(p).split(), Split::Green { edge, .. } if self.edge_key(p, edge as usize) == key)
            })
            .collect();
        greens.sort_unstable();
        greens.dedup();
        greens
    }
}

/// Collapses that share an edge key, transitively: each group must change in one step, since
/// between two of them the shared edge would hang.
fn group_by_shared_edge(plans: Vec<Collapse>) -> Vec<Vec<Collapse>> {
    fn root(up: &mut [usize], mut i: usize) -> usize {
        while up[i] != i {
            up[i] = up[up[i]];
            i = up[i];
        }
        i
    }
    let mut up: Vec<usize> = (0..plans.len()).collect();
    let mut owner: HashMap<u64, usize, FastHash> = HashMap::default();
    for (i, plan) in plans.iter().enumerate() {
        for key in plan.keys {
            let j = *owner.entry(key).or_insert(i);
            let (a, b) = (root(&mut up, i), root(&mut up, j));
            up[a.max(b)] = a.min(b);
        }
    }
    let mut groups: Vec<Vec<Collapse>> = Vec::new();
    let mut group_of: HashMap<usize, usize, FastHash> = HashMap::default();
    for (i, plan) in plans.into_iter().enumerate() {
        let r = root(&mut up, i);
        let g = *group_of.entry(r).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(plan);
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;
    use crate::mesh::test_meshes::{grid, square};

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

    #[test]
    fn a_uniformly_refined_region_collapses_only_as_a_whole() {
        let mut mesh = SubdivisionMesh::new(&grid(3), MeshParams::default());
        let base: Vec<NodeId> = mesh.leaves().collect();
        mesh.refine(&base, &|_| false);
        // Bases bisected green by an earlier closure of the call: select a green half instead.
        let greens: Vec<NodeId> = mesh
            .leaves()
            .filter(|&l| mesh.node(l).kind() == NodeKind::Green)
            .collect();
        mesh.refine(&greens, &|_| false);
        assert_eq!(
            mesh.leaf_count(),
            4 * base.len(),
            "every base triangle split red"
        );
        let centre = 8; // a triangle of the middle square: red neighbours on all three sides
        assert!(mesh.coarsen(centre).is_none());
        let steps = mesh.coarsen_many(&base);
        assert_eq!(steps.len(), 1, "one connected region, one step");
        assert_eq!(steps[0].new_leaves, base);
        assert_eq!(steps[0].replaced_leaves.len(), 4 * base.len());
        assert_eq!(mesh.leaves().collect::<Vec<_>>(), base);
    }

    #[test]
    fn regions_apart_collapse_in_separate_steps() {
        let mut mesh = SubdivisionMesh::new(&grid(3), MeshParams::default());
        // Two corner squares of the 3×3 grid, not touching.
        let (a, b) = ([0, 1], [16, 17]);
        mesh.refine(&[a[0], a[1], b[0], b[1]], &|_| false);
        let steps = mesh.coarsen_many(&[a[0], a[1], b[0], b[1]]);
        assert_eq!(steps.len(), 2);
        assert_eq!(mesh.leaf_count(), 18);
    }

    #[test]
    fn refine_and_collapse_cycles_after_a_recycle_grow_nothing() {
        let scene = grid(3);
        let mut mesh = SubdivisionMesh::new(&scene, MeshParams::default());
        let base: Vec<NodeId> = mesh.leaves().collect();
        let refine_all = |mesh: &mut SubdivisionMesh| {
            for _ in 0..2 {
                let leaves: Vec<NodeId> = mesh.leaves().collect();
                mesh.refine(&leaves, &|_| false);
            }
        };
        let coarsen_all = |mesh: &mut SubdivisionMesh| {
            while !mesh
                .coarsen_many(&(0..mesh.node_count() as NodeId).collect::<Vec<_>>())
                .is_empty()
            {}
        };
        refine_all(&mut mesh);
        let (nodes, memory, leaves) = (mesh.node_count(), mesh.memory(), mesh.leaf_count());
        coarsen_all(&mut mesh);
        assert_eq!(mesh.leaves().collect::<Vec<_>>(), base);
        assert!(mesh.retired_nodes() > 0);
        refine_all(&mut mesh);
        assert!(
            mesh.node_count() > nodes,
            "not recycled: removed nodes stay dead"
        );
        coarsen_all(&mut mesh);
        assert!(mesh.recycle_removed());
        assert_eq!(mesh.node_count(), base.len(), "compacted to the base mesh");
        // From here each refinement reaches the nodes and memory of the first, and each
        // collapse gives them back: nothing grows over the cycles.
        for _ in 0..3 {
            refine_all(&mut mesh);
            assert_eq!(mesh.leaf_count(), leaves, "the same refinement");
            assert_eq!(mesh.node_count(), nodes, "as many nodes as the first time");
            assert_eq!(mesh.memory(), memory, "no capacity grew");
            crate::mesh::invariants::check(&mesh, &scene).unwrap();
            coarsen_all(&mut mesh);
            assert!(mesh.recycle_removed());
            assert_eq!(mesh.node_count(), base.len());
        }
    }
}
