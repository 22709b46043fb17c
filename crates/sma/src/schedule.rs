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
//!
//! This module keeps the turn ordering ([`turns`] holds its decisions, tested with a fake clock
//! and a fake pool); [`viewers`] holds per-viewer state and the epoch sync, [`refinement`] the
//! refinement rounds and the luminance image, [`waits`] the small state machines of what the work
//! waits for.

mod coarsening;
mod costs;
mod display;
mod pending;
mod plan;
mod refinement;
mod requests;
mod turns;
mod viewers;
mod waits;

use std::collections::{BTreeMap, HashMap};
use std::time::{Duration, Instant};

use anyhow::Context;
use glam::Vec3;
use protocol::renderer_link::{Quality, SampleKey, point_flags};
use protocol::viewer_link::{SmaToViewer, Stats, ViewerToSma};
use scene::Scene;
use tokio::sync::{mpsc, watch};

use crate::cache::{CachedSample, ShadingCache};
use crate::clock::sleep_until;
use crate::config::ScheduleConfig;
use crate::criteria::{CriterionKind, CriterionSettings, make_criterion};
use crate::mesh::SubdivisionMesh;
use crate::pool::{Lane, PoolEvent, PoolHandle};
use crate::viewer_link::{ViewerEvent, ViewerId};
use crate::visibility::{Gpu, LuminancePass, Visibility, carry_over};
use coarsening::Coarsening;
use costs::{Pace, Work, WorkCosts};
use pending::PendingRefinement;
use plan::{Aging, MorePaths, NeedsInput, Qualities};
use requests::{BatchLimit, Requests};
use turns::{Feed, RefineGate, TurnView};
use viewers::{SyncInput, Viewer};
use waits::Owed;

/// Rejected answers for one key before the schedule stops asking for it.
const MAX_REJECTIONS: u8 = 3;

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

/// A criterion that found nothing is asked again once this many new samples have come, not after
/// every batch: a round evaluates every visible leaf.
const NEW_INPUT_SAMPLES: u64 = 1024;

