//! The event loop of the SMA (DESIGN.md §3, thesis §2.2, §4.1): one owner of the mesh, the
//! cache, the visibility passes and every viewer's state, fed by two channels (viewers, renderer
//! pool). Each turn it first takes every waiting event, then, in this order:
//!
//! 1. visibility for viewers whose camera changed (or whose leaves changed), two levels;
//! 2. refinement groups whose visible new leaves are all shaded are committed;
//! 3. the request queue is re-planned when the visible sets or the cache changed, and batches
//!    go to the pool while it has room (a queue that empties because answers satisfied it is
//!    re-planned at once);
//! 4. each viewer is brought up to date (`Remove`/`Insert`/`Update`, `ToneMap`, `Epoch`), the
//!    epoch counting what is truly outstanding after step 3;
//! 5. only then, when no camera is waiting, the queue is short and a viewer's camera rests, one
//!    refinement round of at most R selections runs; its passes come at the next turn, after any
//!    camera that arrived meanwhile. A camera change so interrupts refinement at once.
//!
//! It runs on its own thread: the visibility passes block for milliseconds (software
//! rasterizer), and must not stall the tasks serving viewers and renderers.

mod coarsening;
mod display;
mod pending;
mod plan;
mod requests;

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use anyhow::Context;
use glam::Vec3;
use protocol::renderer_link::{Quality, point_flags};
use protocol::viewer_link::{Camera, Epoch, SmaToViewer, Stats, ViewerToSma};
use scene::Scene;
use tokio::sync::{mpsc, watch};

use crate::cache::{CachedSample, ShadingCache};
use crate::criteria::{CRITERIA, Criterion, CriterionInput, CriterionSettings, LuminanceImage};
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::nld::luminance;
use crate::pool::{PoolEvent, PoolHandle};
use crate::viewer_link::{ViewerEvent, ViewerId};
use crate::visibility::{Gpu, LeafView, LuminancePass, Visibility};
use coarsening::Coarsening;
use display::Display;
use pending::PendingRefinement;
use plan::{Aging, NeedsInput, Qualities};
use requests::Requests;

/// Every knob of the loop (the CLI fills it; see `cli` for the defaults and why).
#[derive(Clone, Debug)]
pub struct ScheduleConfig {
    pub criterion: String,
    pub criterion_settings: CriterionSettings,
    /// Refinement at all (off: the end-to-end control run).
    pub refine: bool,
    /// R: selections per refinement round (§4.3.5).
    pub max_selections: usize,
    /// No leaf covering fewer pixels is split.
    pub min_split_pixels: u32,
    /// K: visibility is re-run after this many new samples.
    pub revisit_samples: u64,
    pub batch_points: usize,
    /// Batches in flight per connected renderer.
    pub batches_per_renderer: usize,
    /// Refinement waits until fewer samples than this are queued or in flight.
    pub queue_low: usize,
    /// A camera rests once unchanged this long.
    pub rest: Duration,
    pub view_angle_deg: f32,
    pub stats_every: Duration,
    pub cache_budget_bytes: usize,
    /// Visibility passes a base triangle must be out of every view before its subdivision is
    /// collapsed; 0: never.
    pub coarsen_after_passes: u64,
    pub seed: u64,
}

/// One connected viewer.
struct Viewer {
    outbox: mpsc::UnboundedSender<SmaToViewer>,
    camera: Option<Camera>,
    camera_at: Instant,
    needs_pass: bool,
    /// The camera seq whose epoch is still owed.
    answer_pending: Option<u64>,
    view: Option<LeafView>,
    targets: Vec<(NodeId, protocol::Side)>,
    display: Display,
    criterion: Box<dyn Criterion>,
    paused: bool,
    /// The criterion found nothing more for this view.
    exhausted: bool,
    last_l_white: Option<f32>,
    last_outstanding: Option<u64>,
}

impl Viewer {
    fn send(&self, message: SmaToViewer) {
        // A viewer that left is removed by its `Left` event.
        let _ = self.outbox.send(message);
    }
}

