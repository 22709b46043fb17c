//! What leaves the shading cache (DESIGN.md §5): samples seen least recently when it is over
//! its budget, the samples of subtrees written to the cache file, and every sample of a vertex
//! the mesh freed for reuse.

use protocol::renderer_link::SampleKey;

use super::packed::{Stamp, stamp};
use super::{EVICT_TO_FRACTION, NO_SLOT, ShadingCache, slot_key};
use crate::mesh::VertexId;

impl ShadingCache {
    /// When over budget, removes samples not seen longest first, down to 90 % of the budget;
    /// `keep` and samples seen at `now` are spared. Returns how many were removed.
    pub fn evict(&mut self, now: u64, keep: &dyn Fn(SampleKey) -> bool) -> usize {
        if self.bytes() <= self.budget_bytes {
            return 0;
        }
        let target = (self.budget_bytes as f64 * EVICT_TO_FRACTION) as usize;
        let now = stamp(now);
        let mut candidates: Vec<(Stamp, u32)> = self
            .samples
            .iter()
            .zip(&self.owners)
            .filter(|&(s, &slot)| s.last_seen < now && !keep(slot_key(slot)))
            .map(|(s, &slot)| (s.last_seen, slot))
            .collect();
        candidates.sort_unstable();
        let mut removed = 0;
        for (_, slot) in candidates {
            if self.bytes() <= target {
                break;
            }
            self.remove(slot as usize);
            removed += 1;
        }
        // The budget counts capacity, and a budget that shrank (the mesh grew) must free it:
        // arrays left far larger than what stays are cut to a quarter above it.
        let lean = self.samples.len() + self.samples.len() / 4 + 16;
        if removed > 0 && self.samples.capacity() > lean {
            self.samples.shrink_to(lean);
            self.owners.shrink_to(lean);
        }
        removed
    }

    fn remove(&mut self, slot: usize) {
        let s = std::mem::replace(&mut self.slots[slot], NO_SLOT) as usize;
        self.samples.swap_remove(s);
        self.owners.swap_remove(s);
        self.drop_eyes(slot);
        if let Some(&moved) = self.owners.get(s) {
            self.slots[moved as usize] = s as u32;
        }
    }

    /// Drops the samples of `vertices`, whose subtrees left for the cache file
    /// (`cache_file::evict`); the vertices stay the mesh's. Returns how many were dropped.
    pub fn drop_samples(&mut self, vertices: &[VertexId]) -> usize {
        let mut dropped = 0;
        for &v in vertices {
            for slot in [2 * v as usize, 2 * v as usize + 1] {
                if self.slots.get(slot).is_some_and(|&s| s != NO_SLOT) {
                    self.remove(slot);
                    dropped += 1;
                }
            }
        }
        dropped
    }

    /// Drops every sample of `vertices`, whose ids the mesh freed for reuse
    /// (`SubdivisionMesh::free_unused_midpoints`): a reused id is traced afresh, and its albedo
    /// looked up again.
    pub fn forget_vertices(&mut self, vertices: &[VertexId]) {
        for &v in vertices {
            for slot in [2 * v as usize, 2 * v as usize + 1] {
                if self.slots.get(slot).is_some_and(|&s| s != NO_SLOT) {
                    self.remove(slot);
                }
                self.drop_eyes(slot);
                self.failed.remove(&(slot as u32));
            }
        }
        self.albedos.forget(vertices);
    }
}
