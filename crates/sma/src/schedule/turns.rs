//! The decisions of a turn (see the module documentation of `schedule`), as plain functions of
//! the schedule's state and the time that return what to do, so they are tested with a fake
//! clock: when the request queue is re-planned and fed ([`Feed`]), which viewer may refine, and
//! when the loop must wake for a camera coming to rest. The schedule carries them out. What the
//! paces allow is decided apart, in `pace`.

use std::time::{Duration, Instant};

use super::pace::Allowed;
use super::waits::{Owed, ViewWait};
use crate::viewer_link::ViewerId;

/// A viewer as the turn order sees it.
#[derive(Clone, Copy, Debug)]
pub struct TurnView {
    pub id: ViewerId,
    /// A visibility pass has run for its camera.
    pub has_view: bool,
    pub paused: bool,
    pub wait: ViewWait,
    pub camera_at: Instant,
    /// Its camera replaced an earlier one: the viewer may be walking, so refinement waits for
    /// the camera to rest. A viewer's first camera rests at once: nothing says it moves, and a
    /// person who has just opened a view is looking at it.
    pub camera_replaced: bool,
}

impl TurnView {
    /// When its camera counts as resting.
    fn rests_at(&self, rest: Duration) -> Instant {
        if self.camera_replaced {
            self.camera_at + rest
        } else {
            self.camera_at
        }
    }
}

/// What refinement as a whole waits for, before any viewer is asked.
#[derive(Clone, Copy, Debug)]
pub struct RefineGate {
    /// Refinement at all (off: the control run).
    pub refine: bool,
    /// Refinement groups still wait for samples.
    pub groups_pending: bool,
    /// Samples queued or in flight, and the level below which refinement may add more.
    pub outstanding: usize,
    pub queue_low: usize,
    /// How long a camera that replaced another must be unchanged to rest.
    pub rest: Duration,
    /// No round before this: the rounds' pace (`ScheduleConfig::round_share`).
    pub next_round_at: Option<Instant>,
    /// A pass of coarsening by uniformity is due (`uniformity`): it comes with a round, so a
    /// viewer whose criterion found nothing more still takes its turn for it.
    pub merge_due: bool,
}

/// The viewer whose turn it is to refine at `now`, if refinement may run: never while a pass is
/// owed to anyone (a camera change interrupts refinement at once), while groups wait, while
/// the queue is long, or before the rounds' pace allows; then the resting viewers take turns
/// (`round` counts the rounds so far).
pub fn refinement_candidate(
    gate: &RefineGate,
    viewers: &[TurnView],
    round: usize,
    now: Instant,
) -> Option<ViewerId> {
    if !gate.refine
        || gate.groups_pending
        || gate.outstanding >= gate.queue_low
        || viewers.iter().any(|v| v.wait.needs_pass())
        || gate.next_round_at.is_some_and(|at| now < at)
    {
        return None;
    }
    let ready: Vec<ViewerId> = viewers
        .iter()
        .filter(|v| {
            v.has_view
                && !v.paused
                && (!v.wait.is_exhausted() || gate.merge_due)
                && now >= v.rests_at(gate.rest)
        })
        .map(|v| v.id)
        .collect();
    (!ready.is_empty()).then(|| ready[round % ready.len()])
}

/// When the next viewer's camera comes to rest after `now`, or the rounds' pace allows the next
/// round, whichever is later, if refinement waits only for those.
pub fn next_rest(gate: &RefineGate, viewers: &[TurnView], now: Instant) -> Option<Instant> {
    if !gate.refine {
        return None;
    }
    viewers
        .iter()
        .filter(|v| v.has_view && !v.paused && (!v.wait.is_exhausted() || gate.merge_due))
        .map(|v| v.rests_at(gate.rest).max(gate.next_round_at.unwrap_or(now)))
        .filter(|&t| t > now)
        .min()
}

/// Whether a turn has something to do without any new event: work owed that no pace defers, a
/// pass, or a refinement round.
pub fn has_work_now(
    owed: Owed,
    allowed: &Allowed,
    viewers: &[TurnView],
    candidate: Option<ViewerId>,
) -> bool {
    owed.replan()
        || allowed.replan_soon.now()
        || allowed.sync.now()
        || viewers.iter().any(|v| v.wait.needs_pass())
        || candidate.is_some()
}

/// How a turn re-plans the request queue and feeds the renderers, which the schedule carries
/// out in this order: a re-plan first if `replan`, then batches to the pool while it has room
/// (dropping queued needs that answers have satisfied meanwhile), then, if
/// `replan_if_drained` and that left the queue empty, a re-plan and batches again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Feed {
    pub replan: bool,
    pub replan_if_drained: bool,
}