pub struct Schedule {
    config: ScheduleConfig,
    view_dependent: Vec<bool>,
    qualities: Qualities,
    aging: Aging,
    mesh: SubdivisionMesh,
    cache: ShadingCache,
    visibility: Visibility,
    luminance: LuminancePass,
    pending: PendingRefinement,
    coarsening: Coarsening,
    requests: Requests,
    pool: PoolHandle,
    renderers: usize,
    viewers: BTreeMap<ViewerId, Viewer>,
    /// Re-plan the queue at the next turn / bring viewers up to date.
    replan: bool,
    resync: bool,
    samples: u64,
    samples_since_pass: u64,
    samples_at_last_stats: u64,
    last_stats: Instant,
    frame: u64,
    refine_turn: usize,
}

impl Schedule {
    pub fn new(
        config: ScheduleConfig,
        scene: &Scene,
        mesh: SubdivisionMesh,
        gpu: Gpu,
        pool: PoolHandle,
    ) -> anyhow::Result<Schedule> {
        anyhow::ensure!(
            CRITERIA.contains(&config.criterion.as_str()),
            "unknown criterion {:?}; known: {}",
            config.criterion,
            CRITERIA.join(", ")
        );
        let view_dependent = (0..scene.mesh.triangles.len())
            .map(|t| scene.material_of(t).is_view_dependent())
            .collect();
        let quality = scene.settings.quality;
        let qualities = Qualities::new(Quality {
            paths: quality.paths,
            bounces: quality.bounces,
        });
        let aging = Aging {
            max_angle_rad: config.view_angle_deg.to_radians(),
        };
        let luminance = LuminancePass::new(&gpu);
        let visibility = Visibility::new(gpu, &mesh, scene.mesh.bounds());
        let coarsening = Coarsening::new(mesh.base_count(), config.coarsen_after_passes);
        Ok(Schedule {
            coarsening,
            cache: ShadingCache::new(config.cache_budget_bytes),
            requests: Requests::new(config.seed),
            config,
            view_dependent,
            qualities,
            aging,
            mesh,
            visibility,
            luminance,
            pending: PendingRefinement::default(),
            pool,
            renderers: 0,
            viewers: BTreeMap::new(),
            replan: false,
            resync: false,
            samples: 0,
            samples_since_pass: 0,
            samples_at_last_stats: 0,
            last_stats: Instant::now(),
            frame: 0,
            refine_turn: 0,
        })
    }

    pub fn adapter(&self) -> String {
        self.visibility.gpu().describe()
    }

    /// Runs until shutdown or until both channels close.
    pub async fn run(
        mut self,
        mut viewers: mpsc::UnboundedReceiver<ViewerEvent>,
        mut pool: mpsc::UnboundedReceiver<PoolEvent>,
        mut shutdown: watch::Receiver<bool>,
    ) -> anyhow::Result<()> {
        let mut stats = tokio::time::interval(self.config.stats_every);
        loop {
            let work_now = self.has_work_now();
            let rest_at = self.next_rest();
            tokio::select! {
                biased;
                _ = shutdown.changed() => return Ok(()),
                event = viewers.recv() => match event {
                    Some(event) => self.on_viewer_event(event),
                    None => return Ok(()),
                },
                Some(event) = pool.recv() => self.on_pool_event(event),
                _ = stats.tick() => self.report_stats(),
                _ = sleep_until(rest_at), if rest_at.is_some() => {}
                _ = std::future::ready(()), if work_now => {}
            }
            while let Ok(event) = viewers.try_recv() {
                self.on_viewer_event(event);
            }
            while let Ok(event) = pool.try_recv() {
                self.on_pool_event(event);
            }
            self.turn()?;
        }
    }

    fn on_viewer_event(&mut self, event: ViewerEvent) {
        match event {
            ViewerEvent::Joined { id, outbox } => {
                let criterion = self.make_criterion(&self.config.criterion.clone(), id);
                let viewer = Viewer {
                    outbox,
                    camera: None,
                    camera_at: Instant::now(),
                    needs_pass: false,
                    answer_pending: None,
                    view: None,
                    targets: Vec::new(),
                    display: Display::default(),
                    criterion,
                    paused: false,
                    exhausted: false,
                    last_l_white: None,
                    last_outstanding: None,
                };
                viewer.send(self.refinement_state(&viewer));
                self.viewers.insert(id, viewer);
            }
            ViewerEvent::Left { id } => {
                self.viewers.remove(&id);
                self.replan = true;
            }
            ViewerEvent::Message { id, message } => self.on_viewer_message(id, message),
        }
    }

