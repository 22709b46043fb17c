//! The renderer service (DESIGN.md §2, §8): accepts SMA connections on a TCP listener, and joins
//! the SMAs it is told to (their renderer ports, reconnecting with backoff), one task per
//! connection, and answers shade batches computed on a rayon pool. A peer's bad input is answered
//! and its connection closed; the server itself never panics on it and keeps serving the others.

mod connection;

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use protocol::admission::{Admission, ConnectionLimit, PortLimits};
use protocol::liveness::Liveness;
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinSet;

use crate::world::World;

/// Largest `paths` per point a batch may ask for (a guard against a peer asking for years of work).
pub const MAX_PATHS: u32 = 1 << 20;
/// Most camera rays per pixel one pass over a direct tile may ask for.
pub const MAX_TILE_SAMPLES: u32 = 1024;
/// Largest finite bounce depth a batch may ask for.
pub const MAX_BOUNCES: u32 = 1024;
/// Batches one connection holds at once by default: the SMA keeps a few in flight per renderer
/// (DESIGN.md §2), so this is room for a deeper pipeline, not a queue of minutes.
pub const DEFAULT_MAX_BATCHES: usize = 64;

/// First and longest wait before joining an SMA again.
const JOIN_RETRY: (Duration, Duration) = (Duration::from_millis(100), Duration::from_secs(5));

/// What every connection shares.
pub struct Service {
    pub world: Arc<World>,
    pub pool: Arc<rayon::ThreadPool>,
    pub max_frame: usize,
    /// SMAs served at once, and their handshake deadline (DESIGN.md §8).
    pub port: PortLimits,
    /// When an SMA counts as gone, and how long a frame may take.
    pub liveness: Liveness,
    /// Batches one connection may hold at once; one more is refused.
    pub max_batches: usize,
    /// SMA renderer ports to join, besides accepting SMAs on the listener.
    pub join: Vec<String>,
}

/// The renderer's side of the link only frees a gone SMA's connection (nothing here waits on
/// the SMA), so it waits long: 20 s, against the SMA's 500 ms heartbeats.
pub fn default_liveness() -> Liveness {
    Liveness {
        silence: Duration::from_secs(20),
        ..Liveness::default()
    }
}

impl Service {
    /// A service on a pool of `threads` workers (0 = one per core).
    pub fn new(world: Arc<World>, threads: usize, max_frame: usize) -> anyhow::Result<Service> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("shade-{i}"))
            .build()?;
        Ok(Service {
            world,
            pool: Arc::new(pool),
            max_frame,
            port: PortLimits::default(),
            liveness: default_liveness(),
            max_batches: DEFAULT_MAX_BATCHES,
            join: Vec::new(),
        })
    }

    /// Serves connections from `listener` until `shutdown` completes, then closes every connection
    /// and returns.
    pub async fn serve(
        self,
        listener: TcpListener,
        shutdown: impl Future<Output = ()>,
    ) -> anyhow::Result<()> {
        let service = Arc::new(self);
        let (stop_tx, stop_rx) = watch::channel(false);
        let mut connections = JoinSet::new();
        let limit = ConnectionLimit::new(service.port.max_connections);
        for addr in service.join.clone() {
            connections.spawn(join_forever(addr, Arc::clone(&service), stop_rx.clone()));
        }
        tokio::pin!(shutdown);
        loop {
            tokio::select! {
                _ = &mut shutdown => break,
                accepted = listener.accept() => match accepted {
                    Ok((stream, peer)) => match limit.admit() {
                        Admission::Serve(permit) => {
                            tracing::debug!(%peer, "SMA connected");
                            let service = Arc::clone(&service);
                            let stop = stop_rx.clone();
                            connections.spawn(async move {
                                if let Err(e) = connection::handle(stream, service, stop).await {
                                    tracing::warn!(%peer, "connection ended: {e}");
                                } else {
                                    tracing::debug!(%peer, "connection closed");
                                }
                                drop(permit);
                            });
                        }
                        Admission::Refuse(permit) => {
                            let reason = limit.full_reason();
                            tracing::warn!(%peer, "refusing an SMA: {reason}");
                            let service = Arc::clone(&service);
                            connections.spawn(async move {
                                connection::refuse(stream, &service, reason).await;
                                drop(permit);
                            });
                        }
                        Admission::Close => {
                            tracing::warn!(%peer, "closing a connection at once: too many being refused");
                        }
                    },
                    // Transient accept errors (e.g. too many open files) must not end the server.
                    Err(e) => tracing::warn!("accept failed: {e}"),
                },
                Some(_) = connections.join_next(), if !connections.is_empty() => {}
            }
        }
        tracing::info!("shutting down");
        let _ = stop_tx.send(true);
        while connections.join_next().await.is_some() {}
        Ok(())
    }
}

/// Joins the SMA at `addr` until shutdown: after a link ends (or cannot start), again after a
/// pause that doubles up to a few seconds, and starts short again once a link was up.
async fn join_forever(addr: String, service: Arc<Service>, mut stop: watch::Receiver<bool>) {
    let mut retry = JOIN_RETRY.0;
    while !*stop.borrow() {
        let started = tokio::time::Instant::now();
        let ended = tokio::select! {
            ended = connection::join(&addr, Arc::clone(&service), stop.clone()) => ended,
            _ = stop.changed() => return,
        };
        if started.elapsed() > service.liveness.silence {
            retry = JOIN_RETRY.0;
        }
        match ended {
            Ok(()) => tracing::info!(sma = %addr, "left the SMA"),
            Err(e) => tracing::warn!(sma = %addr, retry_in = ?retry, "joining the SMA: {e}"),
        }
        tokio::select! {
            _ = tokio::time::sleep(retry) => {}
            _ = stop.changed() => return,
        }
        retry = (retry * 2).min(JOIN_RETRY.1);
    }
}
