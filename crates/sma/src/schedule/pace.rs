//! The pace of the work a turn may put off (DESIGN.md §3: rest time goes to the renderers), and
//! the one place that decides, for each turn, which of it runs now. The schedule's thread shares
//! the machine's cores with the renderers, so every millisecond it spends walking the visible
//! leaves is a millisecond less of tracing: the viewers' syncs, the re-plans that only reorder
//! the queue, the refinement rounds, and the visibility passes of a camera that keeps moving
//! (DESIGN.md §3 step 9) are each spaced out by their own measured cost ([`Pace`]). [`Paces::allowed`] says what of the work owed may run at an instant, and what is
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

/// While a camera keeps moving (20–30 cameras a second from a walking viewer), a new view's
/// cycle (its visibility pass, and the re-plan and sync the pass sets off, each a walk over the
/// visible leaves) takes at most this share of the schedule thread's time: a pass is drawn for
/// the latest camera, those that came meanwhile are skipped. Unpaced, the cycles of a large
/// view took the whole thread, and the rasteriser's threads the cores the renderers needed.
/// A camera after a pause finds the pace long due, so its first picture never waits for it.
/// Like the rounds' pace, it holds only while the queue has work for the renderers: with
/// nothing queued the time it saves would be idle time, and on a walk that returns to a place
/// already cached (nothing new to trace) the paced views lagged the camera by half a second,
/// leaving the edge the head turns into black.
const WALKING_VIEW_SHARE: f64 = 1.0 / 3.0;

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

/// The visibility passes owed, as their pace sees them (`turns::passes_owed`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PassesOwed {
    None,
    /// Owed for what may not wait: a viewer's first camera, a camera after a pause, leaves
    /// that changed under an unchanged camera, or every pass while refinement waits for rest
    /// (`ScheduleConfig::work_while_walking` off).
    AtOnce,
    /// Owed only to cameras that replaced the one their view was drawn from while the viewer
    /// walks: paced ([`WALKING_VIEW_SHARE`]).
    Walking,
}

/// What the paces allow, at one instant, of the work owed that may wait.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Allowed {
    /// The visibility passes (`PassesOwed`).
    pub pass: Timing,
    /// Bringing the viewers up to date (`Owed::resync`).
    pub sync: Timing,
    /// A re-plan that only reorders the queue (`Owed::replan_soon`). A re-plan owed at once (a
    /// new view) is never paced.
    pub replan_soon: Timing,
}

impl Allowed {
    /// When the first deferred work becomes due, for the loop to wake then.
    pub fn wake_at(&self) -> Option<Instant> {
        let deferred = [self.pass, self.sync, self.replan_soon].map(Timing::deferred_until);
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
    /// Spaces out a walking camera's views ([`WALKING_VIEW_SHARE`]).
    walking_view: Pace,
}

impl Paces {
    pub fn new(round_share: f64, now: Instant) -> Paces {
        Paces {
            sync: Pace::new(SYNC_INTERVAL, SYNC_SHARE, now),
            replan: Pace::new(REPLAN_INTERVAL, REPLAN_SHARE, now),
            round: Pace::new(Duration::ZERO, round_share, now),
            walking_view: Pace::new(Duration::ZERO, WALKING_VIEW_SHARE, now),
        }
    }

    /// What of `owed` and of the `passes` owed may run at `now`. Passes come at once unless
    /// every one owed is a walking camera's and the renderers have work queued
    /// (`work_queued`, [`WALKING_VIEW_SHARE`]). A sync comes at once after a pass (`pass_ran`:
    /// the viewers see a new view as soon as it is drawn), else at its pace ([`SYNC_INTERVAL`],
    /// [`SYNC_SHARE`]); a re-plan that may wait at its own ([`REPLAN_INTERVAL`],
    /// [`REPLAN_SHARE`]).
    pub fn allowed(
        &self,
        owed: Owed,
        passes: PassesOwed,
        pass_ran: bool,
        work_queued: bool,
        now: Instant,
    ) -> Allowed {
        let paced = passes == PassesOwed::Walking && work_queued;
        Allowed {
            pass: Timing::of(passes != PassesOwed::None, &self.walking_view, !paced, now),
            sync: Timing::of(owed.resync(), &self.sync, pass_ran, now),
            replan_soon: Timing::of(owed.replan_soon(), &self.replan, false, now),
        }
    }

