//! The running SMA: the viewer listener with one task per accepted connection (tokio mini-redis
//! style), the renderer pool, and the schedule on its own thread; all ended gracefully when the
//! shutdown signal flips.

use std::net::SocketAddr;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::Context;
use protocol::admission::{Admission, ConnectionLimit};
use tokio::net::TcpListener;
use tokio::sync::{mpsc, watch};

use crate::cache_file::MeshKey;
use crate::config::SmaConfig;
use crate::mesh::SubdivisionMesh;
use crate::pool::{self, PoolConfig, PoolEvent};
use crate::schedule::{CacheFileSetup, Schedule};
use crate::viewer_link::{
    self, SceneLooks, ViewerEvent, ViewerId, ViewerLinkConfig, scene_identity, scene_info,
};
use crate::visibility::Gpu;

/// Events waiting for the schedule from the viewers, and from the pool: past this their
/// senders wait (the schedule takes every waiting event each turn).
const EVENT_QUEUE: usize = 1024;

/// A started SMA.
pub struct Running {
    /// Where viewers connect (the actual port when `--listen` asked for port 0).
    pub addr: SocketAddr,
    /// Where renderers join, when the SMA has a renderer port.
    pub renderer_addr: Option<SocketAddr>,
    shutdown: watch::Sender<bool>,
    schedule: JoinHandle<anyhow::Result<()>>,
}

impl Running {
    /// Resolves once the SMA has stopped: the `shutdown` given to [`start`] resolved (or
    /// [`Running::stop`] was called), or the schedule ended by itself (an error in it ends the SMA).
    /// Returns the schedule's outcome.
    pub async fn stopped(self) -> anyhow::Result<()> {
        let mut shutdown = self.shutdown.subscribe();
        while !self.schedule.is_finished() && !*shutdown.borrow_and_update() {
            tokio::select! {
                _ = shutdown.changed() => {}
                _ = tokio::time::sleep(Duration::from_millis(100)) => {}
            }
        }
        self.stop().await
    }

    /// Signals every task and the schedule to stop, and waits for the schedule's outcome.
    pub async fn stop(self) -> anyhow::Result<()> {
        let _ = self.shutdown.send(true);
        let schedule = self.schedule;
        let joined = tokio::task::spawn_blocking(move || schedule.join()).await?;
        joined.map_err(|_| anyhow::anyhow!("the schedule thread panicked"))?
    }
}

