//! One SMA connection: handshake with the scene fingerprint, then batches in, replies out. Batches
//! run concurrently on the rayon pool and are answered as each finishes, so the reply order is not
//! the request order (replies carry the batch id). After `Bye`, the end of the peer's stream or a
//! shutdown, batches not yet answered are dropped (the SMA re-issues a lost renderer's work).
//!
//! A direct tile (`direct_tile`) is work of the same kind: it runs on the pool, counts as one
//! batch held, and is answered when done.
//!
//! Liveness and bounds (DESIGN.md §2, §8): heartbeats are answered from this task, never queued
//! behind the workers; an SMA silent past the link's silence limit is gone, and a frame stalled
//! halfway is cut off; a connection holds at most `max_batches` batches, and one more is refused
//! with a `Rejected` that says so, so replies waiting to go out are bounded too.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

use protocol::ProtocolError;
use protocol::connection::{
    SceneCheck, TcpReader, TcpWriter, accept_handshake_within, connect_handshake, refuse_handshake,
    split_tcp,
};
use protocol::direct_tile::TileRequest;
use protocol::handshake::{Hello, Role};
use protocol::renderer_link::{FromRenderer, ShadeBatch, ToRenderer};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use super::{MAX_BOUNCES, MAX_PATHS, MAX_TILE_SAMPLES, Service};
use crate::direct_tile::trace_tile;
use crate::shade::shade_batch;

/// Replies other than radiance (pongs, refusals) that may wait for the writer at once, beyond
/// one per batch held: past them the reader waits for the writer, and TCP holds the SMA back.
const SMALL_REPLIES: usize = 16;

/// Serves an SMA that connected to this renderer's port.
pub async fn handle(
    stream: TcpStream,
    service: Arc<Service>,
    stop: watch::Receiver<bool>,
) -> Result<(), ProtocolError> {
    let (mut reader, mut writer) = split_tcp::<ToRenderer, FromRenderer>(stream, service.max_frame);
    accept_handshake_within(
        &mut reader,
        &mut writer,
        Role::Renderer,
        Role::Sma,
        SceneCheck::Same(service.world.identity()),
        service.port.handshake_deadline,
    )
    .await?;
    serve_link(reader, writer, service, stop).await
}

/// Joins the SMA at `addr` (its renderer port, DESIGN.md §2): connects, shakes hands as a
/// renderer with the scene's identity, then serves it as if it had connected here.
pub async fn join(
    addr: &str,
    service: Arc<Service>,
    stop: watch::Receiver<bool>,
) -> Result<(), ProtocolError> {
    let deadline = service.port.handshake_deadline;
    let connected = tokio::time::timeout(deadline, connect(addr, &service)).await;
    let (reader, writer) =
        connected.unwrap_or(Err(ProtocolError::HandshakeTimeout { deadline }))?;
    tracing::info!(sma = %addr, "joined the SMA");
    serve_link(reader, writer, service, stop).await
}

async fn connect(
    addr: &str,
    service: &Service,
) -> Result<(TcpReader<ToRenderer>, TcpWriter<FromRenderer>), ProtocolError> {
    let stream = TcpStream::connect(addr).await?;
    let (mut reader, mut writer) = split_tcp(stream, service.max_frame);
    let hello = Hello::new(Role::Renderer, Some(service.world.identity()));
    connect_handshake(&mut reader, &mut writer, hello, Role::Sma).await?;
    Ok((reader, writer))
}

