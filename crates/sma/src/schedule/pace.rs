//! Where the schedule thread's time goes, and the pacing of the work it may put off (DESIGN.md §3:
//! rest time goes to the renderers). The thread shares the machine's cores with the renderers,
//! so every millisecond it spends walking the visible leaves is a millisecond less of tracing.
//! [`WorkCosts`] adds up each kind of work between two `Stats` (logged at debug level, beside
//! the statistics); [`Pace`] spaces out a recurring task by its own measured cost.

use std::time::{Duration, Instant};

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
}

impl Work {
    const ALL: [Work; 5] = [
        Work::Pass,
        Work::CarryOver,
        Work::Replan,
        Work::Sync,
        Work::Round,
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

/// Spaces out a recurring task that may wait: the next run comes no sooner than `min_interval`
/// after the last one began, nor sooner than its cost allows for the task to take at most
/// `share` of the thread's time. A cheap task so runs at its interval; one that grew with the
/// scene runs less often instead of taking the thread from everything else.
#[derive(Clone, Copy, Debug)]
pub struct Pace {
    min_interval: Duration,
    share: f64,
    next_at: Instant,
}

impl Pace {
    pub fn new(min_interval: Duration, share: f64, now: Instant) -> Pace {
        assert!(share > 0.0 && share <= 1.0, "a share of the time: {share}");
        Pace {
            min_interval,
            share,
            next_at: now,
        }
    }

    /// When the task may run next.
    pub fn next_at(&self) -> Instant {
        self.next_at
    }

    pub fn due(&self, now: Instant) -> bool {
        now >= self.next_at
    }

    /// The task may run at once again (what made it costly is gone).
    pub fn restart(&mut self, now: Instant) {
        self.next_at = now;
    }

    /// The task ran from `started` for `spent`.
    pub fn ran(&mut self, started: Instant, spent: Duration) {
        let by_cost = spent.mul_f64(1.0 / self.share);
        self.next_at = started + self.min_interval.max(by_cost);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_cheap_task_runs_at_its_interval() {
        let t0 = Instant::now();
        let mut pace = Pace::new(50 * MS, 0.1, t0);
        assert!(pace.due(t0), "the first run is due at once");
        pace.ran(t0, 2 * MS);
        assert!(!pace.due(t0 + 49 * MS));
        assert!(pace.due(t0 + 50 * MS));
    }

    #[test]
    fn a_costly_task_takes_at_most_its_share() {
        let t0 = Instant::now();
        let mut pace = Pace::new(50 * MS, 0.1, t0);
        pace.ran(t0, 30 * MS);
        assert_eq!(pace.next_at(), t0 + 300 * MS, "30 ms is a tenth of 300 ms");
        assert!(!pace.due(t0 + 299 * MS));
        // It became cheap again: back to its interval.
        let t1 = pace.next_at();
        pace.ran(t1, MS);
        assert_eq!(pace.next_at(), t1 + 50 * MS);
    }

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
}
