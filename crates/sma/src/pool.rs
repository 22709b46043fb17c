//! The renderer pool (DESIGN.md §2): any number of renderers, each kept busy with a bounded number
//! of outstanding batches. A lost renderer's batches go back to the front of the queue and are
//! re-issued elsewhere; its link reconnects with backoff. A batch is answered at most once: a
//! reply counts only from the link that holds the batch now, so no reply enters the cache twice.
//!
//! One task per renderer link (connect, handshake, send, receive) and one dispatcher task that
//! owns the queue and the in-flight table, in the style of tokio's mini-redis.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use protocol::connection::{TcpReader, TcpWriter, connect_handshake};
use protocol::renderer_link::{FromRenderer, Radiance, ShadeBatch, ToRenderer};
use protocol::{Fingerprint, Hello, ProtocolError, Role, split_tcp};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};

/// A batch rejected or answered badly this many times is given back to the schedule as failed.
const MAX_ATTEMPTS: u32 = 3;

#[derive(Clone, Debug)]
pub struct PoolConfig {
    /// `host:port` of each renderer.
    pub renderers: Vec<String>,
    /// The scene both sides must have loaded.
    pub fingerprint: Fingerprint,
    /// Batches in flight per renderer: enough to hide a round trip, few enough that a camera
    /// change is not stuck behind stale work.
    pub depth: usize,
    pub max_frame: usize,
    pub backoff_min: Duration,
    pub backoff_max: Duration,
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
    /// The number of connected renderers changed.
    Renderers { connected: usize },
}

/// The schedule's side of the pool.
#[derive(Clone)]
pub struct PoolHandle {
    submit: mpsc::UnboundedSender<ShadeBatch>,
}

impl PoolHandle {
    /// Queues a batch; it is dispatched as soon as a renderer has room.
    pub fn submit(&self, batch: ShadeBatch) {
        // The dispatcher lives as long as the runtime; a send after shutdown is moot.
        let _ = self.submit.send(batch);
    }
}

/// Starts the dispatcher and one link task per renderer.
pub fn spawn(
    config: PoolConfig,
    events: mpsc::UnboundedSender<PoolEvent>,
    shutdown: watch::Receiver<bool>,
) -> PoolHandle {
    let (submit, submitted) = mpsc::unbounded_channel();
    let (link_tx, link_rx) = mpsc::unbounded_channel();
    for (index, addr) in config.renderers.iter().enumerate() {
        let link = Link {
            index,
            addr: addr.clone(),
            config: config.clone(),
            events: link_tx.clone(),
        };
        tokio::spawn(link.run(shutdown.clone()));
    }
    let dispatcher = Dispatcher {
        depth: config.depth.max(1),
        links: vec![LinkSlot::default(); config.renderers.len()],
        queue: VecDeque::new(),
        in_flight: HashMap::new(),
        events,
    };
    tokio::spawn(dispatcher.run(submitted, link_rx));
    PoolHandle { submit }
}

/// What a link task tells the dispatcher. `generation` tells one connection of a link from the
/// next, so news from a dead connection cannot touch batches re-issued since.
enum LinkEvent {
    Up {
        index: usize,
        generation: u64,
        batches: mpsc::UnboundedSender<ShadeBatch>,
    },
    Reply {
        index: usize,
        generation: u64,
        reply: FromRenderer,
    },
    Down {
        index: usize,
        generation: u64,
        reason: String,
    },
}

#[derive(Clone, Default)]
struct LinkSlot {
    generation: u64,
    batches: Option<mpsc::UnboundedSender<ShadeBatch>>,
    outstanding: usize,
}

struct InFlight {
    index: usize,
    generation: u64,
    batch: ShadeBatch,
}

struct Dispatcher {
    depth: usize,
    links: Vec<LinkSlot>,
    queue: VecDeque<(ShadeBatch, u32)>,
    in_flight: HashMap<u64, (InFlight, u32)>,
    events: mpsc::UnboundedSender<PoolEvent>,
}

