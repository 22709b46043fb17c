//! Per-viewer state and the epoch sync (DESIGN.md §3 step 4, §8): what each viewer sees and holds,
//! its criterion, what its messages change, and bringing it up to date with
//! `Remove`/`Insert`/`Update`, `ToneMap` and the `Epoch` that closes each consistent update.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use protocol::viewer_link::{Camera, Epoch, SmaToViewer, ViewerToSma};

use super::ahead;
use super::pending::PendingRefinement;
use super::shown::{Keeping, ShownSet};
use super::targets::targets;
use super::turns::TurnView;
use super::waits::ViewWait;
use crate::cache::ShadingCache;
use crate::config::{Profile, ScheduleConfig};
use crate::criteria::{Criterion, CriterionKind, CriterionSettings, make_criterion};
use crate::direct_tiles::DirectTiles;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::viewer_link::{Outbox, ViewerEvent, ViewerId};
use crate::visibility::LeafView;

/// A walking viewer's view is drawn this many times the time since its last pass ahead of its
/// camera (`Viewer::pass_camera`): the view reaches the viewer a pass and a sync later, and is
/// shown until the next, so it serves cameras from about one interval to about one and a half
/// ahead of the one it was drawn for; the leading edge of the last of them is what must be
/// in it.
const LEAD_PER_INTERVAL: f64 = 1.5;

/// One connected viewer.
pub struct Viewer {
    outbox: Outbox,
    pub camera: Option<Camera>,
    /// When the camera last changed (it rests `ScheduleConfig::rest` later).
    pub camera_at: Instant,
    /// The camera replaced an earlier one (`turns::TurnView::camera_replaced`).
    pub camera_replaced: bool,
    /// The camera it replaced, and when that one came: the motion the plan looks ahead of
    /// (`ahead::focus`).
    pub previous: Option<(Camera, Instant)>,
    /// When its last refinement round began (`turns::TurnView::ready_at`).
    pub refined_at: Option<Instant>,
    /// When its last visibility pass was drawn (`pass_camera`).
    pub drawn_at: Option<Instant>,
    pub wait: ViewWait,
    /// The camera seq whose epoch is still owed.
    answer_pending: Option<u64>,
    pub view: Option<LeafView>,
    targets: Vec<(NodeId, protocol::Side)>,
    pub shown: ShownSet,
    pub criterion: Box<dyn Criterion>,
    pub paused: bool,
    /// The criterion's last round for this camera found nothing to subdivide: the view's
    /// samples then get more paths where their noise shows (DESIGN.md §5, §6).
    pub criterion_dry: bool,
    pub last_l_white: Option<f32>,
    last_outstanding: Option<u64>,
    /// The camera its last sync answered (`shown::Keeping`).
    synced_camera: Option<u64>,
    /// Its resting camera's direct light per pixel (`direct_tiles`).
    pub direct: DirectTiles,
}

/// What the schedule's state a sync reads.
pub struct SyncInput<'a> {
    pub mesh: &'a SubdivisionMesh,
    pub cache: &'a ShadingCache,
    pub pending: &'a PendingRefinement,
    /// Samples queued or in flight.
    pub outstanding_requests: u64,
    /// A run of the indirect filter is owed (its pace put it off) or under way: the shown values
    /// of samples already answered will still change (`indirect_filter`).
    pub filter_owed: bool,
    /// Samples computed so far, and the paths traced for them.
    pub samples: u64,
    pub paths: u64,
    pub now: Instant,
    /// `ScheduleConfig::kept_while_walking`.
    pub kept_while_walking: Duration,
}

impl Viewer {
    pub fn new(outbox: Outbox, criterion: Box<dyn Criterion>) -> Self {
        Viewer {
            outbox,
            camera: None,
            camera_at: Instant::now(),
            camera_replaced: false,
            previous: None,
            refined_at: None,
            drawn_at: None,
            wait: ViewWait::Camera,
            answer_pending: None,
            view: None,
            targets: Vec::new(),
            shown: ShownSet::default(),
            criterion,
            paused: false,
            criterion_dry: false,
            last_l_white: None,
            last_outstanding: None,
            synced_camera: None,
            direct: DirectTiles::default(),
        }
    }

    /// What this viewer's state holds, by capacity: its view, targets and shown table, its
    /// criterion's state, its direct-light tiles, and what waits in its outbox.
    pub fn heap_bytes(&self) -> usize {
        self.view.as_ref().map_or(0, LeafView::heap_bytes)
            + self.targets.capacity() * size_of::<(NodeId, protocol::Side)>()
            + self.shown.heap_bytes()
            + self.criterion.heap_bytes()
            + self.direct.heap_bytes()
            + self.outbox.waiting_bytes()
    }

    pub fn send(&self, message: SmaToViewer) {
        // A viewer that left is removed by its `Left` event.
        self.outbox.send(message);
    }

