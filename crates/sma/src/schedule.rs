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
//! 5. only then, when no pass is owed, the queue is short and a viewer is ready (its camera
//!    rests, or with work while walking the rounds' pace allows, DESIGN.md §3 step 9), one
//!    refinement round of at most R selections runs (first, where it is on and samples or views
//!    came since the last, a pass of coarsening by uniformity at rest, [`uniformity`]); its
//!    passes come at the next turn, after any camera that arrived meanwhile. A camera change so
//!    interrupts refinement at once.
//!
//! A walking camera's passes (step 1) wait for their pace while its new views' cycles would take
//! more than their share of the thread (`pace`); meanwhile the viewer keeps its last view, and
//! is neither synced nor refined, nor are refinement groups committed against a stale view.
//!
//! It runs on its own thread: the visibility passes block for milliseconds (software
//! rasterizer), and must not stall the tasks serving viewers and renderers.
//!
//! The schedule reads one way: [`turns`] decides what a turn does and returns it, [`pace`] decides
//! what of the work that may wait runs now, and this module carries both out. Its state is
//! grouped in named parts: the viewers ([`viewers`]: per-viewer state, their messages, the epoch
//! sync, and what each is shown, [`shown`] and [`targets`]), refinement ([`refinement`], with
//! [`pending`] steps, [`coarsening`] and [`uniformity`]), the request queue ([`plan`] makes each
//! view's needs, [`need`], on the quality [`ladder`]; [`requests`] orders and batches them), the
//! answers from the pool ([`answers`]), what the work owes and waits for ([`waits`]), the paces,
//! and the counters behind `Stats` ([`counters`]).

mod ahead;
mod answers;
mod coarsening;
mod counters;
mod direct;
mod filtering;
mod ladder;
mod memory;
mod need;
mod pace;
mod pending;
mod persistence;
mod plan;
mod refinement;
mod requests;
mod shown;
mod targets;
mod turns;
mod uniformity;
mod viewers;
mod views;
mod waits;

use std::time::{Duration, Instant};

use scene::Scene;
use tokio::sync::{mpsc, watch};

use crate::cache::ShadingCache;
use crate::cache_file::CacheFile;
use crate::clock::sleep_until;
use crate::config::ScheduleConfig;
use crate::indirect_filter::IndirectFilter;
use crate::mesh::SubdivisionMesh;
use crate::pool::{Lane, PoolEvent, PoolHandle};
use crate::viewer_link::{ViewerEvent, ViewerId};
use crate::visibility::{Gpu, LuminancePass, Visibility};
use answers::Answers;
use counters::{Counters, Work};
use pace::{Allowed, Paces, PassesOwed};
pub use persistence::CacheFileSetup;
use plan::{MorePaths, NeedsInput, PlanRules};
use refinement::{Refinement, Round};
use requests::{BatchLimit, Requests};
use turns::RefineGate;
use viewers::{Criteria, Heard, SyncInput, Viewer, Viewers};
use waits::Owed;

pub struct Schedule {
    config: ScheduleConfig,
    mesh: SubdivisionMesh,
    cache: ShadingCache,
    /// Visibility passes so far: the frame a sample or a base triangle was last seen in.
    frame: u64,
    visibility: Visibility,
    luminance: LuminancePass,
    refinement: Refinement,
    /// The quality ladder and what else the plan of every view's needs holds for the run.
    rules: PlanRules,
    requests: Requests,
    pool: PoolHandle,
    /// Renderers answering, as the pool last said.
    renderers: usize,
    answers: Answers,
    viewers: Viewers,
    criteria: Criteria,
    /// What the next turn owes the queue and the viewers.
    owed: Owed,
    paces: Paces,
    counters: Counters,
    memory: memory::MemoryBudget,
    /// The object-space filter of the indirect part, and its runs beside this thread
    /// (`filtering`).
    indirect_filter: IndirectFilter,
    filter_runs: filtering::FilterRuns,
    cache_file: Option<CacheFile>,
}