impl Dispatcher {
    async fn run(
        mut self,
        mut submitted: mpsc::UnboundedReceiver<ShadeBatch>,
        mut links: mpsc::UnboundedReceiver<LinkEvent>,
    ) {
        loop {
            tokio::select! {
                batch = submitted.recv() => match batch {
                    Some(batch) => self.queue.push_back((batch, 0)),
                    None => return,
                },
                Some(event) = links.recv() => self.on_link_event(event),
            }
            self.dispatch();
        }
    }

    fn on_link_event(&mut self, event: LinkEvent) {
        match event {
            LinkEvent::Up {
                index,
                generation,
                batches,
            } => {
                self.links[index] = LinkSlot {
                    generation,
                    batches: Some(batches),
                    outstanding: 0,
                };
                self.report_connected();
            }
            LinkEvent::Down {
                index,
                generation,
                reason,
            } => {
                if self.links[index].generation != generation {
                    return;
                }
                tracing::warn!(renderer = index, %reason, "renderer lost; re-issuing its batches");
                self.links[index].batches = None;
                self.links[index].outstanding = 0;
                self.requeue_link(index, generation);
                self.report_connected();
            }
            LinkEvent::Reply {
                index,
                generation,
                reply,
            } => {
                self.on_reply(index, generation, reply);
            }
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
        };
        // Only the link that holds the batch now may answer it (at most once).
        let owned = self
            .in_flight
            .get(&batch_id)
            .is_some_and(|(f, _)| f.index == index && f.generation == generation);
        if !owned {
            tracing::debug!(
                renderer = index,
                batch_id,
                "reply for a batch this link does not hold"
            );
            return;
        }
        let (flight, attempts) = self.in_flight.remove(&batch_id).expect("checked above");
        self.links[index].outstanding = self.links[index].outstanding.saturating_sub(1);
        match outcome.and_then(|r| checked(&flight.batch, r)) {
            Ok(radiance) => {
                let _ = self.events.send(PoolEvent::Shaded {
                    batch: flight.batch,
                    radiance,
                });
            }
            Err(reason) => self.retry(flight.batch, attempts + 1, reason),
        }
    }

    fn retry(&mut self, batch: ShadeBatch, attempts: u32, reason: String) {
        if attempts >= MAX_ATTEMPTS {
            tracing::warn!(batch_id = batch.batch_id, %reason, "batch failed {attempts} times");
            let _ = self.events.send(PoolEvent::Failed { batch, reason });
        } else {
            self.queue.push_front((batch, attempts));
        }
    }

    /// Puts every batch held by one connection of a link back at the front of the queue, in
    /// their original order.
    fn requeue_link(&mut self, index: usize, generation: u64) {
        let mut lost: Vec<u64> = self
            .in_flight
            .iter()
            .filter(|(_, (f, _))| f.index == index && f.generation == generation)
            .map(|(id, _)| *id)
            .collect();
        lost.sort_unstable_by(|a, b| b.cmp(a));
        for id in lost {
            if let Some((flight, attempts)) = self.in_flight.remove(&id) {
                self.queue.push_front((flight.batch, attempts));
            }
        }
    }

    /// Hands queued batches to links with room, least loaded first.
    fn dispatch(&mut self) {
        while !self.queue.is_empty() {
            let Some(index) = (0..self.links.len())
                .filter(|&i| {
                    self.links[i].batches.is_some() && self.links[i].outstanding < self.depth
                })
                .min_by_key(|&i| self.links[i].outstanding)
            else {
                return;
            };
            let (batch, attempts) = self.queue.pop_front().expect("not empty");
            let slot = &mut self.links[index];
            let sent = slot
                .batches
                .as_ref()
                .is_some_and(|tx| tx.send(batch.clone()).is_ok());
            if sent {
                slot.outstanding += 1;
                let flight = InFlight {
                    index,
                    generation: slot.generation,
                    batch,
                };
                self.in_flight
                    .insert(flight.batch.batch_id, (flight, attempts));
            } else {
                // The link task ended; its Down event is on its way.
                slot.batches = None;
                self.queue.push_front((batch, attempts));
            }
        }
    }

    fn report_connected(&self) {
        let connected = self.links.iter().filter(|l| l.batches.is_some()).count();
        let _ = self.events.send(PoolEvent::Renderers { connected });
    }
}

