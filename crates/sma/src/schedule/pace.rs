//! The pace of the work a turn may put off (DESIGN.md §3: rest time goes to the renderers), and
//! the one place that decides, for each turn, which of it runs now. The schedule's thread shares
//! the machine's cores with the renderers, so every millisecond it spends walking the visible
//! leaves is a millisecond less of tracing: the viewers' syncs, the re-plans that only reorder
//! the queue, and the refinement rounds are each spaced out by their own measured cost
//! ([`Pace`]). [`Paces::allowed`] says what of the work owed may run at an instant, and what is
//! deferred until when; the turn defers it explicitly, and nothing owed is cleared to put it off.

use std::time::{Duration, Instant};

use super::counters::Work;
use super::waits::Owed;

/// Viewers are brought up to date at most this often while the camera rests (at once after a
/// pass): each sync walks every visible leaf, and done after every answered batch it took the
/// SMA's whole core and left the renderers waiting for work (DESIGN.md §3).
const SYNC_INTERVAL: Duration = Duration::from_millis(50);

/// At most this share of the schedule thread's time goes to syncs put off for the interval: with
/// tens of thousands of visible leaves a sync takes milliseconds, and twenty of them a second
/// were a fifth of the SMA's time on Sponza, taken from the renderers it shares the cores with.
const SYNC_SHARE: f64 = 0.1;

/// A re-plan that may wait (see `Owed::replan_soon`) comes at most this often, and takes at most
/// this share of the thread's time: on Sponza a re-plan walks over a hundred thousand visible
/// samples, and each committed refinement group asked for one.
const REPLAN_INTERVAL: Duration = Duration::from_millis(50);
const REPLAN_SHARE: f64 = 0.1;

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

/// Whether owed work that may wait runs this turn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Timing {
    /// Nothing of the kind is owed.
    NotOwed,
    /// Owed, and its pace allows it now.
    Now,
    /// Owed, and deferred by its pace until then: it stays owed.
    Deferred(Instant),
}

impl Timing {
    fn of(owed: bool, pace: &Pace, at_once: bool, now: Instant) -> Timing {
        if !owed {
            Timing::NotOwed
        } else if at_once || pace.due(now) {
            Timing::Now
        } else {
            Timing::Deferred(pace.next_at())
        }
    }

    pub fn now(self) -> bool {
        self == Timing::Now
    }

    fn deferred_until(self) -> Option<Instant> {
        match self {
            Timing::Deferred(at) => Some(at),
            Timing::NotOwed | Timing::Now => None,
        }
    }
}

/// What the paces allow, at one instant, of the work owed that may wait.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Allowed {
    /// Bringing the viewers up to date (`Owed::resync`).
    pub sync: Timing,
    /// A re-plan that only reorders the queue (`Owed::replan_soon`). A re-plan owed at once (a
    /// new view) is never paced.
    pub replan_soon: Timing,
}

impl Allowed {
    /// When the first deferred work becomes due, for the loop to wake then.
    pub fn wake_at(&self) -> Option<Instant> {
        let deferred = [self.sync, self.replan_soon].map(Timing::deferred_until);
        deferred.into_iter().flatten().min()
    }
}

/// The paces of the schedule's work that may wait.
#[derive(Clone, Copy, Debug)]
pub struct Paces {
    sync: Pace,
    replan: Pace,
    /// Spaces out refinement rounds (`ScheduleConfig::round_share`).
    round: Pace,
}

impl Paces {
    pub fn new(round_share: f64, now: Instant) -> Paces {
        Paces {
            sync: Pace::new(SYNC_INTERVAL, SYNC_SHARE, now),
            replan: Pace::new(REPLAN_INTERVAL, REPLAN_SHARE, now),
            round: Pace::new(Duration::ZERO, round_share, now),
        }
    }

    /// What of `owed` may run at `now`. A sync comes at once after a pass (`pass_ran`: the
    /// viewers see a new view as soon as it is drawn), else at its pace ([`SYNC_INTERVAL`],
    /// [`SYNC_SHARE`]); a re-plan that may wait at its own ([`REPLAN_INTERVAL`],
    /// [`REPLAN_SHARE`]).
    pub fn allowed(&self, owed: Owed, pass_ran: bool, now: Instant) -> Allowed {
        Allowed {
            sync: Timing::of(owed.resync(), &self.sync, pass_ran, now),
            replan_soon: Timing::of(owed.replan_soon(), &self.replan, false, now),
        }
    }

    /// No refinement round before this. Spacing the rounds gives their time to the renderers
    /// only while the queue holds work for them (`work_queued`); with nothing queued, rounds are
    /// what gives them work (a view's last refinements), and held back they left the renderers
    /// idle.
    pub fn next_round_at(&self, work_queued: bool) -> Option<Instant> {
        work_queued.then(|| self.round.next_at())
    }

    /// A new view is refined as soon as it rests, whatever the last view's rounds cost.
    pub fn camera_moved(&mut self, now: Instant) {
        self.round.restart(now);
    }

    /// `work` ran from `started` for `spent`: paced work is spaced by it.
    pub fn ran(&mut self, work: Work, started: Instant, spent: Duration) {
        let pace = match work {
            Work::Sync => &mut self.sync,
            Work::Replan => &mut self.replan,
            Work::Round => &mut self.round,
            Work::Pass | Work::CarryOver => return,
        };
        pace.ran(started, spent);
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
    fn a_sync_put_off_by_its_pace_is_deferred_not_forgotten_and_a_pass_brings_it_at_once() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        let mut owed = Owed::default();
        owed.samples_arrived();
        assert_eq!(paces.allowed(owed, false, t0).sync, Timing::Now);
        paces.ran(Work::Sync, t0, MS);
        let later = t0 + 10 * MS;
        let allowed = paces.allowed(owed, false, later);
        assert_eq!(allowed.sync, Timing::Deferred(t0 + SYNC_INTERVAL));
        assert_eq!(allowed.wake_at(), Some(t0 + SYNC_INTERVAL));
        assert!(owed.resync(), "still owed");
        assert_eq!(paces.allowed(owed, true, later).sync, Timing::Now);
        assert_eq!(
            paces.allowed(Owed::default(), true, later).sync,
            Timing::NotOwed
        );
    }

    #[test]
    fn only_a_replan_that_may_wait_is_paced() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        paces.ran(Work::Replan, t0, 20 * MS);
        let mut owed = Owed::default();
        owed.queue_changed();
        let allowed = paces.allowed(owed, false, t0 + MS);
        assert_eq!(allowed.replan_soon, Timing::Deferred(t0 + 200 * MS));
        assert_eq!(allowed.sync, Timing::NotOwed);
        owed.views_changed();
        assert!(owed.replan(), "owed at once, whatever the pace");
        assert_eq!(
            paces.allowed(owed, false, t0 + 200 * MS).replan_soon,
            Timing::Now
        );
    }

    #[test]
    fn rounds_are_spaced_only_while_work_is_queued_and_a_camera_move_lifts_the_spacing() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        paces.ran(Work::Round, t0, 10 * MS);
        assert_eq!(paces.next_round_at(true), Some(t0 + 200 * MS));
        assert_eq!(paces.next_round_at(false), None);
        paces.camera_moved(t0 + MS);
        assert_eq!(paces.next_round_at(true), Some(t0 + MS));
    }
}
