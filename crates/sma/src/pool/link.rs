//! One renderer connection, whichever side opened it (DESIGN.md §2): a renderer the SMA dials
//! (`--renderer`), reconnected with backoff forever, or one that joined on the SMA's renderer
//! port (`renderer serve --join`), which rejoins by itself. Either way the same liveness rule
//! holds: a heartbeat every `liveness.heartbeat`, and a renderer that sends nothing for
//! `liveness.silence` — no pong, no answer — is lost; so is one stalled halfway through a frame.

use std::time::Duration;

use protocol::admission::{Admission, ConnectionLimit};
use protocol::connection::{
    SceneCheck, TcpReader, TcpWriter, accept_handshake_within, connect_handshake, refuse_handshake,
};
use protocol::renderer_link::{FromRenderer, ToRenderer};
use protocol::{Hello, ProtocolError, Role, split_tcp};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{mpsc, watch};
use tokio::time::{Instant, MissedTickBehavior};

use super::PoolConfig;

/// What a link task tells the dispatcher. `generation` tells one connection of a link from the
/// next, so news from a dead connection cannot touch batches re-issued since.
pub enum LinkEvent {
    Up {
        index: usize,
        generation: u64,
        name: String,
        /// It came in on the renderer port: once down, its place is not kept.
        joined: bool,
        batches: mpsc::Sender<ToRenderer>,
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

/// Who a connection is, for the dispatcher.
struct Identity {
    index: usize,
    generation: u64,
    name: String,
    joined: bool,
}

/// One renderer address the SMA dials: connects, serves, and reconnects with backoff, forever.
pub struct Dialed {
    pub index: usize,
    pub addr: String,
    pub config: PoolConfig,
    pub events: mpsc::Sender<LinkEvent>,
}

/// Why a link ended when the pool dropped its batch queue.
const GIVEN_UP_BY_THE_POOL: &str = "given up on by the pool";

impl Dialed {
    pub async fn run(self, mut shutdown: watch::Receiver<bool>) {
        let mut backoff = self.config.backoff_min;
        let mut generation = 0u64;
        while !*shutdown.borrow() {
            generation += 1;
            let served = tokio::select! {
                r = self.connect_and_serve(generation) => r,
                _ = shutdown.changed() => return,
            };
            let reason = match served {
                Ok(reason) => {
                    backoff = self.config.backoff_min;
                    reason
                }
                Err(e) => e.to_string(),
            };
            // A link the pool let go of (at a stop, or a renderer it gave up on and said so) is
            // not news: only a link that failed on its own is worth a line.
            if *shutdown.borrow() || reason == GIVEN_UP_BY_THE_POOL {
                tracing::debug!(renderer = %self.addr, %reason, "renderer link down");
            } else {
                tracing::info!(renderer = %self.addr, %reason, retry_in = ?backoff, "renderer link down");
            }
            tokio::select! {
                _ = tokio::time::sleep(backoff) => {}
                _ = shutdown.changed() => return,
            }
            backoff = (backoff * 2).min(self.config.backoff_max);
        }
    }

    /// One connection: `Err` when it never came up, else why it ended.
    async fn connect_and_serve(&self, generation: u64) -> Result<String, ProtocolError> {
        // A stopped renderer's kernel still accepts the connection; its silence ends the wait.
        let limit = self.config.liveness.silence;
        let connected = tokio::time::timeout(limit, self.connect()).await;
        let (reader, writer) =
            connected.unwrap_or(Err(ProtocolError::HandshakeTimeout { deadline: limit }))?;
        tracing::info!(renderer = %self.addr, "renderer connected");
        let identity = Identity {
            index: self.index,
            generation,
            name: self.addr.clone(),
            joined: false,
        };
        Ok(serve(reader, writer, identity, &self.config, &self.events).await)
    }

    async fn connect(
        &self,
    ) -> Result<(TcpReader<FromRenderer>, TcpWriter<ToRenderer>), ProtocolError> {
        let stream = TcpStream::connect(&self.addr).await?;
        let (mut reader, mut writer) = split_tcp(stream, self.config.max_frame);
        let hello = Hello::new(Role::Sma, Some(self.config.scene));
        connect_handshake(&mut reader, &mut writer, hello, Role::Renderer).await?;
        Ok((reader, writer))
    }
}

/// Accepts renderers that join on the SMA's renderer port, with the same handshake and scene
/// check as a dialed one (DESIGN.md §8), as many at once as the port admits. Indices after the
/// dialed renderers' tell them apart.
pub async fn accept_joining(
    listener: TcpListener,
    limit: ConnectionLimit,
    first_index: usize,
    config: PoolConfig,
    events: mpsc::Sender<LinkEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    let mut next_index = first_index;
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            _ = shutdown.changed() => return,
        };
        let (stream, peer) = match accepted {
            Ok(accepted) => accepted,
            Err(e) => {
                tracing::warn!(error = %e, "accepting a renderer failed");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let (config, events, mut shutdown) = (config.clone(), events.clone(), shutdown.clone());
        let deadline = config.renderer_port.handshake_deadline;
        match limit.admit() {
            Admission::Serve(permit) => {
                let identity = Identity {
                    index: next_index,
                    generation: 1,
                    name: peer.to_string(),
                    joined: true,
                };
                next_index += 1;
                tokio::spawn(async move {
                    tokio::select! {
                        _ = serve_joined(stream, identity, &config, &events) => {}
                        _ = shutdown.changed() => {}
                    }
                    drop(permit);
                });
            }
            Admission::Refuse(permit) => {
                let reason = limit.full_reason();
                tracing::warn!(%peer, "refusing a renderer: {reason}");
                tokio::spawn(async move {
                    let (mut reader, mut writer) =
                        split_tcp::<FromRenderer, ToRenderer>(stream, config.max_frame);
                    refuse_handshake(&mut reader, &mut writer, reason, deadline).await;
                    drop(permit);
                });
            }
            Admission::Close => {
                tracing::warn!(%peer, "closing a connection at once: too many being refused");
            }
        }
    }
}

async fn serve_joined(
    stream: TcpStream,
    identity: Identity,
    config: &PoolConfig,
    events: &mpsc::Sender<LinkEvent>,
) {
    let (mut reader, mut writer) = split_tcp(stream, config.max_frame);
    let handshake = accept_handshake_within(
        &mut reader,
        &mut writer,
        Role::Sma,
        Role::Renderer,
        SceneCheck::Same(config.scene),
        config.renderer_port.handshake_deadline,
    );
    let name = identity.name.clone();
    if let Err(e) = handshake.await {
        tracing::warn!(renderer = %name, error = %e, "a joining renderer's handshake failed");
        return;
    }
    tracing::info!(renderer = %name, "renderer joined");
    let reason = serve(reader, writer, identity, config, events).await;
    tracing::info!(renderer = %name, %reason, "joined renderer gone");
}

/// Serves one connection after its handshake until it ends; returns why. The dispatcher hears
/// `Up` first and `Down` last.
async fn serve(
    mut reader: TcpReader<FromRenderer>,
    mut writer: TcpWriter<ToRenderer>,
    who: Identity,
    config: &PoolConfig,
    events: &mpsc::Sender<LinkEvent>,
) -> String {
    let (index, generation) = (who.index, who.generation);
    let (tx, mut batches) = mpsc::channel(config.depth.max(1));
    let up = LinkEvent::Up {
        index,
        generation,
        name: who.name,
        joined: who.joined,
        batches: tx,
    };
    if events.send(up).await.is_err() {
        return "the pool ended".into();
    }
    let liveness = config.liveness;
    reader.set_frame_timeout(liveness.frame_timeout);
    let mut heartbeat = tokio::time::interval(liveness.heartbeat);
    heartbeat.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut heard = Instant::now();
    let mut nonce = 0u64;
    let reason = loop {
        let out = tokio::select! {
            batch = batches.recv() => match batch {
                Some(work) => work,
                None => break GIVEN_UP_BY_THE_POOL.to_string(),
            },
            _ = heartbeat.tick() => {
                nonce += 1;
                ToRenderer::Ping { nonce }
            }
            _ = tokio::time::sleep_until(heard + liveness.silence) => {
                break format!("renderer silent for {:?}: heartbeats unanswered", liveness.silence);
            }
            reply = reader.recv() => {
                heard = Instant::now();
                let reply = match reply {
                    Ok(FromRenderer::Pong { .. }) => continue,
                    Ok(reply) => reply,
                    Err(e) => break e.to_string(),
                };
                let fatal = match &reply {
                    FromRenderer::Error { message } => Some(message.clone()),
                    _ => None,
                };
                if events.send(LinkEvent::Reply { index, generation, reply }).await.is_err() {
                    return "the pool ended".into();
                }
                match fatal {
                    Some(message) => break ProtocolError::Remote(message).to_string(),
                    None => continue,
                }
            }
        };
        // A renderer that reads nothing cannot hold the link up past its silence.
        match tokio::time::timeout(liveness.silence, writer.send(&out)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => break e.to_string(),
            Err(_) => break format!("renderer read nothing for {:?}", liveness.silence),
        }
    };
    let down = LinkEvent::Down {
        index,
        generation,
        reason: reason.clone(),
    };
    let _ = events.send(down).await;
    reason
}