    /// No refinement round before this. Spacing the rounds gives their time to the renderers
    /// only while the queue holds work for them (`work_queued`); with nothing queued, rounds are
    /// what gives them work (a view's last refinements), and held back they left the renderers
    /// idle. A camera that has come to rest since its viewer's last round is refined at once,
    /// whatever the rounds cost (`turns::TurnView::ready_at`).
    pub fn next_round_at(&self, work_queued: bool) -> Option<Instant> {
        work_queued.then(|| self.round.next_at())
    }

    /// A walking camera's new view (its pass, re-plan and sync) ran from `started` for `spent`:
    /// the next one is spaced by it.
    pub fn walking_view_ran(&mut self, started: Instant, spent: Duration) {
        self.walking_view.ran(started, spent);
    }

    /// `work` ran from `started` for `spent`: paced work is spaced by it.
    pub fn ran(&mut self, work: Work, started: Instant, spent: Duration) {
        let pace = match work {
            Work::Sync => &mut self.sync,
            Work::Replan => &mut self.replan,
            Work::Round => &mut self.round,
            // The filter keeps its own pace (`IndirectFilter::ready`).
            Work::Pass | Work::CarryOver | Work::Filter => return,
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
        let none = PassesOwed::None;
        assert_eq!(paces.allowed(owed, none, false, true, t0).sync, Timing::Now);
        paces.ran(Work::Sync, t0, MS);
        let later = t0 + 10 * MS;
        let allowed = paces.allowed(owed, none, false, true, later);
        assert_eq!(allowed.sync, Timing::Deferred(t0 + SYNC_INTERVAL));
        assert_eq!(allowed.wake_at(), Some(t0 + SYNC_INTERVAL));
        assert!(owed.resync(), "still owed");
        assert_eq!(
            paces.allowed(owed, none, true, true, later).sync,
            Timing::Now
        );
        assert_eq!(
            paces.allowed(Owed::default(), none, true, true, later).sync,
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
        let allowed = paces.allowed(owed, PassesOwed::None, false, true, t0 + MS);
        assert_eq!(allowed.replan_soon, Timing::Deferred(t0 + 200 * MS));
        assert_eq!(allowed.sync, Timing::NotOwed);
        owed.views_changed();
        assert!(owed.replan(), "owed at once, whatever the pace");
        assert_eq!(
            paces
                .allowed(owed, PassesOwed::None, false, true, t0 + 200 * MS)
                .replan_soon,
            Timing::Now
        );
    }

    #[test]
    fn rounds_are_spaced_only_while_work_is_queued() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        paces.ran(Work::Round, t0, 10 * MS);
        assert_eq!(paces.next_round_at(true), Some(t0 + 200 * MS));
        assert_eq!(paces.next_round_at(false), None);
    }

    #[test]
    fn a_walking_cameras_views_take_a_third_of_the_time_and_other_passes_never_wait() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        let pass =
            |paces: &Paces, passes, at| paces.allowed(Owed::default(), passes, false, true, at);
        assert_eq!(pass(&paces, PassesOwed::Walking, t0).pass, Timing::Now);
        paces.walking_view_ran(t0, 20 * MS);
        let soon = t0 + 30 * MS;
        let walking = pass(&paces, PassesOwed::Walking, soon);
        assert_eq!(walking.pass, Timing::Deferred(t0 + 60 * MS), "20 ms in 60");
        assert_eq!(walking.wake_at(), Some(t0 + 60 * MS));
        assert_eq!(pass(&paces, PassesOwed::AtOnce, soon).pass, Timing::Now);
        assert_eq!(pass(&paces, PassesOwed::None, soon).pass, Timing::NotOwed);
        let due = pass(&paces, PassesOwed::Walking, t0 + 60 * MS);
        assert_eq!(due.pass, Timing::Now);
        // Passes are not the other work's pace: a drawn pass spaces nothing by itself.
        paces.ran(Work::Pass, soon, 100 * MS);
        assert_eq!(
            pass(&paces, PassesOwed::Walking, t0 + 60 * MS).pass,
            Timing::Now
        );
    }

    #[test]
    fn a_walking_cameras_views_wait_only_while_the_renderers_have_work_queued() {
        let t0 = Instant::now();
        let mut paces = Paces::new(0.05, t0);
        paces.walking_view_ran(t0, 20 * MS);
        let soon = t0 + 30 * MS;
        let pass = |queued| {
            paces
                .allowed(Owed::default(), PassesOwed::Walking, false, queued, soon)
                .pass
        };
        assert_eq!(pass(true), Timing::Deferred(t0 + 60 * MS));
        assert_eq!(pass(false), Timing::Now, "its time would be idle time");
    }
}
