//! Snapshots on disk: `snapshot_NNN.png` (tone-mapped sRGB), `snapshot_NNN.exr` (linear radiance)
//! and one line per snapshot in `snapshots.csv`, the raw material of the convergence measurements
//! (DESIGN.md §10).
//!
//! Drawing a 1024×768 snapshot on a software rasterizer and encoding it take a few hundred
//! milliseconds of CPU, a quarter of a core at one snapshot a second: taken from the system being
//! measured, that would slow the very convergence the snapshots record. So the viewer only copies
//! what it would draw at the instant (`snapshot_painter::Frame`) and hands it to a writer thread
//! that runs at the lowest scheduling priority (`SCHED_IDLE` on Linux) and draws it with a device
//! of its own. Even there drawing took from the run (six interleaved 4-s runs each on bracara VT:
//! a median 1.90 M paths traced in the first second with the drawing at idle priority, 2.02 M
//! without; on Sponza S3, mean FLIP 0.1 read at 3.7 s against 3.25 s). So the writer holds the
//! frames, when asked to (`ViewerConfig::hold_snapshots`, as the benchmarks do), and draws only
//! once they hold half the memory they may (`held_before_drawing`): in a benchmark's first seconds, when the error
//! falls fastest, nothing is drawn at all. Once the run ends, the viewer's own thread draws and
//! writes what is left, at its normal priority. The record's time is the snapshot's, not the
//! file's.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, Sender, channel, sync_channel};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

use anyhow::Context;
use protocol::viewer_link::Stats;

use crate::offscreen::Snapshot;
use crate::snapshot_painter::{Canvas, Frame, SnapshotPainter};

/// Memory the frames waiting for the writer may hold, at most: a quarter of the machine's
/// memory, between 1 and 16 GiB (a frame is 72 bytes per shown triangle: 14 MB at 200 000; a
/// 60-s benchmark run at 1024×768 queues a few hundred MB, a walk of both passes 0.6–0.8 GB).
/// Beyond it the viewer waits for the writer rather than hold more. A fixed 1 GiB, drawn from
/// at half, had the idle writer drawing in a walk's last minute, and the viewer's loop stalled
/// for 5.5 s there (Sponza's walk, its last stop): a thread of the lowest priority that holds a
/// lock the viewer needs runs only when nothing else wants a core, and the renderer wanted both.
fn max_waiting_bytes() -> usize {
    static MAX: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *MAX.get_or_init(|| {
        let total = std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|info| mem_total_bytes(&info))
            .unwrap_or(0);
        (total / 4).clamp(1 << 30, 16 << 30)
    })
}

/// `MemTotal` of a `/proc/meminfo` text, in bytes.
fn mem_total_bytes(meminfo: &str) -> Option<usize> {
    let line = meminfo.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// A writer that holds its frames draws only while they hold more than this: half the budget,
/// so the viewer never waits for room while the writer catches up.
fn held_before_drawing() -> usize {
    max_waiting_bytes() / 2
}

pub const CSV_NAME: &str = "snapshots.csv";
/// `inserted`/`removed` are summed over the epochs since the previous snapshot (Δins, Δrem);
/// `camera_seq`, `shown`, `samples`, `paths` and `outstanding` are the latest epoch's;
/// the columns after `outstanding` are the latest `Stats`' (one interval of the SMA's, about a
/// second): the renderers' busy share, convergence, the mesh's leaves and the samples cached, the
/// SMA's memory by part (the mesh in all, the cache, then the mesh's nodes, vertices and edge
/// tables, the viewers' state, all accounted, the budget, the SMA's resident memory, an empty
/// cell where the system does not say, and whether the budget stopped refinement) and the
/// mesh's shape (an empty cell before any split).
pub const CSV_HEADER: &str = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,\
                              outstanding,renderer_busy,converged,leaves,cached_samples,\
                              mesh_bytes,cache_bytes,nodes_bytes,vertices_bytes,\
                              edge_tables_bytes,viewers_bytes,accounted_bytes,budget_bytes,\
                              rss_bytes,memory_bound,smallest_split_angle_deg,\
                              smallest_split_angle_ratio,neighbour_bound_hits,uniform_merges,\
                              png,exr";

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
    /// The SMA's latest statistics.
    pub stats: Stats,
}

/// Draws and writes snapshots on a background thread of the lowest priority (see the module
/// documentation); what it has not written when the run ends, the caller of `finish` writes.
pub struct SnapshotWriter {
    waiting: Option<Sender<(SnapshotRecord, Frame)>>,
    shared: Arc<Shared>,
    canvas: Canvas,
    thread: Option<JoinHandle<anyhow::Result<Leftover>>>,
}

