//! The service over real loopback TCP (DESIGN.md §7, §8): batches answered exactly as the
//! in-process estimator answers them for the same seed; malformed frames answered with an error
//! and the connection closed, while the server keeps serving others; a wrong scene refused;
//! direct tiles answered as the in-process tracer answers them.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::*;
use glam::Vec3;
use protocol::connection::TcpReader;
use protocol::direct_tile::{DirectLights, TileRect, TileRequest};
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::renderer_link::{
    FromRenderer, Quality, ShadeBatch, ShadePoint, ToRenderer, point_flags,
};
use protocol::viewer_link::Camera;
use protocol::{MessageReader, MessageWriter, ProtocolError};
use renderer::direct_tile::trace_tile;
use renderer::service::Service;
use renderer::{World, shade_batch};
use scene::{SceneBuilder, Sky};
use tokio::io::AsyncWriteExt;
use tokio::net::tcp::OwnedWriteHalf;
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::oneshot;

fn test_world() -> World {
    let mut b = SceneBuilder::new(settings(
        Some(sun(Vec3::new(0.3, 1.0, 0.2), 1.0e5)),
        Sky::Uniform {
            radiance: [0.5, 0.6, 0.9],
        },
    ));
    let m = b.material(grey(0.6));
    floor(&mut b, Vec3::ZERO, 5.0, m);
    cube(
        &mut b,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 1.5, 1.0),
        false,
        m,
    );
    world(b)
}

fn batch(w: &World, id: u64, seed: u64, n: usize) -> ShadeBatch {
    let points: Vec<ShadePoint> = (0..n)
        .map(|i| {
            let x = -4.0 + 8.0 * (i as f32 + 0.5) / n as f32;
            point_hit_by(w, Vec3::new(x, 3.0, 0.37), Vec3::NEG_Y)
        })
        .collect();
    ShadeBatch {
        batch_id: id,
        quality: Quality {
            paths: 16,
            bounces: Some(2),
        },
        seed,
        points,
    }
}

struct Server {
    addr: std::net::SocketAddr,
    stop: Option<oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<anyhow::Result<()>>,
}