/// A reply must carry one value, variance, path count and flag byte per point. What the values
/// are is judged per point by the schedule: one bad point does not cost the batch's others.
fn checked(batch: &ShadeBatch, radiance: Radiance) -> Result<Radiance, String> {
    let n = batch.points.len();
    let lengths = [
        radiance.rgb.len(),
        radiance.luminance_variance.len(),
        radiance.paths.len(),
        radiance.flags.len(),
    ];
    if lengths.iter().any(|&l| l != n) {
        return Err(format!(
            "reply holds {lengths:?} values, variances, path counts and flags for {n} points"
        ));
    }
    Ok(radiance)
}

/// Why one connection of a [`Link`] ended.
#[derive(Debug)]
enum LinkDown {
    /// Connecting or the handshake failed: the backoff grows.
    Connecting(ProtocolError),
    /// The link had been up: the backoff starts again from its minimum.
    Serving(ProtocolError),
}

impl LinkDown {
    fn was_up(&self) -> bool {
        matches!(self, LinkDown::Serving(_))
    }

    fn error(&self) -> &ProtocolError {
        match self {
            LinkDown::Connecting(e) | LinkDown::Serving(e) => e,
        }
    }
}

/// One renderer address: connects, serves, and reconnects with backoff, forever.
struct Link {
    index: usize,
    addr: String,
    config: PoolConfig,
    events: mpsc::UnboundedSender<LinkEvent>,
}

impl Link {
    async fn run(self, mut shutdown: watch::Receiver<bool>) {
        let mut backoff = self.config.backoff_min;
        let mut generation = 0u64;
        while !*shutdown.borrow() {
            generation += 1;
            let outcome = tokio::select! {
                r = self.serve(generation) => r,
                _ = shutdown.changed() => return,
            };
            let (served, reason) = match outcome {
                Ok(()) => return,
                Err(down) => (down.was_up(), down.error().to_string()),
            };
            let _ = self.events.send(LinkEvent::Down {
                index: self.index,
                generation,
                reason: reason.clone(),
            });
            if served {
                backoff = self.config.backoff_min;
            }
            tracing::info!(renderer = %self.addr, %reason, retry_in = ?backoff, "renderer link down");
            tokio::select! {
                _ = tokio::time::sleep(backoff) => {}
                _ = shutdown.changed() => return,
            }
            backoff = (backoff * 2).min(self.config.backoff_max);
        }
    }

    /// One connection, until it goes down (`Ok` when the pool itself ends).
    async fn serve(&self, generation: u64) -> Result<(), LinkDown> {
        let (mut reader, mut writer) = self.connect().await.map_err(LinkDown::Connecting)?;
        tracing::info!(renderer = %self.addr, "renderer connected");
        let (tx, mut batches) = mpsc::unbounded_channel();
        let up = LinkEvent::Up {
            index: self.index,
            generation,
            batches: tx,
        };
        if self.events.send(up).is_err() {
            return Ok(());
        }
        loop {
            tokio::select! {
                batch = batches.recv() => match batch {
                    Some(batch) => writer.send(&ToRenderer::ShadeBatch(batch)).await.map_err(LinkDown::Serving)?,
                    None => return Ok(()),
                },
                reply = reader.recv() => {
                    let reply = reply.map_err(LinkDown::Serving)?;
                    let fatal = match &reply {
                        FromRenderer::Error { message } => Some(message.clone()),
                        _ => None,
                    };
                    let event = LinkEvent::Reply { index: self.index, generation, reply };
                    if self.events.send(event).is_err() {
                        return Ok(());
                    }
                    if let Some(message) = fatal {
                        return Err(LinkDown::Serving(ProtocolError::Remote(message)));
                    }
                }
            }
        }
    }

    async fn connect(
        &self,
    ) -> Result<(TcpReader<FromRenderer>, TcpWriter<ToRenderer>), ProtocolError> {
        let stream = TcpStream::connect(&self.addr).await?;
        let (mut reader, mut writer) = split_tcp(stream, self.config.max_frame);
        let hello = Hello::new(Role::Sma, Some(self.config.fingerprint));
        connect_handshake(&mut reader, &mut writer, hello, Role::Renderer).await?;
        Ok((reader, writer))
    }
}
