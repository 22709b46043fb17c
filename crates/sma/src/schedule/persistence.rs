//! The schedule's side of the cache file (`crate::cache_file`, DESIGN.md §5): it is opened before
//! the first pass; after each visibility pass the records of base triangles that became visible
//! are loaded, their leaves shown like a refinement round's (pending until shaded, then a new
//! pass sees them); it is told which samples answers changed, saved when due at the end of a
//! turn (a snapshot of at most `cache_file::SNAPSHOT_SLICE`; the writer thread does the rest)
//! and once more at a clean stop.

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
        self.refinement.pending.add(steps);
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

    /// The periodic save, when due.
    pub(super) fn save_if_due(&mut self) {
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
