//! Coarsening driven by the schedule (DESIGN.md §4; the thesis's future work, §6): the
//! subdivision of base triangles that no viewer has seen for a number of visibility passes is
//! collapsed back, level by level, so a long walk does not keep every room it passed through
//! refined. The leaves submitted to level 2 of visibility, the criteria's work and the viewers'
//! tables stay bounded by what was seen lately.
//!
//! A collapse step goes through the pending groups like a refinement step: where it reaches a
//! leaf someone sees (a green closure in a visible neighbour undone), the viewer keeps the old
//! leaves until the new ones are shaded, then swaps them in one update. The mesh keeps its
//! midpoint vertices, so refining a region again reuses them and their cached samples.

use std::collections::BTreeSet;

use crate::mesh::{NodeId, RefinementStep, SubdivisionMesh};
use crate::visible_set::VisibleSet;

#[derive(Debug)]
pub struct Coarsening {
    /// Passes a base triangle must be out of every view before its subdivision goes; 0: never.
    after_passes: u64,
    /// Per base triangle: the last pass in which a viewer saw it.
    last_seen: Vec<u64>,
    /// Base triangles holding subdivision (their own, or a neighbour's green closure).
    refined: BTreeSet<u32>,
}

impl Coarsening {
    pub fn new(base_count: usize, after_passes: u64) -> Self {
        Coarsening {
            after_passes,
            last_seen: vec![0; base_count],
            refined: BTreeSet::new(),
        }
    }

    /// Notes the base triangles a refinement call subdivided.
    pub fn refined(&mut self, mesh: &SubdivisionMesh, steps: &[RefinementStep]) {
        let leaves = steps.iter().flat_map(|s| &s.new_leaves);
        self.refined.extend(leaves.map(|&leaf| mesh.base_of(leaf)));
    }

    /// Marks the base triangles of a visible set as seen at `pass`.
    pub fn seen(&mut self, mesh: &SubdivisionMesh, visible: &VisibleSet, pass: u64) {
        for v in &visible.leaves {
            self.last_seen[mesh.base_of(v.leaf) as usize] = pass;
        }
    }

    /// Collapses, as far as conformity allows, the subdivision of every base triangle unseen for
    /// the set number of passes; returns the steps of all levels, for the pending groups.
    pub fn collapse_stale(&mut self, mesh: &mut SubdivisionMesh, pass: u64) -> Vec<RefinementStep> {
        if self.after_passes == 0 {
            return Vec::new();
        }
        let stale: Vec<u32> = self
            .refined
            .iter()
            .copied()
            .filter(|&b| self.last_seen[b as usize] + self.after_passes <= pass)
            .collect();
        let mut steps = Vec::new();
        loop {
            // Each call undoes the deepest red splits whose children are all leaves; the level
            // above becomes eligible in the next (coarsen_many skips green parents: their red
            // neighbour's collapse undoes them).
            let parents: Vec<NodeId> = stale
                .iter()
                .flat_map(|&b| mesh.leaves_of_base(b))
                .filter_map(|leaf| mesh.node(leaf).parent())
                .collect();
            let level = mesh.coarsen_many(&parents);
            if level.is_empty() {
                break;
            }
            steps.extend(level);
        }
        // A base held by a neighbour's split that stays is kept, and tried again at later passes.
        for b in stale {
            if mesh.leaves_of_base(b) == [b] {
                self.refined.remove(&b);
            }
        }
        steps
    }

    /// Base triangles holding subdivision.
    pub fn refined_bases(&self) -> usize {
        self.refined.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::grid_mesh;

    /// Refines a few leaves of `bases` `levels` times over.
    fn refine_bases(mesh: &mut SubdivisionMesh, c: &mut Coarsening, bases: &[u32], levels: usize) {
        for _ in 0..levels {
            let picks: Vec<NodeId> = bases
                .iter()
                .flat_map(|&b| mesh.leaves_of_base(b).into_iter().take(2))
                .collect();
            let steps = mesh.refine(&picks, &|_| false);
            c.refined(mesh, &steps);
        }
    }

    #[test]
    fn only_subdivision_out_of_view_long_enough_is_collapsed_all_levels_down() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(4), Default::default());
        let base = mesh.base_count();
        let mut c = Coarsening::new(base, 3);
        // Bases 0 and 31 sit in opposite corners: their closures do not meet.
        refine_bases(&mut mesh, &mut c, &[0, 31], 3);
        let far_leaves = mesh.leaves_of_base(31);
        assert!(far_leaves.len() > 4 && mesh.leaves_of_base(0).len() > 4);
        let before: Vec<Vec<NodeId>> = (0..base as u32).map(|b| mesh.leaves_of_base(b)).collect();
        for pass in 1..=3 {
            c.seen(&mesh, &VisibleSet::of_front_leaves(&far_leaves), pass);
            // Base 0 (and its closure) was never seen: due once 3 passes are over.
            let steps = c.collapse_stale(&mut mesh, pass);
            assert_eq!(steps.is_empty(), pass < 3, "pass {pass}");
        }
        assert_eq!(mesh.leaves_of_base(0), vec![0]);
        assert_eq!(
            mesh.leaves_of_base(31),
            far_leaves,
            "a seen base was touched"
        );
        // Elsewhere only whole bases went back (the closures of base 0); the closure of the
        // seen base 31 in its neighbours stays, as coarsening it would change base 31 too.
        for b in 1..base as u32 {
            let now = mesh.leaves_of_base(b);
            assert!(now == before[b as usize] || now == [b], "base {b}");
        }
        assert!(mesh.leaf_count() < before.iter().map(Vec::len).sum::<usize>());
        // Base 31 goes too once unseen long enough, and the mesh is the base mesh again.
        assert!(!c.collapse_stale(&mut mesh, 6).is_empty());
        assert_eq!(mesh.leaf_count(), base);
        assert_eq!(c.refined_bases(), 0);
    }

    #[test]
    fn never_collapses_when_switched_off() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(4), Default::default());
        let mut c = Coarsening::new(mesh.base_count(), 0);
        refine_bases(&mut mesh, &mut c, &[5], 2);
        let leaves = mesh.leaf_count();
        assert!(c.collapse_stale(&mut mesh, 1_000).is_empty());
        assert_eq!(mesh.leaf_count(), leaves);
    }
}