    /// A new camera: its epoch is owed, a pass comes first, the criterion starts over.
    pub fn camera_moved(&mut self, camera: Camera) {
        self.answer_pending = Some(camera.seq);
        self.camera_replaced = self.camera.is_some();
        self.previous = self.camera.take().map(|c| (c, self.camera_at));
        self.camera = Some(camera);
        self.camera_at = Instant::now();
        self.wait.camera_moved();
        self.criterion.reset();
        self.criterion_dry = false;
        // A move returns the viewer to the vertex picture at once (DESIGN.md §3 step 8).
        self.direct.camera_moved();
        self.outbox.drop_tiles();
    }

    /// When its camera rests, if it moved: a sync may be owed then, which, answering the camera
    /// the last one answered, drops what the viewer kept of earlier views (`shown::Keeping`),
    /// and a pass for a view drawn ahead of it (`pass_camera`).
    pub fn moved_camera_rests_at(&self, rest: Duration) -> Option<Instant> {
        self.camera_replaced.then(|| self.camera_at + rest)
    }

    /// Whether, once its camera rests, it owes a sync that drops what it keeps of earlier views
    /// (`shown::Keeping`), or a pass for a view drawn from another camera than the one now at
    /// rest (a walking view's lead, `pass_camera`).
    fn owes_at_rest(&self) -> bool {
        self.shown.kept > 0 || (self.view_behind_camera() && !self.wait.needs_pass())
    }

    /// The camera its pass is drawn from: its own, or while it walks (and `lead`), that camera
    /// a little ahead (`ahead::lead`), by [`LEAD_PER_INTERVAL`] times the time since its last
    /// pass, at most `ahead::MAX_LEAD`.
    pub fn pass_camera(&self, lead: bool, rest: Duration, now: Instant) -> Option<Camera> {
        let camera = self.camera.as_ref()?;
        let walking = self.camera_replaced && now < self.camera_at + rest;
        match (&self.previous, self.drawn_at) {
            (Some((previous, previous_at)), Some(drawn_at)) if lead && walking => {
                let since = now.saturating_duration_since(drawn_at);
                let by = since.mul_f64(LEAD_PER_INTERVAL).min(ahead::MAX_LEAD);
                Some(ahead::lead(
                    (previous, *previous_at),
                    (camera, self.camera_at),
                    by,
                ))
            }
            _ => Some(camera.clone()),
        }
    }

    /// Whether its view was drawn from another camera than its current one.
    pub fn view_behind_camera(&self) -> bool {
        self.view
            .as_ref()
            .is_some_and(|view| view.camera.as_ref() != self.camera.as_ref())
    }

    /// Sends what changed for this viewer, closed by an `Epoch`; nothing when nothing changed,
    /// no camera is answered and completeness did not flip. Nothing either while its pass is
    /// owed (a walking camera's, deferred by its pace): an epoch for its new camera must
    /// answer that camera's view, not the last one's.
    pub fn sync(&mut self, input: &SyncInput) {
        if self.wait.needs_pass() {
            return;
        }
        let (Some(view), Some(camera)) = (&self.view, &self.camera) else {
            return;
        };
        self.targets = targets(view, input.pending, input.mesh, camera.eye_vec());
        // Whether the camera rests is not asked of the clock: a sync follows a pass that took
        // longer than `rest`, so most of a walk's syncs came after its camera "rested" while
        // the next camera already waited unread. A sync for another camera than the last one
        // is a step of a walk; one for the same camera, a stop (or a rest, `moved_camera_rests_at`).
        let moved = self.synced_camera.is_some_and(|seq| seq != camera.seq);
        self.synced_camera = Some(camera.seq);
        let keeping = Keeping {
            now: input.now,
            walking: moved && !input.kept_while_walking.is_zero(),
            for_: input.kept_while_walking,
        };
        let mut messages = self.shown.sync(
            &self.targets,
            input.mesh,
            input.cache,
            camera.eye_vec(),
            keeping,
        );
        let l_white = input.cache.l_white(input.mesh, &view.visible);
        if self.last_l_white != Some(l_white) && l_white > 0.0 {
            self.last_l_white = Some(l_white);
            tracing::debug!(l_white, "tone map");
            messages.push(SmaToViewer::ToneMap { l_white });
        }
        // Truthful: zero only when nothing is asked for, every wanted triangle is shown, and
        // what is shown is final (no filter run owed, nothing kept of earlier views).
        let outstanding = input.outstanding_requests
            + (self.shown.unshown + self.shown.kept) as u64
            + u64::from(input.filter_owed);
        let answered = self.answer_pending.take();
        let completion_changed = self.last_outstanding.map(|o| o == 0) != Some(outstanding == 0);
        if messages.is_empty() && answered.is_none() && !completion_changed {
            return;
        }
        let epoch = Epoch {
            camera_seq: camera.seq,
            shown: self.shown.len() as u64,
            visible_leaves: view.visible.leaves.len() as u64,
            inserted: std::mem::take(&mut self.shown.inserted),
            removed: std::mem::take(&mut self.shown.removed),
            samples: input.samples,
            paths: input.paths,
            outstanding,
        };
        self.last_outstanding = Some(outstanding);
        for message in messages {
            self.send(message);
        }
        self.send(SmaToViewer::Epoch(epoch));
    }
}

