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
//! - Loading is lazy: at start only the key record and the list of stored base triangles are
//!   read; a base triangle's record is read when the base triangle first becomes visible
//!   ([`CacheFile::load`]), so a large site does not load whole at start. Its splits are asked
//!   of the mesh (`restore`), whose closure keeps it conforming across base triangles (a red
//!   split greens a neighbour, loaded or not), and the steps that made come back for the
//!   schedule to show like refinement's. A base triangle whose record is not loaded yet is never
//!   written: the file keeps its record as it was.
//! - Saving is periodic and at a clean stop: the schedule's thread only snapshots the changed
//!   base triangles, at most [`SNAPSHOT_SLICE`] of them per turn's worth of time, and the writer
//!   thread (`writer`) encodes and commits them. Base triangles changed between saves wait for
//!   the period (a save per turn would cost the schedule a pause each turn).
//! - Under the memory budget, the subtrees of base triangles no view sees go to the file rather
//!   than being lost (`evict`): their records are made sure to be in a commit that succeeded,
//!   then they are collapsed, their samples freed, and they load again as records do.
//! - A store that is not this SMA's (truncated, corrupt, another scene, version or settings) is
//!   refused with one warning naming why, renamed to `PATH.rejected`, and the SMA starts empty. A
//!   store it cannot use now (locked by another SMA, an unwritable directory) gets one warning,
//!   and the SMA carries on without it (`store::Unusable`). Neither ends the SMA.

mod evict;
mod key;
mod record;
mod restore;
mod store;
mod writer;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use redb::Database;

use crate::cache::ShadingCache;
use crate::mesh::{RefinementStep, SubdivisionMesh, VertexId};
pub use evict::Dropped;
use evict::Leaving;
pub use key::{FORMAT_VERSION, MeshKey, SampleMeaning, StoreKey};
use record::{BaseRecord, Numbering};
pub use restore::Restored;
use restore::{BadRecord, Parsed};
use store::{Opened, Unusable};
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
    /// Shared with the writer: records are read beside its commits.
    db: Arc<Database>,
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
    /// A periodic snapshot ran out of its slice with base triangles left: the save goes on at
    /// the next turn. Base triangles marked between saves (new samples) wait for the period.
    sliced: bool,
    pauses: Pauses,
    restored: Restored,
    /// Per base triangle: the file holds a record of it not loaded yet.
    unloaded: Vec<bool>,
    /// The snapshots' scratch.
    numbering: Numbering,
    unloaded_count: usize,
    /// One warning for records that cannot be read, not one per load.
    warned_unreadable: bool,
    /// Base triangles on their way to the file under the memory budget (`evict`).
    leaving: Option<Leaving>,
}

impl CacheFile {
    /// Opens the cache file for `mesh` (which must be fresh) and starts its writer; loads no
    /// record yet ([`Self::load`]). None, after one warning, when the file cannot be used: the
    /// SMA carries on without it.
    pub fn open(
        path: &Path,
        save_every: Duration,
        key: &StoreKey,
        mesh: &SubdivisionMesh,
    ) -> Option<CacheFile> {
        let label = path.display().to_string();
        let start = Instant::now();
        let opened = match open_indexed(path, key, mesh.base_count()) {
            Ok(opened) => opened,
            Err(Unusable::Refused(reason)) => Opened {
                db: set_aside(path, key, &reason)?,
                stored: Vec::new(),
            },
            Err(Unusable::Fault(reason)) => {
                tracing::warn!(file = %label, "cache file not used: {reason}; the SMA carries on without it");
                return None;
            }
        };
        let db = Arc::new(opened.db);
        let writer = match Writer::spawn(db.clone(), label.clone()) {
            Ok(writer) => writer,
            Err(e) => {
                tracing::warn!(file = %label, error = %e, "cache file not used: no writer thread");
                return None;
            }
        };
        let mut unloaded = vec![false; mesh.base_count()];
        for &base in &opened.stored {
            unloaded[base as usize] = true;
        }
        let mut file = CacheFile {
            db,
            writer,
            label,
            dirty: Vec::new(),
            is_dirty: vec![false; mesh.base_count()],
            vertex_base: Vec::new(),
            save_every,
            last_save: Instant::now(),
            sliced: false,
            pauses: Pauses::default(),
            restored: Restored::default(),
            unloaded,
            numbering: Numbering::default(),
            unloaded_count: opened.stored.len(),
            warned_unreadable: false,
            leaving: None,
        };
        // A base triangle's corners are owned by one whose record is loaded where there is one:
        // those with records not loaded yet first, so the others' ownership wins.
        let (waiting, loaded): (Vec<u32>, Vec<u32>) =
            (0..mesh.base_count() as u32).partition(|&b| file.unloaded[b as usize]);
        for base in waiting.into_iter().chain(loaded) {
            file.note_owner(&mesh.node(base).vertices, base);
        }
        // Only a file that holds something is news to a person; an empty one is not.
        if file.unloaded_count == 0 {
            tracing::debug!(file = %file.label, "cache file empty: the SMA starts empty");
        } else {
            tracing::info!(
                file = %file.label,
                bases = file.unloaded_count,
                ms = start.elapsed().as_millis() as u64,
                "cache file opened; its base triangles load as they become visible"
            );
        }
        file.restored.open = start.elapsed();
        file.restored.total = file.restored.open;
        Some(file)
    }

