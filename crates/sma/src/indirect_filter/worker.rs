//! The thread that filters beside the schedule's (DESIGN.md §5, "Parts, and textures"). On a
//! walk through Sponza a run took 0.1–0.3 s once half a million leaves were refined, a fifth of
//! the schedule thread's time: run there, it held back the pass of a camera that had just
//! stopped and the syncs that show it. The schedule gathers a run's candidates (`start`), this
//! thread filters them, and the schedule sets what came back (`finish`) at its next turn.

use std::sync::mpsc::{SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use tokio::sync::mpsc::Sender;

use super::{FilterJob, Filtered};

/// The worker, fed one job at a time (the schedule starts a run only when none is under way).
pub struct FilterWorker {
    to_worker: Option<SyncSender<FilterJob>>,
    thread: Option<JoinHandle<()>>,
}

impl FilterWorker {
    /// A worker that sends every job it filtered to `done`; it ends once `done` is closed or
    /// the worker dropped.
    pub fn spawn(done: Sender<Filtered>) -> std::io::Result<FilterWorker> {
        let (to_worker, jobs) = sync_channel::<FilterJob>(1);
        let thread = std::thread::Builder::new()
            .name("sma-filter".into())
            .spawn(move || {
                for job in jobs {
                    if done.blocking_send(job.filter()).is_err() {
                        return;
                    }
                }
            })?;
        Ok(FilterWorker {
            to_worker: Some(to_worker),
            thread: Some(thread),
        })
    }

    /// Hands `job` over; gives it back when the worker has ended or still holds another.
    pub fn submit(&self, job: FilterJob) -> Result<(), FilterJob> {
        match &self.to_worker {
            Some(to_worker) => to_worker.try_send(job).map_err(|e| match e {
                TrySendError::Full(job) | TrySendError::Disconnected(job) => job,
            }),
            None => Err(job),
        }
    }
}

impl Drop for FilterWorker {
    fn drop(&mut self) {
        self.to_worker = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
