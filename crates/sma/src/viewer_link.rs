//! One accepted viewer (DESIGN.md §2, §8): handshake, `SceneInfo` first, then its messages go to
//! the schedule and the schedule's messages go out. A malformed, oversized, unknown or stalled
//! frame, or a camera no renderer could use, gets an `Error` reply and this connection closes; a
//! viewer gets the latest state of its triangles however slowly it reads (`outbox`), is pinged
//! every heartbeat and lost when it answers none within the silence limit, and is disconnected
//! should what waits for it pass a bound; every other viewer is unaffected.

use std::time::Duration;

use protocol::connection::{SceneCheck, TcpWriter, accept_handshake_within, refuse_handshake};
use protocol::viewer_link::{Camera, SceneInfo, SkyInfo, SmaToViewer, SunInfo, ViewerToSma};
use protocol::{ProtocolError, Role, SceneIdentity, split_tcp};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, oneshot, watch};

use crate::config::Profile;
use crate::criteria::CriterionKind;

mod looks;
mod outbox;

pub use looks::SceneLooks;
pub use outbox::Outbox;
use outbox::Outgoing;
#[cfg(test)]
pub(crate) use outbox::outbox;

/// Identifies one viewer connection for the life of the process.
pub type ViewerId = u64;

/// Largest image side a viewer may ask for: the visibility passes allocate width × height.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// What a viewer connection tells the schedule.
#[derive(Debug)]
pub enum ViewerEvent {
    Joined { id: ViewerId, outbox: Outbox },
    Message { id: ViewerId, message: ViewerToSma },
    Left { id: ViewerId },
}

/// What every viewer connection needs to know.
#[derive(Clone, Debug)]
pub struct ViewerLinkConfig {
    pub scene_info: SceneInfo,
    /// Each texture of `scene_info`'s table, sent right after it (`SceneLooks::images`).
    pub textures: std::sync::Arc<[SmaToViewer]>,
    pub scene: SceneIdentity,
    pub max_frame: usize,
    /// A viewer that has not completed its handshake by then is closed (DESIGN.md §8).
    pub handshake_deadline: Duration,
    /// A frame begun must be complete within this long, in either direction: a viewer whose
    /// socket takes none of a frame for this long is cut off.
    pub frame_timeout: Duration,
    /// How often the viewer is pinged.
    pub heartbeat: Duration,
    /// A viewer that has not answered a ping this long after it reached its socket is lost.
    pub silence: Duration,
    /// Bytes of changes that may wait for one viewer; past them it is disconnected.
    pub backlog_bytes: usize,
}

/// Why a viewer's link ended.
enum End {
    /// It left, or the server is shutting down.
    Quiet,
    Protocol(ProtocolError),
    /// It stopped reading and the changes waiting for it passed the bound.
    Backlog,
    /// It answered no ping within the silence limit.
    Silent,
    /// The writing task ended: the outbox closed, or a write failed or stalled.
    Written(Option<ProtocolError>),
}

/// Writes what waits for one viewer until a write fails or stalls, or `stop`. Returns the
/// writer, for a last word.
async fn write_out(
    mut writer: TcpWriter<SmaToViewer>,
    outgoing: Outgoing,
    frame_timeout: Duration,
    mut stop: oneshot::Receiver<()>,
) -> (TcpWriter<SmaToViewer>, Result<(), ProtocolError>) {
    let result = 'writing: loop {
        let messages = tokio::select! {
            messages = outgoing.next() => messages,
            _ = &mut stop => break Ok(()),
        };
        for message in messages {
            let sent = tokio::select! {
                sent = tokio::time::timeout(frame_timeout, writer.send(&message)) => sent,
                _ = &mut stop => break 'writing Ok(()),
            };
            match sent {
                Ok(Ok(())) => outgoing.written(&message),
                Ok(Err(e)) => break 'writing Err(e),
                Err(_) => {
                    break 'writing Err(ProtocolError::WriteStalled {
                        after: frame_timeout,
                    });
                }
            }
        }
    };
    (writer, result)
}

/// The heartbeat of one viewer link: one ping out at a time; the viewer is lost when a ping has
/// been on its socket for `silence` unanswered. Only the answer counts: a viewer that sends
/// cameras but reads nothing proves its writing, not that it takes what the SMA writes.
struct Heartbeat {
    nonce: u64,
    answered: bool,
    silence: Duration,
}

impl Heartbeat {
    fn new(silence: Duration) -> Self {
        Heartbeat {
            nonce: 0,
            answered: true,
            silence,
        }
    }

    fn pong(&mut self, nonce: u64) {
        self.answered |= nonce == self.nonce;
    }

