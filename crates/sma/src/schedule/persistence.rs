//! The schedule's side of the cache file (`crate::cache_file`, DESIGN.md §5): it is opened and
//! restored before the first pass, told which samples answers changed, saved when due at the end
//! of a turn (a snapshot of at most `cache_file::SNAPSHOT_SLICE`; the writer thread does the
//! rest) and once more at a clean stop.

use protocol::renderer_link::ShadeBatch;
use scene::Scene;

use super::Schedule;
use super::plan::PlanRules;
use crate::cache::ShadingCache;
use crate::cache_file::{CacheFile, CacheFileConfig, MeshKey, SampleMeaning, StoreKey};
use crate::config::ScheduleConfig;
use crate::mesh::SubdivisionMesh;

/// Where the cache file is, and the mesh settings its key holds (they are the SMA's, not the
/// schedule's).
pub struct CacheFileSetup {
    pub config: CacheFileConfig,
    pub mesh: MeshKey,
}

/// Opens the cache file and restores it into the fresh `mesh` and `cache`.
pub fn open(
    setup: &CacheFileSetup,
    scene: &Scene,
    config: &ScheduleConfig,
    rules: &PlanRules,
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> Option<CacheFile> {
    let key = StoreKey {
        scene: scene.fingerprint,
        mesh: setup.mesh,
        samples: SampleMeaning::new(config.ladder, rules.qualities.full),
    };
    let path = setup.config.path(&scene.name, &scene.fingerprint);
    CacheFile::open(&path, setup.config.save_every, &key, mesh, cache)
}

impl Schedule {
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
