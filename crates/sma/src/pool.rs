//! The renderer pool (DESIGN.md §2): whichever renderers are there now — dialed at `--renderer`
//! addresses, or joined on the SMA's renderer port — each kept busy with a bounded number of
//! outstanding batches, sent where they will finish first at each renderer's measured rate.
//!
//! A renderer is lost when its link goes down, when it stops answering heartbeats, or when a
//! batch it holds passes its deadline (its expected time at that renderer's rate, times a
//! factor). A lost renderer's batches go back to the front of the backlog and are re-issued
//! elsewhere; its link closes and reconnects with backoff (a joined one rejoins by itself). A
//! batch is answered at most once: a reply counts only from the connection that holds the batch
//! now, so a late answer is ignored and no reply enters the cache twice. With no renderer
//! answering, batches wait in the backlog and the SMA says so; they go out when one answers.
//!
//! One task per renderer connection and one dispatcher task that owns the in-flight table and
//! sends from the backlog (`backlog`: what the schedule handed over and may still withdraw), in
//! the style of tokio's mini-redis. Every channel between them is bounded, and so is the backlog.

mod backlog;
mod busy;
mod link;
mod rate;
mod tiles;

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use protocol::SceneIdentity;
use protocol::admission::{ConnectionLimit, PortLimits};
use protocol::liveness::Liveness;
use protocol::renderer_link::{FromRenderer, Radiance, ShadeBatch, ToRenderer};
use tokio::net::TcpListener;
use tokio::sync::{Notify, mpsc, watch};
use tokio::time::Instant;

use crate::clock::sleep_until;
use backlog::{Backlog, Queued};
use busy::BusyMeter;
use link::{Dialed, LinkEvent};
use rate::Rate;

/// A batch rejected or answered badly this many times is given back to the schedule as failed.
const MAX_ATTEMPTS: u32 = 3;
/// Batches per renderer that may wait in the backlog beyond those the renderers hold, whatever
/// their size: a bound on what a withdrawal hands back (the schedule keeps to it, through
/// [`PoolHandle::most_batches`]) and on what the pool holds for the schedule (it refuses past
/// it). The schedule sizes the backlog in seconds of the renderers' capacity, a fraction of a
/// second (DESIGN.md §3), so this bounds it only where batches are very short.
const BACKLOG_BATCHES_PER_RENDERER: usize = 64;
/// News from the link tasks waiting for the dispatcher.
const LINK_QUEUE: usize = 256;

#[derive(Clone, Debug)]
pub struct PoolConfig {
    /// `host:port` of each renderer the SMA dials.
    pub renderers: Vec<String>,
    /// The scene both sides must have loaded, textures on or off alike.
    pub scene: SceneIdentity,
    /// Batches in flight per renderer: enough to hide a round trip, few enough that a camera
    /// change is not stuck behind stale work.
    pub depth: usize,
    pub max_frame: usize,
    pub backoff_min: Duration,
    pub backoff_max: Duration,
    pub liveness: Liveness,
    /// A batch is lost once this many times its expected time has passed (plus the silence
    /// limit, for the round trip and a loaded host's scheduling).
    pub deadline_factor: f64,
    /// A batch's deadline before its renderer's rate is measured.
    pub first_deadline: Duration,
    /// Renderers the renderer port serves at once, and their handshake deadline.
    pub renderer_port: PortLimits,
}

/// What the pool tells the schedule.
#[derive(Debug)]
pub enum PoolEvent {
    /// A batch answered, checked to hold one value per point.
    Shaded {
        batch: ShadeBatch,
        radiance: Radiance,
    },
    /// A batch no renderer would take; its points are not shaded.
    Failed { batch: ShadeBatch, reason: String },
    /// The number of renderers answering changed.
    Renderers { connected: usize },
    /// What became of a direct-light tile (`tiles`).
    Tile(TileNews),
}

pub use backlog::Lane;
pub use tiles::TileNews;