impl Schedule {
    pub fn new(
        config: ScheduleConfig,
        scene: std::sync::Arc<Scene>,
        mesh: SubdivisionMesh,
        gpu: Gpu,
        pool: PoolHandle,
        cache_file: Option<&CacheFileSetup>,
    ) -> Schedule {
        let now = Instant::now();
        let rules = PlanRules::new(&config, &scene);
        let mut cache = ShadingCache::new(config.memory_budget_bytes)
            .with_l_white_outliers(config.l_white_outliers)
            .with_albedos_of(scene.clone());
        let cache_file =
            cache_file.and_then(|setup| persistence::open(setup, &scene, &config, &rules, &mesh));
        cache.cover_albedos(&mesh);
        let luminance = LuminancePass::new(&gpu);
        let visibility = Visibility::new(gpu, &mesh, scene.mesh.bounds());
        let indirect_filter = IndirectFilter::new(config.indirect_filter, &mesh);
        Schedule {
            refinement: Refinement::new(mesh.base_count(), &config),
            rules,
            cache,
            requests: Requests::new(config.seed, config.top_up_share),
            criteria: Criteria::new(&config),
            paces: Paces::new(config.round_share, now),
            memory: memory::MemoryBudget::new(config.memory_budget_bytes),
            config,
            mesh,
            frame: 0,
            visibility,
            luminance,
            pool,
            renderers: 0,
            answers: Answers::default(),
            viewers: Viewers::default(),
            owed: Owed::default(),
            counters: Counters::new(now),
            indirect_filter,
            filter_runs: filtering::FilterRuns::default(),
            cache_file,
        }
    }

    pub fn adapter(&self) -> String {
        self.visibility.gpu().describe()
    }

    /// Runs until shutdown or until both channels close; then saves the cache file.
    pub async fn run(
        mut self,
        viewers: mpsc::Receiver<ViewerEvent>,
        pool: mpsc::Receiver<PoolEvent>,
        shutdown: watch::Receiver<bool>,
    ) -> anyhow::Result<()> {
        let outcome = self.serve(viewers, pool, shutdown).await;
        self.close_cache_file();
        outcome
    }

