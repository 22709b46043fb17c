//! One memory budget for the SMA's own structures (`--memory-mib`; DESIGN.md §4, §5): the mesh's
//! nodes, vertices and edge tables, the shading cache, and each viewer's view, shown table and
//! outbox, counted by capacity (what is allocated, not what is used).
//!
//! The cache gets what the mesh and the viewers leave, and evicts what was seen least recently
//! (`ShadingCache::evict`). A refinement round goes on while everything, grown by what the
//! round may add, stays under nine tenths of the budget: past it, the subdivision of the base
//! triangles seen least recently, and in no current view, is collapsed first, the removed
//! nodes are reused (`mesh::free_nodes`) and the node array's free end given back
//! (`mesh::compact`), and the midpoint vertices and split edges no live node uses are freed for
//! reuse; with nothing out of view left to collapse, the samples no current view shows are
//! evicted. With a cache file, what is out of view goes to the file first (`persistence`). When the current views alone need more, refinement stops and the SMA says
//! it is memory-bound (`Stats`; the log warns the first time).

use std::collections::HashSet;

use protocol::viewer_link::SmaMemory;

use super::persistence::Eviction;
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{MeshMemory, VertexId};
use crate::viewer_link::ViewerId;

/// Near the budget: past this share of it, refinement gives way to coarsening. The cache shrinks
/// as the mesh grows (it gets a share of what the mesh leaves), so with a full cache the mesh
/// stops near half the budget, and with a cache that needs little it may take most of it.
const PRESSED: f64 = 0.9;

/// The cache's arrays grow by a quarter (`mesh::push_lean`), so a cache evicting down to this
/// share of what is left stays within it by capacity.
const CACHE_FILL: f64 = 0.8;

/// Refinement splits made per selected leaf, at most, counted for the growth a round may cause:
/// the leaf and its closure, which rarely reaches further than three neighbours.
const SPLITS_PER_SELECTION: usize = 4;

/// What the SMA's structures hold, by part.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryAccount {
    pub mesh: MeshMemory,
    pub cache: usize,
    pub viewers: usize,
}

impl MemoryAccount {
    pub fn total(&self) -> usize {
        self.fixed() + self.cache
    }

    /// What eviction cannot free: the mesh and the viewers.
    fn fixed(&self) -> usize {
        self.mesh.total() + self.viewers
    }
}

/// The budget and whether it binds.
#[derive(Debug)]
pub struct MemoryBudget {
    budget: usize,
    bound: bool,
    /// Times the SMA became memory-bound: near the budget it comes and goes as views change,
    /// so only the first time is a warning and the others are counted at debug level.
    times_bound: u64,
}

impl MemoryBudget {
    pub fn new(budget_bytes: usize) -> Self {
        MemoryBudget {
            budget: budget_bytes,
            bound: false,
            times_bound: 0,
        }
    }

    /// What the cache may hold by its own count (`ShadingCache::bytes`).
    pub fn cache_budget(&self, account: &MemoryAccount) -> usize {
        let left = self.budget.saturating_sub(account.fixed());
        (left as f64 * CACHE_FILL) as usize
    }

    /// Whether everything, the mesh grown by `growth` bytes, stays under the pressed share.
    pub fn fits(&self, account: &MemoryAccount, growth: usize) -> bool {
        self.excess(account, growth) == 0
    }

    /// Bytes to free for everything, the mesh grown by `growth` bytes, to stay under the
    /// pressed share.
    pub fn excess(&self, account: &MemoryAccount, growth: usize) -> usize {
        let room = (PRESSED * self.budget as f64) as usize;
        (account.total() + growth).saturating_sub(room)
    }

    /// Splits a round of `selections` may make, for [`crate::mesh::SubdivisionMesh::growth_bytes`].
    pub fn round_splits(selections: usize) -> usize {
        selections * SPLITS_PER_SELECTION
    }

    /// Records whether the current views alone need more than the budget: a warning the first
    /// time, and each later change at debug level with the count (`Stats` says it every time).
    pub fn set_bound(&mut self, bound: bool, account: &MemoryAccount) {
        if bound == self.bound {
            return;
        }
        self.bound = bound;
        self.times_bound += u64::from(bound);
        let mib = |bytes: usize| format!("{:.1}", bytes as f64 / f64::from(1 << 20));
        let (accounted_mib, budget_mib) = (mib(account.total()), mib(self.budget));
        match (bound, self.times_bound) {
            (true, 1) => tracing::warn!(
                accounted_mib,
                mesh_mib = mib(account.mesh.total()),
                cache_mib = mib(account.cache),
                viewers_mib = mib(account.viewers),
                budget_mib,
                "memory-bound: the current views need more than --memory-mib, refinement stops \
                 (later changes are logged at debug level)"
            ),
            (true, times) => {
                tracing::debug!(accounted_mib, budget_mib, times, "memory-bound again")
            }
            (false, times) => tracing::debug!(
                accounted_mib,
                budget_mib,
                times,
                "no longer memory-bound: refinement goes on"
            ),
        }
    }

