//! The cache file's writer thread: encodes the records the schedule snapshot and commits them,
//! so the schedule's thread never waits for the disk (DESIGN.md §5: "saving is periodic and at
//! a clean stop, on another thread"). A commit that fails (a full disk) leaves the last good
//! one in the file; its records are kept and tried again with the next commit, with one warning
//! until a commit succeeds again. Each commit has a number, and the writer publishes the last
//! one in the file: a subtree leaves memory for the file only once a commit that holds its
//! record is there (`evict`).

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use redb::Database;

use super::record::BaseRecord;
use super::store;

/// Commits waiting for the writer; past them the schedule keeps its changes for a later save
/// rather than wait.
const COMMITS_WAITING: usize = 4;

/// What the writer has done so far.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WriterStats {
    pub commits: u64,
    /// Records written (replaced or removed).
    pub records: u64,
    /// Encoded bytes of the records written.
    pub bytes: u64,
    /// Time spent encoding and committing.
    pub busy: Duration,
    pub failed_commits: u64,
}

enum ToWriter {
    /// A commit and its number.
    Commit(u64, Vec<(u32, Option<BaseRecord>)>),
    /// Answered once every commit sent before it is done (or has failed).
    Flush(SyncSender<()>),
}

pub struct Writer {
    to_writer: Option<SyncSender<ToWriter>>,
    thread: Option<JoinHandle<()>>,
    stats: Arc<Mutex<WriterStats>>,
    /// The number of the last commit handed over.
    sent: u64,
    shared: Arc<Shared>,
}

/// What the writer thread publishes beside its stats.
#[derive(Default)]
struct Shared {
    /// The number of the last commit in the file: every record handed over with it or before
    /// it is there (a failed commit's records go in with the next one that succeeds).
    committed: AtomicU64,
    /// The last commit failed.
    failing: AtomicBool,
    /// Tests: commits fail as on a full disk.
    #[cfg(test)]
    fail: AtomicBool,
}

/// A commit the writer had no room for: the caller keeps its records' base triangles dirty.
pub struct Busy(pub Vec<(u32, Option<BaseRecord>)>);

impl Writer {
    pub fn spawn(db: Arc<Database>, label: String) -> std::io::Result<Writer> {
        let (to_writer, from_schedule) = sync_channel(COMMITS_WAITING);
        let stats = Arc::new(Mutex::new(WriterStats::default()));
        let shared = Arc::new(Shared::default());
        let thread = {
            let (stats, shared) = (stats.clone(), shared.clone());
            std::thread::Builder::new()
                .name("sma-cache-file".into())
                .spawn(move || write_loop(db, from_schedule, &stats, &shared, &label))?
        };
        Ok(Writer {
            to_writer: Some(to_writer),
            thread: Some(thread),
            stats,
            sent: 0,
            shared,
        })
    }

    /// The number of the last commit handed over: once [`Self::committed`] reaches it, every
    /// record handed over so far is in the file.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    /// The number of the last commit in the file.
    pub fn committed(&self) -> u64 {
        self.shared.committed.load(Ordering::Acquire)
    }

    /// Whether the last commit failed (the file keeps its last good one).
    pub fn failing(&self) -> bool {
        self.shared.failing.load(Ordering::Acquire)
    }

    /// Tests: makes commits fail, as on a full disk, or succeed again.
    #[cfg(test)]
    pub fn fail_commits(&self, fail: bool) {
        self.shared.fail.store(fail, Ordering::Release);
    }

    /// Hands a commit over without waiting; gives it back when the writer is behind.
    pub fn try_commit(&mut self, records: Vec<(u32, Option<BaseRecord>)>) -> Result<(), Busy> {
        let Some(to_writer) = &self.to_writer else {
            return Err(Busy(records));
        };
        match to_writer.try_send(ToWriter::Commit(self.sent + 1, records)) {
            Ok(()) => {
                self.sent += 1;
                Ok(())
            }
            Err(TrySendError::Full(ToWriter::Commit(_, r)))
            | Err(TrySendError::Disconnected(ToWriter::Commit(_, r))) => Err(Busy(r)),
            Err(_) => unreachable!("only commits are tried"),
        }
    }

    /// Hands a commit over, waiting for room, and waits until it is done.
    pub fn commit_and_wait(&mut self, records: Vec<(u32, Option<BaseRecord>)>) {
        let Some(to_writer) = &self.to_writer else {
            return;
        };
        let (done, wait) = sync_channel(1);
        if to_writer
            .send(ToWriter::Commit(self.sent + 1, records))
            .is_ok()
        {
            self.sent += 1;
            if to_writer.send(ToWriter::Flush(done)).is_ok() {
                let _ = wait.recv();
            }
        }
    }

    pub fn stats(&self) -> WriterStats {
        *self.stats.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Lets the writer finish what it was given, and waits for it.
    pub fn close(&mut self) {
        self.to_writer.take();
        if let Some(thread) = self.thread.take()
            && thread.join().is_err()
        {
            tracing::warn!(
                "the cache file's writer thread panicked; the file keeps its last commit"
            );
        }
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        self.close();
    }
}

fn write_loop(
    db: Arc<Database>,
    from_schedule: Receiver<ToWriter>,
    stats: &Mutex<WriterStats>,
    shared: &Shared,
    label: &str,
) {
    // Records not yet in the file, by base triangle: a newer snapshot of a base replaces an
    // older one that a failed commit left here.
    let mut waiting: BTreeMap<u32, Option<Vec<u8>>> = BTreeMap::new();
    let mut failing = false;
    for message in from_schedule {
        let (number, records) = match message {
            ToWriter::Commit(number, records) => (number, records),
            ToWriter::Flush(done) => {
                let _ = done.send(());
                continue;
            }
        };
        let start = Instant::now();
        for (base, record) in records {
            let bytes = record.map(|r| postcard::to_stdvec(&r).expect("a record encodes"));
            waiting.insert(base, bytes);
        }
        let batch: Vec<(u32, Option<Vec<u8>>)> =
            waiting.iter().map(|(b, r)| (*b, r.clone())).collect();
        let outcome = commit(&db, &batch, shared);
        let mut s = stats.lock().unwrap_or_else(|p| p.into_inner());
        s.busy += start.elapsed();
        match outcome {
            Ok(()) => {
                s.commits += 1;
                s.records += batch.len() as u64;
                s.bytes += batch
                    .iter()
                    .flat_map(|(_, r)| r)
                    .map(|r| r.len() as u64)
                    .sum::<u64>();
                waiting.clear();
                shared.committed.store(number, Ordering::Release);
                shared.failing.store(false, Ordering::Release);
                if failing {
                    tracing::info!(file = label, "the cache file is written again");
                    failing = false;
                }
            }
            Err(e) => {
                s.failed_commits += 1;
                shared.failing.store(true, Ordering::Release);
                if !failing {
                    tracing::warn!(
                        file = label,
                        error = %e,
                        "saving the cache file failed; it keeps its last good commit, and the SMA carries on and tries again at the next save"
                    );
                    failing = true;
                }
            }
        }
    }
}

/// One commit of `batch`; tests may make it fail, as on a full disk.
#[cfg_attr(not(test), allow(unused_variables))]
fn commit(db: &Database, batch: &[(u32, Option<Vec<u8>>)], shared: &Shared) -> Result<(), String> {
    #[cfg(test)]
    if shared.fail.load(Ordering::Acquire) {
        return Err("commits fail (a test)".into());
    }
    store::commit(db, batch).map_err(|e| e.to_string())
}