/// The link after its handshake, whichever side connected.
async fn serve_link(
    mut reader: TcpReader<ToRenderer>,
    mut writer: TcpWriter<FromRenderer>,
    service: Arc<Service>,
    mut stop: watch::Receiver<bool>,
) -> Result<(), ProtocolError> {
    reader.set_frame_timeout(service.liveness.frame_timeout);
    let (replies, mut outbox) = mpsc::channel::<FromRenderer>(service.max_batches + SMALL_REPLIES);
    // Set when the link ends, so queued batches of a gone peer are skipped.
    let closed = Arc::new(AtomicBool::new(false));
    let held = Arc::new(AtomicUsize::new(0));
    let send_loop = tokio::spawn(async move {
        while let Some(msg) = outbox.recv().await {
            let last = matches!(msg, FromRenderer::Error { .. });
            if writer.send(&msg).await.is_err() || last {
                break;
            }
        }
    });

    let silence = service.liveness.silence;
    let mut heard = Instant::now();
    let outcome = loop {
        let msg = tokio::select! {
            _ = stop.changed() => break Ok(()),
            _ = tokio::time::sleep_until(heard + silence) => {
                break Err(silent(silence));
            }
            msg = reader.recv() => msg,
        };
        heard = Instant::now();
        let reply = match msg {
            Ok(ToRenderer::ShadeBatch(batch)) => {
                match take(&service, Work::Batch(batch), &replies, &closed, &held) {
                    Some(reply) => reply,
                    None => continue,
                }
            }
            Ok(ToRenderer::DirectTile(tile)) => {
                match take(&service, Work::Tile(tile), &replies, &closed, &held) {
                    Some(reply) => reply,
                    None => continue,
                }
            }
            Ok(ToRenderer::Ping { nonce }) => FromRenderer::Pong { nonce },
            Ok(ToRenderer::Bye) => break Ok(()),
            Err(e) if e.is_disconnect() => break Ok(()),
            Err(e) => {
                // Malformed, oversized, unknown or stalled frame: say why, then close (DESIGN.md §8).
                let _ = replies.try_send(FromRenderer::Error {
                    message: e.to_string(),
                });
                break Err(e);
            }
        };
        if replies.send(reply).await.is_err() {
            break Ok(());
        }
    };
    closed.store(true, Ordering::Relaxed);
    drop(replies);
    if outcome.is_err() {
        // Let the error reply go out before the socket closes, but not wait on a peer that
        // reads nothing.
        let _ = tokio::time::timeout(silence, send_loop).await;
    } else {
        send_loop.abort();
    }
    outcome
}

fn silent(silence: Duration) -> ProtocolError {
    ProtocolError::Io(std::io::Error::new(
        std::io::ErrorKind::TimedOut,
        format!("the SMA said nothing for {silence:?}"),
    ))
}

/// What the workers compute for the SMA: a batch of points, or one pass over a direct tile.
enum Work {
    Batch(ShadeBatch),
    Tile(TileRequest),
}

impl Work {
    /// The reply that refuses it, saying why.
    fn refusal(&self, reason: String) -> FromRenderer {
        match self {
            Work::Batch(b) => FromRenderer::Rejected {
                batch_id: b.batch_id,
                reason,
            },
            Work::Tile(t) => FromRenderer::TileRejected {
                tile_id: t.tile_id,
                reason,
            },
        }
    }

    fn check(&self) -> Result<(), String> {
        match self {
            Work::Batch(b) => check(b),
            Work::Tile(t) => t.check(MAX_TILE_SAMPLES),
        }
    }

    fn run(&self, world: &crate::world::World) -> FromRenderer {
        match self {
            Work::Batch(b) => FromRenderer::Radiance(shade_batch(world, b).0),
            Work::Tile(t) => FromRenderer::DirectTile(trace_tile(world, t).0),
        }
    }
}

/// Starts `work` on the workers, or the reply that refuses it.
fn take(
    service: &Arc<Service>,
    work: Work,
    replies: &mpsc::Sender<FromRenderer>,
    closed: &Arc<AtomicBool>,
    held: &Arc<AtomicUsize>,
) -> Option<FromRenderer> {
    if let Err(reason) = work.check() {
        return Some(work.refusal(reason));
    }
    // One reply place per batch held, so a worker never waits for the writer.
    let permit = (held.load(Ordering::Relaxed) < service.max_batches)
        .then(|| replies.clone().try_reserve_owned().ok())
        .flatten();
    let Some(permit) = permit else {
        let reason = format!(
            "this renderer holds at most {} batches per connection; batch refused",
            service.max_batches
        );
        return Some(work.refusal(reason));
    };
    held.fetch_add(1, Ordering::Relaxed);
    let world = Arc::clone(&service.world);
    let (closed, held) = (Arc::clone(closed), Arc::clone(held));
    service.pool.spawn(move || {
        if !closed.load(Ordering::Relaxed) {
            permit.send(work.run(&world));
        }
        held.fetch_sub(1, Ordering::Relaxed);
    });
    None
}

/// Tells an SMA that arrived past the connection bound that it is refused, then closes.
pub async fn refuse(stream: TcpStream, service: &Service, reason: String) {
    let (mut reader, mut writer) = split_tcp::<ToRenderer, FromRenderer>(stream, service.max_frame);
    refuse_handshake(
        &mut reader,
        &mut writer,
        reason,
        service.port.handshake_deadline,
    )
    .await;
}

/// A batch the renderer will not take (it is well-formed but asks for something unreasonable).
fn check(batch: &ShadeBatch) -> Result<(), String> {
    let q = batch.quality;
    if q.paths == 0 || q.paths > MAX_PATHS {
        return Err(format!("paths {} outside 1..={MAX_PATHS}", q.paths));
    }
    if q.bounces.is_some_and(|b| b > MAX_BOUNCES) {
        return Err(format!("bounces {:?} above {MAX_BOUNCES}", q.bounces));
    }
    Ok(())
}
