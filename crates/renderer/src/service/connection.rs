//! One SMA connection: handshake with the scene fingerprint, then batches in, replies out. Batches
//! run concurrently on the rayon pool and are answered as each finishes, so the reply order is not
//! the request order (replies carry the batch id). After `Bye`, the end of the peer's stream or a
//! shutdown, batches not yet answered are dropped (the SMA re-issues a lost renderer's work).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use protocol::ProtocolError;
use protocol::connection::{SceneCheck, accept_handshake_within, refuse_handshake, split_tcp};
use protocol::handshake::Role;
use protocol::renderer_link::{FromRenderer, ShadeBatch, ToRenderer};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};

use super::{MAX_BOUNCES, MAX_PATHS, Service};
use crate::shade::shade_batch;

pub async fn handle(
    stream: TcpStream,
    service: Arc<Service>,
    mut stop: watch::Receiver<bool>,
) -> Result<(), ProtocolError> {
    let (mut reader, mut writer) = split_tcp::<ToRenderer, FromRenderer>(stream, service.max_frame);
    let fingerprint = service.world.scene.fingerprint;
    accept_handshake_within(
        &mut reader,
        &mut writer,
        Role::Renderer,
        Role::Sma,
        SceneCheck::Same(fingerprint),
        service.port.handshake_deadline,
    )
    .await?;

    let (replies, mut outbox) = mpsc::unbounded_channel::<FromRenderer>();
    // Set when the link ends, so queued batches of a gone peer are skipped.
    let closed = Arc::new(AtomicBool::new(false));
    let send_loop = tokio::spawn(async move {
        while let Some(msg) = outbox.recv().await {
            let last = matches!(msg, FromRenderer::Error { .. });
            if writer.send(&msg).await.is_err() || last {
                break;
            }
        }
    });

    let outcome = loop {
        tokio::select! {
            _ = stop.changed() => break Ok(()),
            msg = reader.recv() => match msg {
                Ok(ToRenderer::ShadeBatch(batch)) => match check(&batch) {
                    Ok(()) => start_batch(&service, batch, replies.clone(), Arc::clone(&closed)),
                    Err(reason) => {
                        let _ = replies.send(FromRenderer::Rejected { batch_id: batch.batch_id, reason });
                    }
                },
                Ok(ToRenderer::Bye) => break Ok(()),
                Err(e) if e.is_disconnect() => break Ok(()),
                Err(e) => {
                    // Malformed, oversized or unknown frame: say why, then close (DESIGN.md §8).
                    let _ = replies.send(FromRenderer::Error { message: e.to_string() });
                    break Err(e);
                }
            }
        }
    };
    closed.store(true, Ordering::Relaxed);
    drop(replies);
    if outcome.is_err() {
        // Let the error reply go out before the socket closes.
        let _ = send_loop.await;
    } else {
        send_loop.abort();
    }
    outcome
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

fn start_batch(
    service: &Arc<Service>,
    batch: ShadeBatch,
    replies: mpsc::UnboundedSender<FromRenderer>,
    closed: Arc<AtomicBool>,
) {
    let world = Arc::clone(&service.world);
    service.pool.spawn(move || {
        if closed.load(Ordering::Relaxed) {
            return;
        }
        let (radiance, _) = shade_batch(&world, &batch);
        let _ = replies.send(FromRenderer::Radiance(radiance));
    });
}