/// What the idle thread hands back when told to finish: the files, and the frames it did not
/// get to.
struct Leftover {
    files: SnapshotFiles,
    queue: Receiver<(SnapshotRecord, Frame)>,
}

impl SnapshotWriter {
    /// Creates `dir` and a fresh CSV with its header, and starts the writer thread, which opens
    /// its device before this returns (a missing adapter is this call's error); with `hold`, the
    /// thread holds the frames (see the module documentation). Returns the writer and the
    /// adapter it draws with.
    pub fn create(
        dir: &Path,
        canvas: Canvas,
        hold: bool,
    ) -> anyhow::Result<(SnapshotWriter, String)> {
        let held_before_drawing = if hold { held_before_drawing() } else { 0 };
        let files = SnapshotFiles::create(dir)?;
        // Bounded in bytes, not in count: `Shared::reserve` admits a frame only while the frames
        // queued hold at most `max_waiting_bytes`, each counting at least its own size. A count
        // bound could not stand in for it: frames range from a few hundred bytes to tens of
        // megabytes, a `sync_channel` of the count the budget allows would allocate its slots up
        // front, and one that filled first would leave a holding writer waiting for bytes that
        // never come while the viewer waited for a slot.
        let (waiting, queue) = channel();
        let (opened, adapter) = sync_channel(1);
        let shared = Arc::new(Shared::default());
        let thread_shared = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("snapshot-writer".into())
            .spawn(move || {
                // Stopped on every exit, so a viewer waiting for room never waits on a writer
                // that has gone.
                let _stopped = StopOnDrop(&thread_shared);
                lowest_priority();
                let painter = SnapshotPainter::open(canvas);
                let description = painter.as_ref().map(|p| p.describe());
                let _ = opened.send(description.map_err(|e| format!("{e:#}")));
                write_while_running(files, painter?, queue, &thread_shared, held_before_drawing)
            })
            .context("starting the snapshot writer")?;
        let mut writer = SnapshotWriter {
            waiting: Some(waiting),
            shared,
            canvas,
            thread: Some(thread),
        };
        match adapter.recv() {
            Ok(Ok(adapter)) => Ok((writer, adapter)),
            Ok(Err(e)) => {
                let _ = writer.finish();
                Err(anyhow::anyhow!(e))
            }
            Err(_) => Err(writer
                .finish()
                .err()
                .unwrap_or_else(|| anyhow::anyhow!("the snapshot writer stopped"))),
        }
    }

    /// Queues one snapshot, waiting while the frames already queued hold too much memory; fails
    /// with the writer's error if it stopped on one.
    pub fn write(&mut self, record: SnapshotRecord, frame: Frame) -> anyhow::Result<()> {
        let bytes = frame.bytes();
        let sent = self.shared.reserve(bytes)
            && self
                .waiting
                .as_ref()
                .is_some_and(|w| w.send((record, frame)).is_ok());
        if sent {
            Ok(())
        } else {
            self.finish()
                .and(Err(anyhow::anyhow!("the snapshot writer stopped")))
        }
    }

    /// Writes every queued snapshot and returns once they are on disk. The run is over, so
    /// nothing is measured any more: the idle thread stops after the frame in hand, and the
    /// caller draws the rest at its own priority, on a device of its own. Left to the idle
    /// thread, they would wait for whatever else keeps the machine busy (a ground truth
    /// rendering beside the benchmark, other tests).
    pub fn finish(&mut self) -> anyhow::Result<()> {
        self.shared.finish();
        self.waiting = None;
        let leftover = match self.thread.take().map(JoinHandle::join) {
            None => return Ok(()),
            Some(Ok(leftover)) => leftover?,
            Some(Err(_)) => anyhow::bail!("the snapshot writer panicked"),
        };
        let Leftover { mut files, queue } = leftover;
        let rest: Vec<_> = queue.try_iter().collect();
        if rest.is_empty() {
            return Ok(());
        }
        tracing::debug!(snapshots = rest.len(), "writing the snapshots left");
        let mut painter = SnapshotPainter::open(self.canvas)?;
        for (record, frame) in rest {
            files.write(&record, &painter.paint(&frame)?)?;
        }
        Ok(())
    }
}

impl Drop for SnapshotWriter {
    fn drop(&mut self) {
        if let Err(e) = self.finish() {
            tracing::error!("snapshots: {e:#}");
        }
    }
}

