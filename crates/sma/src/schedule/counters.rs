//! What the schedule counts, and the `Stats` it reports from the counts (DESIGN.md §10: cost is
//! counted in paths): samples and paths answered, points rejected, whether the views have
//! reached their stated end, and where the thread's time went ([`WorkCosts`], logged at debug
//! level beside the statistics).

use std::time::{Duration, Instant};

use protocol::viewer_link::{MeshShape, SmaMemory, SmaToViewer, Stats};

use crate::mesh::SplitShapes;

use super::answers::Answered;
use super::requests::HandedOut;

/// A criterion that found nothing is asked again once this many new samples have come, not after
/// every batch: a round evaluates every visible leaf.
const NEW_INPUT_SAMPLES: u64 = 1024;

/// The kinds of work of a turn that grow with the visible leaves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// Visibility passes (the software rasterizer's threads work inside them).
    Pass,
    /// Views carried over to a refined or coarsened mesh without a pass (`visibility::carry_over`).
    CarryOver,
    /// Rebuilding the request queue from the visible sets and the cache.
    Replan,
    /// Bringing the viewers up to date.
    Sync,
    /// A refinement round: the criterion, the luminance pass, the mesh's splits.
    Round,
    /// A run of the object-space filter of the indirect part (`indirect_filter`), spaced by its
    /// own cost there: its part on this thread, gathering and setting (`filtering`).
    Filter,
}

impl Work {
    const ALL: [Work; 6] = [
        Work::Pass,
        Work::CarryOver,
        Work::Replan,
        Work::Sync,
        Work::Round,
        Work::Filter,
    ];

    fn index(self) -> usize {
        self as usize
    }
}

/// How many times each kind of work ran and how long it took, since the last `take`.
#[derive(Clone, Copy, Debug, Default)]
pub struct WorkCosts {
    runs: [u32; Work::ALL.len()],
    spent: [Duration; Work::ALL.len()],
}

impl WorkCosts {
    pub fn add(&mut self, work: Work, spent: Duration) {
        self.runs[work.index()] += 1;
        self.spent[work.index()] += spent;
    }

    /// The figures so far, as `kind: runs × mean ms`, and a fresh start.
    pub fn take(&mut self) -> String {
        let text = Work::ALL
            .iter()
            .map(|&w| {
                let (runs, spent) = (self.runs[w.index()], self.spent[w.index()]);
                let mean = spent.as_secs_f64() * 1e3 / f64::from(runs.max(1));
                format!("{w:?}: {runs} × {mean:.1} ms")
            })
            .collect::<Vec<_>>()
            .join(", ");
        *self = WorkCosts::default();
        text
    }
}

/// The schedule's counts since it started, and since the last `Stats`.
#[derive(Debug)]
pub struct Counters {
    /// Samples answered, and the paths traced for them.
    pub samples: u64,
    pub paths: u64,
    /// Samples since the last visibility pass that drew (thesis §4.1's revisit every K samples).
    pub since_pass: u64,
    /// Samples since the criteria were last told of new input.
    since_input: u64,
    /// Points whose answer was not a valid estimate.
    rejected_points: u64,
    /// Whether the last turn found every view at its stated end (`Counters::converged`).
    converged: bool,
    /// Where the thread's time went since the last `Stats`.
    pub costs: WorkCosts,
    /// `samples` and `paths` at the previous `Stats`, and when it was.
    at_last_stats: (u64, u64),
    last_stats: Instant,
}

/// What the schedule holds at a `Stats`, beside its counts.
#[derive(Clone, Copy, Debug, Default)]
pub struct Gauges {
    pub renderer_busy: f32,
    pub renderers: usize,
    pub viewers: usize,
    pub leaves: usize,
    pub cached_samples: usize,
    /// The SMA's memory by part against its budget (`memory`).
    pub memory: SmaMemory,
    pub queued: usize,
    /// The queue per urgency (`Urgency` order), and what went out since the last `Stats`.
    pub queued_by_urgency: [usize; 6],
    pub handed_out: HandedOut,
    pub in_flight: usize,
    pub pending_steps: usize,
    /// Parents merged back by uniformity since the start (`uniformity`).
    pub uniform_merges: u64,
    pub neighbour_bound_hits: u64,
    pub split_shapes: SplitShapes,
}

impl Counters {
    pub fn new(now: Instant) -> Counters {
        Counters {
            samples: 0,
            paths: 0,
            since_pass: 0,
            since_input: 0,
            rejected_points: 0,
            converged: false,
            costs: WorkCosts::default(),
            at_last_stats: (0, 0),
            last_stats: now,
        }
    }

    /// Counts one batch's answers; returns whether the criteria are due news of new input: new
    /// samples are new input for every criterion, and one that had found nothing may find
    /// something now ([`NEW_INPUT_SAMPLES`]).
    pub fn answered(&mut self, answered: Answered) -> bool {
        let n = answered.points;
        self.samples += n;
        self.paths += answered.paths;
        self.since_pass += n;
        self.rejected_points += answered.rejected;
        self.since_input += n;
        let new_input = self.since_input >= NEW_INPUT_SAMPLES;
        if new_input {
            self.since_input = 0;
        }
        new_input
    }

