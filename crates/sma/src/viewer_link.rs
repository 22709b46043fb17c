//! One accepted viewer (DESIGN.md §2, §8): handshake, `SceneInfo` first, then its messages go to
//! the schedule and the schedule's messages go out. A malformed, oversized or unknown frame, or a
//! camera no renderer could use, gets an `Error` reply and this connection closes; every other
//! viewer is unaffected.

use std::time::Duration;

use protocol::connection::{SceneCheck, accept_handshake_within, refuse_handshake};
use protocol::viewer_link::{Camera, SceneInfo, SkyInfo, SmaToViewer, SunInfo, ViewerToSma};
use protocol::{Fingerprint, ProtocolError, Role, split_tcp};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, watch};

use crate::criteria::CriterionKind;

/// Identifies one viewer connection for the life of the process.
pub type ViewerId = u64;

/// Largest image side a viewer may ask for: the visibility passes allocate width × height.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// What a viewer connection tells the schedule.
#[derive(Debug)]
pub enum ViewerEvent {
    Joined {
        id: ViewerId,
        outbox: mpsc::UnboundedSender<SmaToViewer>,
    },
    Message {
        id: ViewerId,
        message: ViewerToSma,
    },
    Left {
        id: ViewerId,
    },
}

/// What every viewer connection needs to know.
#[derive(Clone, Debug)]
pub struct ViewerLinkConfig {
    pub scene_info: SceneInfo,
    pub fingerprint: Fingerprint,
    pub max_frame: usize,
    /// A viewer that has not completed its handshake by then is closed (DESIGN.md §8).
    pub handshake_deadline: Duration,
}

/// Serves one viewer until it leaves, breaks the protocol, or the server shuts down.
pub async fn serve(
    stream: TcpStream,
    id: ViewerId,
    config: ViewerLinkConfig,
    events: mpsc::UnboundedSender<ViewerEvent>,
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
        SceneCheck::Tell(config.fingerprint),
        config.handshake_deadline,
    );
    if let Err(e) = handshake.await {
        tracing::warn!(viewer = id, %peer, error = %e, "viewer handshake failed");
        return;
    }
    if writer
        .send(&SmaToViewer::SceneInfo(config.scene_info))
        .await
        .is_err()
    {
        return;
    }
    tracing::info!(viewer = id, %peer, "viewer connected");
    let (outbox, mut outgoing) = mpsc::unbounded_channel();
    if events.send(ViewerEvent::Joined { id, outbox }).is_err() {
        return;
    }
    let ended = loop {
        tokio::select! {
            incoming = reader.recv() => match incoming.and_then(checked) {
                Ok(ViewerToSma::Bye) => break None,
                Ok(message) => {
                    if events.send(ViewerEvent::Message { id, message }).is_err() {
                        break None;
                    }
                }
                Err(e) if e.is_disconnect() => break None,
                Err(e) => break Some(e),
            },
            message = outgoing.recv() => match message {
                Some(message) => {
                    if let Err(e) = writer.send(&message).await {
                        break (!e.is_disconnect()).then_some(e);
                    }
                }
                None => break None,
            },
            _ = shutdown.changed() => break None,
        }
    };
    if let Some(e) = ended {
        tracing::warn!(viewer = id, %peer, error = %e, "closing viewer after a protocol error");
        let _ = writer
            .send(&SmaToViewer::Error {
                message: e.to_string(),
            })
            .await;
    }
    let _ = events.send(ViewerEvent::Left { id });
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

/// What a viewer learns of `scene` first (it has no scene of its own, DESIGN.md §2): its name,
/// fingerprint, bounds, viewpoints, and the criteria, the one viewers start with first.
pub fn scene_info(scene: &scene::Scene, active: CriterionKind) -> SceneInfo {
    let (lo, hi) = scene.mesh.bounds();
    let criteria = std::iter::once(active)
        .chain(CriterionKind::ALL.into_iter().filter(|&k| k != active))
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
