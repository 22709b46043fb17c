//! Removed children kept for reuse, so a long walk's nodes plateau (DESIGN.md §4): coarsening
//! frees what refinement makes again elsewhere. Children are consecutive ids (a red split's
//! four, a green split's two), so whole blocks are reused, by size.
//!
//! A removed block is first *retired*: the schedule's views, pending groups and viewers' tables
//! may still name its ids (a carried-over view walks up from a removed leaf, `carry_over`), so
//! it is reused only after [`FreeNodes::recycle`], which the caller runs where nothing names a
//! removed node any more; [`FreeNodes::recycles`] counts those points, so a view made before one
//! knows it may name reused ids.

use super::NodeId;

#[derive(Clone, Debug, Default)]
pub(super) struct FreeNodes {
    /// First ids of removed blocks not yet reusable: two-blocks, then four-blocks.
    retired: [Vec<NodeId>; 2],
    /// First ids of blocks ready for reuse, by size as above.
    free: [Vec<NodeId>; 2],
    recycles: u64,
}

fn class(len: usize) -> usize {
    debug_assert!(len == 2 || len == 4, "children come in twos and fours");
    usize::from(len == 4)
}

const BLOCK: [usize; 2] = [2, 4];

impl FreeNodes {
    /// The block of `len` children from `first` was removed.
    pub(super) fn retire(&mut self, first: NodeId, len: usize) {
        self.retired[class(len)].push(first);
    }

    /// A removed block of `len` ids to reuse, if a recycled one is left.
    pub(super) fn take(&mut self, len: usize) -> Option<NodeId> {
        self.free[class(len)].pop()
    }

    /// Makes every retired block reusable; false when none was retired (nothing changes).
    pub(super) fn recycle(&mut self) -> bool {
        if self.retired.iter().all(Vec::is_empty) {
            return false;
        }
        // Taken, not drained: the retired lists' capacity goes back to the memory budget.
        for (free, retired) in self.free.iter_mut().zip(&mut self.retired) {
            free.extend(std::mem::take(retired));
        }
        self.recycles += 1;
        true
    }

    /// Takes every block ready for reuse, as (first id, length).
    pub(super) fn take_free(&mut self) -> Vec<(NodeId, usize)> {
        let mut blocks = Vec::new();
        for (free, len) in self.free.iter_mut().zip(BLOCK) {
            blocks.extend(std::mem::take(free).into_iter().map(|first| (first, len)));
        }
        blocks
    }

    /// Makes `blocks` (first id, length) the ones ready for reuse, lowest ids taken first: the
    /// array's end then stays free for the next compaction to give back.
    pub(super) fn set_free(&mut self, mut blocks: Vec<(NodeId, usize)>) {
        debug_assert!(self.free.iter().all(Vec::is_empty));
        blocks.sort_unstable_by(|a, b| b.cmp(a));
        for (first, len) in blocks {
            self.free[class(len)].push(first);
        }
        for free in &mut self.free {
            free.shrink_to_fit();
        }
    }

    pub(super) fn recycles(&self) -> u64 {
        self.recycles
    }

    /// Node slots in retired blocks.
    pub(super) fn retired_slots(&self) -> usize {
        slots(&self.retired)
    }

    /// Node slots ready for reuse.
    pub(super) fn free_slots(&self) -> usize {
        slots(&self.free)
    }

    pub(super) fn heap_bytes(&self) -> usize {
        self.retired
            .iter()
            .chain(&self.free)
            .map(|v| v.capacity() * size_of::<NodeId>())
            .sum()
    }
}

fn slots(blocks: &[Vec<NodeId>; 2]) -> usize {
    blocks.iter().zip(BLOCK).map(|(b, n)| b.len() * n).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_removed_block_is_reused_by_size_and_only_once_recycled() {
        let mut free = FreeNodes::default();
        free.retire(10, 4);
        free.retire(20, 2);
        assert_eq!(free.take(4), None, "retired, not yet recycled");
        assert_eq!((free.retired_slots(), free.free_slots()), (6, 0));
        assert!(free.recycle());
        assert!(!free.recycle(), "nothing new retired");
        assert_eq!(free.recycles(), 1);
        assert_eq!(free.free_slots(), 6);
        assert_eq!(free.take(2), Some(20));
        assert_eq!(free.take(4), Some(10));
        assert_eq!(free.take(4), None);
    }
}
