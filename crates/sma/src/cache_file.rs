//! The SMA's cache file (DESIGN.md §5, "persistence"): the subdivision mesh and the shading
//! cache kept in an embedded transactional store, `redb`, so a site walked yesterday appears at
//! once today (Radiance's holodeck file did this for rays).
//!
//! - One record per base triangle (`record`): its refinement subtree and the samples of its
//!   vertices, postcard-encoded. Saves are incremental: only the base triangles whose subtree
//!   changed (`SubdivisionMesh::take_changed_bases`) or whose samples changed since the last
//!   commit are snapshot again.
//! - A key record (`key`): scene fingerprint, format version, the mesh settings that shape
//!   subdivision and what a sample means. A store is used only when its key matches.
//! - Loading is at start, whole (`restore`), not lazily per base triangle: refinement's closure
//!   crosses base triangles (a red split greens its neighbours), so one base triangle's subtree
//!   restored alone would leave its neighbours with hanging vertices, a crack; replaying every
//!   record's splits at once keeps the mesh conforming. The viewers then get the restored leaves
//!   as the usual `Insert`s of their first views.
//! - Saving is periodic and at a clean stop: the schedule's thread only snapshots the changed
//!   base triangles, at most [`SNAPSHOT_SLICE`] of them per turn's worth of time, and the writer
//!   thread (`writer`) encodes and commits them.
//! - A store that is not this SMA's (truncated, corrupt, another scene, version or settings) is
//!   refused with one warning naming why, renamed to `PATH.rejected`, and the SMA starts empty. A
//!   store it cannot use now (locked by another SMA, an unwritable directory) gets one warning,
//!   and the SMA carries on without it (`store::Unusable`). Neither ends the SMA.

mod key;
mod record;
mod restore;
mod store;
mod writer;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::cache::ShadingCache;
use crate::mesh::{SubdivisionMesh, VertexId};
pub use key::{FORMAT_VERSION, MeshKey, SampleMeaning, StoreKey};
use record::BaseRecord;
pub use restore::Restored;
use restore::{BadRecord, Parsed};
use store::Unusable;
use writer::Writer;
pub use writer::WriterStats;

/// How long one periodic snapshot may hold the schedule's thread: the base triangles left over
/// wait for the next turn (DESIGN.md §3: a new view must not wait behind bookkeeping; the
/// schedule may pause at most 20 ms for a save). A quarter of that: on two cores shared with
/// the renderers and the writer thread, wall time runs well past CPU time (BENCHMARKS.md,
/// cache file section).
pub const SNAPSHOT_SLICE: Duration = Duration::from_millis(5);

/// Where the cache file is and how often it is saved.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CacheFileConfig {
    pub location: Location,
    pub save_every: Duration,
}

/// A file named by the caller, or one per scene in a directory (the launcher's default, in the
/// user's cache directory): `DIR/<scene name>-<fingerprint prefix>.redb`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Location {
    File(PathBuf),
    PerScene(PathBuf),
}

impl CacheFileConfig {
    /// The default period: a crash loses at most this much of the work.
    pub const SAVE_EVERY: Duration = Duration::from_secs(10);

    pub fn at(path: impl Into<PathBuf>) -> CacheFileConfig {
        CacheFileConfig {
            location: Location::File(path.into()),
            save_every: Self::SAVE_EVERY,
        }
    }

    /// The file for the scene named `scene` with fingerprint `fingerprint`.
    pub fn path(&self, scene: &str, fingerprint: &[u8; 32]) -> PathBuf {
        match &self.location {
            Location::File(path) => path.clone(),
            Location::PerScene(dir) => dir.join(per_scene_file_name(scene, fingerprint)),
        }
    }
}

/// `<scene name>-<first 12 hex digits of the fingerprint>.redb`, the name kept to what any file
/// system takes.
pub fn per_scene_file_name(scene: &str, fingerprint: &[u8; 32]) -> String {
    let name: String = scene
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    let hex = scene::fingerprint_hex(fingerprint);
    format!("{name}-{}.redb", &hex[..12.min(hex.len())])
}

/// The schedule's thread's pauses for snapshots.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pauses {
    pub count: u64,
    pub longest: Duration,
    pub total: Duration,
}

