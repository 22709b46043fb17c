//! Per-viewer state and the epoch sync (DESIGN.md §3 step 4, §8): what each viewer sees and holds,
//! its criterion, and bringing it up to date with `Remove`/`Insert`/`Update`, `ToneMap` and the
//! `Epoch` that closes each consistent update.

use std::time::Instant;

use protocol::viewer_link::{Camera, Epoch, SmaToViewer};

use super::display::Display;
use super::pending::PendingRefinement;
use super::plan;
use super::waits::ViewWait;
use crate::cache::ShadingCache;
use crate::criteria::Criterion;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::viewer_link::Outbox;
use crate::visibility::LeafView;

/// One connected viewer.
pub struct Viewer {
    outbox: Outbox,
    pub camera: Option<Camera>,
    /// When the camera last changed (refinement waits for it to rest).
    pub camera_at: Instant,
    /// The camera replaced an earlier one (`turns::TurnView::camera_replaced`).
    pub camera_replaced: bool,
    pub wait: ViewWait,
    /// The camera seq whose epoch is still owed.
    answer_pending: Option<u64>,
    pub view: Option<LeafView>,
    targets: Vec<(NodeId, protocol::Side)>,
    pub display: Display,
    pub criterion: Box<dyn Criterion>,
    pub paused: bool,
    /// The criterion's last round for this camera found nothing to subdivide: the view's
    /// samples then get more paths where their noise shows (DESIGN.md §5, §6).
    pub criterion_dry: bool,
    pub last_l_white: Option<f32>,
    last_outstanding: Option<u64>,
}

/// What the schedule's state a sync reads.
pub struct SyncInput<'a> {
    pub mesh: &'a SubdivisionMesh,
    pub cache: &'a ShadingCache,
    pub pending: &'a PendingRefinement,
    /// Samples queued or in flight.
    pub outstanding_requests: u64,
    /// Samples computed so far, and the paths traced for them.
    pub samples: u64,
    pub paths: u64,
}

impl Viewer {
    pub fn new(outbox: Outbox, criterion: Box<dyn Criterion>) -> Self {
        Viewer {
            outbox,
            camera: None,
            camera_at: Instant::now(),
            camera_replaced: false,
            wait: ViewWait::Camera,
            answer_pending: None,
            view: None,
            targets: Vec::new(),
            display: Display::default(),
            criterion,
            paused: false,
            criterion_dry: false,
            last_l_white: None,
            last_outstanding: None,
        }
    }

    pub fn send(&self, message: SmaToViewer) {
        // A viewer that left is removed by its `Left` event.
        self.outbox.send(message);
    }

    /// A new camera: its epoch is owed, a pass comes first, the criterion starts over.
    pub fn camera_moved(&mut self, camera: Camera) {
        self.answer_pending = Some(camera.seq);
        self.camera_replaced = self.camera.is_some();
        self.camera = Some(camera);
        self.camera_at = Instant::now();
        self.wait.camera_moved();
        self.criterion.reset();
        self.criterion_dry = false;
    }

    /// Sends what changed for this viewer, closed by an `Epoch`; nothing when nothing changed,
    /// no camera is answered and completeness did not flip.
    pub fn sync(&mut self, input: &SyncInput) {
        let (Some(view), Some(camera)) = (&self.view, &self.camera) else {
            return;
        };
        self.targets = plan::targets(view, input.pending, input.mesh, camera.eye_vec());
        let mut messages =
            self.display
                .sync(&self.targets, input.mesh, input.cache, camera.eye_vec());
        let l_white = input.cache.l_white(input.mesh, &view.visible);
        if self.last_l_white != Some(l_white) && l_white > 0.0 {
            self.last_l_white = Some(l_white);
            tracing::debug!(l_white, "tone map");
            messages.push(SmaToViewer::ToneMap { l_white });
        }
        // Truthful: zero only when nothing is asked for and every wanted triangle is shown.
        let outstanding = input.outstanding_requests + self.display.unshown as u64;
        let answered = self.answer_pending.take();
        let completion_changed = self.last_outstanding.map(|o| o == 0) != Some(outstanding == 0);
        if messages.is_empty() && answered.is_none() && !completion_changed {
            return;
        }
        let epoch = Epoch {
            camera_seq: camera.seq,
            shown: self.display.shown() as u64,
            visible_leaves: view.visible.leaves.len() as u64,
            inserted: std::mem::take(&mut self.display.inserted),
            removed: std::mem::take(&mut self.display.removed),
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
