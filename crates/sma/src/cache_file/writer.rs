//! The cache file's writer thread: encodes the records the schedule snapshot and commits them,
//! so the schedule's thread never waits for the disk (DESIGN.md §5: "saving is periodic and at
//! a clean stop, on another thread"). A commit that fails (a full disk) leaves the last good
//! one in the file; its records are kept and tried again with the next commit, with one warning
//! until a commit succeeds again.

use std::collections::BTreeMap;
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
    Commit(Vec<(u32, Option<BaseRecord>)>),
    /// Answered once every commit sent before it is done (or has failed).
    Flush(SyncSender<()>),
}

pub struct Writer {
    to_writer: Option<SyncSender<ToWriter>>,
    thread: Option<JoinHandle<()>>,
    stats: Arc<Mutex<WriterStats>>,
}

/// A commit the writer had no room for: the caller keeps its records' base triangles dirty.
pub struct Busy(pub Vec<(u32, Option<BaseRecord>)>);

impl Writer {
    pub fn spawn(db: Arc<Database>, label: String) -> std::io::Result<Writer> {
        let (to_writer, from_schedule) = sync_channel(COMMITS_WAITING);
        let stats = Arc::new(Mutex::new(WriterStats::default()));
        let thread = {
            let stats = stats.clone();
            std::thread::Builder::new()
                .name("sma-cache-file".into())
                .spawn(move || write_loop(db, from_schedule, &stats, &label))?
        };
        Ok(Writer {
            to_writer: Some(to_writer),
            thread: Some(thread),
            stats,
        })
    }

    /// Hands a commit over without waiting; gives it back when the writer is behind.
    pub fn try_commit(&self, records: Vec<(u32, Option<BaseRecord>)>) -> Result<(), Busy> {
        let Some(to_writer) = &self.to_writer else {
            return Err(Busy(records));
        };
        match to_writer.try_send(ToWriter::Commit(records)) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(ToWriter::Commit(r)))
            | Err(TrySendError::Disconnected(ToWriter::Commit(r))) => Err(Busy(r)),
            Err(_) => unreachable!("only commits are tried"),
        }
    }

    /// Hands a commit over, waiting for room, and waits until it is done.
    pub fn commit_and_wait(&self, records: Vec<(u32, Option<BaseRecord>)>) {
        let Some(to_writer) = &self.to_writer else {
            return;
        };
        let (done, wait) = sync_channel(1);
        if to_writer.send(ToWriter::Commit(records)).is_ok()
            && to_writer.send(ToWriter::Flush(done)).is_ok()
        {
            let _ = wait.recv();
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
    label: &str,
) {
    // Records not yet in the file, by base triangle: a newer snapshot of a base replaces an
    // older one that a failed commit left here.
    let mut waiting: BTreeMap<u32, Option<Vec<u8>>> = BTreeMap::new();
    let mut failing = false;
    for message in from_schedule {
        let records = match message {
            ToWriter::Commit(records) => records,
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
        let outcome = store::commit(&db, &batch);
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
                if failing {
                    tracing::info!(file = label, "the cache file is written again");
                    failing = false;
                }
            }
            Err(e) => {
                s.failed_commits += 1;
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