/// The most batches handed over to the pool and not yet answered, with `renderers` answering
/// (counted as one when none is): the `depth` each holds, and [`BACKLOG_BATCHES_PER_RENDERER`]
/// more waiting in the backlog.
fn most_batches(depth: usize, renderers: usize) -> usize {
    (depth.max(1) + BACKLOG_BATCHES_PER_RENDERER) * renderers.max(1)
}

/// The schedule's side of the pool.
#[derive(Clone)]
pub struct PoolHandle {
    backlog: Arc<Mutex<Backlog>>,
    /// Wakes the dispatcher when a batch is handed over.
    submitted: Arc<Notify>,
    busy: Arc<Mutex<BusyMeter>>,
    tiles: Arc<Mutex<tiles::TileQueue>>,
    /// Batches in flight per renderer (`PoolConfig::depth`).
    depth: usize,
    /// The backlog's bound: [`most_batches`] with every renderer the pool may serve answering
    /// (those dialed, and those the renderer port admits). A schedule that keeps to
    /// [`PoolHandle::most_batches`] never reaches it: what waits in the backlog is part of what
    /// it handed over, and no more renderers answer than the pool may serve.
    max_backlog: usize,
}

impl PoolHandle {
    /// The most batches the schedule may have handed over and not had answered, with
    /// `renderers` answering.
    pub fn most_batches(&self, renderers: usize) -> usize {
        most_batches(self.depth, renderers)
    }

    /// Queues a batch in its lane of the backlog; it is dispatched as soon as a renderer has
    /// room. A full backlog gives the batch back, for the schedule to ask again later.
    pub fn submit(&self, batch: ShadeBatch, lane: Lane) -> Result<(), ShadeBatch> {
        {
            let mut backlog = lock(&self.backlog);
            if backlog.len() >= self.max_backlog {
                return Err(batch);
            }
            backlog.push_back(batch, lane);
        }
        self.submitted.notify_one();
        Ok(())
    }

    /// Takes back every batch not yet sent to a renderer (the schedule's plan changed).
    pub fn withdraw(&self) -> Vec<ShadeBatch> {
        lock(&self.backlog).withdraw()
    }

    /// Seconds of the renderers' measured capacity that the backlog holds (None until a
    /// renderer's rate is measured).
    pub fn backlog_seconds(&self) -> Option<f64> {
        lock(&self.backlog).seconds()
    }

    /// The renderers' busy share since the previous call (0..1; see `busy`).
    pub fn take_busy(&self) -> f32 {
        lock(&self.busy).take(std::time::Instant::now())
    }
}

/// The pool's shared state is left consistent by every holder, so a poisoned lock is still good.
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|e| e.into_inner())
}

/// Starts the dispatcher, one link task per dialed renderer, and the renderer port's acceptor
/// when `joining` is given.
pub fn spawn(
    config: PoolConfig,
    events: mpsc::Sender<PoolEvent>,
    joining: Option<TcpListener>,
    shutdown: watch::Receiver<bool>,
) -> PoolHandle {
    let joined = if joining.is_some() {
        config.renderer_port.max_connections
    } else {
        0
    };
    let depth = config.depth;
    let max_backlog = most_batches(config.depth, config.renderers.len() + joined);
    let backlog = Arc::new(Mutex::new(Backlog::default()));
    let submitted = Arc::new(Notify::new());
    let tiles = Arc::new(Mutex::new(tiles::TileQueue::default()));
    let (link_tx, link_rx) = mpsc::channel(LINK_QUEUE);
    for (index, addr) in config.renderers.iter().enumerate() {
        let link = Dialed {
            index,
            addr: addr.clone(),
            config: config.clone(),
            events: link_tx.clone(),
        };
        tokio::spawn(link.run(shutdown.clone()));
    }
    if let Some(listener) = joining {
        let limit = ConnectionLimit::new(config.renderer_port.max_connections);
        tokio::spawn(link::accept_joining(
            listener,
            limit,
            config.renderers.len(),
            config.clone(),
            link_tx,
            shutdown.clone(),
        ));
    }
    let busy = Arc::new(Mutex::new(BusyMeter::new(std::time::Instant::now())));
    let dispatcher = Dispatcher {
        busy: Arc::clone(&busy),
        config,
        links: BTreeMap::new(),
        rates: HashMap::new(),
        backlog: Arc::clone(&backlog),
        in_flight: HashMap::new(),
        tiles: tiles::TileLane::new(Arc::clone(&tiles)),
        news: VecDeque::new(),
        answering: 0,
        none_answering: false,
    };
    tokio::spawn(dispatcher.run(Arc::clone(&submitted), link_rx, events, shutdown));
    PoolHandle {
        backlog,
        submitted,
        busy,
        tiles,
        depth,
        max_backlog,
    }
}

