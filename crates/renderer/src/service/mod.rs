//! The renderer service (DESIGN.md §2, §8): accepts SMA connections on a TCP listener, one task per
//! connection, and answers shade batches computed on a rayon pool. A peer's bad input is answered
//! and its connection closed; the server itself never panics on it and keeps serving the others.

mod connection;

use std::future::Future;
use std::sync::Arc;

use protocol::admission::{Admission, ConnectionLimit, PortLimits};
use tokio::net::TcpListener;
use tokio::sync::watch;
use tokio::task::JoinSet;

use crate::world::World;

/// Largest `paths` per point a batch may ask for (a guard against a peer asking for years of work).
pub const MAX_PATHS: u32 = 1 << 20;
/// Largest finite bounce depth a batch may ask for.
pub const MAX_BOUNCES: u32 = 1024;

/// What every connection shares.
pub struct Service {
    pub world: Arc<World>,
    pub pool: Arc<rayon::ThreadPool>,
    pub max_frame: usize,
    /// SMAs served at once, and their handshake deadline (DESIGN.md §8).
    pub port: PortLimits,
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