    /// Loads the records of those of `bases` (base triangles that became visible) whose
    /// records are not loaded yet: their splits into `mesh`, their samples into `cache` where it
    /// has none. Returns the steps that take the viewers from the leaves before to those after.
    /// A record that cannot be read gets one warning and is left out.
    pub fn load(
        &mut self,
        bases: impl IntoIterator<Item = u32>,
        mesh: &mut SubdivisionMesh,
        cache: &mut ShadingCache,
    ) -> Vec<RefinementStep> {
        if self.unloaded_count == 0 {
            return Vec::new();
        }
        let mut wanted = Vec::new();
        for base in bases {
            if let Some(flag) = self.unloaded.get_mut(base as usize)
                && *flag
            {
                *flag = false;
                wanted.push(base);
            }
        }
        if wanted.is_empty() {
            return Vec::new();
        }
        self.unloaded_count -= wanted.len();
        let start = Instant::now();
        let records = match store::read_records(&self.db, &wanted) {
            Ok(records) => records,
            Err(e) => {
                self.warn_unreadable(&e);
                return Vec::new();
            }
        };
        let base_count = mesh.base_count();
        let mut parsed = Vec::with_capacity(records.len());
        for (base, record) in records {
            let checked =
                record.and_then(|r| Parsed::new(base, r, base_count).map_err(|e| e.to_string()));
            match checked {
                Ok(p) => parsed.push(p),
                Err(e) => self.warn_unreadable(&e),
            }
        }
        let read = start.elapsed();
        // What changed before the load is this run's work, to be saved; what the load changes
        // is in the file already.
        for base in mesh.take_changed_bases() {
            self.mark(base);
        }
        let replayed = restore::restore(&parsed, mesh, cache);
        mesh.take_changed_bases();
        for (vertex, base) in replayed.owners {
            self.note_owner(&[vertex], base);
        }
        let load = Restored {
            read,
            total: start.elapsed(),
            ..replayed.restored
        };
        self.restored.add(load);
        tracing::debug!(
            file = %self.label,
            bases = load.bases,
            samples = load.samples,
            unmatched_vertices = load.unmatched_vertices,
            ms = load.total.as_secs_f64() * 1e3,
            "cache file records loaded"
        );
        replayed.steps
    }

    /// Whether the file holds records not loaded yet: while it does, each pass's visible base
    /// triangles are worth looking up.
    pub fn has_unloaded(&self) -> bool {
        self.unloaded_count > 0
    }

    /// Loads every record not loaded yet (a camera that sees the whole site; tests, benchmarks).
    pub fn load_all(
        &mut self,
        mesh: &mut SubdivisionMesh,
        cache: &mut ShadingCache,
    ) -> Vec<RefinementStep> {
        self.load(0..mesh.base_count() as u32, mesh, cache)
    }

    fn warn_unreadable(&mut self, why: &str) {
        if !std::mem::replace(&mut self.warned_unreadable, true) {
            tracing::warn!(file = %self.label, "cache file records not used: {why}; the SMA traces those base triangles afresh");
        }
    }