async fn start(world: Arc<World>) -> Server {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let service = Service::new(world, 2, DEFAULT_MAX_FRAME).unwrap();
    let (tx, rx) = oneshot::channel::<()>();
    let task = tokio::spawn(service.serve(listener, async {
        let _ = rx.await;
    }));
    Server {
        addr,
        stop: Some(tx),
        task,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn batches_match_the_in_process_estimator_and_bad_frames_are_answered() {
    let world = Arc::new(test_world());
    let fp = world.identity();
    let server = start(Arc::clone(&world)).await;

    // Several batches in flight at once on one link; replies come per batch, in any order.
    let (mut r, mut w) = connect_as_sma(server.addr, fp).await.unwrap();
    let batches: Vec<ShadeBatch> = (0..4)
        .map(|i| batch(&world, 100 + i, 7 + i, 40 + 10 * i as usize))
        .collect();
    for b in &batches {
        w.send(&ToRenderer::ShadeBatch(b.clone())).await.unwrap();
    }
    let mut seen = Vec::new();
    for _ in 0..batches.len() {
        let FromRenderer::Radiance(reply) = recv(&mut r).await.unwrap() else {
            panic!("expected radiance")
        };
        let b = batches
            .iter()
            .find(|b| b.batch_id == reply.batch_id)
            .expect("known batch id");
        let (local, _) = shade_batch(&world, b);
        assert_eq!(reply.parts, local.parts, "batch {}", b.batch_id);
        assert_eq!(reply.flags, local.flags);
        assert_eq!(reply.quality, b.quality);
        assert!(reply.parts.iter().any(|p| p.radiance([1.0; 3])[0] > 0.0));
        seen.push(reply.batch_id);
    }
    seen.sort();
    assert_eq!(seen, vec![100, 101, 102, 103]);

    // A batch with a bad point still gets an answer, with that point flagged.
    let mut b = batch(&world, 200, 1, 3);
    b.points[1].base_triangle = u32::MAX;
    w.send(&ToRenderer::ShadeBatch(b)).await.unwrap();
    let FromRenderer::Radiance(reply) = recv(&mut r).await.unwrap() else {
        panic!("expected radiance")
    };
    assert_eq!(reply.flags[1], point_flags::INVALID_POINT);
    assert_eq!(reply.parts[1], protocol::SampleParts::default());

    // An unreasonable batch is rejected, and the link goes on.
    let mut b = batch(&world, 201, 1, 3);
    b.quality.paths = 0;
    w.send(&ToRenderer::ShadeBatch(b)).await.unwrap();
    assert!(matches!(
        recv(&mut r).await.unwrap(),
        FromRenderer::Rejected { batch_id: 201, .. }
    ));

    // A direct tile is answered as the in-process tracer answers it; one outside its image is
    // refused with its reason, and the link goes on.
    let tile = TileRequest {
        tile_id: 9,
        camera: Camera {
            seq: 2,
            eye: [3.0, 2.0, 3.0],
            orientation: [-0.5f32.sqrt(), 0.0, 0.0, 0.5f32.sqrt()],
            fov_y_deg: 30.0,
            width: 40,
            height: 30,
        },
        rect: TileRect {
            x: 32,
            y: 16,
            width: 8,
            height: 14,
        },
        samples_per_pixel: 2,
        pass: 3,
        lights: DirectLights::All,
    };
    w.send(&ToRenderer::DirectTile(tile.clone())).await.unwrap();
    let FromRenderer::DirectTile(answer) = recv(&mut r).await.unwrap() else {
        panic!("expected a tile")
    };
    assert_eq!(answer.pixels, trace_tile(&world, &tile).0.pixels);
    assert!(answer.pixels.iter().any(|p| p.rgb[0] > 0.0));
    let outside = TileRequest {
        rect: TileRect { x: 33, ..tile.rect },
        ..tile
    };
    w.send(&ToRenderer::DirectTile(outside)).await.unwrap();
    let FromRenderer::TileRejected { tile_id: 9, reason } = recv(&mut r).await.unwrap() else {
        panic!("expected a refusal")
    };
    assert!(reason.contains("outside"), "{reason}");

    // A second SMA on its own link is served at the same time.
    let (mut r2, mut w2) = connect_as_sma(server.addr, fp).await.unwrap();

    drop(w);
    drop(r);
    // Garbage in a well-formed frame: an error reply, then the link closes.
    let (mut r, mut raw) = connect_raw(server.addr, fp).await;
    raw.write_all(&[0, 0, 0, 3, 0xff, 0xff, 0xff])
        .await
        .unwrap();
    raw.flush().await.unwrap();
    assert!(matches!(recv(&mut r).await, Ok(FromRenderer::Error { .. })));
    assert!(matches!(
        recv(&mut r).await,
        Err(ProtocolError::Closed) | Err(ProtocolError::Io(_))
    ));

    // The other link still works.
    let b = batch(&world, 300, 5, 8);
    w2.send(&ToRenderer::ShadeBatch(b.clone())).await.unwrap();
    let FromRenderer::Radiance(reply) = recv(&mut r2).await.unwrap() else {
        panic!("expected radiance")
    };
    assert_eq!(reply.parts, shade_batch(&world, &b).0.parts);

    // An oversized frame header: error, close.
    let (mut r3, mut raw) = connect_raw(server.addr, fp).await;
    raw.write_all(&[0xff, 0xff, 0xff, 0xff]).await.unwrap();
    raw.flush().await.unwrap();
    assert!(matches!(
        recv(&mut r3).await,
        Ok(FromRenderer::Error { .. })
    ));

    // A peer with another scene is refused at the handshake.
    let mut other = fp;
    other.fingerprint[0] ^= 1;
    assert!(matches!(
        connect_as_sma(server.addr, other).await,
        Err(ProtocolError::Refused(_))
    ));

    // Bye closes politely; then shut the server down, which returns.
    w2.send(&ToRenderer::Bye).await.unwrap();
    let mut server = server;
    server.stop.take().unwrap().send(()).unwrap();
    tokio::time::timeout(Duration::from_secs(10), server.task)
        .await
        .expect("server stops")
        .unwrap()
        .unwrap();
}

/// A link after the handshake whose sending half is the raw socket, to send frames no honest
/// peer would.
async fn connect_raw(
    addr: std::net::SocketAddr,
    scene: protocol::SceneIdentity,
) -> (TcpReader<FromRenderer>, OwnedWriteHalf) {
    let stream = TcpStream::connect(addr).await.unwrap();
    let (rh, mut wh) = stream.into_split();
    let mut r = MessageReader::new(rh, DEFAULT_MAX_FRAME);
    let mut w = MessageWriter::<_, ToRenderer>::new(&mut wh, DEFAULT_MAX_FRAME);
    handshake_as_sma(&mut r, &mut w, scene).await.unwrap();
    drop(w);
    (r, wh)
}
