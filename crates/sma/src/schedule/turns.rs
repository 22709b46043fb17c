//! The decisions of a turn (see the module documentation of `schedule`), as plain functions of
//! the schedule's state and the time that return what to do, so they are tested with a fake
//! clock: when the request queue is re-planned and fed ([`Feed`]), which passes are owed and how
//! urgently ([`passes_owed`]), which viewer may refine, and when the loop must wake for a camera
//! coming to rest or a round's pace. The schedule carries them out. What the paces allow is
//! decided apart, in `pace`.

use std::time::{Duration, Instant};

use super::pace::{Allowed, PassesOwed};
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
    /// Its camera replaced an earlier one: the viewer may be walking, so its camera rests only
    /// once unchanged for `RefineGate::rest`. A viewer's first camera rests at once: nothing
    /// says it moves, and a person who has just opened a view is looking at it.
    pub camera_replaced: bool,
    /// Its view was drawn from another camera than its current one: the pass it is owed is a
    /// new view, not the same view's changed leaves.
    pub view_behind_camera: bool,
    /// When its last refinement round began.
    pub refined_at: Option<Instant>,
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

    /// Whether the pass it is owed is a walking camera's, which may wait for its pace: its
    /// view was drawn from another camera, and the current one has not come to rest yet. A
    /// camera at rest is a stop, whose view is owed at once (DESIGN.md §3 step 6:
    /// interactivity first): the pace is the walk's cycles' cost times three, so with a large
    /// mesh a stop's first picture waited up to a second and a half for it.
    fn walking(&self, rest: Duration, now: Instant) -> bool {
        self.has_view && self.view_behind_camera && now < self.rests_at(rest)
    }

    /// Whether it may be refined at all: it has a view, is not paused, and its criterion has
    /// not run dry, or a pass of coarsening by uniformity is due, which a viewer whose criterion
    /// found nothing more still takes its turn for (`uniformity`).
    fn refinable(&self, gate: &RefineGate) -> bool {
        self.has_view && !self.paused && (!self.wait.is_exhausted() || gate.merge_due)
    }

    /// When it may be refined, as far as its camera and the rounds' pace say. A camera that has
    /// come to rest since the viewer's last round is a new view, refined at its rest whatever
    /// the rounds cost (DESIGN.md §3 step 6: interactivity first); otherwise rounds keep their
    /// pace. Without work while walking a camera is refined only at rest; with it (DESIGN.md §3
    /// step 9), a moving camera is refined at the rounds' pace too.
    fn ready_at(&self, gate: &RefineGate, now: Instant) -> Instant {
        let rests_at = self.rests_at(gate.rest);
        let paced = gate.next_round_at.unwrap_or(now);
        let new_rest = self.refined_at.is_none_or(|at| rests_at > at);
        if self.wait.is_exhausted() {
            // A turn for merging alone: a view is judged uniform only at rest.
            return rests_at.max(paced);
        }
        match (new_rest, gate.while_walking) {
            (true, true) => rests_at.min(paced),
            (true, false) => rests_at,
            (false, _) => rests_at.max(paced),
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
    /// Refinement also while a camera moves (`ScheduleConfig::work_while_walking`).
    pub while_walking: bool,
    /// No round before this: the rounds' pace (`ScheduleConfig::round_share`).
    pub next_round_at: Option<Instant>,
    /// A pass of coarsening by uniformity is due (`uniformity`): it comes with a round, so a
    /// viewer whose criterion found nothing more still takes its turn for it.
    pub merge_due: bool,
}

/// The viewer whose turn it is to refine at `now`, if refinement may run: never while a pass is
/// owed to anyone (a camera change interrupts refinement at once, and a round reads the current
/// camera's view), while groups wait, while the queue is long (a new view's missing samples
/// come first), or before a viewer is ready (`TurnView::ready_at`); then the ready viewers take
/// turns (`round` counts the rounds so far).
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
    {
        return None;
    }
    let ready: Vec<ViewerId> = viewers
        .iter()
        .filter(|v| v.refinable(gate) && now >= v.ready_at(gate, now))
        .map(|v| v.id)
        .collect();
    (!ready.is_empty()).then(|| ready[round % ready.len()])
}

/// When the next viewer becomes ready to refine after `now` (a camera coming to rest, or the
/// rounds' pace), if refinement waits only for that.
pub fn next_ready(gate: &RefineGate, viewers: &[TurnView], now: Instant) -> Option<Instant> {
    if !gate.refine {
        return None;
    }
    viewers
        .iter()
        .filter(|v| v.refinable(gate))
        .map(|v| v.ready_at(gate, now))
        .filter(|&t| t > now)
        .min()
}

/// The passes owed at `now`, and whether they may wait for their pace: only when every one owed
/// is for a walking viewer's new camera not yet at rest (`while_walking`, DESIGN.md §3 step 9;
/// `TurnView::walking`). A viewer's first camera (no view yet, its first picture waits for the
/// pass), a camera come to rest and leaves that changed under an unchanged camera never wait;
/// without work while walking nothing does, as before.
pub fn passes_owed(
    viewers: &[TurnView],
    while_walking: bool,
    rest: Duration,
    now: Instant,
) -> PassesOwed {
    let mut owed = viewers.iter().filter(|v| v.wait.needs_pass()).peekable();
    if owed.peek().is_none() {
        PassesOwed::None
    } else if while_walking && owed.all(|v| v.walking(rest, now)) {
        PassesOwed::Walking
    } else {
        PassesOwed::AtOnce
    }
}

/// When the first walking camera owed a pass comes to rest after `now`: its pass is then owed
/// at once, and the loop must wake for it rather than for the walking pace.
pub fn next_rest(viewers: &[TurnView], rest: Duration, now: Instant) -> Option<Instant> {
    viewers
        .iter()
        .filter(|v| v.wait.needs_pass() && v.walking(rest, now))
        .map(|v| v.rests_at(rest))
        .min()
}

/// Whether a turn has something to do without any new event: work owed that no pace defers (a
/// pass among it), or a refinement round.
pub fn has_work_now(owed: Owed, allowed: &Allowed, candidate: Option<ViewerId>) -> bool {
    owed.replan()
        || allowed.replan_soon.now()
        || allowed.sync.now()
        || allowed.pass.now()
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
mod tests;