/// A connection that is up.
struct Slot {
    generation: u64,
    name: String,
    joined: bool,
    /// Batches and direct-light tiles, each counted in `outstanding`.
    batches: mpsc::Sender<ToRenderer>,
    outstanding: usize,
    /// The units of the batches it holds.
    units: f64,
}

struct InFlight {
    index: usize,
    generation: u64,
    batch: ShadeBatch,
    attempts: u32,
    sent: Instant,
    deadline: Instant,
}

struct Dispatcher {
    config: PoolConfig,
    /// Shared with the schedule's handle, which reads it for `Stats`.
    busy: Arc<Mutex<BusyMeter>>,
    links: BTreeMap<usize, Slot>,
    /// Measured rates, kept across a dialed renderer's reconnections.
    rates: HashMap<usize, Rate>,
    /// Shared with the schedule's handle, which fills it and may withdraw what is not sent.
    backlog: Arc<Mutex<Backlog>>,
    in_flight: HashMap<u64, InFlight>,
    tiles: tiles::TileLane,
    /// Events for the schedule, sent in order once a turn of the dispatcher is done.
    news: VecDeque<PoolEvent>,
    /// The renderers answering, as last told to the schedule.
    answering: usize,
    /// Every renderer there was stopped answering, and none has answered since.
    none_answering: bool,
}

impl Dispatcher {
    async fn run(
        mut self,
        submitted: Arc<Notify>,
        mut links: mpsc::Receiver<LinkEvent>,
        events: mpsc::Sender<PoolEvent>,
        mut shutdown: watch::Receiver<bool>,
    ) {
        loop {
            let due = self.in_flight.values().map(|f| f.deadline).min();
            tokio::select! {
                _ = shutdown.changed() => return,
                _ = submitted.notified() => {}
                Some(event) = links.recv() => self.on_link_event(event),
                _ = sleep_until(due), if due.is_some() => self.expire(Instant::now()),
            }
            self.dispatch();
            self.dispatch_tiles();
            self.observe_busy();
            self.publish_capacity();
            self.report_answering();
            while let Some(event) = self.news.pop_front() {
                if events.send(event).await.is_err() {
                    return;
                }
            }
        }
    }

    /// The answering renderers' summed rate, for the schedule to size the backlog by.
    fn publish_capacity(&self) {
        let measured: Vec<f64> = self
            .links
            .keys()
            .filter_map(|i| self.rates.get(i).and_then(Rate::units_per_sec))
            .collect();
        let capacity = (!measured.is_empty()).then(|| measured.iter().sum());
        lock(&self.backlog).set_capacity(capacity);
    }

    fn observe_busy(&self) {
        let holding = self.links.values().filter(|s| s.outstanding > 0).count();
        lock(&self.busy).observe(std::time::Instant::now(), holding, self.links.len());
    }