    /// The account as `Stats` carries it, with the process's resident memory.
    pub fn wire(&self, account: &MemoryAccount) -> SmaMemory {
        SmaMemory {
            nodes_bytes: account.mesh.nodes as u64,
            vertices_bytes: account.mesh.vertices as u64,
            edge_tables_bytes: account.mesh.edge_tables as u64,
            cache_bytes: account.cache as u64,
            viewers_bytes: account.viewers as u64,
            budget_bytes: self.budget as u64,
            rss_bytes: process_rss_bytes(),
            memory_bound: self.bound,
        }
    }
}

/// Removed nodes are recycled once they are this share of the nodes, or when the mesh is
/// pressed: recycling makes every view be drawn afresh (a carried-over view may name them).
const RECYCLE_SHARE: f64 = 1.0 / 16.0;

/// The share of the refined base triangles out of view that one pressed pass collapses, seen
/// least recently first.
const PRESSED_COLLAPSE_SHARE: f64 = 0.125;

/// What keeping the budget before the passes did.
pub struct Kept {
    /// Coarsening changed the leaves.
    pub leaves_changed: bool,
    /// Removed nodes were recycled: no view may be carried over.
    pub recycled: bool,
}

impl super::Schedule {
    pub(super) fn memory_account(&self) -> MemoryAccount {
        MemoryAccount {
            mesh: self.mesh.memory(),
            cache: self.cache.capacity_bytes(),
            viewers: self.viewers.iter().map(super::Viewer::heap_bytes).sum(),
        }
    }

    /// Before the passes: recycles removed nodes where nothing names them (no refinement step
    /// pending; every view is drawn afresh next), collapses what no viewer has seen lately, and
    /// more, least recently seen first, when a round would not fit; then gives the cache what
    /// is left.
    pub(super) fn keep_memory_budget(&mut self) -> Kept {
        let pressed = !self.round_fits_budget(&self.memory_account());
        let retired = self.mesh.retired_nodes() as f64;
        let recycled = self.refinement.pending.is_empty()
            && (pressed || retired > RECYCLE_SHARE * self.mesh.node_count() as f64)
            && self.mesh.recycle_removed();
        if recycled {
            self.viewers.leaves_changed();
            if pressed {
                self.free_unused_midpoints();
            }
        }
        let mut leaves_changed = match self.stale_to_file() {
            Some(changed) => changed,
            None => self.refinement.coarsen_stale(&mut self.mesh, self.frame),
        };
        if pressed {
            leaves_changed |= self.relieve_pressure() == Some(true);
        }
        let cache_budget = self.memory.cache_budget(&self.memory_account());
        self.cache.set_budget_bytes(cache_budget);
        Kept {
            leaves_changed,
            recycled,
        }
    }

    /// Whether a refinement round for viewer `id` fits the budget. When it does not, what was
    /// seen least recently and is in no view is collapsed, and the viewer waits for the pass
    /// that follows (or for new input); when nothing out of view is left to collapse, the
    /// cached samples no current view shows are evicted, least recently seen first, as far as
    /// the round needs. When that is not enough either, the current views alone need more: the
    /// SMA is memory-bound, and the viewer's samples get their paths as when its criterion runs
    /// dry (its stated end, DESIGN.md §5).
    pub(super) fn round_fits(&mut self, id: ViewerId) -> bool {
        let account = self.memory_account();
        if self.round_fits_budget(&account) {
            self.memory.set_bound(false, &account);
            return true;
        }
        match self.relieve_pressure() {
            // Subtrees wait for the cache file's commit: a later turn drops them.
            None => return false,
            Some(true) => self.viewers.leaves_changed(),
            Some(false) => {}
        }
        if self.refinement.pressed_in_vain() && self.evict_unseen_for_round() {
            let account = self.memory_account();
            self.memory.set_bound(false, &account);
            return true;
        }
        let bound = self.refinement.pressed_in_vain();
        self.memory.set_bound(bound, &account);
        if let Some(viewer) = self.viewers.get_mut(id) {
            viewer.wait.exhausted();
            if bound && !viewer.criterion_dry {
                viewer.criterion_dry = true;
                self.owed.queue_changed();
            }
        }
        false
    }

    /// Frees what no view shows, seen least recently first: subtrees go to the cache file where
    /// one takes them (`persistence`, DESIGN.md §5), else they are coarsened away. Whether the
    /// leaves changed; None while subtrees wait for the file's commit.
    fn relieve_pressure(&mut self) -> Option<bool> {
        let share = PRESSED_COLLAPSE_SHARE;
        match self.evict_to_file(share) {
            Some(Eviction::Dropped) => Some(true),
            Some(Eviction::Waiting) => None,
            None => Some(
                self.refinement
                    .coarsen_pressed(&mut self.mesh, self.frame, share),
            ),
        }
    }