/// Makes each viewer's criterion, with its own random stream.
#[derive(Clone, Debug)]
pub struct Criteria {
    /// The criterion a viewer starts with.
    first: CriterionKind,
    settings: CriterionSettings,
    seed: u64,
    /// Refinement at all (off: every viewer is told it is paused).
    refine: bool,
    /// Which criteria a viewer may ask for, and what runs for each (`Profile::criterion`).
    profile: Profile,
}

impl Criteria {
    /// A criterion's noise-aware significance floor is the schedule's `display_error`, and its
    /// samples settle at the ladder's cap: the stated end (DESIGN.md §5) asks samples and leaves
    /// for the same precision, one display step.
    pub fn new(config: &ScheduleConfig) -> Criteria {
        Criteria {
            first: config.criterion,
            settings: CriterionSettings {
                display_error: config.display_error,
                max_paths: config.max_paths,
                ..config.criterion_settings
            },
            seed: config.seed,
            refine: config.refine,
            profile: config.profile,
        }
    }

    /// A criterion of `kind` for viewer `id`.
    fn make(&self, kind: CriterionKind, id: ViewerId) -> Box<dyn Criterion> {
        make_criterion(kind, &self.settings, self.seed ^ id)
    }

    fn refinement_state(&self, viewer: &Viewer) -> SmaToViewer {
        SmaToViewer::Refinement {
            criterion: viewer.criterion.kind().name().to_string(),
            paused: viewer.paused || !self.refine,
        }
    }
}

/// What a viewer's event changes beyond that viewer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heard {
    Nothing,
    /// A viewer left: the queue holds needs of its view.
    Left,
}

/// Every connected viewer, by id.
#[derive(Default)]
pub struct Viewers {
    by_id: BTreeMap<ViewerId, Viewer>,
}

impl Viewers {
    pub fn is_empty(&self) -> bool {
        self.by_id.is_empty()
    }

    pub fn len(&self) -> usize {
        self.by_id.len()
    }

    pub fn get(&self, id: ViewerId) -> Option<&Viewer> {
        self.by_id.get(&id)
    }

    pub fn get_mut(&mut self, id: ViewerId) -> Option<&mut Viewer> {
        self.by_id.get_mut(&id)
    }

    pub fn iter(&self) -> impl Iterator<Item = &Viewer> {
        self.by_id.values()
    }

    pub fn iter_mut(&mut self) -> impl Iterator<Item = &mut Viewer> {
        self.by_id.values_mut()
    }

    /// Every viewer's current view.
    pub fn views(&self) -> impl Iterator<Item = &LeafView> {
        self.iter().filter_map(|v| v.view.as_ref())
    }

    /// The first rest of a camera whose viewer owes something at its rest
    /// (`Viewer::owes_at_rest`). The loop wakes for it while it lies ahead; once passed, the
    /// sync it owes waits for the sync's own pace, not a spinning loop.
    pub fn next_rest_owed(&self, rest: Duration) -> Option<Instant> {
        self.iter()
            .filter(|v| v.owes_at_rest())
            .filter_map(|v| v.moved_camera_rests_at(rest))
            .min()
    }

    /// Whether a camera has come to rest by `now` while its viewer owes something at its rest:
    /// then a sync is owed, and a view drawn ahead of the camera is owed its pass.
    pub fn came_to_rest(&mut self, rest: Duration, now: Instant) -> bool {
        let mut any = false;
        for viewer in self.iter_mut().filter(|v| v.owes_at_rest()) {
            if viewer.moved_camera_rests_at(rest).is_some_and(|t| t <= now) {
                any = true;
                if viewer.view_behind_camera() {
                    viewer.wait.leaves_changed();
                }
            }
        }
        any
    }

    /// Whether a visibility pass is owed to anyone.
    pub fn need_pass(&self) -> bool {
        self.iter().any(|v| v.wait.needs_pass())
    }

    /// The leaves changed, or K samples came: every viewer with a camera needs a pass.
    pub fn leaves_changed(&mut self) {
        self.iter_mut().for_each(|v| v.wait.leaves_changed());
    }

    /// New input for every viewer's criterion (samples, committed groups).
    pub fn new_input(&mut self) {
        self.iter_mut().for_each(|v| v.wait.new_input());
    }

