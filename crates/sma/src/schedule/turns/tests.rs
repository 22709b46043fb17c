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
        while_walking: false,
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
        view_behind_camera: false,
        refined_at: None,
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
        next_ready(&gate(), &viewers, clock.now()),
        Some(clock.now() + Duration::from_millis(100))
    );
    clock.advance(100);
    assert_eq!(
        refinement_candidate(&gate(), &viewers, 0, clock.now()),
        Some(1)
    );
    assert_eq!(
        next_ready(&gate(), &viewers, clock.now()),
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
    assert_eq!(next_ready(&gate(), &[first], clock.now()), None);
}

#[test]
fn rounds_wait_for_their_pace_and_the_loop_wakes_for_it() {
    let mut clock = FakeClock(Instant::now());
    let mut viewer = resting(1, clock.now());
    clock.advance(1000);
    viewer.refined_at = Some(clock.now());
    let viewers = [viewer];
    let paced = RefineGate {
        next_round_at: Some(clock.now() + Duration::from_millis(400)),
        ..gate()
    };
    assert_eq!(refinement_candidate(&paced, &viewers, 0, clock.now()), None);
    assert_eq!(
        next_ready(&paced, &viewers, clock.now()),
        paced.next_round_at,
        "the loop wakes when the pace allows, not only when a camera rests"
    );
    clock.advance(400);
    assert_eq!(
        refinement_candidate(&paced, &viewers, 0, clock.now()),
        Some(1)
    );
    assert_eq!(next_ready(&paced, &viewers, clock.now()), None);
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
    let pass = Allowed {
        pass: Timing::Now,
        ..all_allowed(Owed::default())
    };
    assert!(has_work_now(Owed::default(), &pass, None));
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
        next_ready(&due, &[exhausted], clock.now()),
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

/// A viewer walking: a new camera every 33 ms, its view drawn for each.
fn walking(clock: &mut FakeClock, viewer: &mut TurnView, steps: usize) {
    for _ in 0..steps {
        clock.advance(33);
        viewer.camera_at = clock.now();
    }
}

#[test]
fn a_walking_camera_is_refined_at_the_rounds_pace_only_when_working_while_walking() {
    let mut clock = FakeClock(Instant::now());
    let mut viewer = resting(1, clock.now());
    viewer.refined_at = Some(clock.now());
    walking(&mut clock, &mut viewer, 10);
    let walk = RefineGate {
        while_walking: true,
        ..gate()
    };
    assert_eq!(
        refinement_candidate(&gate(), &[viewer], 0, clock.now()),
        None
    );
    assert_eq!(
        next_ready(&gate(), &[viewer], clock.now()),
        Some(clock.now() + Duration::from_millis(100)),
        "only once it rests"
    );
    assert_eq!(
        refinement_candidate(&walk, &[viewer], 0, clock.now()),
        Some(1)
    );
    // At the rounds' pace, not at every camera.
    let paced = RefineGate {
        next_round_at: Some(clock.now() + Duration::from_millis(50)),
        ..walk
    };
    assert_eq!(
        refinement_candidate(&paced, &[viewer], 0, clock.now()),
        None
    );
    assert_eq!(
        next_ready(&paced, &[viewer], clock.now()),
        paced.next_round_at
    );
    clock.advance(50);
    assert_eq!(
        refinement_candidate(&paced, &[viewer], 0, clock.now()),
        Some(1)
    );
    // A pass owed for its next camera comes first, walking or not.
    viewer.wait = ViewWait::Pass { exhausted: false };
    assert_eq!(refinement_candidate(&walk, &[viewer], 0, clock.now()), None);
}

#[test]
fn a_camera_coming_to_rest_lifts_the_rounds_pace_once() {
    let mut clock = FakeClock(Instant::now());
    let mut viewer = resting(1, clock.now());
    walking(&mut clock, &mut viewer, 10);
    viewer.refined_at = Some(clock.now());
    for while_walking in [true, false] {
        let paced = RefineGate {
            while_walking,
            next_round_at: Some(clock.now() + Duration::from_secs(5)),
            ..gate()
        };
        let rests_at = viewer.camera_at + paced.rest;
        assert_eq!(next_ready(&paced, &[viewer], clock.now()), Some(rests_at));
        let at_rest = rests_at;
        assert_eq!(refinement_candidate(&paced, &[viewer], 0, at_rest), Some(1));
        // Refined since it rests: the pace holds again.
        let refined = TurnView {
            refined_at: Some(at_rest),
            ..viewer
        };
        assert_eq!(refinement_candidate(&paced, &[refined], 0, at_rest), None);
        assert_eq!(next_ready(&paced, &[refined], at_rest), paced.next_round_at);
    }
}

#[test]
fn only_a_walking_cameras_passes_may_wait() {
    let now = Instant::now();
    let moved = TurnView {
        wait: ViewWait::Pass { exhausted: false },
        view_behind_camera: true,
        ..resting(1, now)
    };
    let leaves = TurnView {
        view_behind_camera: false,
        ..moved
    };
    let first = TurnView {
        has_view: false,
        camera_replaced: false,
        ..moved
    };
    let settled = resting(2, now);
    let owed =
        |viewers: &[TurnView], while_walking| passes_owed(viewers, while_walking, gate().rest, now);
    assert_eq!(owed(&[settled], true), PassesOwed::None);
    assert_eq!(owed(&[moved, settled], true), PassesOwed::Walking);
    assert_eq!(owed(&[moved], false), PassesOwed::AtOnce, "off");
    for at_once in [leaves, first] {
        assert_eq!(owed(&[moved, at_once], true), PassesOwed::AtOnce);
    }
    // A pass its pace defers is no work now: the loop sleeps until it is due.
    let deferred = Allowed {
        pass: later(),
        ..all_allowed(Owed::default())
    };
    assert!(!has_work_now(Owed::default(), &deferred, None));
    assert!(deferred.wake_at().is_some());
}

/// A walking camera that stops (a person stops to look) is owed its view at once once it
/// rests, whatever the walk's pace, and the loop wakes for that instant.
#[test]
fn a_camera_come_to_rest_is_owed_its_pass_at_once() {
    let mut clock = FakeClock(Instant::now());
    let rest = gate().rest;
    let stopped = TurnView {
        wait: ViewWait::Pass { exhausted: false },
        view_behind_camera: true,
        ..resting(1, clock.now())
    };
    let viewers = [stopped];
    assert_eq!(
        passes_owed(&viewers, true, rest, clock.now()),
        PassesOwed::Walking
    );
    assert_eq!(
        next_rest(&viewers, rest, clock.now()),
        Some(clock.now() + rest)
    );
    clock.advance(100);
    assert_eq!(
        passes_owed(&viewers, true, rest, clock.now()),
        PassesOwed::AtOnce
    );
    assert_eq!(next_rest(&viewers, rest, clock.now()), None);
}

/// Nothing deferred: everything owed may run now.
fn all_allowed(owed: Owed) -> Allowed {
    let timing = |owed| if owed { Timing::Now } else { Timing::NotOwed };
    Allowed {
        pass: Timing::NotOwed,
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
    assert!(!has_work_now(owed, &deferred, None));
    assert!(feed(owed, &all_allowed(owed), 3).replan);
    assert!(has_work_now(owed, &all_allowed(owed), None));
}

#[test]
fn an_owed_replan_comes_before_submitting_whatever_the_paces() {
    let mut owed = Owed::default();
    owed.views_changed();
    let deferred = Allowed {
        pass: Timing::NotOwed,
        sync: later(),
        replan_soon: Timing::NotOwed,
    };
    let fed = feed(owed, &deferred, 3);
    assert!(fed.replan && !fed.replan_if_drained);
    assert!(has_work_now(owed, &deferred, None));
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
    assert!(!has_work_now(owed, &deferred, None));
}

#[test]
fn nothing_owed_only_submits() {
    let owed = Owed::default();
    let fed = feed(owed, &all_allowed(owed), 3);
    assert!(!fed.replan && !fed.replan_if_drained);
    assert!(!has_work_now(owed, &all_allowed(owed), None));
}
