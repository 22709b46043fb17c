//! Which base triangles' subtrees changed since the last time someone asked: the cache file
//! rewrites only those (DESIGN.md §5, "incremental saves").

/// A set of base triangles, in the order first marked; a flag per base keeps marking O(1).
#[derive(Clone, Debug, Default)]
pub(super) struct ChangedBases {
    marked: Vec<bool>,
    list: Vec<u32>,
}

impl ChangedBases {
    pub(super) fn new(base_count: usize) -> Self {
        ChangedBases {
            marked: vec![false; base_count],
            list: Vec::new(),
        }
    }

    pub(super) fn mark(&mut self, base: u32) {
        if let Some(flag) = self.marked.get_mut(base as usize)
            && !*flag
        {
            *flag = true;
            self.list.push(base);
        }
    }

    /// The bases marked since the last call, which unmarks them.
    pub(super) fn take(&mut self) -> Vec<u32> {
        for &b in &self.list {
            self.marked[b as usize] = false;
        }
        std::mem::take(&mut self.list)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_base_is_listed_once_until_taken() {
        let mut changed = ChangedBases::new(4);
        changed.mark(2);
        changed.mark(0);
        changed.mark(2);
        changed.mark(9);
        assert_eq!(changed.take(), vec![2, 0]);
        assert!(changed.take().is_empty());
        changed.mark(2);
        assert_eq!(changed.take(), vec![2]);
    }
}
