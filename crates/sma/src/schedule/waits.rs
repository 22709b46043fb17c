//! What the schedule's work waits for, as two small state machines instead of loose flags
//! (DESIGN.md §3): per viewer, what its view and its refinement wait for ([`ViewWait`]); for the
//! whole SMA, what the next turn owes the request queue and the viewers ([`Owed`]).

/// What one viewer's view waits for before it can be refined.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewWait {
    /// No camera yet: nothing to see, nothing to refine.
    Camera,
    /// A visibility pass: the camera moved, the leaves changed, or K new samples came.
    /// `exhausted` carries over what the refinement waited for before (see `Input`).
    Pass { exhausted: bool },
    /// Its turn (its camera to rest, or with work while walking the rounds' pace): the view is
    /// current and its criterion has more to give.
    Rest,
    /// New input: the criterion found nothing more for this view, until new samples arrive,
    /// refinement groups are committed, or the viewer picks another criterion.
    Input,
}

impl ViewWait {
    /// A new camera: a pass first, and the criterion starts over.
    pub fn camera_moved(&mut self) {
        *self = ViewWait::Pass { exhausted: false };
    }

    /// The leaves changed or enough samples came: a viewer with a camera needs a pass.
    pub fn leaves_changed(&mut self) {
        *self = match *self {
            ViewWait::Camera => ViewWait::Camera,
            ViewWait::Pass { exhausted } => ViewWait::Pass { exhausted },
            ViewWait::Rest => ViewWait::Pass { exhausted: false },
            ViewWait::Input => ViewWait::Pass { exhausted: true },
        };
    }

    /// New input for the criterion (samples, committed groups, another criterion).
    pub fn new_input(&mut self) {
        *self = match *self {
            ViewWait::Pass { .. } => ViewWait::Pass { exhausted: false },
            ViewWait::Input => ViewWait::Rest,
            other => other,
        };
    }

    /// The visibility pass ran.
    pub fn pass_done(&mut self) {
        if let ViewWait::Pass { exhausted } = *self {
            *self = if exhausted {
                ViewWait::Input
            } else {
                ViewWait::Rest
            };
        }
    }

    /// The criterion found nothing more for this view.
    pub fn exhausted(&mut self) {
        if *self == ViewWait::Rest {
            *self = ViewWait::Input;
        }
    }

    pub fn needs_pass(self) -> bool {
        matches!(self, ViewWait::Pass { .. })
    }

    /// Whether the criterion waits for new input (also across a pending pass).
    pub fn is_exhausted(self) -> bool {
        matches!(self, ViewWait::Input | ViewWait::Pass { exhausted: true })
    }
}

/// What the next turn owes, beyond the viewers' passes: a re-plan of the request queue (the
/// visible sets or the renderers' work changed), at once or when its pace allows, and bringing
/// the viewers up to date (the cache or the visible sets changed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Owed {
    replan: bool,
    /// A re-plan that may wait for its pace: nothing new must be asked for at once, only the
    /// order of what is queued went stale.
    replan_soon: bool,
    resync: bool,
}

impl Owed {
    /// A viewer left, a batch failed or came back, a criterion ran dry: the queue must be
    /// re-planned, not at once.
    pub fn queue_changed(&mut self) {
        self.replan_soon = true;
    }

    /// Samples arrived: viewers may be shown more.
    pub fn samples_arrived(&mut self) {
        self.resync = true;
    }

    /// A pass ran: the visible sets changed, new leaves may lack samples. Both, at once.
    pub fn views_changed(&mut self) {
        self.replan = true;
        self.resync = true;
    }

    /// Refinement groups were committed: the viewers see new leaves, every one of them shaded,
    /// so the queue's order may wait for its pace.
    pub fn groups_committed(&mut self) {
        self.replan_soon = true;
        self.resync = true;
    }

    /// A walking camera came to rest: what its viewer kept of earlier views goes
    /// (`shown::Keeping`).
    pub fn camera_rested(&mut self) {
        self.resync = true;
    }

    pub fn replan(self) -> bool {
        self.replan
    }

    pub fn replan_soon(self) -> bool {
        self.replan_soon
    }

    pub fn resync(self) -> bool {
        self.resync
    }

    pub fn replanned(&mut self) {
        self.replan = false;
        self.replan_soon = false;
    }

    pub fn synced(&mut self) {
        self.resync = false;
    }

    pub fn any(self) -> bool {
        self.replan || self.replan_soon || self.resync
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_leads_through_a_pass_to_rest() {
        let mut w = ViewWait::Camera;
        w.leaves_changed();
        assert_eq!(w, ViewWait::Camera, "no camera, no pass");
        w.camera_moved();
        assert!(w.needs_pass() && !w.is_exhausted());
        w.pass_done();
        assert_eq!(w, ViewWait::Rest);
    }

    #[test]
    fn exhaustion_survives_a_pass_until_new_input() {
        let mut w = ViewWait::Rest;
        w.exhausted();
        assert_eq!(w, ViewWait::Input);
        w.leaves_changed();
        assert_eq!(w, ViewWait::Pass { exhausted: true });
        w.pass_done();
        assert_eq!(w, ViewWait::Input);
        w.new_input();
        assert_eq!(w, ViewWait::Rest);
        w.exhausted();
        w.camera_moved();
        assert_eq!(
            w,
            ViewWait::Pass { exhausted: false },
            "a camera starts over"
        );
    }

    #[test]
    fn new_input_during_a_pass_clears_exhaustion() {
        let mut w = ViewWait::Pass { exhausted: true };
        w.new_input();
        w.pass_done();
        assert_eq!(w, ViewWait::Rest);
    }

    #[test]
    fn owed_work_is_cleared_separately() {
        let mut owed = Owed::default();
        assert!(!owed.any());
        owed.views_changed();
        owed.replanned();
        assert!(!owed.replan() && owed.resync());
        owed.synced();
        owed.queue_changed();
        assert!(!owed.replan() && owed.replan_soon() && !owed.resync());
        owed.groups_committed();
        owed.replanned();
        assert!(!owed.replan_soon() && owed.resync());
    }
}