    async fn serve(
        &mut self,
        mut viewers: mpsc::Receiver<ViewerEvent>,
        mut pool: mpsc::Receiver<PoolEvent>,
        mut shutdown: watch::Receiver<bool>,
    ) -> anyhow::Result<()> {
        let mut stats = tokio::time::interval(self.config.stats_every);
        let mut filtered = self.filter_runs.start_worker();
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
                Some(done) = filtered.recv() => self.finish_filter(done),
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
            while let Ok(done) = filtered.try_recv() {
                self.finish_filter(done);
            }
            self.turn()?;
            // By the clock, not only on the tick: while work keeps this loop busy, the
            // runtime's timers are not polled and the tick came seconds late.
            if self.counters.stats_due(self.config.stats_every) {
                self.report_stats();
            }
        }
    }

    fn on_viewer_event(&mut self, event: ViewerEvent) {
        if let Heard::Left = self.viewers.on_event(event, &self.criteria) {
            self.owed.queue_changed();
        }
    }

    fn on_pool_event(&mut self, event: PoolEvent) {
        match event {
            PoolEvent::Shaded { batch, radiance } => {
                self.requests.finished(&batch);
                self.samples_changed(&batch);
                self.cache.cover_albedos(&self.mesh);
                let answered = self.answers.shaded(
                    &batch,
                    &radiance,
                    &self.rules.view_dependent,
                    self.frame,
                    &mut self.cache,
                );
                if answered.points > 0 {
                    self.refinement.merge_input();
                    self.filter_runs.due = true;
                }
                if self.counters.answered(answered) {
                    self.viewers.new_input();
                }
                self.owed.samples_arrived();
            }
            PoolEvent::Failed { batch, reason } => {
                tracing::warn!(batch = batch.batch_id, %reason, "batch failed; its samples will be asked again");
                self.requests.finished(&batch);
                self.owed.queue_changed();
            }
            PoolEvent::Renderers { connected } => self.renderers = connected,
            PoolEvent::Tile(news) => self.on_tile_news(news),
        }
    }

    /// One turn after the events (see the module documentation).
    fn turn(&mut self) -> anyhow::Result<()> {
        if self.counters.since_pass >= self.config.revisit_samples {
            self.viewers.leaves_changed();
        }
        let (frame, start) = (self.frame, Instant::now());
        if self.viewers.came_to_rest(self.config.rest, start) {
            self.owed.camera_rested();
        }
        let passes = self.passes_owed();
        if self.allowed(passes, false).pass.now() {
            self.run_passes()?;
        }
        // Against the views of the current cameras only: a group committed for a stale view
        // could show new leaves that the deferred view needs unshaded.
        if !self.viewers.need_pass() {
            self.commit_ready_groups();
        }
        let allowed = self.allowed(self.passes_owed(), self.frame != frame);
        let feed = turns::feed(self.owed, &allowed, self.requests.queued());
        if feed.replan {
            self.replan();
        }
        self.submit_batches();
        if feed.replan_if_drained && self.requests.queued() == 0 {
            self.replan();
            self.submit_batches();
        }
        self.request_tiles();
        let pass_ran = self.frame != frame;
        let filtered = allowed.sync.now().then(|| self.sync_and_filter());
        if passes == PassesOwed::Walking && pass_ran {
            // A walking camera's cycle is its pass, re-plan and sync (the filter's own pace).
            let cycle = start.elapsed().saturating_sub(filtered.unwrap_or_default());
            self.paces.walking_view_ran(start, cycle);
        }
        if let Some(id) = self.refinement_candidate(Instant::now()) {
            self.timed(Work::Round, |s| s.refine_round(id))?;
        }
        self.note_convergence();
        self.trim_cache_to_budget();
        self.save_if_due();
        Ok(())
    }

    /// What of the work owed, and of the `passes` owed, its pace allows now (`pass_ran`: the
    /// viewers see a new view at once).
    fn allowed(&self, passes: PassesOwed, pass_ran: bool) -> Allowed {
        let work_queued = self.requests.queued() > 0;
        self.paces
            .allowed(self.owed, passes, pass_ran, work_queued, Instant::now())
    }

    /// The passes owed, and whether they may wait (`turns::passes_owed`).
    fn passes_owed(&self) -> PassesOwed {
        let views = self.viewers.turn_views();
        let (walking, rest) = (self.config.work_while_walking, self.config.rest);
        turns::passes_owed(&views, walking, rest, Instant::now())
    }

    /// Runs `work`, counts its time, and spaces the next run of paced work by it.
    fn timed<T>(&mut self, work: Work, run: impl FnOnce(&mut Self) -> T) -> T {
        let start = Instant::now();
        let out = run(self);
        let spent = start.elapsed();
        self.paces.ran(work, start, spent);
        self.counters.costs.add(work, spent);
        out
    }

    /// The stated end of DESIGN.md §5 for every viewer: its criterion finds nothing to subdivide
    /// and no sample is wanted (every visible one is below the displayed-error threshold or at
    /// the ladder's cap), nothing is in flight and no refinement step waits.
    fn note_convergence(&mut self) {
        let converged = !self.viewers.is_empty()
            && self.viewers.iter().all(|v| {
                // Without refinement no criterion runs: there is nothing to subdivide.
                let dry = v.criterion_dry || !self.config.refine;
                v.view.is_some() && dry && !v.wait.needs_pass() && self.tiles_converged(v)
            })
            && self.requests.outstanding() == 0
            && self.refinement.pending.is_empty()
            && !self.filter_runs.in_flight()
            && !self.owed.any();
        self.counters.converged(converged);
    }

    fn run_passes(&mut self) -> anyhow::Result<()> {
        if !self.viewers.need_pass() {
            return Ok(());
        }
        let start = Instant::now();
        self.frame += 1;
        let kept = self.keep_memory_budget();
        if kept.leaves_changed {
            self.viewers.leaves_changed();
        }
        // Every K samples the views are drawn afresh (thesis §4.1's revisit): a carried view
        // differs from a drawn one by slivers the rasteriser's sub-pixel grid decides, and the
        // redraw keeps them from adding up over hundreds of rounds. (Single 20-s runs on
        // bracara VT, mean FLIP at 20 s: 0.0369 carried throughout, 0.0360 with this redraw,
        // 0.0355 with every view drawn; within the runs' spread, so not a measured cure.)
        let redraw = self.counters.since_pass >= self.config.revisit_samples || kept.recycled;
        let drew = self.pass_views(redraw)?;
        // Every viewer's view counts as seen now, not only those just re-run: while one viewer
        // walks, what another one rests on is neither evicted nor coarsened.
        for view in self.viewers.views() {
            self.cache
                .touch_visible(&self.mesh, &view.visible, self.frame);
            self.refinement.seen(&self.mesh, view, self.frame);
        }
        if drew {
            self.counters.since_pass = 0;
        }
        self.cache.evict(self.frame, &|_| false);
        self.filter_runs.due = true;
        self.owed.views_changed();
        self.refinement.merge_input();
        let work = if drew { Work::Pass } else { Work::CarryOver };
        self.counters.costs.add(work, start.elapsed());
        Ok(())
    }

    /// Commits every pending group whose visible new leaves are shaded: the viewers see new
    /// leaves, new input for their criteria.
    fn commit_ready_groups(&mut self) {
        let views = self.viewers.views();
        if self.refinement.commit_ready(views, &self.mesh, &self.cache) {
            self.viewers.new_input();
            self.owed.groups_committed();
        }
    }

    /// Rebuilds the request queue from the visible sets and the cache.
    fn replan(&mut self) {
        self.timed(Work::Replan, Self::replan_requests);
        self.owed.replanned();
    }

    fn replan_requests(&mut self) {
        // What the backlog holds was batched under the old plan; the new one batches it again
        // in the new order (a camera move must not wait behind the old view's backlog).
        for batch in self.pool.withdraw() {
            self.requests.finished(&batch);
        }
        let mut needs = Vec::new();
        for viewer in self.viewers.iter() {
            let (Some(view), Some(camera)) = (&viewer.view, &viewer.camera) else {
                continue;
            };
            needs.extend(plan::needs(&NeedsInput {
                view,
                eye: camera.eye_vec(),
                pending: &self.refinement.pending,
                mesh: &self.mesh,
                cache: &self.cache,
                rules: &self.rules,
                more_paths: MorePaths::for_viewer(&self.config, viewer),
                focus: self.focus_of(viewer),
            }));
        }
        self.requests.replan(needs);
    }

    /// Where a walking viewer's next steps look on its image (`ahead`), while its camera moves
    /// and work goes on while walking; otherwise None, the image's centre (also for a view
    /// drawn ahead of the camera, `Viewer::pass_camera`: it looks where the motion heads).
    fn focus_of(&self, viewer: &Viewer) -> Option<(f32, f32)> {
        let (Some(view), Some(camera), Some((previous, previous_at))) =
            (&viewer.view, &viewer.camera, &viewer.previous)
        else {
            return None;
        };
        let moving = viewer.camera_at.elapsed() < self.config.rest;
        if !self.config.work_while_walking || !moving || viewer.view_behind_camera() {
            return None;
        }
        let depth = ahead::centre_depth(view, &self.mesh, camera);
        let (previous, current) = ((previous, *previous_at), (camera, viewer.camera_at));
        Some(ahead::focus(previous, current, depth))
    }

    /// Brings every viewer up to date, then starts a run of the indirect filter if one is due
    /// (`filtering`). Returns the time that start took.
    fn sync_and_filter(&mut self) -> Duration {
        self.timed(Work::Sync, Self::sync_viewers);
        let start = Instant::now();
        self.start_filter();
        start.elapsed()
    }

    fn sync_viewers(&mut self) {
        let input = SyncInput {
            mesh: &self.mesh,
            cache: &self.cache,
            pending: &self.refinement.pending,
            outstanding_requests: self.requests.outstanding() as u64,
            filter_owed: self.filter_runs.due || self.filter_runs.in_flight(),
            samples: self.counters.samples,
            paths: self.counters.paths,
            now: Instant::now(),
            kept_while_walking: self.config.kept_while_walking,
        };
        for viewer in self.viewers.iter_mut() {
            viewer.sync(&input);
        }
        // A filter run due keeps the sync owed: the next one, at the sync's own pace, starts it
        // if its pace allows, and the one after its results shows what it changed; only then is
        // the picture idle.
        if !self.filter_runs.due {
            self.owed.synced();
        }
    }

    /// Keeps each renderer holding `batches_per_renderer` batches, and the pool's backlog
    /// holding `renderer_backlog` of the renderers' measured capacity beyond them, within the
    /// pool's bound in batches (`PoolHandle::most_batches`): the backlog is sent while this
    /// thread is busy with a pass or a refinement round (DESIGN.md §3: rest time goes to the
    /// renderers).
    fn submit_batches(&mut self) {
        let held = self.config.batches_per_renderer.max(1) * self.renderers.max(1);
        let most = self.pool.most_batches(self.renderers);
        let backlog = self.config.renderer_backlog.as_secs_f64();
        let limit = BatchLimit {
            points: self.config.batch_points,
            paths: self.config.batch_paths,
        };
        loop {
            let in_flight = self.requests.batches_in_flight();
            let backlog_full = self.pool.backlog_seconds().is_none_or(|s| s >= backlog);
            if in_flight >= most || (in_flight >= held && backlog_full) {
                break;
            }
            let Some(batch) = self.requests.next_batch(limit, &self.cache) else {
                break;
            };
            let lane = if self.requests.is_urgent(batch.batch_id) {
                Lane::Urgent
            } else {
                Lane::Background
            };
            // A full backlog gives the batch back, its samples asked for again later.
            if let Err(batch) = self.pool.submit(batch, lane) {
                self.requests.finished(&batch);
                self.owed.queue_changed();
                break;
            }
        }
    }

    /// What refinement as a whole waits for at this instant.
    fn refine_gate(&self) -> RefineGate {
        RefineGate {
            refine: self.config.refine,
            groups_pending: !self.refinement.pending.is_empty(),
            outstanding: self.requests.outstanding_before_paths(),
            queue_low: self.config.queue_low,
            rest: self.config.rest,
            while_walking: self.config.work_while_walking,
            next_round_at: self.paces.next_round_at(self.requests.queued() > 0),
            merge_due: self.config.refine && self.refinement.merge_due(),
        }
    }

    /// The viewer whose turn it is to refine at `now`, if refinement may run.
    fn refinement_candidate(&self, now: Instant) -> Option<ViewerId> {
        let views = self.viewers.turn_views();
        turns::refinement_candidate(&self.refine_gate(), &views, self.refinement.rounds, now)
    }

    /// One refinement round for viewer `id`: the viewers learn of its new leaves, the queue
    /// that the criterion ran dry. A due pass of coarsening by uniformity comes first; where it
    /// merged, the round ends there: the views are owed a pass.
    fn refine_round(&mut self, id: ViewerId) -> anyhow::Result<()> {
        let started = Instant::now();
        if self.refinement.merge_due() && self.merge_uniform() {
            self.viewers.leaves_changed();
            return Ok(());
        }
        let exhausted = self
            .viewers
            .get(id)
            .expect("candidate exists")
            .wait
            .is_exhausted();
        // Exhausted: its turn came for the merge pass only (`RefineGate::merge_due`).
        if exhausted || !self.round_fits(id) {
            return Ok(());
        }
        let viewer = self.viewers.get(id).expect("candidate exists");
        let image =
            refinement::luminance_image(viewer, &self.mesh, &self.visibility, &mut self.luminance)?;
        let viewer = self.viewers.get_mut(id).expect("candidate exists");
        viewer.refined_at = Some(started);
        match self
            .refinement
            .round(id, viewer, image, &mut self.mesh, &self.cache)
        {
            Round::Exhausted { newly_dry: true } => self.owed.queue_changed(),
            Round::Refined => self.viewers.leaves_changed(),
            Round::Exhausted { newly_dry: false } | Round::TooSmall => {}
        }
        Ok(())
    }

    /// Whether a turn has work without any new event, and else when to wake: a camera coming to
    /// rest, a round's pace, or a pass, a sync or a re-plan its pace put off.
    fn waiting_for(&self) -> (bool, Option<Instant>) {
        let now = Instant::now();
        let (views, gate) = (self.viewers.turn_views(), self.refine_gate());
        let passes = self.passes_owed();
        let allowed = self.allowed(passes, false);
        let candidate = turns::refinement_candidate(&gate, &views, self.refinement.rounds, now);
        let ready = turns::next_ready(&gate, &views, now);
        let rested = turns::next_rest(&views, gate.rest, now);
        let kept = self.viewers.next_rest_owed(gate.rest).filter(|&t| t > now);
        let wake = [ready, allowed.wake_at(), rested, kept];
        (
            turns::has_work_now(self.owed, &allowed, candidate),
            wake.into_iter().flatten().chain(self.save_due_at()).min(),
        )
    }
}