/// What the viewer and the writer thread share: bytes of the frames queued and not yet
/// written, whether the writer has stopped, and whether it is asked to finish.
#[derive(Default)]
struct Shared {
    state: Mutex<SharedState>,
    changed: Condvar,
}

#[derive(Default)]
struct SharedState {
    held: usize,
    stopped: bool,
    finishing: bool,
}

impl Shared {
    fn lock(&self) -> std::sync::MutexGuard<'_, SharedState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Waits until `bytes` more fit (a frame always fits into an empty queue); false once the
    /// writer has stopped.
    fn reserve(&self, bytes: usize) -> bool {
        let mut state = self
            .changed
            .wait_while(self.lock(), |s| {
                !s.stopped && s.held > 0 && s.held + bytes > max_waiting_bytes()
            })
            .unwrap_or_else(|e| e.into_inner());
        state.held += bytes;
        self.changed.notify_all();
        !state.stopped
    }

    /// Waits until the frames waiting hold more than `held_before_drawing` bytes (true: draw
    /// one) or the run is over (false).
    fn wait_to_draw(&self, held_before_drawing: usize) -> bool {
        let state = self
            .changed
            .wait_while(self.lock(), |s| {
                !s.finishing && !s.stopped && s.held <= held_before_drawing
            })
            .unwrap_or_else(|e| e.into_inner());
        !state.finishing && !state.stopped
    }

    fn release(&self, bytes: usize) {
        let mut state = self.lock();
        state.held = state.held.saturating_sub(bytes);
        self.changed.notify_all();
    }

    fn stop(&self) {
        self.lock().stopped = true;
        self.changed.notify_all();
    }

    fn finish(&self) {
        self.lock().finishing = true;
        self.changed.notify_all();
    }
}

struct StopOnDrop<'a>(&'a Shared);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.stop();
    }
}

/// The idle thread's work: the oldest frame whenever the frames waiting hold more than
/// `held_before_drawing` bytes, until the queue closes or the run is over.
fn write_while_running(
    mut files: SnapshotFiles,
    mut painter: SnapshotPainter,
    queue: Receiver<(SnapshotRecord, Frame)>,
    shared: &Shared,
    held_before_drawing: usize,
) -> anyhow::Result<Leftover> {
    while shared.wait_to_draw(held_before_drawing) {
        let Ok((record, frame)) = queue.recv() else {
            break;
        };
        let snapshot = painter.paint(&frame)?;
        shared.release(frame.bytes());
        drop(frame);
        files.write(&record, &snapshot)?;
    }
    Ok(Leftover { files, queue })
}