    fn on_link_event(&mut self, event: LinkEvent) {
        match event {
            LinkEvent::Up {
                index,
                generation,
                name,
                joined,
                batches,
            } => {
                let slot = Slot {
                    generation,
                    name,
                    joined,
                    batches,
                    outstanding: 0,
                    units: 0.0,
                };
                self.links.insert(index, slot);
            }
            LinkEvent::Down {
                index,
                generation,
                reason,
            } => self.lose(index, generation, &reason),
            LinkEvent::Reply {
                index,
                generation,
                reply,
            } => self.on_reply(index, generation, reply),
        }
    }

    /// Drops one connection of a renderer: its batches go back to the front of the queue, in
    /// their original order, and its link task, its batch channel closed, ends the connection.
    fn lose(&mut self, index: usize, generation: u64, reason: &str) {
        let Some(slot) = self
            .links
            .get(&index)
            .filter(|s| s.generation == generation)
        else {
            return;
        };
        let held = slot.outstanding;
        tracing::warn!(renderer = %slot.name, %reason, held, "renderer lost; re-issuing its batches");
        let joined = slot.joined;
        self.links.remove(&index);
        self.drop_tiles_of(index, generation);
        if joined {
            self.rates.remove(&index);
        }
        let mut lost: Vec<u64> = self
            .in_flight
            .iter()
            .filter(|(_, f)| f.index == index && f.generation == generation)
            .map(|(id, _)| *id)
            .collect();
        lost.sort_unstable_by(|a, b| b.cmp(a));
        let mut backlog = lock(&self.backlog);
        for id in lost {
            if let Some(flight) = self.in_flight.remove(&id) {
                backlog.push_front(Queued {
                    batch: flight.batch,
                    attempts: flight.attempts,
                });
            }
        }
    }

    /// Every renderer holding a batch past its deadline is lost.
    fn expire(&mut self, now: Instant) {
        let mut late: Vec<(usize, u64, Duration)> = self
            .in_flight
            .values()
            .filter(|f| f.deadline <= now)
            .map(|f| (f.index, f.generation, f.deadline - f.sent))
            .collect();
        late.sort_unstable_by_key(|&(index, generation, _)| (index, generation));
        late.dedup_by_key(|&mut (index, generation, _)| (index, generation));
        for (index, generation, allowed) in late {
            let reason = format!("a batch is not answered within its deadline of {allowed:.1?}");
            self.lose(index, generation, &reason);
        }
    }

    fn on_reply(&mut self, index: usize, generation: u64, reply: FromRenderer) {
        let (batch_id, outcome) = match reply {
            FromRenderer::Radiance(radiance) => (radiance.batch_id, Ok(radiance)),
            FromRenderer::Rejected { batch_id, reason } => (batch_id, Err(reason)),
            FromRenderer::Error { message } => {
                tracing::warn!(renderer = index, %message, "renderer reported an error");
                return;
            }
            FromRenderer::Pong { .. } => return,
            FromRenderer::DirectTile(answer) => {
                let tile_id = answer.tile_id;
                return self.on_tile_reply(index, generation, tile_id, Ok(answer));
            }
            FromRenderer::TileRejected { tile_id, reason } => {
                return self.on_tile_reply(index, generation, tile_id, Err(reason));
            }
        };
        // Only the connection that holds the batch now may answer it (at most once).
        let owned = self
            .in_flight
            .get(&batch_id)
            .is_some_and(|f| f.index == index && f.generation == generation);
        if !owned {
            tracing::debug!(
                renderer = index,
                batch_id,
                "reply for a batch this link does not hold (late, or re-issued)"
            );
            return;
        }
        let flight = self.in_flight.remove(&batch_id).expect("checked above");
        let units = rate::units(&flight.batch);
        if let Some(slot) = self.links.get_mut(&index) {
            slot.outstanding = slot.outstanding.saturating_sub(1);
            slot.units = (slot.units - units).max(0.0);
        }
        match outcome.and_then(|r| checked(&flight.batch, r)) {
            Ok(radiance) => {
                let rate = self.rates.entry(index).or_default();
                rate.answered(units, flight.sent.into_std(), Instant::now().into_std());
                self.news.push_back(PoolEvent::Shaded {
                    batch: flight.batch,
                    radiance,
                });
            }
            Err(reason) => self.retry(flight.batch, flight.attempts + 1, reason),
        }
    }