pub struct Schedule {
    config: ScheduleConfig,
    /// Rejected answers per key not yet given up on, and all rejected answers.
    rejections: HashMap<SampleKey, u8>,
    rejected_points: u64,
    /// Whether the last turn found every view at its stated end (`note_convergence`).
    converged: bool,
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
    /// What the next turn owes the queue and the viewers.
    owed: Owed,
    samples: u64,
    /// Paths traced for `samples` (DESIGN.md §10: cost is counted in paths).
    paths: u64,
    samples_since_pass: u64,
    samples_since_input: u64,
    sync_pace: Pace,
    replan_pace: Pace,
    /// Spaces out refinement rounds (`ScheduleConfig::round_share`).
    round_pace: Pace,
    /// Where the thread's time went since the last `Stats`.
    costs: WorkCosts,
    /// `samples` and `paths` at the previous `Stats`.
    counted_at_last_stats: (u64, u64),
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
    ) -> Schedule {
        let view_dependent = (0..scene.mesh.triangles.len())
            .map(|t| scene.material_of(t).is_view_dependent())
            .collect();
        let quality = scene.settings.quality;
        let round_pace = Pace::new(Duration::ZERO, config.round_share, Instant::now());
        let qualities = Qualities::new(
            Quality {
                paths: quality.paths,
                bounces: config.bounces.or(quality.bounces),
            },
            config.max_paths,
            config.early_rung,
        );
        let aging = Aging {
            max_angle_rad: config.view_angle_deg.to_radians(),
        };
        let luminance = LuminancePass::new(&gpu);
        let visibility = Visibility::new(gpu, &mesh, scene.mesh.bounds());
        let coarsening = Coarsening::new(mesh.base_count(), config.coarsen_after_passes);
        Schedule {
            rejections: HashMap::new(),
            rejected_points: 0,
            converged: false,
            coarsening,
            cache: ShadingCache::new(config.cache_budget_bytes),
            requests: Requests::new(config.seed, config.top_up_share),
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
            owed: Owed::default(),
            samples: 0,
            paths: 0,
            samples_since_pass: 0,
            samples_since_input: 0,
            sync_pace: Pace::new(SYNC_INTERVAL, SYNC_SHARE, Instant::now()),
            replan_pace: Pace::new(REPLAN_INTERVAL, REPLAN_SHARE, Instant::now()),
            round_pace,
            costs: WorkCosts::default(),
            counted_at_last_stats: (0, 0),
            last_stats: Instant::now(),
            frame: 0,
            refine_turn: 0,
        }
    }

    pub fn adapter(&self) -> String {
        self.visibility.gpu().describe()
    }

    /// Runs until shutdown or until both channels close.
    pub async fn run(
        mut self,
        mut viewers: mpsc::Receiver<ViewerEvent>,
        mut pool: mpsc::Receiver<PoolEvent>,
        mut shutdown: watch::Receiver<bool>,
    ) -> anyhow::Result<()> {
        let mut stats = tokio::time::interval(self.config.stats_every);
        loop {
            let (work_now, wake_at) = self.waiting_for();
            tokio::select! {
                biased;
                _ = shutdown.changed() => return Ok(()),
                event = viewers.recv() => match event {
                    Some(event) => self.on_viewer_event(event),
                    None => return Ok(()),
                },
                Some(event) = pool.recv() => self.on_pool_event(event),
                _ = stats.tick() => {}
                _ = sleep_until(wake_at), if wake_at.is_some() => {}
                _ = std::future::ready(()), if work_now => {}
            }
            while let Ok(event) = viewers.try_recv() {
                self.on_viewer_event(event);
            }
            while let Ok(event) = pool.try_recv() {
                self.on_pool_event(event);
            }
            self.turn()?;
            // By the clock, not only on the tick: while work keeps this loop busy, the
            // runtime's timers are not polled and the tick came seconds late.
            if self.last_stats.elapsed() >= self.config.stats_every {
                self.report_stats();
            }
        }
    }

    fn on_viewer_event(&mut self, event: ViewerEvent) {
        match event {
            ViewerEvent::Joined { id, outbox } => {
                let viewer = Viewer::new(outbox, self.criterion(self.config.criterion, id));
                viewer.send(self.refinement_state(&viewer));
                self.viewers.insert(id, viewer);
            }
            ViewerEvent::Left { id } => {
                self.viewers.remove(&id);
                self.owed.queue_changed();
            }
            ViewerEvent::Message { id, message } => self.on_viewer_message(id, message),
        }
    }

    fn on_viewer_message(&mut self, id: ViewerId, message: ViewerToSma) {
        let Some(viewer) = self.viewers.get(&id) else {
            return;
        };
        let criterion = match &message {
            ViewerToSma::SetCriterion { name } => match CriterionKind::from_name(name) {
                Some(kind) => Some(self.criterion(kind, id)),
                None => {
                    viewer.send(SmaToViewer::Error {
                        message: format!(
                            "unknown criterion {name:?}; known: {}",
                            CriterionKind::names()
                        ),
                    });
                    None
                }
            },
            _ => None,
        };
        let viewer = self.viewers.get_mut(&id).expect("looked up above");
        match message {
            ViewerToSma::Camera(camera) => {
                viewer.camera_moved(camera);
                // A new view is refined as soon as it rests, whatever the last view's rounds
                // cost.
                self.round_pace.restart(Instant::now());
            }
            ViewerToSma::SetCriterion { .. } => {
                if let Some(criterion) = criterion {
                    viewer.criterion = criterion;
                    viewer.wait.new_input();
                }
            }
            ViewerToSma::Pause => viewer.paused = true,
            ViewerToSma::Resume => viewer.paused = false,
            // The viewer's link keeps these to itself (`viewer_link::serve`).
            ViewerToSma::Bye | ViewerToSma::Pong { .. } => return,
        }
        let viewer = &self.viewers[&id];
        viewer.send(self.refinement_state(viewer));
    }

    fn refinement_state(&self, viewer: &Viewer) -> SmaToViewer {
        SmaToViewer::Refinement {
            criterion: viewer.criterion.kind().name().to_string(),
            paused: viewer.paused || !self.config.refine,
        }
    }

    /// A criterion of `kind` for viewer `id`, with its own random stream. Its noise-aware
    /// significance floor is the schedule's `display_error`, and its samples settle at the
    /// ladder's cap: the stated end (DESIGN.md §5) asks samples and leaves for the same
    /// precision, one display step.
    fn criterion(&self, kind: CriterionKind, id: ViewerId) -> Box<dyn crate::criteria::Criterion> {
        let settings = CriterionSettings {
            display_error: self.config.display_error,
            max_paths: self.config.max_paths,
            ..self.config.criterion_settings
        };
        make_criterion(kind, &settings, self.config.seed ^ id)
    }

    fn on_pool_event(&mut self, event: PoolEvent) {
        match event {
            PoolEvent::Shaded { batch, radiance } => {
                self.requests.finished(&batch);
                for (i, point) in batch.points.iter().enumerate() {
                    let base = point.base_triangle as usize;
                    let view_dependent = self.view_dependent.get(base).copied().unwrap_or(false)
                        || radiance.flags[i] & point_flags::VIEW_DEPENDENT != 0;
                    let sample = CachedSample {
                        rgb: radiance.rgb[i],
                        luminance_variance: radiance.luminance_variance[i],
                        quality: Quality {
                            paths: radiance.paths[i],
                            bounces: radiance.quality.bounces,
                        },
                        view_dependent,
                        eye: point.eye.map(Vec3::from),
                        last_seen: self.frame,
                    };
                    if sample.estimate().is_valid() {
                        self.cache.insert(point.key, sample);
                    } else {
                        self.reject(point.key, &sample);
                    }
                }
                let n = batch.points.len() as u64;
                // New samples are new input for every criterion: one that had found nothing may
                // find something now.
                self.samples_since_input += n;
                if self.samples_since_input >= NEW_INPUT_SAMPLES {
                    self.samples_since_input = 0;
                    self.viewers.values_mut().for_each(|v| v.wait.new_input());
                }
                self.samples += n;
                self.paths += radiance.paths.iter().map(|&p| u64::from(p)).sum::<u64>();
                self.samples_since_pass += n;
                self.owed.samples_arrived();
            }
            PoolEvent::Failed { batch, reason } => {
                tracing::warn!(batch = batch.batch_id, %reason, "batch failed; its samples will be asked again");
                self.requests.finished(&batch);
                self.owed.queue_changed();
            }
            PoolEvent::Renderers { connected } => self.renderers = connected,
        }
    }

    /// A point whose answer is not a valid estimate (NaN, infinite or negative radiance or
    /// variance, no paths) is neither cached nor shown; it stays missing, so it is asked for
    /// again, up to [`MAX_REJECTIONS`] times, after which the cache gives up on it.
    fn reject(&mut self, key: SampleKey, sample: &CachedSample) {
        self.rejected_points += 1;
        let count = self.rejections.entry(key).or_insert(0);
        *count += 1;
        if *count >= MAX_REJECTIONS {
            tracing::warn!(
                ?key,
                rgb = ?sample.rgb,
                variance = sample.luminance_variance,
                paths = sample.quality.paths,
                "renderers answered this sample badly {MAX_REJECTIONS} times: it is shown with \
                 the mean of its triangles' other vertices"
            );
            self.rejections.remove(&key);
            self.cache.mark_failed(key);
        }
    }

    /// One turn after the events (see the module documentation).
    fn turn(&mut self) -> anyhow::Result<()> {
        if self.samples_since_pass >= self.config.revisit_samples {
            self.viewers
                .values_mut()
                .for_each(|v| v.wait.leaves_changed());
        }
        let frame = self.frame;
        self.run_passes()?;
        self.commit_ready_groups();
        let sync_now = self.sync_due(self.frame != frame);
        let owed = self.owed;
        self.owed = turns::feed(if sync_now { owed } else { owed.resync_later() }, self);
        if owed.resync() && !sync_now {
            self.owed.samples_arrived();
        }
        if sync_now {
            let start = Instant::now();
            self.sync_viewers();
            let spent = start.elapsed();
            self.sync_pace.ran(start, spent);
            self.costs.add(Work::Sync, spent);
        }
        if let Some(id) = self.refinement_candidate() {
            let start = Instant::now();
            self.refine_round(id)?;
            let spent = start.elapsed();
            self.round_pace.ran(start, spent);
            self.costs.add(Work::Round, spent);
        }
        self.note_convergence();
        Ok(())
    }

    /// The stated end of DESIGN.md §5 for every viewer: its criterion finds nothing to subdivide
    /// and no sample is wanted (every visible one is below the displayed-error threshold or at
    /// the ladder's cap), nothing is in flight and no refinement step waits.
    fn note_convergence(&mut self) {
        let converged = !self.viewers.is_empty()
            && self.viewers.values().all(|v| {
                // Without refinement no criterion runs: there is nothing to subdivide.
                let dry = v.criterion_dry || !self.config.refine;
                v.view.is_some() && dry && !v.wait.needs_pass()
            })
            && self.requests.outstanding() == 0
            && self.pending.is_empty()
            && !self.owed.any();
        if converged && !self.converged {
            tracing::info!(
                samples = self.samples,
                "converged: every visible sample is as good as it will get"
            );
        }
        self.converged = converged;
    }

    fn run_passes(&mut self) -> anyhow::Result<()> {
        if !self.viewers.values().any(|v| v.wait.needs_pass()) {
            return Ok(());
        }
        let start = Instant::now();
        self.frame += 1;
        self.coarsen_stale();
        let mut drew = false;
        // Every K samples the views are drawn afresh (thesis §4.1's revisit): a carried view
        // differs from a drawn one by slivers the rasteriser's sub-pixel grid decides, and the
        // redraw keeps them from adding up over hundreds of rounds. (Single 20-s runs on
        // bracara VT, mean FLIP at 20 s: 0.0369 carried throughout, 0.0360 with this redraw,
        // 0.0355 with every view drawn; within the runs' spread, so not a measured cure.)
        let redraw = self.samples_since_pass >= self.config.revisit_samples;
        for viewer in self.viewers.values_mut().filter(|v| v.wait.needs_pass()) {
            viewer.wait.pass_done();
            let Some(camera) = &viewer.camera else {
                continue;
            };
            // The camera unchanged, only the leaves did (a round, coarsening): the view is
            // carried over, exact but for slivers, without drawing (`visibility::carry_over`).
            let carried = viewer
                .view
                .take()
                .filter(|view| !redraw && view.camera.as_ref() == Some(camera))
                .and_then(|view| carry_over(view, &self.mesh, camera));
            let view = match carried {
                Some(view) => view,
                None => {
                    drew = true;
                    self.visibility
                        .leaf_view(&self.mesh, camera)
                        .context("visibility pass")?
                }
            };
            viewer.view = Some(view);
        }
        // Every viewer's view counts as seen now, not only those just re-run: while one viewer
        // walks, what another one rests on is neither evicted nor coarsened.
        for view in self.viewers.values().filter_map(|v| v.view.as_ref()) {
            self.cache
                .touch_visible(&self.mesh, &view.visible, self.frame);
            self.coarsening.seen(&self.mesh, &view.visible, self.frame);
        }
        if drew {
            self.samples_since_pass = 0;
        }
        self.cache.evict(self.frame, &|_| false);
        self.owed.views_changed();
        let work = if drew { Work::Pass } else { Work::CarryOver };
        self.costs.add(work, start.elapsed());
        Ok(())
    }

    fn replan_requests(&mut self) {
        // What the backlog holds was batched under the old plan; the new one batches it again
        // in the new order (a camera move must not wait behind the old view's backlog).
        for batch in self.pool.withdraw() {
            self.requests.finished(&batch);
        }
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
                more_paths: self.more_paths_for(viewer),
            }));
        }
        self.requests.replan(needs);
    }

    /// Every shown view gets more paths where its noise shows, below every other need: they
    /// keep the renderers busy between refinement rounds and passes (DESIGN.md §3, §5). While
    /// its criterion still refines, its quieter samples too, last of all (`Urgency::Polish`).
    fn more_paths_for(&self, viewer: &Viewer) -> Option<MorePaths> {
        Some(MorePaths {
            l_white: viewer.last_l_white?,
            threshold: self.config.display_error,
            polish: self.config.refine && !viewer.criterion_dry,
        })
    }

    fn sync_viewers(&mut self) {
        let input = SyncInput {
            mesh: &self.mesh,
            cache: &self.cache,
            pending: &self.pending,
            outstanding_requests: self.requests.outstanding() as u64,
            samples: self.samples,
            paths: self.paths,
        };
        for viewer in self.viewers.values_mut() {
            viewer.sync(&input);
        }
        self.owed.synced();
    }

    /// Keeps each renderer holding `batches_per_renderer` batches, and the pool's backlog
    /// holding `renderer_backlog` of the renderers' measured capacity beyond them, within the
    /// pool's bound in batches (`PoolHandle::most_batches`): the backlog is sent while this
    /// thread is busy with a pass or a refinement round (DESIGN.md §3: rest time goes to the
    /// renderers).
    fn submit_batches(&mut self) {
        let renderers = self.renderers.max(1);
        let held = self.config.batches_per_renderer.max(1) * renderers;
        let most = self.pool.most_batches(self.renderers);
        let backlog = self.config.renderer_backlog.as_secs_f64();
        loop {
            let in_flight = self.requests.batches_in_flight();
            let backlog_full = self.pool.backlog_seconds().is_none_or(|s| s >= backlog);
            if in_flight >= most || (in_flight >= held && backlog_full) {
                break;
            }
            let limit = BatchLimit {
                points: self.config.batch_points,
                paths: self.config.batch_paths,
            };
            let Some(batch) = self.requests.next_batch(limit, &self.cache) else {
                break;
            };
            let lane = if self.requests.is_urgent(batch.batch_id) {
                Lane::Urgent
            } else {
                Lane::Background
            };
            // A full backlog gives the batch back: its samples are asked for again later.
            if let Err(batch) = self.pool.submit(batch, lane) {
                self.requests.finished(&batch);
                self.owed.queue_changed();
                break;
            }
        }
    }

    /// The viewers as the turn order sees them.
    fn turn_views(&self) -> Vec<TurnView> {
        self.viewers
            .iter()
            .map(|(&id, v)| TurnView {
                id,
                has_view: v.view.is_some(),
                paused: v.paused,
                wait: v.wait,
                camera_at: v.camera_at,
                camera_replaced: v.camera_replaced,
            })
            .collect()
    }

    fn refine_gate(&self) -> RefineGate {
        RefineGate {
            refine: self.config.refine,
            groups_pending: !self.pending.is_empty(),
            outstanding: self.requests.outstanding_before_paths(),
            queue_low: self.config.queue_low,
            rest: self.config.rest,
            // Spacing the rounds gives their time to the renderers only while the queue holds
            // work for them; with nothing queued, rounds are what gives them work (a view's
            // last refinements), and held back they left the renderers idle.
            next_round_at: (self.requests.queued() > 0).then(|| self.round_pace.next_at()),
        }
    }

    /// The viewer whose turn it is to refine, if refinement may run now.
    fn refinement_candidate(&self) -> Option<ViewerId> {
        let views = self.turn_views();
        turns::refinement_candidate(
            &self.refine_gate(),
            &views,
            self.refine_turn,
            Instant::now(),
        )
    }

    /// Whether a turn has work without any new event, and else when to wake: a camera coming to
    /// rest, or a sync or a re-plan put off by its pace.
    fn waiting_for(&self) -> (bool, Option<Instant>) {
        let (views, gate, now) = (self.turn_views(), self.refine_gate(), Instant::now());
        let candidate = turns::refinement_candidate(&gate, &views, self.refine_turn, now);
        let sync_at = self.owed.resync().then(|| self.sync_pace.next_at());
        let replan_at = self.owed.replan_soon().then(|| self.replan_pace.next_at());
        let mut owed = self.owed;
        if sync_at.is_some_and(|at| at > now) {
            owed = owed.resync_later();
        }
        if replan_at.is_some_and(|at| at > now) {
            owed = owed.replan_later();
        }
        let wake = [
            turns::next_rest(&gate, &views, now),
            sync_at.filter(|&at| at > now),
            replan_at.filter(|&at| at > now),
        ];
        (
            turns::has_work_now(owed, &views, candidate),
            wake.into_iter().flatten().min(),
        )
    }

    /// Whether the viewers are due a sync now: owed one, and a pass just ran or the sync's pace
    /// allows it ([`SYNC_INTERVAL`], [`SYNC_SHARE`]).
    fn sync_due(&self, pass_ran: bool) -> bool {
        self.owed.resync() && (pass_ran || self.sync_pace.due(Instant::now()))
    }

    fn report_stats(&mut self) {
        let secs = self.last_stats.elapsed().as_secs_f32().max(1e-3);
        let (samples, paths) = self.counted_at_last_stats;
        let rate = (self.samples - samples) as f32 / secs;
        let paths_rate = (self.paths - paths) as f32 / secs;
        self.counted_at_last_stats = (self.samples, self.paths);
        self.last_stats = Instant::now();
        let stats = Stats {
            samples_per_sec: rate,
            paths_per_sec: paths_rate,
            renderer_busy: self.pool.take_busy(),
            leaves: self.mesh.leaf_count() as u64,
            cached_samples: self.cache.len() as u64,
            renderers: self.renderers as u32,
            converged: self.converged,
            rejected_points: self.rejected_points,
        };
        tracing::debug!(
            samples = self.samples,
            samples_per_sec = format!("{rate:.0}"),
            paths_per_sec = format!("{paths_rate:.0}"),
            renderer_busy = format!("{:.2}", stats.renderer_busy),
            leaves = stats.leaves,
            cached = stats.cached_samples,
            cache_mib = format!("{:.1}", self.cache.bytes() as f64 / (1 << 20) as f64),
            mesh_mib = format!("{:.1}", self.mesh.heap_bytes() as f64 / (1 << 20) as f64),
            queued = self.requests.queued(),
            in_flight = self.requests.in_flight_keys(),
            pending_steps = self.pending.len(),
            converged = self.converged,
            rejected = self.rejected_points,
            renderers = self.renderers,
            viewers = self.viewers.len(),
            work = self.costs.take(),
            "stats"
        );
        for viewer in self.viewers.values() {
            viewer.send(SmaToViewer::Stats(stats));
        }
    }
}

impl Feed for Schedule {
    fn queued(&self) -> usize {
        self.requests.queued()
    }

    fn replan(&mut self) {
        let start = Instant::now();
        self.replan_requests();
        let spent = start.elapsed();
        self.replan_pace.ran(start, spent);
        self.costs.add(Work::Replan, spent);
    }

    fn replan_due(&self) -> bool {
        self.replan_pace.due(Instant::now())
    }

    fn submit(&mut self) {
        self.submit_batches();
    }
}
