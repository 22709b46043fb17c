//! The schedule's side of the cache file (`crate::cache_file`, DESIGN.md §5): it is opened before
//! the first pass; after each visibility pass the records of base triangles that became visible
//! are loaded, their leaves shown like a refinement round's (pending until shaded, then a new
//! pass sees them); it is told which samples answers changed, saved when due at the end of a
//! turn (a snapshot of at most `cache_file::SNAPSHOT_SLICE`; the writer thread does the rest)
//! and once more at a clean stop. Under the memory budget, the subtrees of base triangles no view
//! sees leave for the file (`cache_file::evict`) rather than being coarsened away.

use protocol::renderer_link::ShadeBatch;
use scene::Scene;

use super::Schedule;
use super::plan::PlanRules;
use crate::cache_file::{CacheFile, CacheFileConfig, MeshKey, SampleMeaning, StoreKey};
use crate::config::ScheduleConfig;
use crate::mesh::SubdivisionMesh;

/// Where the cache file is, and the mesh settings its key holds (they are the SMA's, not the
/// schedule's).
pub struct CacheFileSetup {
    pub config: CacheFileConfig,
    pub mesh: MeshKey,
}

/// Opens the cache file for the fresh `mesh`.
pub fn open(
    setup: &CacheFileSetup,
    scene: &Scene,
    config: &ScheduleConfig,
    rules: &PlanRules,
    mesh: &SubdivisionMesh,
) -> Option<CacheFile> {
    let key = StoreKey {
        scene: scene.fingerprint,
        mesh: setup.mesh,
        samples: SampleMeaning::new(config.ladder, rules.qualities.full),
    };
    let path = setup.config.path(&scene.name, &scene.fingerprint);
    CacheFile::open(&path, setup.config.save_every, &key, mesh)
}

/// What the cache file did for the memory budget.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Eviction {
    /// Subtrees left memory: the leaves changed.
    Dropped,
    /// Subtrees wait for the writer's commit (or nothing left this time): the next turns see.
    Waiting,
}

impl Schedule {
    /// Loads the records of the base triangles the views show that are not loaded yet. Their
    /// leaves wait in the pending groups like a round's until their visible ones are shaded
    /// (restored samples mostly), and a pass is owed to see them. Returns whether any was.
    pub(super) fn load_visible_records(&mut self) -> bool {
        let Some(file) = self.cache_file.as_mut().filter(|f| f.has_unloaded()) else {
            return false;
        };
        let mesh = &self.mesh;
        let bases: Vec<u32> = self
            .viewers
            .views()
            .flat_map(|view| &view.visible.leaves)
            .map(|v| mesh.base_of(v.leaf))
            .collect();
        let steps = file.load(bases, &mut self.mesh, &mut self.cache);
        if steps.is_empty() {
            return false;
        }
        self.refinement.cache_file_steps(&self.mesh, steps, &[]);
        self.viewers.leaves_changed();
        true
    }

    /// A batch's answers are in the cache: their base triangles' records are out of date.
    pub(super) fn samples_changed(&mut self, batch: &ShadeBatch) {
        if let Some(file) = &mut self.cache_file {
            file.samples_changed(batch.points.iter().map(|p| p.key.vertex));
        }
    }

    /// When the next periodic save is due: the loop wakes for it even while nothing else
    /// happens.
    pub(super) fn save_due_at(&self) -> Option<std::time::Instant> {
        self.cache_file.as_ref().map(CacheFile::save_due_at)
    }

    /// Under the memory budget's pressure, with a cache file whose last commit succeeded
    /// (DESIGN.md §5): drops the subtrees written out since the last call once their commit is
    /// in, or starts the `share` of the refined base triangles in no view that were seen least
    /// recently on their way to the file. None without such a file, or with nothing out of view
    /// that the file has loaded: the caller coarsens as without a file.
    pub(super) fn evict_to_file(&mut self, share: f64) -> Option<Eviction> {
        let file = self.cache_file.as_mut().filter(|f| f.takes_subtrees())?;
        if file.writing_out() {
            return Some(if self.drop_written() {
                Eviction::Dropped
            } else {
                Eviction::Waiting
            });
        }
        let bases = self
            .refinement
            .least_recent_unseen(self.frame, share, |b| file.is_loaded(b));
        if bases.is_empty() {
            return None;
        }
        file.write_out(bases, &mut self.mesh, &self.cache);
        Some(Eviction::Waiting)
    }

    /// With a cache file whose last commit succeeded, the subtrees no view has seen for long go
    /// to it rather than being coarsened away (DESIGN.md §4, §5): written out, then dropped
    /// once their commit is in. Whether the leaves changed; None without such a file: the
    /// caller coarsens as without one.
    pub(super) fn stale_to_file(&mut self) -> Option<bool> {
        let file = self.cache_file.as_mut().filter(|f| f.takes_subtrees())?;
        if file.writing_out() {
            return Some(self.drop_written());
        }
        let stale = self.refinement.stale(self.frame);
        if !stale.is_empty() {
            file.write_out(stale, &mut self.mesh, &self.cache);
        }
        Some(false)
    }

    /// Drops the subtrees written out to the file once its commit is in; not while refinement
    /// steps wait, whose leaves the collapse could remove. Returns whether the leaves changed
    /// (the caller tells the viewers).
    fn drop_written(&mut self) -> bool {
        let Some(file) = self.cache_file.as_mut().filter(|f| f.writing_out()) else {
            return false;
        };
        if !self.refinement.pending.is_empty() {
            return false;
        }
        let (refinement, frame) = (&self.refinement, self.frame);
        let Some(dropped) = file.drop_written(&mut self.mesh, &mut self.cache, |b| {
            refinement.unseen(b, frame)
        }) else {
            return false;
        };
        tracing::debug!(
            bases = dropped.bases.len(),
            samples = dropped.samples,
            steps = dropped.steps.len(),
            "subtrees written to the cache file and dropped, for the memory budget"
        );
        let changed = !dropped.steps.is_empty();
        self.refinement
            .cache_file_steps(&self.mesh, dropped.steps, &dropped.bases);
        changed
    }

    /// The periodic save, when due; first, subtrees written out whose commit is in leave memory.
    pub(super) fn save_if_due(&mut self) {
        if self.drop_written() {
            self.viewers.leaves_changed();
        }
        if let Some(file) = &mut self.cache_file {
            file.save_if_due(&mut self.mesh, &self.cache);
        }
    }

    /// The last save of a clean stop.
    pub(super) fn close_cache_file(&mut self) {
        if let Some(file) = self.cache_file.take() {
            file.close(&mut self.mesh, &self.cache);
        }
    }
}