/// An open cache file: what the schedule owes it and the writer thread.
pub struct CacheFile {
    writer: Writer,
    label: String,
    /// Base triangles to snapshot, in the order they changed, with a flag each.
    dirty: Vec<u32>,
    is_dirty: Vec<bool>,
    /// A base triangle whose record holds each vertex, `u32::MAX` where none is known yet (a
    /// vertex new since its base triangle's last snapshot, which is dirty already).
    vertex_base: Vec<u32>,
    save_every: Duration,
    last_save: Instant,
    pauses: Pauses,
    restored: Restored,
}

impl CacheFile {
    /// Opens the cache file, restores what it holds into `mesh` and `cache` (which must be fresh),
    /// and starts its writer. None, after one warning, when the file cannot be used: the SMA
    /// carries on without it.
    pub fn open(
        path: &Path,
        save_every: Duration,
        key: &StoreKey,
        mesh: &mut SubdivisionMesh,
        cache: &mut ShadingCache,
    ) -> Option<CacheFile> {
        let label = path.display().to_string();
        let start = Instant::now();
        let (opened, records) = match open_parsed(path, key, mesh.base_count()) {
            Ok(found) => found,
            Err(Unusable::Refused(reason)) => {
                let fresh = set_aside(path, key, &reason)?;
                (fresh, Vec::new())
            }
            Err(Unusable::Fault(reason)) => {
                tracing::warn!(file = %label, "cache file not used: {reason}; the SMA carries on without it");
                return None;
            }
        };
        let read = start.elapsed();
        let (mut restored, owners) = restore::restore(&records, mesh, cache);
        restored.read = read;
        let writer = match Writer::spawn(opened, label.clone()) {
            Ok(writer) => writer,
            Err(e) => {
                tracing::warn!(file = %label, error = %e, "cache file not used: no writer thread");
                return None;
            }
        };
        let mut file = CacheFile {
            writer,
            label,
            dirty: Vec::new(),
            is_dirty: vec![false; mesh.base_count()],
            vertex_base: Vec::new(),
            save_every,
            last_save: Instant::now(),
            pauses: Pauses::default(),
            restored,
        };
        for base in 0..mesh.base_count() as u32 {
            file.note_owner(&mesh.node(base).vertices, base);
        }
        for (vertex, base) in owners {
            file.note_owner(&[vertex], base);
        }
        // The restore's own splits are in the file already.
        mesh.take_changed_bases();
        // Only a file that brought something back is news to a person; an empty one is not.
        if restored.bases == 0 {
            tracing::debug!(file = %file.label, "cache file empty: the SMA starts empty");
        } else {
            tracing::info!(
                file = %file.label,
                bases = restored.bases,
                leaves = mesh.leaf_count(),
                samples = restored.samples,
                unmatched_vertices = restored.unmatched_vertices,
                ms = start.elapsed().as_millis() as u64,
                "cache file loaded"
            );
        }
        file.restored.total = start.elapsed();
        Some(file)
    }

    /// What the file brought back at start.
    pub fn restored(&self) -> Restored {
        self.restored
    }

    pub fn writer_stats(&self) -> WriterStats {
        self.writer.stats()
    }

    pub fn pauses(&self) -> Pauses {
        self.pauses
    }

    /// New or better samples of `vertices`: their base triangles' records are out of date.
    pub fn samples_changed(&mut self, vertices: impl IntoIterator<Item = VertexId>) {
        for v in vertices {
            if let Some(&base) = self.vertex_base.get(v as usize)
                && base != u32::MAX
            {
                self.mark(base);
            }
        }
    }

    /// The periodic save: when due, snapshots changed base triangles for at most
    /// [`SNAPSHOT_SLICE`] and hands them to the writer; what is left waits for the next call.
    pub fn save_if_due(&mut self, mesh: &mut SubdivisionMesh, cache: &ShadingCache) {
        let leftover = !self.dirty.is_empty();
        if !leftover && self.last_save.elapsed() < self.save_every {
            return;
        }
        let start = Instant::now();
        let records = self.snapshot(mesh, cache, Some(start + SNAPSHOT_SLICE));
        if !records.is_empty()
            && let Err(writer::Busy(back)) = self.writer.try_commit(records)
        {
            // The writer is behind (a slow disk): these base triangles go in a later commit.
            back.iter().for_each(|(base, _)| self.mark(*base));
        }
        self.note_pause(start.elapsed());
        if self.dirty.is_empty() {
            self.last_save = Instant::now();
        }
    }

    /// When [`Self::save_if_due`] next has work: now while a sliced snapshot has base triangles
    /// left, else a period after the last save.
    pub fn save_due_at(&self) -> Instant {
        if self.dirty.is_empty() {
            self.last_save + self.save_every
        } else {
            Instant::now()
        }
    }