    fn on_viewer_message(&mut self, id: ViewerId, message: ViewerToSma) {
        let seed = self.config.seed;
        let settings = self.config.criterion_settings;
        let Some(viewer) = self.viewers.get_mut(&id) else {
            return;
        };
        match message {
            ViewerToSma::Camera(camera) => {
                viewer.answer_pending = Some(camera.seq);
                viewer.camera = Some(camera);
                viewer.camera_at = Instant::now();
                viewer.needs_pass = true;
                viewer.exhausted = false;
                viewer.criterion.reset();
            }
            ViewerToSma::SetCriterion { name } => {
                match crate::criteria::make_criterion(&name, &settings, seed ^ id) {
                    Some(c) => {
                        viewer.criterion = c;
                        viewer.exhausted = false;
                    }
                    None => viewer.send(SmaToViewer::Error {
                        message: format!(
                            "unknown criterion {name:?}; known: {}",
                            CRITERIA.join(", ")
                        ),
                    }),
                }
            }
            ViewerToSma::Pause => viewer.paused = true,
            ViewerToSma::Resume => viewer.paused = false,
            ViewerToSma::Bye => {}
        }
        if let Some(viewer) = self.viewers.get(&id) {
            viewer.send(self.refinement_state(viewer));
        }
    }

    fn refinement_state(&self, viewer: &Viewer) -> SmaToViewer {
        SmaToViewer::Refinement {
            criterion: viewer.criterion.name().to_string(),
            paused: viewer.paused || !self.config.refine,
        }
    }

    fn make_criterion(&self, name: &str, id: ViewerId) -> Box<dyn Criterion> {
        crate::criteria::make_criterion(
            name,
            &self.config.criterion_settings,
            self.config.seed ^ id,
        )
        .expect("criterion name checked at start")
    }

    fn on_pool_event(&mut self, event: PoolEvent) {
        match event {
            PoolEvent::Shaded { batch, radiance } => {
                self.requests.finished(&batch);
                for ((point, rgb), flags) in
                    batch.points.iter().zip(&radiance.rgb).zip(&radiance.flags)
                {
                    let base = point.base_triangle as usize;
                    let view_dependent = self.view_dependent.get(base).copied().unwrap_or(false)
                        || flags & point_flags::VIEW_DEPENDENT != 0;
                    let sample = CachedSample {
                        rgb: *rgb,
                        quality: radiance.quality,
                        view_dependent,
                        eye: point.eye.map(Vec3::from),
                        last_seen: self.frame,
                    };
                    self.cache.insert(point.key, sample);
                }
                let n = batch.points.len() as u64;
                // New samples are new input for every criterion: one that had found nothing may
                // find something now.
                self.viewers.values_mut().for_each(|v| v.exhausted = false);
                self.samples += n;
                self.samples_since_pass += n;
                self.resync = true;
            }
            PoolEvent::Failed { batch, reason } => {
                tracing::warn!(batch = batch.batch_id, %reason, "batch failed; its samples will be asked again");
                self.requests.finished(&batch);
                self.replan = true;
            }
            PoolEvent::Renderers { connected } => self.renderers = connected,
        }
    }

    /// One turn after the events (see the module documentation).
    fn turn(&mut self) -> anyhow::Result<()> {
        if self.samples_since_pass >= self.config.revisit_samples {
            self.viewers
                .values_mut()
                .for_each(|v| v.needs_pass |= v.camera.is_some());
        }
        self.run_passes()?;
        self.commit_ready_groups();
        self.feed_renderers();
        if self.resync {
            self.sync_viewers();
        }
        if let Some(id) = self.refinement_candidate() {
            self.refine_round(id)?;
        }
        Ok(())
    }

