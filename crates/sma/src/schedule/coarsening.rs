//! Coarsening driven by the schedule (DESIGN.md §4; the thesis's future work, §6): the
//! subdivision of base triangles that no viewer has seen for a number of visibility passes is
//! collapsed back, level by level, so a long walk does not keep every room it passed through
//! refined. The leaves submitted to level 2 of visibility, the criteria's work and the viewers'
//! tables stay bounded by what was seen lately.
//!
//! A collapse step goes through the pending groups like a refinement step: where it reaches a
//! leaf someone sees (a green closure in a visible neighbour undone), the viewer keeps the old
//! leaves until the new ones are shaded, then swaps them in one update. The mesh keeps its
//! midpoint vertices, so refining a region again reuses them and their cached samples, unless
//! the memory budget is pressed (`schedule::memory`). With a cache file, what this picks goes to
//! the file instead, and loads again when seen (`schedule::persistence`, DESIGN.md §5).

use std::collections::BTreeSet;

use crate::mesh::{RefinementStep, SubdivisionMesh};
use crate::visible_set::VisibleSet;

#[derive(Debug)]
pub struct Coarsening {
    /// Passes a base triangle must be out of every view before its subdivision goes; 0: never.
    after_passes: u64,
    /// Per base triangle: the last pass in which a viewer saw it.
    last_seen: Vec<u64>,
    /// Base triangles holding subdivision (their own, or a neighbour's green closure).
    refined: BTreeSet<u32>,
    /// The last pressed collapse found nothing out of view to collapse.
    pressed_in_vain: bool,
}

impl Coarsening {
    pub fn new(base_count: usize, after_passes: u64) -> Self {
        Coarsening {
            after_passes,
            last_seen: vec![0; base_count],
            refined: BTreeSet::new(),
            pressed_in_vain: false,
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
        let stale = self.stale(pass);
        self.collapse(mesh, stale)
    }

    /// The refined base triangles unseen for the set number of passes at `pass`.
    pub fn stale(&self, pass: u64) -> Vec<u32> {
        if self.after_passes == 0 {
            return Vec::new();
        }
        self.refined
            .iter()
            .copied()
            .filter(|&b| self.last_seen[b as usize] + self.after_passes <= pass)
            .collect()
    }

    /// Under the memory budget's pressure (`schedule::memory`): collapses the subdivision of the
    /// `share` of refined base triangles in no view at `pass` that were seen least recently (one
    /// at least; the next ones where those collapse nothing), whatever the set number of
    /// passes; empty when nothing out of view collapses.
    pub fn collapse_least_recent(
        &mut self,
        mesh: &mut SubdivisionMesh,
        pass: u64,
        share: f64,
    ) -> Vec<RefinementStep> {
        let (unseen, take) = self.unseen_least_recent_first(pass, share, |_| true);
        // A base refined only by a neighbour's closure goes with that neighbour: chunks that
        // hold nothing to collapse alone are passed over.
        for chunk in unseen.chunks(take) {
            let steps = self.collapse(mesh, chunk.to_vec());
            if !steps.is_empty() {
                self.pressed_in_vain = false;
                return steps;
            }
        }
        self.pressed_in_vain = true;
        Vec::new()
    }

    /// Whether the last [`Self::collapse_least_recent`] found nothing out of view to collapse.
    pub fn pressed_in_vain(&self) -> bool {
        self.pressed_in_vain
    }

    /// Collapses the subdivision of `stale` bases as far as conformity allows, every level.
    fn collapse(&mut self, mesh: &mut SubdivisionMesh, stale: Vec<u32>) -> Vec<RefinementStep> {
        let steps = mesh.collapse_bases(&stale);
        self.collapsed(mesh, &stale);
        steps
    }

    /// Forgets those of `bases` that are bare base triangles again. A base held by a
    /// neighbour's split that stays is kept, and tried again at later passes.
    pub fn collapsed(&mut self, mesh: &SubdivisionMesh, bases: &[u32]) {
        for &b in bases {
            if mesh.leaves_of_base(b) == [b] {
                self.refined.remove(&b);
            }
        }
    }

    /// The `share` of refined base triangles in no view at `pass` that were seen least
    /// recently (one at least) among those `eligible`, least recent first: what goes to the
    /// cache file under the memory budget's pressure (`schedule::persistence`). Not empty: the
    /// last pressed collapse is not in vain.
    pub fn least_recent(
        &mut self,
        pass: u64,
        share: f64,
        eligible: impl Fn(u32) -> bool,
    ) -> Vec<u32> {
        let (mut unseen, take) = self.unseen_least_recent_first(pass, share, eligible);
        unseen.truncate(take);
        if !unseen.is_empty() {
            self.pressed_in_vain = false;
        }
        unseen
    }

    /// The refined base triangles in no view at `pass` among those `eligible`, seen least
    /// recently first, and how many make the `share` of them (one at least).
    fn unseen_least_recent_first(
        &self,
        pass: u64,
        share: f64,
        eligible: impl Fn(u32) -> bool,
    ) -> (Vec<u32>, usize) {
        let mut unseen: Vec<(u64, u32)> = self
            .refined
            .iter()
            .map(|&b| (self.last_seen[b as usize], b))
            .filter(|&(seen, b)| seen < pass && eligible(b))
            .collect();
        unseen.sort_unstable();
        let take = ((unseen.len() as f64 * share).ceil() as usize).max(1);
        (unseen.into_iter().map(|(_, b)| b).collect(), take)
    }

    /// Whether base triangle `base` is in no view at `pass`.
    pub fn unseen(&self, base: u32, pass: u64) -> bool {
        self.last_seen
            .get(base as usize)
            .is_some_and(|&seen| seen < pass)
    }

    /// Base triangles holding subdivision.
    pub fn refined_bases(&self) -> usize {
        self.refined.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::NodeId;
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

    #[test]
    fn pressed_coarsening_takes_the_least_recently_seen_first_and_never_what_is_in_view() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(4), Default::default());
        let mut c = Coarsening::new(mesh.base_count(), 1_000);
        // Corners of the grid, apart, split once (their neighbours bisected green): seen at
        // passes 3, 1 and 2; base 24 is in view at pass 4.
        let bases = [0, 31, 6, 24];
        refine_bases(&mut mesh, &mut c, &bases, 1);
        for (pass, b) in [(3, 0), (1, 31), (2, 6), (4, 24)] {
            let leaves = mesh.leaves_of_base(b);
            c.seen(&mesh, &VisibleSet::of_front_leaves(&leaves), pass);
        }
        let refined = |mesh: &SubdivisionMesh, b: u32| mesh.leaves_of_base(b).len() > 1;
        assert!(!c.collapse_least_recent(&mut mesh, 4, 0.0).is_empty());
        assert!(!c.pressed_in_vain());
        assert!(!refined(&mesh, 31), "seen longest ago: first");
        assert!(refined(&mesh, 6) && refined(&mesh, 0));
        c.collapse_least_recent(&mut mesh, 4, 1.0);
        assert!(!refined(&mesh, 6) && !refined(&mesh, 0));
        assert!(refined(&mesh, 24), "in view");
        assert!(c.collapse_least_recent(&mut mesh, 4, 1.0).is_empty());
        assert!(
            c.pressed_in_vain(),
            "the greens beside base 24 go only with it"
        );
    }
}