    /// On each tick: false when the viewer is lost; otherwise pings it if no ping is out.
    fn tick(&mut self, outbox: &Outbox) -> bool {
        if self.answered {
            self.nonce += 1;
            self.answered = false;
            outbox.send(SmaToViewer::Ping { nonce: self.nonce });
            return true;
        }
        // Not yet written (waiting behind other changes) is not lost: a write that stalls is
        // cut off by the frame timeout.
        outbox
            .ping_written(self.nonce)
            .is_none_or(|written| written.elapsed() < self.silence)
    }
}

/// Serves one viewer until it leaves, breaks the protocol, or the server shuts down.
pub async fn serve(
    stream: TcpStream,
    id: ViewerId,
    config: ViewerLinkConfig,
    events: mpsc::Sender<ViewerEvent>,
    mut shutdown: watch::Receiver<bool>,
) {
    let peer = stream
        .peer_addr()
        .map(|a| a.to_string())
        .unwrap_or_default();
    let (mut reader, mut writer) = split_tcp::<ViewerToSma, SmaToViewer>(stream, config.max_frame);
    let handshake = accept_handshake_within(
        &mut reader,
        &mut writer,
        Role::Sma,
        Role::Viewer,
        SceneCheck::Tell(config.scene),
        config.handshake_deadline,
    );
    if let Err(e) = handshake.await {
        tracing::warn!(viewer = id, %peer, error = %e, "viewer handshake failed");
        return;
    }
    if writer
        .send(&SmaToViewer::SceneInfo(Box::new(config.scene_info)))
        .await
        .is_err()
    {
        return;
    }
    // Before the outbox exists, so before any `Insert`; a texture is megabytes at most, so each
    // is held to the frame timeout here as the writing task holds every later frame.
    for texture in config.textures.iter() {
        match tokio::time::timeout(config.frame_timeout, writer.send(texture)).await {
            Ok(Ok(())) => {}
            Ok(Err(_)) => return,
            Err(_) => {
                tracing::warn!(viewer = id, %peer, "a viewer took no texture within the frame timeout");
                return;
            }
        }
    }
    reader.set_frame_timeout(config.frame_timeout);
    tracing::info!(viewer = id, %peer, "viewer connected");
    let (outbox, outgoing) = outbox::outbox(config.backlog_bytes);
    if events
        .send(ViewerEvent::Joined {
            id,
            outbox: outbox.clone(),
        })
        .await
        .is_err()
    {
        return;
    }
    // Writing has its own task, so a viewer's cameras are read even while a write to it is
    // blocked, and its backlog's overflow is seen at once.
    let (stop_writing, stopped) = oneshot::channel();
    let mut writing = tokio::spawn(write_out(writer, outgoing, config.frame_timeout, stopped));
    let mut heartbeat = Heartbeat::new(config.silence);
    let mut ticks = tokio::time::interval(config.heartbeat);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let ended = loop {
        tokio::select! {
            incoming = reader.recv() => match incoming.and_then(checked) {
                Ok(ViewerToSma::Bye) => break End::Quiet,
                Ok(ViewerToSma::Pong { nonce }) => heartbeat.pong(nonce),
                Ok(message) => {
                    if events.send(ViewerEvent::Message { id, message }).await.is_err() {
                        break End::Quiet;
                    }
                }
                Err(e) if e.is_disconnect() => break End::Quiet,
                Err(e) => break End::Protocol(e),
            },
            _ = ticks.tick() => if !heartbeat.tick(&outbox) {
                break End::Silent;
            },
            written = &mut writing => break End::Written(written.ok().and_then(|(_, r)| r.err())),
            _ = outbox.overflowed() => break End::Backlog,
            _ = shutdown.changed() => break End::Quiet,
        }
    };
    match ended {
        End::Quiet => writing.abort(),
        End::Written(None) => {}
        End::Written(Some(e)) if e.is_disconnect() => {}
        End::Written(Some(e)) => {
            tracing::warn!(viewer = id, %peer, error = %e, "closing viewer: a write failed");
        }
        End::Protocol(e) => {
            tracing::warn!(viewer = id, %peer, error = %e, "closing viewer after a protocol error");
            let _ = stop_writing.send(());
            if let Ok((mut writer, _)) = writing.await {
                let error = SmaToViewer::Error {
                    message: e.to_string(),
                };
                let _ = tokio::time::timeout(config.frame_timeout, writer.send(&error)).await;
            }
        }
        End::Silent => {
            writing.abort();
            tracing::warn!(
                viewer = id,
                %peer,
                silence_ms = config.silence.as_millis() as u64,
                "disconnecting a viewer that answers no heartbeat"
            );
        }
        End::Backlog => {
            writing.abort();
            tracing::warn!(
                viewer = id,
                %peer,
                bound_bytes = config.backlog_bytes,
                "disconnecting a viewer that does not read: the changes waiting for it passed the bound"
            );
        }
    }
    let _ = events.send(ViewerEvent::Left { id }).await;
    tracing::info!(viewer = id, %peer, "viewer left");
}