    fn run_passes(&mut self) -> anyhow::Result<()> {
        if !self.viewers.values().any(|v| v.needs_pass) {
            return Ok(());
        }
        self.frame += 1;
        self.coarsen_stale();
        for viewer in self.viewers.values_mut().filter(|v| v.needs_pass) {
            viewer.needs_pass = false;
            let Some(camera) = &viewer.camera else {
                continue;
            };
            let view = self
                .visibility
                .leaf_view(&self.mesh, camera)
                .context("visibility pass")?;
            viewer.view = Some(view);
        }
        // Every viewer's view counts as seen now, not only those just re-run: while one viewer
        // walks, what another one rests on is neither evicted nor coarsened.
        for view in self.viewers.values().filter_map(|v| v.view.as_ref()) {
            self.cache
                .touch_visible(&self.mesh, &view.visible, self.frame);
            self.coarsening.seen(&self.mesh, &view.visible, self.frame);
        }
        self.samples_since_pass = 0;
        self.cache.evict(self.frame, &|_| false);
        self.replan = true;
        self.resync = true;
        Ok(())
    }

    /// Collapses subdivision out of every view for long (DESIGN.md §4, thesis §6) before the
    /// passes, so they see the coarser mesh; steps wait in the pending groups like refinement
    /// steps until what they expose is shaded. Not while refinement steps wait, whose leaves
    /// they could remove.
    fn coarsen_stale(&mut self) {
        if !self.pending.is_empty() {
            return;
        }
        let steps = self.coarsening.collapse_stale(&mut self.mesh, self.frame);
        if steps.is_empty() {
            return;
        }
        tracing::debug!(
            steps = steps.len(),
            leaves = self.mesh.leaf_count(),
            refined_bases = self.coarsening.refined_bases(),
            "coarsened what no viewer has seen lately"
        );
        self.pending.add(steps);
        for viewer in self.viewers.values_mut() {
            viewer.needs_pass |= viewer.camera.is_some();
        }
    }

    /// Commits every pending group none of whose visible new leaves lacks a sample.
    fn commit_ready_groups(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let mut waiting = std::collections::HashSet::new();
        for view in self.viewers.values().filter_map(|v| v.view.as_ref()) {
            for v in &view.visible.leaves {
                if let Some(g) = self.pending.group_of(v.leaf)
                    && self
                        .cache
                        .missing_keys(&self.mesh, v.leaf, v.side)
                        .next()
                        .is_some()
                {
                    waiting.insert(g);
                }
            }
        }
        let ready: Vec<usize> = self
            .pending
            .ids()
            .into_iter()
            .filter(|g| !waiting.contains(g))
            .collect();
        if ready.is_empty() {
            return;
        }
        for g in ready {
            self.pending.commit(g);
        }
        for viewer in self.viewers.values_mut() {
            viewer.exhausted = false;
        }
        self.resync = true;
        self.replan = true;
    }

    fn replan_requests(&mut self) {
        let mut needs = Vec::new();
        for viewer in self.viewers.values() {
            let (Some(view), Some(camera)) = (&viewer.view, &viewer.camera) else {
                continue;
            };
            needs.extend(plan::needs(&NeedsInput {
                view,
                eye: camera.eye_vec(),
                pending: &self.pending,
                mesh: &self.mesh,
                cache: &self.cache,
                view_dependent: &self.view_dependent,
                qualities: self.qualities,
                aging: self.aging,
            }));
        }
        self.requests.replan(needs);
        self.replan = false;
    }

    fn sync_viewers(&mut self) {
        let outstanding_requests = self.requests.outstanding() as u64;
        for viewer in self.viewers.values_mut() {
            let (Some(view), Some(camera)) = (&viewer.view, &viewer.camera) else {
                continue;
            };
            viewer.targets = plan::targets(view, &self.pending, &self.mesh, camera.eye_vec());
            let mut messages =
                viewer
                    .display
                    .sync(&viewer.targets, &self.mesh, &self.cache, camera.eye_vec());
            let l_white = self.cache.l_white(&self.mesh, &view.visible);
            if viewer.last_l_white != Some(l_white) && l_white > 0.0 {
                viewer.last_l_white = Some(l_white);
                tracing::debug!(l_white, "tone map");
                messages.push(SmaToViewer::ToneMap { l_white });
            }
            // Truthful: zero only when nothing is asked for and every wanted triangle is shown.
            let outstanding = outstanding_requests + viewer.display.unshown as u64;
            let answered = viewer.answer_pending.take();
            let completion_changed =
                viewer.last_outstanding.map(|o| o == 0) != Some(outstanding == 0);
            if messages.is_empty() && answered.is_none() && !completion_changed {
                continue;
            }
            let epoch = Epoch {
                camera_seq: camera.seq,
                shown: viewer.display.shown() as u64,
                visible_leaves: view.visible.leaves.len() as u64,
                inserted: std::mem::take(&mut viewer.display.inserted),
                removed: std::mem::take(&mut viewer.display.removed),
                samples: self.samples,
                outstanding,
            };
            viewer.last_outstanding = Some(outstanding);
            for message in messages {
                viewer.send(message);
            }
            viewer.send(SmaToViewer::Epoch(epoch));
        }
        self.resync = false;
    }

