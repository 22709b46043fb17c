//! A renderer stand-in on a free loopback port: it shades a known function of position (so a test
//! can predict every radiance), logs every request, and can misbehave at a chosen batch.

use std::sync::{Arc, Mutex};

use glam::Vec3;
use protocol::connection::{SceneCheck, accept_handshake};
use protocol::direct_tile::{TileAnswer, TileRequest};
use protocol::renderer_link::{FromRenderer, Quality, Radiance, SampleKey, ShadePoint, ToRenderer};
use protocol::types::PartEstimate;
use protocol::{Role, SampleParts, SceneIdentity, Side, split_tcp};
use scene::Scene;
use tokio::net::TcpListener;

/// Radiance at a world point seen from `side`, at `quality`, for the eye of a view-dependent point.
pub type Shading = fn(Vec3, Side, Quality, Option<Vec3>) -> [f32; 3];

/// Every point requested: its key, the batch's quality and the point's eye.
pub type Log = Arc<Mutex<Vec<(SampleKey, Quality, Option<[f32; 3]>)>>>;

/// How the stand-in misbehaves at its n-th batch: it takes it, answers nothing, and closes the
/// connection, then either stops listening (killed mid-batch) or accepts again (restarted).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    None,
    Die(usize),
    Drop(usize),
    /// Every answer says its paths scattered by half its luminance (variance `(L / 2)²`), so
    /// the SMA has noise to take paths against; the means stay exact.
    Noisy,
    /// As `Noisy`, and each batch takes this long per thousand paths it traces, as a renderer
    /// does: work queues up in the SMA as it would against real renderers.
    NoisyTaking(std::time::Duration),
    /// The points of this mesh vertex are answered NaN, every other point as usual.
    NanAt(u32),
    /// A direct-light tile is taken and never answered: the link is dropped, the listener kept.
    DropAtTile,
}

/// Where `point` lies in the world.
fn position(scene: &Scene, point: &ShadePoint) -> Vec3 {
    let [a, b, c] = scene.mesh.triangle_positions(point.base_triangle as usize);
    let [u, v] = point.bary;
    a * (1.0 - u - v) + b * u + c * v
}

/// A tile's answer: every pixel a direct part of 0.5 whose samples scatter by as much, so its
/// accumulation's standard error falls pass after pass.
fn direct_tile(tile: &TileRequest) -> FromRenderer {
    let pixel = PartEstimate {
        rgb: [0.5; 3],
        luminance_variance: 0.25,
    };
    FromRenderer::DirectTile(TileAnswer {
        tile_id: tile.tile_id,
        camera_seq: tile.camera.seq,
        rect: tile.rect,
        pass: tile.pass,
        samples_per_pixel: tile.samples_per_pixel,
        pixels: vec![pixel; tile.rect.pixels()],
        micros: 1,
    })
}

/// Starts the stand-in for `scene`; returns its address and its request log.
pub async fn start(scene: Scene, shading: Shading, fault: Fault) -> (String, Log) {
    let listener = TcpListener::bind("127.0.0.1:0")
        .await
        .expect("binding a loopback port");
    let addr = listener.local_addr().expect("a bound address").to_string();
    let log: Log = Arc::default();
    tokio::spawn(serve(listener, scene, shading, fault, log.clone()));
    (addr, log)
}

async fn serve(listener: TcpListener, scene: Scene, shading: Shading, fault: Fault, log: Log) {
    let mut batches = 0;
    while let Ok((stream, _)) = listener.accept().await {
        let (mut reader, mut writer) = split_tcp::<ToRenderer, FromRenderer>(stream, 1 << 26);
        let fp = SceneCheck::Same(SceneIdentity {
            fingerprint: scene.fingerprint,
            textures: scene.settings.textures.enabled,
        });
        if accept_handshake(&mut reader, &mut writer, Role::Renderer, Role::Sma, fp)
            .await
            .is_err()
        {
            continue;
        }
        loop {
            let batch = match reader.recv().await {
                Ok(ToRenderer::ShadeBatch(batch)) => batch,
                // Heartbeats are answered like a real renderer's, however the batches go.
                Ok(ToRenderer::Ping { nonce }) => {
                    if writer.send(&FromRenderer::Pong { nonce }).await.is_err() {
                        break;
                    }
                    continue;
                }
                Ok(ToRenderer::DirectTile(_)) if fault == Fault::DropAtTile => break,
                Ok(ToRenderer::DirectTile(tile)) => {
                    if writer.send(&direct_tile(&tile)).await.is_err() {
                        break;
                    }
                    continue;
                }
                _ => break,
            };
            batches += 1;
            match fault {
                Fault::Die(n) if n == batches => return, // listener and link dropped
                Fault::Drop(n) if n == batches => {
                    // Link dropped, listener kept. Closed gracefully: a socket closed with unread
                    // batches in it resets the connection, and the reset can discard replies
                    // already sent (the SMA then rightly asks for them again, which would read as
                    // a repeat here). So: FIN after the replies, then read until the SMA closes.
                    drop(writer);
                    while reader.recv().await.is_ok() {}
                    break;
                }
                _ => {}
            }
            log.lock()
                .expect("log lock")
                .extend(batch.points.iter().map(|p| (p.key, batch.quality, p.eye)));
            if let Fault::NoisyTaking(per_kilo_path) = fault {
                let paths = batch.points.len() as u32 * batch.quality.paths;
                tokio::time::sleep(per_kilo_path * paths / 1000).await;
            }
            let rgb: Vec<[f32; 3]> = batch
                .points
                .iter()
                .map(|p| match fault {
                    Fault::NanAt(vertex) if p.key.vertex == vertex => [f32::NAN; 3],
                    _ => shading(
                        position(&scene, p),
                        p.side,
                        batch.quality,
                        p.eye.map(Vec3::from),
                    ),
                })
                .collect();
            // The fake's shading is radiance, shown as it is whatever the point's albedo, and
            // not indirect light: the object-space filter of the indirect part (DESIGN.md §5)
            // leaves it as it is.
            let parts = rgb
                .iter()
                .map(|c| {
                    let luminance_variance = match fault {
                        Fault::Noisy | Fault::NoisyTaking(_) => {
                            (0.5 * conventions::luminance(*c)).powi(2)
                        }
                        _ => 0.0,
                    };
                    SampleParts::radiance_only(*c, luminance_variance)
                })
                .collect();
            let reply = Radiance {
                batch_id: batch.batch_id,
                quality: batch.quality,
                parts,
                paths: vec![batch.quality.paths; batch.points.len()],
                flags: vec![0; batch.points.len()],
                micros: 1,
            };
            if writer.send(&FromRenderer::Radiance(reply)).await.is_err() {
                break;
            }
        }
    }
}
