//! Snapshots on disk: `snapshot_NNN.png` (tone-mapped sRGB), `snapshot_NNN.exr` (linear radiance)
//! and one line per snapshot in `snapshots.csv`, the raw material of the convergence measurements
//! (DESIGN.md §10).
//!
//! Encoding a 1024×768 snapshot takes a few hundred milliseconds of CPU, a quarter of a core at one
//! snapshot a second: taken from the system being measured, that would slow the very convergence
//! the snapshots record. So the viewer only renders and reads back a snapshot at its instant, and
//! hands it to a writer thread that runs at the lowest scheduling priority (`SCHED_IDLE` on Linux):
//! it encodes when the renderer, the SMA and the viewer leave a core idle, and at the latest once
//! the run ends. The record's time is the snapshot's, not the file's.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use anyhow::Context;

use crate::offscreen::Snapshot;

/// Snapshots waiting for the writer, at most (about 13 MB each at 1024×768: a 60-s run at one a
/// second fits). Beyond it the viewer waits for the writer rather than hold more.
const MAX_WAITING_SNAPSHOTS: usize = 64;

pub const CSV_NAME: &str = "snapshots.csv";
/// `inserted`/`removed` are summed over the epochs since the previous snapshot (Δins, Δrem);
/// `camera_seq`, `shown`, `samples`, `paths` and `outstanding` are the latest epoch's;
/// `renderer_busy` and `converged` the latest `Stats`' (one interval of the SMA's, about a second).
pub const CSV_HEADER: &str = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,\
                              outstanding,renderer_busy,converged,png,exr";

/// One CSV row.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotRecord {
    pub index: u32,
    pub time_s: f64,
    pub camera_seq: u64,
    pub shown: u64,
    pub inserted: u64,
    pub removed: u64,
    pub samples: u64,
    pub paths: u64,
    pub outstanding: u64,
    pub renderer_busy: f32,
    pub converged: bool,
}

/// Writes snapshots on a background thread of the lowest priority (see the module documentation).
pub struct SnapshotWriter {
    waiting: Option<SyncSender<(SnapshotRecord, Snapshot)>>,
    thread: Option<JoinHandle<anyhow::Result<()>>>,
}

impl SnapshotWriter {
    /// Creates `dir` and a fresh CSV with its header, and starts the writer thread.
    pub fn create(dir: &Path) -> anyhow::Result<SnapshotWriter> {
        let files = SnapshotFiles::create(dir)?;
        let (waiting, queue) = sync_channel(MAX_WAITING_SNAPSHOTS);
        let thread = std::thread::Builder::new()
            .name("snapshot-writer".into())
            .spawn(move || write_all(files, queue))
            .context("starting the snapshot writer")?;
        Ok(SnapshotWriter {
            waiting: Some(waiting),
            thread: Some(thread),
        })
    }

    /// Queues one snapshot; fails with the writer's error if it stopped on one.
    pub fn write(&mut self, record: SnapshotRecord, snapshot: Snapshot) -> anyhow::Result<()> {
        let sent = self
            .waiting
            .as_ref()
            .is_some_and(|w| w.send((record, snapshot)).is_ok());
        if sent {
            Ok(())
        } else {
            self.finish()
                .and(Err(anyhow::anyhow!("the snapshot writer stopped")))
        }
    }

    /// Waits until every queued snapshot is on disk.
    pub fn finish(&mut self) -> anyhow::Result<()> {
        self.waiting = None;
        match self.thread.take().map(JoinHandle::join) {
            None => Ok(()),
            Some(Ok(written)) => written,
            Some(Err(_)) => anyhow::bail!("the snapshot writer panicked"),
        }
    }
}

impl Drop for SnapshotWriter {
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            tracing::error!("snapshots: {e:#}");
        }
    }
}

fn write_all(
    mut files: SnapshotFiles,
    queue: Receiver<(SnapshotRecord, Snapshot)>,
) -> anyhow::Result<()> {
    lowest_priority();
    for (record, snapshot) in queue {
        files.write(&record, &snapshot)?;
    }
    Ok(())
}

/// Puts the calling thread in Linux's `SCHED_IDLE` class: it runs only on a core nothing else
/// wants. Elsewhere the thread keeps its priority.
fn lowest_priority() {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: 0 };
        // SAFETY: `param` is a valid `sched_param` for the call's duration; pid 0 is the calling
        // thread, and SCHED_IDLE needs no privilege.
        let failed = unsafe { libc::sched_setscheduler(0, libc::SCHED_IDLE, &param) } != 0;
        if failed {
            tracing::debug!(
                error = %std::io::Error::last_os_error(),
                "snapshot writer keeps its priority"
            );
        }
    }
}

/// The files themselves: the writer thread owns them, and writes one snapshot at a time.
struct SnapshotFiles {
    dir: PathBuf,
    csv: std::fs::File,
}

impl SnapshotFiles {
    fn create(dir: &Path) -> anyhow::Result<SnapshotFiles> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join(CSV_NAME);
        let mut csv =
            std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        writeln!(csv, "{CSV_HEADER}")?;
        Ok(SnapshotFiles {
            dir: dir.to_path_buf(),
            csv,
        })
    }

    fn write(&mut self, record: &SnapshotRecord, snapshot: &Snapshot) -> anyhow::Result<()> {
        let stem = format!("snapshot_{:03}", record.index);
        let (png, exr) = (format!("{stem}.png"), format!("{stem}.exr"));
        write_png(&self.dir.join(&png), snapshot)?;
        write_exr(&self.dir.join(&exr), snapshot)?;
        let r = record;
        writeln!(
            self.csv,
            "{},{:.3},{},{},{},{},{},{},{},{:.3},{},{png},{exr}",
            r.index,
            r.time_s,
            r.camera_seq,
            r.shown,
            r.inserted,
            r.removed,
            r.samples,
            r.paths,
            r.outstanding,
            r.renderer_busy,
            u8::from(r.converged)
        )?;
        self.csv.flush()?;
        Ok(())
    }
}

pub fn write_png(path: &Path, snapshot: &Snapshot) -> anyhow::Result<()> {
    let rgb = image::DynamicImage::ImageRgba8(snapshot.display.clone()).into_rgb8();
    rgb.save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// Linear radiance with the coverage as alpha (1: sees geometry, 0: sky), as the ground truth
/// carries it.
pub fn write_exr(path: &Path, snapshot: &Snapshot) -> anyhow::Result<()> {
    let width = snapshot.width as usize;
    exr::prelude::write_rgba_file(path, width, snapshot.height as usize, |x, y| {
        let i = y * width + x;
        let [r, g, b] = snapshot.linear[i];
        (r, g, b, f32::from(u8::from(snapshot.covered[i])))
    })
    .with_context(|| format!("writing {}", path.display()))
}