    /// Re-plans when asked to, or when the queue ran dry while new input came, and keeps the
    /// renderers fed. Submitting drops queued needs that answers have satisfied meanwhile; a
    /// queue emptied that way is re-planned at once, before the viewers are told what is
    /// outstanding, so an epoch never reports needs that no longer exist (nor misses new ones).
    fn feed_renderers(&mut self) {
        let planned = self.replan || (self.requests.queued() == 0 && self.resync);
        if planned {
            self.replan_requests();
        }
        self.submit_batches();
        if !planned && self.resync && self.requests.queued() == 0 {
            self.replan_requests();
            self.submit_batches();
        }
    }

    fn submit_batches(&mut self) {
        let room = self.config.batches_per_renderer.max(1) * self.renderers.max(1);
        while self.requests.batches_in_flight() < room {
            let Some(batch) = self
                .requests
                .next_batch(self.config.batch_points, &self.cache)
            else {
                break;
            };
            self.pool.submit(batch);
        }
    }

    /// Whether a turn has something to do without any new event.
    fn has_work_now(&self) -> bool {
        self.replan
            || self.resync
            || self.viewers.values().any(|v| v.needs_pass)
            || self.refinement_candidate().is_some()
    }

    /// The viewer whose turn it is to refine, if refinement may run now.
    fn refinement_candidate(&self) -> Option<ViewerId> {
        if !self.config.refine
            || !self.pending.is_empty()
            || self.requests.outstanding() >= self.config.queue_low
            || self.viewers.values().any(|v| v.needs_pass)
        {
            return None;
        }
        let ready: Vec<ViewerId> = self
            .viewers
            .iter()
            .filter(|(_, v)| {
                v.view.is_some()
                    && !v.paused
                    && !v.exhausted
                    && v.camera_at.elapsed() >= self.config.rest
            })
            .map(|(&id, _)| id)
            .collect();
        (!ready.is_empty()).then(|| ready[self.refine_turn % ready.len()])
    }

    /// When the next viewer's camera comes to rest, if refinement waits only for that.
    fn next_rest(&self) -> Option<Instant> {
        if !self.config.refine {
            return None;
        }
        self.viewers
            .values()
            .filter(|v| v.view.is_some() && !v.paused && !v.exhausted)
            .map(|v| v.camera_at + self.config.rest)
            .filter(|&t| t > Instant::now())
            .min()
    }

    /// Empty criterion calls in a row after which a viewer's refinement counts as exhausted (enough
    /// for `nld-os` to step S_ref from its start down to S_min with the default settings).
    const EMPTY_CALLS_BEFORE_EXHAUSTED: usize = 32;

