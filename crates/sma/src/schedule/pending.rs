//! Refinement steps waiting for their samples (DESIGN.md §3 step 6, §4): until every visible
//! new leaf of a step's closure is shaded, viewers keep being shown the leaves it replaced, so
//! they never see a hole or a T-junction; then the whole closure swaps in one update.
//!
//! Steps of one `refine` call may chain (a later step re-splits a green leaf an earlier one made),
//! so overlapping steps are merged into one group first: its new leaves are those no step of the
//! group replaced again, its replaced leaves those that existed before the call.

use std::collections::{HashMap, HashSet};

use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, RefinementStep};

#[derive(Debug)]
pub struct Group {
    pub new_leaves: Vec<NodeId>,
    pub replaced_leaves: Vec<NodeId>,
    /// Whether its guard leaves (`visibility::guards`: no pixels) hold it back too. Those of a
    /// refinement step do: a step shown before its guards may open a crack pixel. Those of a
    /// subtree the cache file brought back do not: its guards come from today's view, not the
    /// saved one, so their hidden corners may never have been sampled, and the site walked
    /// yesterday must appear at once (DESIGN.md §5, persistence), not after a renderer answers
    /// (never, with none).
    pub waits_for_guards: bool,
}

/// Pending groups, and for each of their new leaves the group it belongs to.
#[derive(Debug, Default)]
pub struct PendingRefinement {
    groups: HashMap<usize, Group, FastHash>,
    group_of: HashMap<NodeId, usize, FastHash>,
    next_group: usize,
}

impl PendingRefinement {
    pub fn is_empty(&self) -> bool {
        self.groups.is_empty()
    }

    pub fn len(&self) -> usize {
        self.groups.len()
    }

    /// Adds the steps of one `refine` call, merged into independent groups.
    pub fn add(&mut self, steps: Vec<RefinementStep>) {
        self.add_groups(steps, true);
    }

    /// Adds the steps of subtrees the cache file brought back or took away, whose guards do
    /// not hold them back ([`Group::waits_for_guards`]).
    pub fn add_from_file(&mut self, steps: Vec<RefinementStep>) {
        self.add_groups(steps, false);
    }

    fn add_groups(&mut self, steps: Vec<RefinementStep>, waits_for_guards: bool) {
        for group in merge(steps, waits_for_guards) {
            let id = self.next_group;
            self.next_group += 1;
            for &leaf in &group.new_leaves {
                self.group_of.insert(leaf, id);
            }
            self.groups.insert(id, group);
        }
    }

    /// The group a new leaf belongs to, while pending.
    pub fn group_of(&self, leaf: NodeId) -> Option<usize> {
        self.group_of.get(&leaf).copied()
    }

    /// Whether group `id`'s guards hold it back; false once it is gone.
    pub fn waits_for_guards(&self, id: usize) -> bool {
        self.groups.get(&id).is_some_and(|g| g.waits_for_guards)
    }

    pub fn group(&self, id: usize) -> Option<&Group> {
        self.groups.get(&id)
    }

    pub fn ids(&self) -> Vec<usize> {
        self.groups.keys().copied().collect()
    }

    /// Ends a group: its new leaves are shown from now on.
    pub fn commit(&mut self, id: usize) {
        if let Some(group) = self.groups.remove(&id) {
            for leaf in group.new_leaves {
                self.group_of.remove(&leaf);
            }
        }
    }
}

/// Connected components of steps linked by a leaf one creates and another replaces, each a group
/// that waits for its guards or not (`Group::waits_for_guards`).
fn merge(steps: Vec<RefinementStep>, waits_for_guards: bool) -> Vec<Group> {
    let mut parent: Vec<usize> = (0..steps.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    let mut creator: HashMap<NodeId, usize> = HashMap::new();
    for (i, step) in steps.iter().enumerate() {
        for &leaf in &step.replaced_leaves {
            if let Some(&j) = creator.get(&leaf) {
                let (a, b) = (root(&mut parent, i), root(&mut parent, j));
                parent[a] = b;
            }
        }
        for &leaf in &step.new_leaves {
            creator.insert(leaf, i);
        }
    }
    let mut members: HashMap<usize, Vec<usize>> = HashMap::new();
    for i in 0..steps.len() {
        members.entry(root(&mut parent, i)).or_default().push(i);
    }
    members
        .into_values()
        .map(|ids| {
            let created: HashSet<NodeId> = ids
                .iter()
                .flat_map(|&i| steps[i].new_leaves.iter().copied())
                .collect();
            let replaced: HashSet<NodeId> = ids
                .iter()
                .flat_map(|&i| steps[i].replaced_leaves.iter().copied())
                .collect();
            let mut new_leaves: Vec<NodeId> = created.difference(&replaced).copied().collect();
            let mut replaced_leaves: Vec<NodeId> = replaced.difference(&created).copied().collect();
            new_leaves.sort_unstable();
            replaced_leaves.sort_unstable();
            Group {
                new_leaves,
                replaced_leaves,
                waits_for_guards,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(new_leaves: &[NodeId], replaced_leaves: &[NodeId]) -> RefinementStep {
        RefinementStep {
            new_leaves: new_leaves.to_vec(),
            replaced_leaves: replaced_leaves.to_vec(),
            new_vertices: vec![],
        }
    }

    #[test]
    fn chained_steps_merge_and_independent_ones_do_not() {
        let mut pending = PendingRefinement::default();
        // Step 1 splits 1 into 10..14 and greens 2 into 14, 15; step 2 re-splits green 14 (undo
        // and red split of 2 into 16..20); step 3 is elsewhere.
        pending.add(vec![
            step(&[10, 11, 12, 13, 14, 15], &[1, 2]),
            step(&[16, 17, 18, 19], &[14, 15]),
            step(&[30, 31], &[5]),
        ]);
        assert_eq!(pending.len(), 2);
        let g = pending.group(pending.group_of(10).unwrap()).unwrap();
        assert_eq!(g.new_leaves, vec![10, 11, 12, 13, 16, 17, 18, 19]);
        assert_eq!(g.replaced_leaves, vec![1, 2]);
        assert_eq!(pending.group_of(14), None);
        let other = pending.group_of(30).unwrap();
        assert_ne!(Some(other), pending.group_of(10));
        pending.commit(other);
        assert_eq!(pending.group_of(31), None);
        assert_eq!(pending.len(), 1);
    }
}
