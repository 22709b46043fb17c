//! The object-space filter of the indirect part as the schedule runs it (DESIGN.md §5, "Parts,
//! and textures"): the viewers, the criteria and the stopping rule all read the filtered part.
//! A run starts after a sync, when samples or views changed since the last and its pace allows
//! (`IndirectFilter::ready`); the schedule's thread gathers its candidates, a worker filters them
//! (`FilterWorker`), and the turn after it is done sets what came back and owes the viewers a
//! sync. Run whole on the schedule's thread, a run of 0.1–0.3 s on a refined Sponza held back
//! the pass of a camera that had just stopped; counted in the sync's cost, a run of tens of
//! milliseconds spaced the syncs and the walking camera's views by ten times that (`pace`).

use std::time::{Duration, Instant};

use tokio::sync::mpsc::{Receiver, channel};

use super::Schedule;
use super::counters::Work;
use crate::indirect_filter::{FilterWorker, Filtered};

/// The filter's runs: the worker, and whether one is under way.
#[derive(Default)]
pub struct FilterRuns {
    /// Started with the schedule's loop (`start_worker`); None before, or where its thread could
    /// not start: runs are then filtered on the schedule's thread.
    worker: Option<FilterWorker>,
    /// Samples or views changed since the last run started.
    pub due: bool,
    in_flight: bool,
    /// What gathering the run under way took on the schedule's thread.
    gathered_in: Duration,
}

impl FilterRuns {
    /// Starts the worker (again, if it ran before); its results come back on the receiver, for
    /// the schedule's loop to wait on.
    pub fn start_worker(&mut self) -> Receiver<Filtered> {
        let (to_schedule, done) = channel(1);
        self.worker = FilterWorker::spawn(to_schedule)
            .inspect_err(|e| {
                tracing::warn!(%e, "no thread for the indirect filter: it runs on the schedule's")
            })
            .ok();
        self.in_flight = false;
        done
    }

    /// Whether a run is being filtered (its results not yet set).
    pub fn in_flight(&self) -> bool {
        self.in_flight
    }
}

impl Schedule {
    /// Starts a run when one is due, none is under way and its pace allows.
    pub(super) fn start_filter(&mut self) {
        let runs = &self.filter_runs;
        if !runs.due || runs.in_flight || !self.indirect_filter.ready(Instant::now()) {
            return;
        }
        let start = Instant::now();
        self.filter_runs.due = false;
        let views = self.viewers.views().map(|v| &v.visible);
        let Some(job) = self.indirect_filter.start(&self.mesh, views, &self.cache) else {
            return;
        };
        self.filter_runs.gathered_in = start.elapsed();
        let job = match &self.filter_runs.worker {
            Some(worker) => match worker.submit(job) {
                Ok(()) => {
                    self.filter_runs.in_flight = true;
                    return;
                }
                Err(job) => job,
            },
            None => job,
        };
        self.finish_filter(job.filter());
    }

    /// Sets a run's results: the viewers are owed a sync that shows them. The run counts once
    /// in the thread's costs, its gathering and this (`Work::Filter`).
    pub(super) fn finish_filter(&mut self, filtered: Filtered) {
        let start = Instant::now();
        self.filter_runs.in_flight = false;
        self.indirect_filter
            .finish(filtered, &self.mesh, &mut self.cache);
        let spent = self.filter_runs.gathered_in + start.elapsed();
        self.counters.costs.add(Work::Filter, spent);
        self.owed.samples_arrived();
    }
}