/// Re-plans when owed at once, when owed soon and its pace allows, or when the queue ran dry
/// while a sync is due, and keeps the renderers fed. A queue that submitting empties is
/// re-planned at once when a sync is due, before the viewers are told what is outstanding, so
/// an epoch never reports needs that no longer exist (nor misses new ones). A sync deferred by
/// its pace asks for neither: the next turn that syncs re-plans first.
pub fn feed(owed: Owed, allowed: &Allowed, queued: usize) -> Feed {
    let sync = allowed.sync.now();
    let replan = owed.replan() || allowed.replan_soon.now() || (queued == 0 && sync);
    Feed {
        replan,
        replan_if_drained: !replan && sync,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule::pace::Timing;

    /// A clock that moves only when told.
    struct FakeClock(Instant);

    impl FakeClock {
        fn now(&self) -> Instant {
            self.0
        }
        fn advance(&mut self, ms: u64) {
            self.0 += Duration::from_millis(ms);
        }
    }

    fn gate() -> RefineGate {
        RefineGate {
            refine: true,
            groups_pending: false,
            outstanding: 0,
            queue_low: 256,
            rest: Duration::from_millis(100),
            next_round_at: None,
            merge_due: false,
        }
    }

    fn resting(id: ViewerId, camera_at: Instant) -> TurnView {
        TurnView {
            id,
            has_view: true,
            paused: false,
            wait: ViewWait::Rest,
            camera_at,
            camera_replaced: true,
        }
    }

    #[test]
    fn refinement_waits_for_the_camera_to_rest() {
        let mut clock = FakeClock(Instant::now());
        let viewers = [resting(1, clock.now())];
        assert_eq!(
            refinement_candidate(&gate(), &viewers, 0, clock.now()),
            None
        );
        assert_eq!(
            next_rest(&gate(), &viewers, clock.now()),
            Some(clock.now() + Duration::from_millis(100))
        );
        clock.advance(100);
        assert_eq!(
            refinement_candidate(&gate(), &viewers, 0, clock.now()),
            Some(1)
        );
        assert_eq!(
            next_rest(&gate(), &viewers, clock.now()),
            None,
            "already resting"
        );
    }

    #[test]
    fn a_first_camera_rests_at_once() {
        let clock = FakeClock(Instant::now());
        let first = TurnView {
            camera_replaced: false,
            ..resting(1, clock.now())
        };
        assert_eq!(
            refinement_candidate(&gate(), &[first], 0, clock.now()),
            Some(1)
        );
        assert_eq!(next_rest(&gate(), &[first], clock.now()), None);
    }

    #[test]
    fn rounds_wait_for_their_pace_and_the_loop_wakes_for_it() {
        let mut clock = FakeClock(Instant::now());
        let viewers = [resting(1, clock.now())];
        clock.advance(1000);
        let paced = RefineGate {
            next_round_at: Some(clock.now() + Duration::from_millis(400)),
            ..gate()
        };
        assert_eq!(refinement_candidate(&paced, &viewers, 0, clock.now()), None);
        assert_eq!(
            next_rest(&paced, &viewers, clock.now()),
            paced.next_round_at,
            "the loop wakes when the pace allows, not only when a camera rests"
        );
        clock.advance(400);
        assert_eq!(
            refinement_candidate(&paced, &viewers, 0, clock.now()),
            Some(1)
        );
        assert_eq!(next_rest(&paced, &viewers, clock.now()), None);
    }

    #[test]
    fn a_pass_owed_to_anyone_holds_every_refinement() {
        let mut clock = FakeClock(Instant::now());
        let mut moving = resting(2, clock.now());
        moving.wait = ViewWait::Pass { exhausted: false };
        let viewers = [resting(1, clock.now()), moving];
        clock.advance(1000);
        assert_eq!(
            refinement_candidate(&gate(), &viewers, 0, clock.now()),
            None
        );
        assert!(has_work_now(
            Owed::default(),
            &all_allowed(Owed::default()),
            &viewers,
            None
        ));
    }

    #[test]
    fn a_long_queue_pending_groups_or_no_refinement_hold_it_too() {
        let mut clock = FakeClock(Instant::now());
        let viewers = [resting(1, clock.now())];
        clock.advance(1000);
        let held = [
            RefineGate {
                outstanding: 256,
                ..gate()
            },
            RefineGate {
                groups_pending: true,
                ..gate()
            },
            RefineGate {
                refine: false,
                ..gate()
            },
        ];
        for g in held {
            assert_eq!(
                refinement_candidate(&g, &viewers, 0, clock.now()),
                None,
                "{g:?}"
            );
        }
    }

    #[test]
    fn resting_viewers_take_turns_and_exhausted_or_paused_ones_are_skipped() {
        let mut clock = FakeClock(Instant::now());
        let t = clock.now();
        let mut paused = resting(3, t);
        paused.paused = true;
        let mut exhausted = resting(4, t);
        exhausted.wait = ViewWait::Input;
        let viewers = [resting(1, t), resting(2, t), paused, exhausted];
        clock.advance(200);
        let picks: Vec<_> = (0..4)
            .map(|round| refinement_candidate(&gate(), &viewers, round, clock.now()))
            .collect();
        assert_eq!(picks, [Some(1), Some(2), Some(1), Some(2)]);
        assert!(!has_work_now(
            Owed::default(),
            &all_allowed(Owed::default()),
            &viewers,
            None
        ));
    }

    #[test]
    fn an_exhausted_viewer_takes_its_turn_for_a_due_merge_pass_and_only_at_rest() {
        let mut clock = FakeClock(Instant::now());
        let mut exhausted = resting(1, clock.now());
        exhausted.wait = ViewWait::Input;
        let due = RefineGate {
            merge_due: true,
            ..gate()
        };
        assert_eq!(
            refinement_candidate(&gate(), &[exhausted], 0, clock.now()),
            None
        );
        assert_eq!(
            refinement_candidate(&due, &[exhausted], 0, clock.now()),
            None
        );
        assert_eq!(
            next_rest(&due, &[exhausted], clock.now()),
            Some(clock.now() + Duration::from_millis(100))
        );
        clock.advance(100);
        assert_eq!(
            refinement_candidate(&due, &[exhausted], 0, clock.now()),
            Some(1)
        );
        let paused = TurnView {
            paused: true,
            ..exhausted
        };
        assert_eq!(refinement_candidate(&due, &[paused], 0, clock.now()), None);
    }

    /// Nothing deferred: everything owed may run now.
    fn all_allowed(owed: Owed) -> Allowed {
        let timing = |owed| if owed { Timing::Now } else { Timing::NotOwed };
        Allowed {
            sync: timing(owed.resync()),
            replan_soon: timing(owed.replan_soon()),
        }
    }

    /// Deferred by a pace.
    fn later() -> Timing {
        Timing::Deferred(Instant::now() + Duration::from_secs(1))
    }

    #[test]
    fn a_replan_that_may_wait_waits_for_its_pace() {
        let mut owed = Owed::default();
        owed.queue_changed();
        let deferred = Allowed {
            replan_soon: later(),
            ..all_allowed(owed)
        };
        let nothing = Feed {
            replan: false,
            replan_if_drained: false,
        };
        assert_eq!(feed(owed, &deferred, 3), nothing, "only submits");
        assert!(!has_work_now(owed, &deferred, &[], None));
        assert!(feed(owed, &all_allowed(owed), 3).replan);
        assert!(has_work_now(owed, &all_allowed(owed), &[], None));
    }

    #[test]
    fn an_owed_replan_comes_before_submitting_whatever_the_paces() {
        let mut owed = Owed::default();
        owed.views_changed();
        let deferred = Allowed {
            sync: later(),
            replan_soon: Timing::NotOwed,
        };
        let fed = feed(owed, &deferred, 3);
        assert!(fed.replan && !fed.replan_if_drained);
        assert!(has_work_now(owed, &deferred, &[], None));
    }

    #[test]
    fn a_queue_emptied_by_answers_is_replanned_before_the_viewers_are_told() {
        let mut owed = Owed::default();
        owed.samples_arrived();
        let allowed = all_allowed(owed);
        assert_eq!(
            feed(owed, &allowed, 3),
            Feed {
                replan: false,
                replan_if_drained: true,
            },
            "submitting may empty it"
        );
        assert!(feed(owed, &allowed, 0).replan, "already empty");
    }

    #[test]
    fn a_deferred_sync_is_owed_still_and_asks_for_no_replan() {
        let mut owed = Owed::default();
        owed.samples_arrived();
        let deferred = Allowed {
            sync: later(),
            ..all_allowed(owed)
        };
        for queued in [0, 3] {
            assert_eq!(
                feed(owed, &deferred, queued),
                Feed {
                    replan: false,
                    replan_if_drained: false,
                }
            );
        }
        assert!(owed.resync());
        assert!(!has_work_now(owed, &deferred, &[], None));
    }

    #[test]
    fn nothing_owed_only_submits() {
        let owed = Owed::default();
        let fed = feed(owed, &all_allowed(owed), 3);
        assert!(!fed.replan && !fed.replan_if_drained);
        assert!(!has_work_now(owed, &all_allowed(owed), &[], None));
    }
}
