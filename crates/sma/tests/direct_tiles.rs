//! Per-pixel direct light while a viewer rests (DESIGN.md §3 step 8), the SMA service in-process
//! against a fake renderer that answers every tile (`testkit::fake_renderer`) and the scripted
//! viewer of `testkit::probe`, which checks every tile it gets. Needs a wgpu adapter (Mesa
//! without a GPU): without one the test says so and returns, unless `WALKTHROUGH_REQUIRE_GPU`
//! is set.

use std::collections::HashSet;
use std::time::Duration;

use protocol::direct_tile::TileRect;
use sma::config::SmaConfig;
use sma::visibility::Gpu;
use testkit::fake_renderer::{self, Fault};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const W: u32 = 80;
const H: u32 = 48;
const WAIT: Duration = Duration::from_secs(60);

fn flat(
    _: glam::Vec3,
    _: protocol::Side,
    _: protocol::renderer_link::Quality,
    _: Option<glam::Vec3>,
) -> [f32; 3] {
    [0.5; 3]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resting_viewer_receives_direct_tiles_and_a_camera_move_drops_them() {
    if gpu_or_skip(Gpu::new()).is_none() {
        return;
    }
    let scene = scene::load("cornell").expect("built-in scene");
    let (renderer, _) = fake_renderer::start(scene.clone(), flat, Fault::None).await;
    let mut config = SmaConfig {
        listen: "127.0.0.1:0".into(),
        renderers: vec![renderer],
        ..SmaConfig::default()
    };
    config.schedule.rest = Duration::ZERO;
    config.schedule.direct_tiles.enabled = true;
    let sma = sma::server::start(config, scene, std::future::pending())
        .await
        .unwrap();
    let mut probe = Probe::connect(&sma.addr.to_string()).await.unwrap();
    let name = probe.scene.viewpoints[0].name.clone();
    let first = probe.view(&name, W, H).await.unwrap();
    let cover: HashSet<TileRect> = TileRect::cover(W, H).into_iter().collect();
    // Every tile of the resting camera arrives, and again as later passes accumulate.
    probe
        .until_tiles(WAIT, |tiles| {
            let twice = tiles.iter().filter(|(_, t)| t.samples > 4);
            twice.map(|(_, t)| t.rect).collect::<HashSet<_>>() == cover
        })
        .await
        .unwrap();
    assert!(probe.tiles.iter().all(|(_, t)| t.camera_seq == first.seq));
    let (_, latest) = probe.tiles.last().unwrap();
    let (_, earliest) = (probe.tiles.iter())
        .find(|(_, t)| t.rect == latest.rect)
        .unwrap();
    let error = |t: &protocol::direct_tile::ViewerTile| t.pixels[0].standard_error.decode();
    assert!(latest.samples > earliest.samples);
    assert!(
        error(latest) < error(earliest),
        "accumulation lowers the standard error"
    );
    // A move: once the epoch answering the new camera arrived, no tile of the old one follows.
    let mut moved = first.clone();
    moved.eye[0] += 10.0;
    let moved = probe.camera(moved).await.unwrap();
    probe.complete(moved.seq, WAIT).await.unwrap();
    let answered_at = probe
        .epochs
        .iter()
        .position(|e| e.camera_seq == moved.seq)
        .unwrap();
    probe
        .until_tiles(WAIT, |tiles| {
            let new = tiles.iter().filter(|(_, t)| t.camera_seq == moved.seq);
            new.map(|(_, t)| t.rect).collect::<HashSet<_>>() == cover
        })
        .await
        .unwrap();
    let stale: Vec<_> = (probe.tiles.iter())
        .filter(|(epochs, t)| *epochs > answered_at && t.camera_seq != moved.seq)
        .map(|(_, t)| (t.camera_seq, t.rect))
        .collect();
    assert!(
        stale.is_empty(),
        "tiles of the old camera after the move: {stale:?}"
    );
    drop(probe);
    sma.stop().await.unwrap();
}