/// Starts the SMA for `scene` as `config` says: binds the listener, connects the pool, opens the
/// graphics device; everything stops when `shutdown` resolves (or at [`Running::stop`]). Must be
/// called within a multi-threaded tokio runtime.
pub async fn start(
    config: SmaConfig,
    scene: scene::Scene,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> anyhow::Result<Running> {
    let scene = std::sync::Arc::new(scene);
    let mesh = SubdivisionMesh::new(&scene.mesh, config.mesh);
    let gpu = Gpu::new().context("visibility needs a graphics adapter")?;
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let on_shutdown = shutdown_tx.clone();
    tokio::spawn(async move {
        shutdown.await;
        let _ = on_shutdown.send(true);
    });
    let joining = match &config.renderer_listen {
        Some(addr) => Some(
            TcpListener::bind(addr)
                .await
                .with_context(|| format!("listening for renderers on {addr}"))?,
        ),
        None => None,
    };
    let renderer_addr = joining.as_ref().map(|l| l.local_addr()).transpose()?;
    let (pool_tx, pool_rx) = mpsc::channel(EVENT_QUEUE);
    let pool_config = PoolConfig {
        renderers: config.renderers.clone(),
        scene: scene_identity(&scene),
        depth: config.schedule.batches_per_renderer.max(1),
        max_frame: config.max_frame,
        backoff_min: Duration::from_millis(100),
        backoff_max: Duration::from_secs(5),
        liveness: config.liveness,
        deadline_factor: config.deadline_factor,
        first_deadline: config.first_deadline,
        renderer_port: config.renderer_port,
    };
    let pool = pool::spawn(pool_config, pool_tx, joining, shutdown_rx.clone());
    let looks = SceneLooks::of(&scene);
    tracing::debug!(
        textures = looks.texture_table.len(),
        bytes = looks.texture_table.iter().map(|t| t.bytes).sum::<u64>(),
        "textures for viewers"
    );
    let link = ViewerLinkConfig {
        scene_info: scene_info(
            &scene,
            config.schedule.criterion,
            config.schedule.profile,
            &looks,
        ),
        textures: looks.images,
        scene: scene_identity(&scene),
        max_frame: config.max_frame,
        handshake_deadline: config.viewer_port.handshake_deadline,
        frame_timeout: config.liveness.frame_timeout,
        heartbeat: config.liveness.heartbeat,
        silence: config.viewer_silence,
        backlog_bytes: config.viewer_backlog_bytes,
    };
    tracing::info!(
        profile = config.schedule.profile.label(),
        criterion = %config.schedule.criterion,
        scene = %scene.name,
        "sma starting"
    );
    let cache_file = config.cache_file.map(|file| CacheFileSetup {
        config: file,
        mesh: MeshKey::of(&config.mesh),
    });
    let schedule = Schedule::new(
        config.schedule,
        std::sync::Arc::clone(&scene),
        mesh,
        gpu,
        pool,
        cache_file.as_ref(),
    );
    tracing::debug!(adapter = %schedule.adapter(), scene = %scene.name, "visibility device");
    let listener = TcpListener::bind(&config.listen)
        .await
        .with_context(|| format!("listening on {}", config.listen))?;
    let addr = listener.local_addr()?;
    let (viewer_tx, viewer_rx) = mpsc::channel(EVENT_QUEUE);
    tokio::spawn(accept_viewers(
        listener,
        ConnectionLimit::new(config.viewer_port.max_connections),
        link,
        viewer_tx,
        shutdown_rx.clone(),
    ));
    let schedule = spawn_schedule(schedule, viewer_rx, pool_rx, shutdown_rx)?;
    Ok(Running {
        addr,
        renderer_addr,
        shutdown: shutdown_tx,
        schedule,
    })
}

/// The schedule on its own thread with its own single-threaded runtime: its visibility passes
/// block for milliseconds and must not stall the tasks serving viewers and renderers.
fn spawn_schedule(
    schedule: Schedule,
    viewers: mpsc::Receiver<ViewerEvent>,
    pool: mpsc::Receiver<PoolEvent>,
    shutdown: watch::Receiver<bool>,
) -> anyhow::Result<JoinHandle<anyhow::Result<()>>> {
    std::thread::Builder::new()
        .name("sma-schedule".into())
        .spawn(move || {
            let runtime = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            let outcome = runtime.block_on(schedule.run(viewers, pool, shutdown));
            if let Err(e) = &outcome {
                tracing::error!(error = format!("{e:#}"), "schedule ended");
            }
            outcome
        })
        .context("starting the schedule thread")
}

/// Accepts viewers until shutdown, as many at once as `limit` admits; past it a viewer is
/// refused (DESIGN.md §8). Accept errors (e.g. out of file descriptors) are logged and retried
/// after a pause rather than ending the server.
async fn accept_viewers(
    listener: TcpListener,
    limit: ConnectionLimit,
    config: ViewerLinkConfig,
    events: mpsc::Sender<ViewerEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut next_id: ViewerId = 1;
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = shutdown.changed() => return,
        };
        match accepted {
            Ok((stream, peer)) => match limit.admit() {
                Admission::Serve(permit) => {
                    let task = viewer_link::serve(
                        stream,
                        next_id,
                        config.clone(),
                        events.clone(),
                        shutdown.clone(),
                    );
                    tokio::spawn(async move {
                        task.await;
                        drop(permit);
                    });
                    next_id += 1;
                }
                Admission::Refuse(permit) => {
                    tracing::warn!(%peer, "refusing a viewer: {}", limit.full_reason());
                    let task = viewer_link::refuse(stream, limit.full_reason(), config.clone());
                    tokio::spawn(async move {
                        task.await;
                        drop(permit);
                    });
                }
                Admission::Close => {
                    tracing::warn!(%peer, "closing a connection at once: too many being refused");
                }
            },
            Err(e) => {
                tracing::warn!(error = %e, "accepting a viewer failed");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}