    fn retry(&mut self, batch: ShadeBatch, attempts: u32, reason: String) {
        if attempts >= MAX_ATTEMPTS {
            tracing::warn!(batch_id = batch.batch_id, %reason, "batch failed {attempts} times");
            self.news.push_back(PoolEvent::Failed { batch, reason });
        } else {
            lock(&self.backlog).push_front(Queued { batch, attempts });
        }
    }

    /// Hands queued batches to renderers with room, each to the one that would finish it first
    /// at its measured rate (one not yet measured first, so it gets measured).
    fn dispatch(&mut self) {
        loop {
            let Some(queued) = lock(&self.backlog).pop_front() else {
                return;
            };
            let units = rate::units(&queued.batch);
            let finish = |(index, slot): (&usize, &Slot)| {
                let rate = self.rates.get(index).copied().unwrap_or_default();
                let seconds = rate.expected(slot.units + units).map(|d| d.as_secs_f64());
                (seconds.unwrap_or(0.0), slot.outstanding, *index)
            };
            let best = self
                .links
                .iter()
                .filter(|(_, s)| s.outstanding < self.config.depth.max(1))
                .map(finish)
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let Some((_, _, index)) = best else {
                lock(&self.backlog).push_front(queued);
                return;
            };
            let rate = self.rates.get(&index).copied().unwrap_or_default();
            let slot = self.links.get_mut(&index).expect("chosen among the links");
            let allowed = rate::deadline(
                &rate,
                slot.units + units,
                self.config.deadline_factor,
                self.config.liveness.silence,
                self.config.first_deadline,
            );
            if (slot.batches)
                .try_send(ToRenderer::ShadeBatch(queued.batch.clone()))
                .is_err()
            {
                // The link task ended; its Down is on its way.
                let generation = slot.generation;
                lock(&self.backlog).push_front(queued);
                self.lose(index, generation, "its link task ended");
                continue;
            }
            slot.outstanding += 1;
            slot.units += units;
            let now = Instant::now();
            let flight = InFlight {
                index,
                generation: slot.generation,
                batch: queued.batch,
                attempts: queued.attempts,
                sent: now,
                deadline: now + allowed,
            };
            self.in_flight.insert(flight.batch.batch_id, flight);
        }
    }

    /// Tells the schedule when the number of renderers answering changed, and says so in the
    /// log when none is answering, or when one answers again.
    fn report_answering(&mut self) {
        let connected = self.links.len();
        if self.answering == connected {
            return;
        }
        if connected == 0 {
            tracing::warn!(
                waiting = lock(&self.backlog).len(),
                "no renderer is answering; the view keeps what it shows and its work waits"
            );
            self.none_answering = true;
        } else if self.none_answering {
            tracing::info!(
                renderers = connected,
                "a renderer answers again; work resumes"
            );
            self.none_answering = false;
        }
        self.answering = connected;
        self.news.push_back(PoolEvent::Renderers { connected });
    }
}

/// A reply must carry one answer in parts, path count and flag byte per point. What the values
/// are is judged per point by the schedule: one bad point does not cost the batch's others.
fn checked(batch: &ShadeBatch, radiance: Radiance) -> Result<Radiance, String> {
    let n = batch.points.len();
    let lengths = [
        radiance.parts.len(),
        radiance.paths.len(),
        radiance.flags.len(),
    ];
    if lengths.iter().any(|&l| l != n) {
        return Err(format!(
            "reply holds {lengths:?} answers in parts, path counts and flags for {n} points"
        ));
    }
    Ok(radiance)
}

#[cfg(test)]
mod tests;