    /// Evicts cached samples that no view showed at the last pass, least recently seen first,
    /// until a round fits or none is left (the cache's budget is set again before the next
    /// passes); returns whether it fits now. What the current views show stays cached. The
    /// budget counts capacity, which an eviction gives back only once the arrays are a quarter
    /// above what stays (`ShadingCache::evict`): it goes by eighths of the cache at least.
    fn evict_unseen_for_round(&mut self) -> bool {
        let splits = MemoryBudget::round_splits(self.config.max_selections);
        loop {
            let growth = self.mesh.growth_bytes(splits);
            let excess = self.memory.excess(&self.memory_account(), growth);
            if excess == 0 {
                return true;
            }
            let bytes = self.cache.bytes();
            self.cache
                .set_budget_bytes(bytes.saturating_sub(excess.max(bytes / 8)));
            if self.cache.evict(self.frame, &|_| false) == 0 {
                return false;
            }
        }
    }

    /// Under pressure, with no refinement step pending: the midpoint vertices no live node
    /// uses are freed for reuse, with their samples (`SubdivisionMesh::free_unused_midpoints`),
    /// but for those a shown triangle or a sample asked for still names.
    fn free_unused_midpoints(&mut self) {
        let shown = self.viewers.iter().flat_map(|v| v.shown.shown_triangles());
        let named: HashSet<VertexId, FastHash> = self
            .requests
            .vertices()
            .chain(shown.flat_map(|(corners, _)| corners))
            .collect();
        let freed = self.mesh.free_unused_midpoints(&|v| named.contains(&v));
        self.cache.forget_vertices(&freed);
        self.answers
            .forget_vertices(&freed.into_iter().collect::<HashSet<_, FastHash>>());
    }

    /// At a turn's end: the viewers' state grows at a sync and the cache with answers, after the
    /// cache's share was set before the passes, so everything could end a turn over the budget
    /// (by 38 KB of 24.5 MB at one snapshot of bracara's walk under a quarter of its peak). The
    /// cache gives the excess back at once, least recently seen first; what the current views
    /// see stays, and a view that needs more makes the SMA memory-bound at its next round.
    pub(super) fn trim_cache_to_budget(&mut self) {
        let account = self.memory_account();
        if account.total() <= self.memory.budget {
            return;
        }
        self.cache
            .set_budget_bytes(self.memory.cache_budget(&account));
        self.cache.evict(self.frame, &|_| false);
    }

    fn round_fits_budget(&self, account: &MemoryAccount) -> bool {
        let splits = MemoryBudget::round_splits(self.config.max_selections);
        self.memory.fits(account, self.mesh.growth_bytes(splits))
    }
}

/// The process's resident memory: `/proc/self/statm`'s second field, in pages.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn process_rss_bytes() -> Option<u64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    // SAFETY: sysconf only reads a system constant.
    let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    Some(pages * u64::try_from(page).ok()?)
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn process_rss_bytes() -> Option<u64> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn account(mesh: usize, cache: usize, viewers: usize) -> MemoryAccount {
        MemoryAccount {
            mesh: MeshMemory {
                nodes: mesh,
                vertices: 0,
                edge_tables: 0,
            },
            cache,
            viewers,
        }
    }

    #[test]
    fn the_cache_gets_what_the_mesh_and_viewers_leave_and_rounds_stop_near_the_budget() {
        let budget = MemoryBudget::new(1000);
        assert_eq!(budget.cache_budget(&account(300, 500, 100)), 480);
        assert_eq!(budget.cache_budget(&account(900, 0, 200)), 0);
        assert!(budget.fits(&account(400, 300, 100), 100));
        assert!(!budget.fits(&account(400, 300, 100), 101));
        assert_eq!(budget.excess(&account(400, 300, 100), 101), 1);
        assert_eq!(budget.excess(&account(400, 300, 100), 0), 0);
        assert!(
            budget.fits(&account(800, 0, 0), 100),
            "a cache that needs little"
        );
    }

    #[test]
    fn being_memory_bound_is_said_in_the_wire_form_with_the_parts() {
        let mut budget = MemoryBudget::new(1 << 20);
        let a = MemoryAccount {
            mesh: MeshMemory {
                nodes: 1,
                vertices: 2,
                edge_tables: 3,
            },
            cache: 4,
            viewers: 5,
        };
        budget.set_bound(true, &a);
        let wire = budget.wire(&a);
        assert!(wire.memory_bound);
        assert_eq!(wire.mesh_bytes(), 6);
        assert_eq!(wire.accounted_bytes(), a.total() as u64);
        assert_eq!(wire.budget_bytes, 1 << 20);
        if cfg!(all(target_os = "linux", target_env = "gnu")) {
            assert!(wire.rss_bytes.is_some_and(|b| b > 1 << 20), "{wire:?}");
        }
        budget.set_bound(false, &a);
        assert!(!budget.wire(&a).memory_bound);
    }
}