/// Tells a viewer that arrived past the connection bound that it is refused, then closes.
pub async fn refuse(stream: TcpStream, reason: String, config: ViewerLinkConfig) {
    let (mut reader, mut writer) = split_tcp::<ViewerToSma, SmaToViewer>(stream, config.max_frame);
    refuse_handshake(&mut reader, &mut writer, reason, config.handshake_deadline).await;
}

/// Rejects messages that decode but that the SMA cannot act on.
fn checked(message: ViewerToSma) -> Result<ViewerToSma, ProtocolError> {
    if let ViewerToSma::Camera(camera) = &message {
        camera_problem(camera).map_or(Ok(()), |p| Err(ProtocolError::Malformed(p)))?;
    }
    Ok(message)
}

/// Why a camera cannot be rendered, if it cannot.
pub fn camera_problem(camera: &Camera) -> Option<String> {
    let finite = camera
        .eye
        .iter()
        .chain(&camera.orientation)
        .all(|v| v.is_finite());
    let norm: f32 = camera.orientation.iter().map(|v| v * v).sum();
    if !finite || norm < 1e-6 {
        Some("camera eye or orientation is not finite or not a rotation".into())
    } else if !(camera.fov_y_deg > 0.1 && camera.fov_y_deg < 179.0) {
        Some(format!(
            "camera field of view {} is outside (0.1, 179) degrees",
            camera.fov_y_deg
        ))
    } else if camera.width == 0
        || camera.height == 0
        || camera.width > MAX_IMAGE_SIDE
        || camera.height > MAX_IMAGE_SIDE
    {
        Some(format!(
            "camera image {}x{} is outside 1..={MAX_IMAGE_SIDE} per side",
            camera.width, camera.height
        ))
    } else {
        None
    }
}

/// The scene as the handshakes compare it: its fingerprint and whether its textures are on
/// (DESIGN.md §5, §8).
pub fn scene_identity(scene: &scene::Scene) -> SceneIdentity {
    SceneIdentity {
        fingerprint: scene.fingerprint,
        textures: scene.settings.textures.enabled,
    }
}

/// What a viewer learns of `scene` first (it has no scene of its own, DESIGN.md §2): its name,
/// fingerprint, textures on or off, bounds, viewpoints, the criteria `profile` offers, the one
/// viewers start with first, and its materials and textures (`looks`).
pub fn scene_info(
    scene: &scene::Scene,
    active: CriterionKind,
    profile: Profile,
    looks: &SceneLooks,
) -> SceneInfo {
    let (lo, hi) = scene.mesh.bounds();
    let criteria = std::iter::once(active)
        .chain(profile.criteria().into_iter().filter(|&k| k != active))
        .map(|k| k.name().to_string())
        .collect();
    SceneInfo {
        name: scene.name.clone(),
        fingerprint: scene.fingerprint,
        bounds: protocol::types::Bounds {
            min: lo.to_array(),
            max: hi.to_array(),
        },
        viewpoints: scene
            .settings
            .viewpoints
            .iter()
            .map(|v| protocol::types::Viewpoint {
                name: v.name.clone(),
                eye: v.eye,
                target: v.target,
                up: v.up,
                fov_y_deg: v.fov_y_deg,
            })
            .collect(),
        criteria,
        sky: sky_info(&scene.settings),
        quality: protocol::renderer_link::Quality {
            paths: scene.settings.quality.paths,
            bounces: scene.settings.quality.bounces,
        },
        textures: scene.settings.textures.enabled,
        materials: looks.materials.clone(),
        texture_table: looks.texture_table.clone(),
    }
}

/// The sky and sun a viewer draws behind the geometry, as the renderer lights with them.
fn sky_info(settings: &scene::SceneSettings) -> SkyInfo {
    let radiance = match settings.sky {
        scene::Sky::None => [0.0; 3],
        scene::Sky::Uniform { radiance } => radiance,
    };
    let sun = settings.sun.as_ref().map(|sun| SunInfo {
        direction: glam::Vec3::from(sun.direction).normalize().to_array(),
        radiance: sun.radiance,
        angular_diameter_deg: sun.angular_diameter_deg,
    });
    SkyInfo { radiance, sun }
}