    /// Notes whether every view is at its stated end (DESIGN.md §5), saying so when it comes.
    pub fn converged(&mut self, converged: bool) {
        if converged && !self.converged {
            tracing::info!(
                samples = self.samples,
                "converged: every visible sample is as good as it will get"
            );
        }
        self.converged = converged;
    }

    /// Whether the last `Stats` is `every` old.
    pub fn stats_due(&self, every: Duration) -> bool {
        self.last_stats.elapsed() >= every
    }

    /// The `Stats` since the last one, logged at debug level with `gauges` and the thread's
    /// costs; the counts start over.
    pub fn report(&mut self, gauges: Gauges) -> Stats {
        let secs = self.last_stats.elapsed().as_secs_f32().max(1e-3);
        let (samples, paths) = self.at_last_stats;
        let rate = (self.samples - samples) as f32 / secs;
        let paths_rate = (self.paths - paths) as f32 / secs;
        self.at_last_stats = (self.samples, self.paths);
        self.last_stats = Instant::now();
        let stats = Stats {
            samples_per_sec: rate,
            paths_per_sec: paths_rate,
            renderer_busy: gauges.renderer_busy,
            leaves: gauges.leaves as u64,
            cached_samples: gauges.cached_samples as u64,
            renderers: gauges.renderers as u32,
            converged: self.converged,
            rejected_points: self.rejected_points,
            memory: gauges.memory,
            mesh: MeshShape {
                smallest_split_angle_deg: gauges.split_shapes.smallest_angle().map(f32::to_degrees),
                smallest_split_angle_ratio: gauges.split_shapes.smallest_ratio_to_base(),
                neighbour_bound_hits: gauges.neighbour_bound_hits,
                uniform_merges: gauges.uniform_merges,
            },
        };
        let mib = |bytes: u64| format!("{:.1}", bytes as f64 / (1 << 20) as f64);
        tracing::debug!(
            samples = self.samples,
            samples_per_sec = format!("{rate:.0}"),
            paths_per_sec = format!("{paths_rate:.0}"),
            renderer_busy = format!("{:.2}", stats.renderer_busy),
            leaves = stats.leaves,
            cached = stats.cached_samples,
            cache_mib = mib(gauges.memory.cache_bytes),
            mesh_mib = mib(gauges.memory.mesh_bytes()),
            viewers_mib = mib(gauges.memory.viewers_bytes),
            accounted_mib = mib(gauges.memory.accounted_bytes()),
            rss_mib = gauges.memory.rss_bytes.map(mib),
            memory_bound = gauges.memory.memory_bound,
            queued = gauges.queued,
            queued_by_urgency = ?gauges.queued_by_urgency,
            handed_out_points_paths = ?gauges.handed_out,
            in_flight = gauges.in_flight,
            pending_steps = gauges.pending_steps,
            merged_uniform = gauges.uniform_merges,
            converged = self.converged,
            rejected = self.rejected_points,
            renderers = gauges.renderers,
            viewers = gauges.viewers,
            work = self.costs.take(),
            "stats"
        );
        stats
    }
}

impl super::Schedule {
    /// Sends every viewer the `Stats` since the last ones, with what the schedule holds now.
    pub(super) fn report_stats(&mut self) {
        let gauges = Gauges {
            renderer_busy: self.pool.take_busy(),
            renderers: self.renderers,
            viewers: self.viewers.len(),
            leaves: self.mesh.leaf_count(),
            cached_samples: self.cache.len(),
            memory: self.memory.wire(&self.memory_account()),
            queued: self.requests.queued(),
            queued_by_urgency: self.requests.queued_by_urgency(),
            handed_out: self.requests.take_handed_out(),
            in_flight: self.requests.in_flight_keys(),
            pending_steps: self.refinement.pending.len(),
            uniform_merges: self.refinement.uniform_merges(),
            neighbour_bound_hits: self.mesh.neighbour_stats().bound_hits,
            split_shapes: self.mesh.split_shapes(),
        };
        let stats = self.counters.report(gauges);
        for viewer in self.viewers.iter() {
            viewer.send(SmaToViewer::Stats(stats));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn costs_add_up_per_kind_and_start_over_when_taken() {
        let mut costs = WorkCosts::default();
        costs.add(Work::Sync, 4 * MS);
        costs.add(Work::Sync, 6 * MS);
        costs.add(Work::Replan, 7 * MS);
        let text = costs.take();
        assert!(text.contains("Sync: 2 × 5.0 ms"), "{text}");
        assert!(text.contains("Replan: 1 ×"), "{text}");
        assert!(text.contains("Pass: 0 × 0.0 ms"), "{text}");
        assert!(costs.take().contains("Sync: 0 ×"));
    }

    #[test]
    fn the_criteria_hear_of_new_samples_once_enough_have_come() {
        let mut counters = Counters::new(Instant::now());
        let batch = Answered {
            points: NEW_INPUT_SAMPLES / 2,
            paths: 64 * NEW_INPUT_SAMPLES / 2,
            rejected: 1,
        };
        assert!(!counters.answered(batch));
        assert!(counters.answered(batch));
        assert!(!counters.answered(batch), "counting starts over");
        assert_eq!(
            (counters.samples, counters.paths, counters.since_pass),
            (3 * batch.points, 3 * batch.paths, 3 * batch.points)
        );
        assert_eq!(counters.report(Gauges::default()).rejected_points, 3);
    }
}