    /// One refinement round for one viewer (DESIGN.md §3 step 6, §6).
    fn refine_round(&mut self, id: ViewerId) -> anyhow::Result<()> {
        self.refine_turn += 1;
        let image = self.luminance_image(id)?;
        let viewer = self.viewers.get_mut(&id).expect("candidate exists");
        let view = viewer.view.as_ref().expect("candidate has a view");
        let input = CriterionInput {
            mesh: &self.mesh,
            cache: &self.cache,
            visible: &view.visible,
            l_white: viewer
                .last_l_white
                .unwrap_or_else(|| self.cache.l_white(&self.mesh, &view.visible)),
            image: image.as_ref(),
        };
        // A criterion may answer an empty call and still have more to give: `nld-os` lowers
        // S_ref one step after a pass that selects nothing (§4.3.4). Only a run of empty calls
        // means it has nothing left for this view.
        let selected = (0..Self::EMPTY_CALLS_BEFORE_EXHAUSTED)
            .map(|_| viewer.criterion.select(&input, self.config.max_selections))
            .find(|s| !s.is_empty())
            .unwrap_or_default();
        if selected.is_empty() {
            viewer.exhausted = true;
            tracing::debug!(viewer = id, "criterion found nothing more to refine");
            return Ok(());
        }
        let pixels: HashMap<NodeId, u32> = view
            .visible
            .leaves
            .iter()
            .map(|v| (v.leaf, v.pixels))
            .collect();
        let min_pixels = self.config.min_split_pixels;
        let too_small = |leaf: NodeId| pixels.get(&leaf).is_none_or(|&p| p < min_pixels);
        // A resumable criterion may still hold a leaf that coarsening has removed since.
        let selected: Vec<NodeId> = selected
            .into_iter()
            .filter(|&l| self.mesh.is_leaf(l))
            .collect();
        let steps = self.mesh.refine(&selected, &too_small);
        if steps.is_empty() {
            // Every selected leaf was too small; criteria offer a leaf once per view, so the
            // next round moves on to others.
            tracing::debug!(
                viewer = id,
                selected = selected.len(),
                "selected leaves too small"
            );
            return Ok(());
        }
        tracing::debug!(
            viewer = id,
            selected = selected.len(),
            steps = steps.len(),
            "refinement round"
        );
        self.coarsening.refined(&self.mesh, &steps);
        self.pending.add(steps);
        for viewer in self.viewers.values_mut() {
            viewer.needs_pass |= viewer.camera.is_some();
        }
        Ok(())
    }

    /// The Gouraud luminance image of what `id` shows, when its criterion needs one.
    fn luminance_image(&mut self, id: ViewerId) -> anyhow::Result<Option<LuminanceImage>> {
        let viewer = &self.viewers[&id];
        let (Some(view), Some(camera)) = (&viewer.view, &viewer.camera) else {
            return Ok(None);
        };
        if !viewer.criterion.needs_image() {
            return Ok(None);
        }
        let triangles: Vec<_> = viewer
            .display
            .shown_triangles()
            .map(|(node, rgb)| (self.mesh.leaf_positions(node), rgb.map(luminance)))
            .collect();
        let view_proj = self.visibility.view_projection(camera);
        let lum = self
            .luminance
            .render(
                self.visibility.gpu(),
                &triangles,
                view_proj,
                camera.width,
                camera.height,
            )
            .context("luminance pass")?;
        let ids = view
            .pixel_leaves
            .iter()
            .map(|l| l.unwrap_or(LuminanceImage::NONE))
            .collect();
        Ok(Some(LuminanceImage {
            width: camera.width,
            height: camera.height,
            luminance: lum,
            ids,
        }))
    }

    fn report_stats(&mut self) {
        let secs = self.last_stats.elapsed().as_secs_f32().max(1e-3);
        let rate = (self.samples - self.samples_at_last_stats) as f32 / secs;
        self.samples_at_last_stats = self.samples;
        self.last_stats = Instant::now();
        let stats = Stats {
            samples_per_sec: rate,
            leaves: self.mesh.leaf_count() as u64,
            cached_samples: self.cache.len() as u64,
            renderers: self.renderers as u32,
        };
        tracing::info!(
            samples = self.samples,
            samples_per_sec = format!("{rate:.0}"),
            leaves = stats.leaves,
            cached = stats.cached_samples,
            cache_mib = format!("{:.1}", self.cache.bytes() as f64 / (1 << 20) as f64),
            mesh_mib = format!("{:.1}", self.mesh.heap_bytes() as f64 / (1 << 20) as f64),
            queued = self.requests.queued(),
            in_flight = self.requests.in_flight_keys(),
            pending_steps = self.pending.len(),
            renderers = self.renderers,
            viewers = self.viewers.len(),
            "stats"
        );
        for viewer in self.viewers.values() {
            viewer.send(SmaToViewer::Stats(stats));
        }
    }
}

async fn sleep_until(at: Option<Instant>) {
    if let Some(at) = at {
        tokio::time::sleep_until(at.into()).await;
    }
}
