//! Eviction to the cache file under the memory budget (DESIGN.md §5, persistence; §4, the
//! budget): the subtree of a base triangle no view sees leaves memory for the file rather than
//! being lost. It goes in two turns, so the schedule never waits for the disk (DESIGN.md §3:
//! the schedule pauses at most 20 ms for a save): [`CacheFile::write_out`] snapshots the
//! records out of date and hands them to the writer; once a commit holding them is in the file,
//! [`CacheFile::drop_written`] collapses the subtrees, frees the samples no leaf shows any
//! more, and marks the base triangles as not loaded, so they load again, as any record does,
//! when they become visible. A base triangle that changed in between (seen again, new samples)
//! stays; while commits fail, nothing leaves and the schedule coarsens as without a file.

use std::time::{Duration, Instant};

use super::{CacheFile, SNAPSHOT_SLICE};
use crate::cache::ShadingCache;
use crate::mesh::{NodeId, RefinementStep, SubdivisionMesh, VertexId};

/// How soon the schedule looks again whether the writer's commit is in the file.
pub const POLL: Duration = Duration::from_millis(2);

/// Base triangles on their way to the file: every record they need was handed to the writer
/// with commit `ticket` or before it.
pub struct Leaving {
    bases: Vec<u32>,
    ticket: u64,
}

/// What leaving memory for the file did.
#[derive(Debug, Default)]
pub struct Dropped {
    /// The base triangles whose subtrees left, marked as not loaded.
    pub bases: Vec<u32>,
    /// The collapse's steps, for the pending groups like coarsening's.
    pub steps: Vec<RefinementStep>,
    /// Cached samples freed.
    pub samples: usize,
}

impl CacheFile {
    /// Whether subtrees may leave for the file: its last commit succeeded (DESIGN.md §5: a
    /// record leaves memory only once a commit holding it is in the file).
    pub fn takes_subtrees(&self) -> bool {
        !self.writer.failing()
    }

    /// Whether `base`'s record is loaded (or it has none in the file): it may leave.
    pub fn is_loaded(&self, base: u32) -> bool {
        self.unloaded.get(base as usize) == Some(&false)
    }

    /// Whether base triangles are on their way to the file.
    pub fn writing_out(&self) -> bool {
        self.leaving.is_some()
    }

    /// Starts `bases` (no view sees them) on their way to the file: the records out of date
    /// among them are snapshot, for [`SNAPSHOT_SLICE`] at most, and handed to the writer.
    /// Those left out of date stay in memory at [`Self::drop_written`], for a later try.
    pub fn write_out(&mut self, bases: Vec<u32>, mesh: &mut SubdivisionMesh, cache: &ShadingCache) {
        let start = Instant::now();
        for base in mesh.take_changed_bases() {
            self.mark(base);
        }
        let mut records = Vec::new();
        for &base in &bases {
            if Instant::now() >= start + SNAPSHOT_SLICE {
                break;
            }
            if self.is_dirty[base as usize] {
                records.push(self.snapshot_base(mesh, cache, base));
            }
        }
        let is_dirty = &self.is_dirty;
        self.dirty.retain(|&b| is_dirty[b as usize]);
        self.hand_over(records);
        self.note_pause(start.elapsed());
        self.leaving = Some(Leaving {
            bases,
            ticket: self.writer.sent(),
        });
    }

    /// Once the file holds every record the leaving base triangles need: collapses those still
    /// unchanged and out of every view (`unseen`; one not loaded yet keeps its record as it is), frees the cached samples of the vertices no
    /// leaf has any more, and marks them as not loaded. None while that commit is not in the
    /// file yet (a failed one: until a later commit succeeds).
    pub fn drop_written(
        &mut self,
        mesh: &mut SubdivisionMesh,
        cache: &mut ShadingCache,
        unseen: impl Fn(u32) -> bool,
    ) -> Option<Dropped> {
        if self.writer.committed() < self.leaving.as_ref()?.ticket {
            return None;
        }
        let leaving = self.leaving.take()?;
        for base in mesh.take_changed_bases() {
            self.mark(base);
        }
        let bases: Vec<u32> = leaving
            .bases
            .into_iter()
            .filter(|&b| !self.is_dirty[b as usize] && unseen(b))
            .collect();
        let leaves = |mesh: &SubdivisionMesh| -> Vec<NodeId> {
            bases.iter().flat_map(|&b| mesh.leaves_of_base(b)).collect()
        };
        let before = corners(mesh, leaves(mesh));
        let steps = mesh.collapse_bases(&bases);
        // A vertex a leaf elsewhere still has lies on a leaving base triangle's border, where
        // the conforming mesh makes it a corner of one of its leaves or of a new leaf too.
        let new_leaves = steps.iter().flat_map(|s| s.new_leaves.iter().copied());
        let after = corners(mesh, leaves(mesh).into_iter().chain(new_leaves));
        let freed: Vec<VertexId> = before
            .into_iter()
            .filter(|v| after.binary_search(v).is_err())
            .collect();
        let samples = cache.drop_samples(&freed);
        // The file keeps the records written, and the loader reads them when the base
        // triangles are seen again; what the collapse changed in neighbours is theirs to save.
        for &base in &bases {
            let unloaded = &mut self.unloaded[base as usize];
            self.unloaded_count += usize::from(!*unloaded);
            *unloaded = true;
        }
        for base in mesh.take_changed_bases() {
            self.mark(base);
        }
        Some(Dropped {
            bases,
            steps,
            samples,
        })
    }
}

/// The corners of `leaves`, sorted, each once.
fn corners(mesh: &SubdivisionMesh, leaves: impl IntoIterator<Item = NodeId>) -> Vec<VertexId> {
    let mut vertices: Vec<VertexId> = leaves
        .into_iter()
        .flat_map(|leaf| mesh.node(leaf).vertices)
        .collect();
    vertices.sort_unstable();
    vertices.dedup();
    vertices
}