    /// What the file brought back so far: the open, and every load since.
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
        if !self.sliced && self.last_save.elapsed() < self.save_every {
            return;
        }
        let start = Instant::now();
        let records = self.snapshot(mesh, cache, Some(start + SNAPSHOT_SLICE));
        self.sliced = !self.dirty.is_empty();
        self.hand_over(records);
        self.note_pause(start.elapsed());
        if !self.sliced {
            self.last_save = Instant::now();
        }
    }

    /// When [`Self::save_if_due`] next has work: now while a sliced snapshot has base triangles
    /// left, else a period after the last save.
    pub fn save_due_at(&self) -> Instant {
        if self.leaving.is_some() && self.takes_subtrees() {
            // Subtrees wait for the writer's commit to leave memory (`evict`): soon, without
            // spinning on the cores the writer needs.
            Instant::now() + evict::POLL
        } else if self.sliced {
            Instant::now()
        } else {
            self.last_save + self.save_every
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
        self.sliced = false;
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

    /// Marks `base`'s record out of date, unless its stored record is not loaded yet: the file
    /// keeps that one as it is.
    fn mark(&mut self, base: u32) {
        if self.unloaded.get(base as usize) == Some(&true) {
            return;
        }
        if let Some(flag) = self.is_dirty.get_mut(base as usize)
            && !*flag
        {
            *flag = true;
            self.dirty.push(base);
        }
    }

    /// Hands `records` to the writer without waiting.
    fn hand_over(&mut self, records: Vec<(u32, Option<BaseRecord>)>) {
        if !records.is_empty()
            && let Err(writer::Busy(back)) = self.writer.try_commit(records)
        {
            // The writer is behind (a slow disk): these base triangles go in a later commit.
            back.iter().for_each(|(base, _)| self.mark(*base));
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
            records.push(self.snapshot_base(mesh, cache, self.dirty[taken]));
            taken += 1;
        }
        self.dirty.drain(..taken);
        records
    }

    /// The record of `base` now, which is no longer out of date (the caller takes it out of
    /// `dirty`); None where the record is gone.
    fn snapshot_base(
        &mut self,
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
        base: u32,
    ) -> (u32, Option<BaseRecord>) {
        let (record, vertices) = BaseRecord::snapshot(mesh, cache, base, &mut self.numbering);
        self.note_owner(&vertices, base);
        self.is_dirty[base as usize] = false;
        (base, (!record.is_empty()).then_some(record))
    }
}

/// Every base triangle's record with something in it, encoded as the store holds it: what the
/// benchmark's monolithic snapshot writes to one file instead, to compare the two layouts.
#[cfg(feature = "testing")]
pub fn encoded_records(mesh: &SubdivisionMesh, cache: &ShadingCache) -> Vec<(u32, Vec<u8>)> {
    let mut numbering = Numbering::default();
    (0..mesh.base_count() as u32)
        .map(|base| {
            (
                base,
                BaseRecord::snapshot(mesh, cache, base, &mut numbering).0,
            )
        })
        .filter(|(_, record)| !record.is_empty())
        .map(|(base, record)| {
            (
                base,
                postcard::to_stdvec(&record).expect("a record encodes"),
            )
        })
        .collect()
}

/// Decodes records [`encoded_records`] made and restores them into the fresh `mesh` and
/// `cache`: the monolithic snapshot's load.
#[cfg(feature = "testing")]
pub fn restore_encoded(
    records: &[(u32, Vec<u8>)],
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> Result<Restored, String> {
    let start = Instant::now();
    let parsed = records
        .iter()
        .map(|(base, bytes)| {
            let record = postcard::from_bytes(bytes).map_err(|e| e.to_string())?;
            Parsed::new(*base, record, mesh.base_count()).map_err(|e| e.to_string())
        })
        .collect::<Result<Vec<_>, String>>()?;
    let read = start.elapsed();
    let restored = restore::restore(&parsed, mesh, cache).restored;
    Ok(Restored {
        read,
        total: start.elapsed(),
        ..restored
    })
}

/// Opens the store and checks that its records are of this mesh's base triangles.
fn open_indexed(path: &Path, key: &StoreKey, base_count: usize) -> Result<Opened, Unusable> {
    let opened = store::open(path, key)?;
    match opened.stored.iter().find(|&&b| b as usize >= base_count) {
        Some(&base) => Err(Unusable::Refused(BadRecord::NoSuchBase(base).to_string())),
        None => Ok(opened),
    }
}

/// Moves a refused store to `PATH.rejected` with one warning that says why, and opens a fresh
/// one in its place; None (with that warning) when either fails.
fn set_aside(path: &Path, key: &StoreKey, reason: &str) -> Option<Database> {
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