    /// The viewers as the turn order sees them.
    pub fn turn_views(&self) -> Vec<TurnView> {
        self.by_id
            .iter()
            .map(|(&id, v)| TurnView {
                id,
                has_view: v.view.is_some(),
                paused: v.paused,
                wait: v.wait,
                camera_at: v.camera_at,
                camera_replaced: v.camera_replaced,
                view_behind_camera: v.view_behind_camera(),
                refined_at: v.refined_at,
            })
            .collect()
    }

    /// A viewer joined, left or sent a message (DESIGN.md §8).
    pub fn on_event(&mut self, event: ViewerEvent, criteria: &Criteria) -> Heard {
        match event {
            ViewerEvent::Joined { id, outbox } => {
                let viewer = Viewer::new(outbox, criteria.make(criteria.first, id));
                viewer.send(criteria.refinement_state(&viewer));
                self.by_id.insert(id, viewer);
                Heard::Nothing
            }
            ViewerEvent::Left { id } => {
                self.by_id.remove(&id);
                Heard::Left
            }
            ViewerEvent::Message { id, message } => self.on_message(id, message, criteria),
        }
    }

    fn on_message(&mut self, id: ViewerId, message: ViewerToSma, criteria: &Criteria) -> Heard {
        let Some(viewer) = self.by_id.get_mut(&id) else {
            return Heard::Nothing;
        };
        let heard = match message {
            ViewerToSma::Camera(camera) => {
                viewer.camera_moved(camera);
                Heard::Nothing
            }
            ViewerToSma::SetCriterion { name } => {
                // Under the thesis profile `nld-os` runs as `nld-os-thesis` (the `Refinement`
                // reply names it) and `nld-px` is refused: the viewer keeps its criterion.
                match criteria.profile.criterion_named(&name) {
                    Ok(kind) => {
                        viewer.criterion = criteria.make(kind, id);
                        viewer.wait.new_input();
                    }
                    Err(refused) => {
                        tracing::warn!(viewer = id, %name, %refused, "criterion refused");
                        viewer.send(SmaToViewer::Error {
                            message: refused.to_string(),
                        });
                    }
                }
                Heard::Nothing
            }
            ViewerToSma::Pause => {
                viewer.paused = true;
                Heard::Nothing
            }
            ViewerToSma::Resume => {
                viewer.paused = false;
                Heard::Nothing
            }
            // The viewer's link keeps these to itself (`viewer_link::serve`).
            ViewerToSma::Bye | ViewerToSma::Pong { .. } => return Heard::Nothing,
        };
        viewer.send(criteria.refinement_state(viewer));
        heard
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use conventions::camera::look_rotation;
    use glam::Vec3;

    const REST: Duration = Duration::from_millis(100);

    fn viewer() -> Viewer {
        let (outbox, _writer) = crate::viewer_link::outbox(1 << 20);
        let settings = CriterionSettings::default();
        Viewer::new(outbox, make_criterion(CriterionKind::NldPx, &settings, 1))
    }

    fn camera(seq: u64, target_x: f32) -> Camera {
        Camera {
            seq,
            eye: [0.0; 3],
            orientation: look_rotation(Vec3::ZERO, Vec3::new(target_x, 0.0, -1.0), Vec3::Y)
                .to_array(),
            fov_y_deg: 60.0,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn a_walking_viewers_pass_leads_its_camera_and_at_rest_its_view_is_drawn_again() {
        let mut v = viewer();
        v.camera_moved(camera(1, 0.0));
        let first = v.camera_at;
        assert_eq!(v.pass_camera(true, REST, first), Some(camera(1, 0.0)));
        v.camera_moved(camera(2, 0.03));
        let now = v.camera_at;
        v.drawn_at = now.checked_sub(Duration::from_millis(200));
        let led = v.pass_camera(true, REST, now).unwrap();
        let turned_right = led.pinhole().forward().x > camera(2, 0.03).pinhole().forward().x;
        assert!(turned_right, "the turn continued: {led:?}");
        assert_eq!(v.pass_camera(false, REST, now), Some(camera(2, 0.03)));
        let rested = now + REST;
        assert_eq!(v.pass_camera(true, REST, rested), Some(camera(2, 0.03)));
        // Its view drawn from the led camera: at rest a pass is owed, from the camera itself.
        v.wait.pass_done();
        v.view = Some(LeafView {
            camera: Some(led),
            ..LeafView::default()
        });
        let mut viewers = Viewers::default();
        viewers.by_id.insert(1, v);
        assert_eq!(viewers.next_rest_owed(REST), Some(rested));
        assert!(!viewers.came_to_rest(REST, now));
        assert!(!viewers.need_pass());
        assert!(viewers.came_to_rest(REST, rested));
        assert!(viewers.need_pass(), "drawn again at rest");
    }
}