/// Puts the calling thread in Linux's `SCHED_IDLE` class: it runs only on a core nothing else
/// wants, and so do the threads it starts (a software rasterizer's workers among them).
/// Elsewhere the thread keeps its priority.
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
        let (r, s) = (record, &record.stats);
        let optional = |x: Option<f32>| x.map_or(String::new(), |x| format!("{x:.4}"));
        writeln!(
            self.csv,
            "{},{:.3},{},{},{},{},{},{},{},{:.3},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{png},{exr}",
            r.index,
            r.time_s,
            r.camera_seq,
            r.shown,
            r.inserted,
            r.removed,
            r.samples,
            r.paths,
            r.outstanding,
            s.renderer_busy,
            u8::from(s.converged),
            s.leaves,
            s.cached_samples,
            s.memory.mesh_bytes(),
            s.memory.cache_bytes,
            s.memory.nodes_bytes,
            s.memory.vertices_bytes,
            s.memory.edge_tables_bytes,
            s.memory.viewers_bytes,
            s.memory.accounted_bytes(),
            s.memory.budget_bytes,
            s.memory.rss_bytes.map_or(String::new(), |b| b.to_string()),
            u8::from(s.memory.memory_bound),
            optional(s.mesh.smallest_split_angle_deg),
            optional(s.mesh.smallest_split_angle_ratio),
            s.mesh.neighbour_bound_hits,
            s.mesh.uniform_merges,
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

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::Duration;

    use super::*;

    fn record(index: u32) -> SnapshotRecord {
        SnapshotRecord {
            index,
            time_s: f64::from(index),
            camera_seq: 1,
            shown: 0,
            inserted: 0,
            removed: 0,
            samples: u64::from(index),
            paths: 0,
            outstanding: 0,
            stats: Stats::default(),
        }
    }

    /// However far the idle thread got, `finish` leaves every queued snapshot on disk, in order.
    #[test]
    fn finish_writes_every_queued_snapshot_in_order() {
        finish_writes_every_queued_snapshot("finish_writes_every_queued_snapshot_in_order", false);
    }

    /// The same when the writer held every frame until the run was over.
    #[test]
    fn finish_writes_every_held_snapshot_in_order() {
        finish_writes_every_queued_snapshot("finish_writes_every_held_snapshot_in_order", true);
    }

    fn finish_writes_every_queued_snapshot(test: &str, hold: bool) {
        let Some(_) = crate::gpu::headless_or_skip(test).unwrap() else {
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let canvas = Canvas {
            width: 32,
            height: 24,
            overlay: false,
        };
        let (mut writer, _) = SnapshotWriter::create(dir.path(), canvas, hold).unwrap();
        let camera = protocol::viewer_link::Camera {
            seq: 1,
            eye: [0.0, 0.0, 5.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
            width: 32,
            height: 24,
        };
        let table = crate::table::TriangleTable::new();
        for index in 0..6 {
            let frame = Frame::capture(
                (&table, &Default::default(), &Default::default()),
                &camera,
                Default::default(),
                None,
            );
            writer.write(record(index), frame).unwrap();
        }
        writer.finish().unwrap();
        let csv = std::fs::read_to_string(dir.path().join(CSV_NAME)).unwrap();
        let indices: Vec<&str> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap())
            .collect();
        assert_eq!(indices, ["0", "1", "2", "3", "4", "5"], "{csv}");
        for index in 0..6 {
            for ext in ["png", "exr"] {
                assert!(
                    dir.path()
                        .join(format!("snapshot_{index:03}.{ext}"))
                        .is_file()
                );
            }
        }
    }

    #[test]
    fn the_budget_holds_a_frame_back_until_room_is_released() {
        let budget = Arc::new(Shared::default());
        assert!(budget.reserve(max_waiting_bytes() - 10));
        let admitted = Arc::new(AtomicBool::new(false));
        let waiter = {
            let (budget, admitted) = (Arc::clone(&budget), Arc::clone(&admitted));
            std::thread::spawn(move || {
                let open = budget.reserve(100);
                admitted.store(true, Ordering::SeqCst);
                open
            })
        };
        std::thread::sleep(Duration::from_millis(100));
        assert!(!admitted.load(Ordering::SeqCst), "100 bytes do not fit yet");
        budget.release(max_waiting_bytes() - 10);
        assert!(waiter.join().unwrap(), "room was released");
    }

    #[test]
    fn the_writer_draws_only_past_the_held_bytes_and_stops_when_the_run_is_over() {
        let shared = Arc::new(Shared::default());
        let waiter = |shared: &Arc<Shared>| {
            let shared = Arc::clone(shared);
            std::thread::spawn(move || shared.wait_to_draw(1000))
        };
        let first = waiter(&shared);
        assert!(shared.reserve(1000));
        std::thread::sleep(Duration::from_millis(100));
        assert!(
            !first.is_finished(),
            "1000 bytes held: not yet more than 1000"
        );
        assert!(shared.reserve(1));
        assert!(first.join().unwrap(), "past the held bytes: draw");
        shared.release(1001);
        let second = waiter(&shared);
        std::thread::sleep(Duration::from_millis(50));
        shared.finish();
        assert!(
            !second.join().unwrap(),
            "the run is over: the caller draws the rest"
        );
    }

    #[test]
    fn the_budget_is_a_quarter_of_the_machines_memory_within_bounds() {
        let info = "MemTotal:       24576000 kB\nMemFree:  100 kB\n";
        assert_eq!(mem_total_bytes(info), Some(24_576_000 * 1024));
        assert_eq!(mem_total_bytes("MemFree: 1 kB\n"), None);
        let max = max_waiting_bytes();
        assert!((1 << 30..=16 << 30).contains(&max), "{max}");
    }

    #[test]
    fn a_frame_larger_than_the_budget_fits_an_empty_queue() {
        let budget = Shared::default();
        assert!(budget.reserve(2 * max_waiting_bytes()));
    }

    #[test]
    fn a_stopped_writer_releases_whoever_waits_for_room() {
        let budget = Arc::new(Shared::default());
        assert!(budget.reserve(max_waiting_bytes()));
        let waiter = {
            let budget = Arc::clone(&budget);
            std::thread::spawn(move || budget.reserve(1))
        };
        std::thread::sleep(Duration::from_millis(50));
        drop(StopOnDrop(&budget));
        assert!(!waiter.join().unwrap(), "the writer has stopped");
    }
}