    /// Snapshots every changed base triangle and waits until the writer has committed them (a
    /// clean stop, tests, benchmarks).
    pub fn save_now(&mut self, mesh: &mut SubdivisionMesh, cache: &ShadingCache) {
        let start = Instant::now();
        let records = self.snapshot(mesh, cache, None);
        self.note_pause(start.elapsed());
        self.writer.commit_and_wait(records);
        self.last_save = Instant::now();
    }

    /// The clean stop: a last save, then the writer finishes and the file is closed.
    pub fn close(mut self, mesh: &mut SubdivisionMesh, cache: &ShadingCache) {
        self.save_now(mesh, cache);
        self.writer.close();
        let (stats, pauses) = (self.writer.stats(), self.pauses);
        tracing::debug!(
            file = %self.label,
            commits = stats.commits,
            failed_commits = stats.failed_commits,
            mib_written = stats.bytes as f64 / (1 << 20) as f64,
            writer_ms = stats.busy.as_millis() as u64,
            snapshots = pauses.count,
            longest_pause_ms = pauses.longest.as_secs_f64() * 1e3,
            "cache file saved and closed"
        );
    }

    fn mark(&mut self, base: u32) {
        if let Some(flag) = self.is_dirty.get_mut(base as usize)
            && !*flag
        {
            *flag = true;
            self.dirty.push(base);
        }
    }

    fn note_owner(&mut self, vertices: &[VertexId], base: u32) {
        for &v in vertices {
            let v = v as usize;
            if v >= self.vertex_base.len() {
                self.vertex_base.resize(v + 1, u32::MAX);
            }
            self.vertex_base[v] = base;
        }
    }

    fn note_pause(&mut self, pause: Duration) {
        self.pauses.count += 1;
        self.pauses.longest = self.pauses.longest.max(pause);
        self.pauses.total += pause;
    }

    /// The records of changed base triangles, until `until` (None: all of them).
    fn snapshot(
        &mut self,
        mesh: &mut SubdivisionMesh,
        cache: &ShadingCache,
        until: Option<Instant>,
    ) -> Vec<(u32, Option<BaseRecord>)> {
        for base in mesh.take_changed_bases() {
            self.mark(base);
        }
        let mut records = Vec::new();
        let mut taken = 0;
        while taken < self.dirty.len() && until.is_none_or(|t| Instant::now() < t) {
            let base = self.dirty[taken];
            let (record, vertices) = BaseRecord::snapshot(mesh, cache, base);
            self.note_owner(&vertices, base);
            records.push((base, (!record.is_empty()).then_some(record)));
            taken += 1;
        }
        for base in self.dirty.drain(..taken) {
            self.is_dirty[base as usize] = false;
        }
        records
    }
}

/// Opens the store and checks every record against this mesh, before anything is restored.
fn open_parsed(
    path: &Path,
    key: &StoreKey,
    base_count: usize,
) -> Result<(redb::Database, Vec<Parsed>), Unusable> {
    let opened = store::open(path, key)?;
    let records = opened
        .records
        .into_iter()
        .map(|(base, record)| Parsed::new(base, record, base_count))
        .collect::<Result<Vec<_>, BadRecord>>()
        .map_err(|e| Unusable::Refused(e.to_string()))?;
    Ok((opened.db, records))
}

/// Moves a refused store to `PATH.rejected` with one warning that says why, and opens a fresh
/// one in its place; None (with that warning) when either fails.
fn set_aside(path: &Path, key: &StoreKey, reason: &str) -> Option<redb::Database> {
    let rejected = store::rejected_path(path);
    if let Err(e) = std::fs::rename(path, &rejected) {
        tracing::warn!(
            file = %path.display(),
            "cache file refused: {reason}; it could not be renamed to {} ({e}), so the SMA carries on without a cache file",
            rejected.display()
        );
        return None;
    }
    tracing::warn!(
        file = %path.display(),
        "cache file refused: {reason}; renamed to {}, the SMA starts with an empty cache",
        rejected.display()
    );
    match store::open(path, key) {
        Ok(opened) => Some(opened.db),
        Err(Unusable::Refused(e) | Unusable::Fault(e)) => {
            tracing::warn!(file = %path.display(), "a fresh cache file cannot be made: {e}; the SMA carries on without one");
            None
        }
    }
}
