//! The dispatcher and its backlog against a renderer stand-in on loopback.

use std::collections::HashSet;

use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadePoint};
use testkit::fake_renderer::{self, Fault};

use super::*;

fn point(vertex: u32) -> ShadePoint {
    ShadePoint {
        key: SampleKey {
            vertex,
            side: Side::Front,
        },
        base_triangle: 0,
        bary: [0.25; 2],
        side: Side::Front,
        eye: None,
    }
}

fn batch(id: u64) -> ShadeBatch {
    ShadeBatch {
        batch_id: id,
        quality: Quality::DIRECT,
        seed: id,
        points: (0..8).map(point).collect(),
    }
}

fn flat([x, y, z]: [f32; 3]) -> [f32; 3] {
    [x.abs() + 0.5, y.abs() + 0.5, z.abs() + 0.5]
}

/// A pool of one stand-in renderer that holds one batch at a time.
async fn pool_of_one() -> (PoolHandle, mpsc::Receiver<PoolEvent>, watch::Sender<bool>) {
    let scene = scene::load("cornell").expect("the built-in Cornell box");
    pool_dialing(scene.clone(), &scene, Fault::None).await
}

/// A pool of the SMA's `scene` dialing one stand-in renderer that has loaded `renderers`.
async fn pool_dialing(
    renderers: scene::Scene,
    scene: &scene::Scene,
    fault: Fault,
) -> (PoolHandle, mpsc::Receiver<PoolEvent>, watch::Sender<bool>) {
    let (addr, _log) = fake_renderer::start(renderers, |p, _, _, _| flat(p.into()), fault).await;
    let config = PoolConfig {
        renderers: vec![addr],
        scene: crate::viewer_link::scene_identity(scene),
        depth: 1,
        max_frame: 1 << 24,
        backoff_min: Duration::from_millis(50),
        backoff_max: Duration::from_millis(500),
        liveness: Liveness::default(),
        deadline_factor: 8.0,
        first_deadline: Duration::from_secs(10),
        renderer_port: PortLimits::default(),
    };
    let (events_tx, events) = mpsc::channel(1024);
    let (shutdown, shutdown_rx) = watch::channel(false);
    (
        spawn(config, events_tx, None, shutdown_rx),
        events,
        shutdown,
    )
}

/// Waits for the renderer to be up, so that batches go out as they are handed over.
async fn until_connected(events: &mut mpsc::Receiver<PoolEvent>) {
    while let Some(event) = events.recv().await {
        if matches!(event, PoolEvent::Renderers { connected: 1 }) {
            return;
        }
    }
    panic!("the pool closed before its renderer connected");
}

/// The next answer the pool reports.
async fn next_answer(events: &mut mpsc::Receiver<PoolEvent>) -> u64 {
    loop {
        match events.recv().await {
            Some(PoolEvent::Shaded { batch, .. }) => return batch.batch_id,
            Some(PoolEvent::Failed { batch, reason }) => {
                panic!("batch {} failed: {reason}", batch.batch_id)
            }
            Some(PoolEvent::Renderers { .. }) => {}
            Some(PoolEvent::Tile(news)) => panic!("no tile was asked for: {news:?}"),
            None => panic!("the pool closed"),
        }
    }
}

/// A renderer whose textures are on where the SMA's are off is refused at every try (the
/// fingerprints are left equal, so only the textures differ): it never joins the pool.
#[tokio::test]
async fn a_renderer_with_other_textures_never_joins() {
    let scene = scene::load("cornell").expect("the built-in Cornell box");
    let mut textured = scene.clone();
    textured.settings.textures.enabled = true;
    let (_pool, mut events, _shutdown) = pool_dialing(textured, &scene, Fault::None).await;
    let joined = tokio::time::timeout(Duration::from_millis(1500), until_connected(&mut events));
    assert!(
        joined.await.is_err(),
        "the pool took a renderer with other textures"
    );
}

// The test's runtime has one thread: the dispatcher, the link and the stand-in run only while
// the test awaits, so what is sent before the withdrawal is up to the awaits.
#[tokio::test]
async fn a_batch_is_answered_or_withdrawn_never_both_and_never_lost() {
    let (pool, mut events, _shutdown) = pool_of_one().await;
    until_connected(&mut events).await;
    for id in 1..=20 {
        pool.submit(batch(id), Lane::Background).unwrap();
    }
    // The renderer answers one (and may hold the next) before the rest are handed over.
    let mut answered = HashSet::from([next_answer(&mut events).await]);
    for id in 21..=40 {
        pool.submit(batch(id), Lane::Background).unwrap();
    }
    let withdrawn: HashSet<u64> = pool.withdraw().iter().map(|b| b.batch_id).collect();
    assert!(
        (21..=40).all(|id| withdrawn.contains(&id)),
        "batches handed over since the last await were sent: {withdrawn:?}"
    );
    let wait = tokio::time::timeout(Duration::from_secs(20), async {
        while answered.len() + withdrawn.len() < 40 {
            assert!(
                answered.insert(next_answer(&mut events).await),
                "answered twice"
            );
        }
    });
    wait.await.expect("every batch not withdrawn is answered");
    assert!(
        answered.len() > 1,
        "the batch held at the withdrawal was answered"
    );
    assert!(
        answered.is_disjoint(&withdrawn),
        "a withdrawn batch was sent"
    );
    assert_eq!(answered.len() + withdrawn.len(), 40);
    assert!(pool.withdraw().is_empty());
}

#[tokio::test]
async fn urgent_batches_go_out_before_more_paths_handed_over_earlier() {
    let (pool, mut events, _shutdown) = pool_of_one().await;
    until_connected(&mut events).await;
    for id in 1..=20 {
        pool.submit(batch(id), Lane::Background).unwrap();
    }
    pool.submit(batch(100), Lane::Urgent).unwrap();
    let mut order = Vec::new();
    while order.len() < 21 {
        order.push(next_answer(&mut events).await);
    }
    let urgent_at = order.iter().position(|&id| id == 100).unwrap();
    // At most the batch the renderer already held, and the one the dispatcher may have been
    // sending meanwhile, go before it.
    assert!(
        urgent_at <= 2,
        "the urgent batch came {urgent_at}th: {order:?}"
    );
}

fn tile_request(tile_id: u64) -> protocol::direct_tile::TileRequest {
    use protocol::direct_tile::{DirectLights, TileRect, TileRequest};
    use protocol::viewer_link::Camera;
    TileRequest {
        tile_id,
        camera: Camera {
            seq: 1,
            eye: [0.0, 1.0, 5.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
            width: 64,
            height: 64,
        },
        rect: TileRect::cover(64, 64)[0],
        samples_per_pixel: 2,
        pass: 0,
        lights: DirectLights::All,
    }
}

#[tokio::test]
async fn a_tile_goes_out_only_once_no_batch_waits_and_a_withdrawn_one_never() {
    let (pool, mut events, _shutdown) = pool_of_one().await;
    until_connected(&mut events).await;
    for id in 1..=10 {
        pool.submit(batch(id), Lane::Background).unwrap();
    }
    pool.submit_tile(tile_request(7));
    pool.submit_tile(tile_request(8));
    pool.withdraw_tiles(&[8]);
    let mut order = Vec::new();
    let wait = tokio::time::timeout(Duration::from_secs(20), async {
        while order.len() < 11 {
            match events.recv().await {
                Some(PoolEvent::Shaded { batch, .. }) => order.push(Some(batch.batch_id)),
                Some(PoolEvent::Tile(TileNews::Answered(answer))) => {
                    assert_eq!(answer.tile_id, 7, "only the tile not withdrawn");
                    order.push(None);
                }
                Some(PoolEvent::Renderers { .. }) => {}
                other => panic!("{other:?}"),
            }
        }
    });
    wait.await.expect("every batch and the tile answered");
    assert_eq!(
        order.last(),
        Some(&None),
        "the tile went after every batch: {order:?}"
    );
}

#[tokio::test]
async fn a_tile_its_renderer_took_down_with_it_is_dropped_not_reissued() {
    let scene = scene::load("cornell").expect("the built-in Cornell box");
    let (pool, mut events, _shutdown) =
        pool_dialing(scene.clone(), &scene, Fault::DropAtTile).await;
    until_connected(&mut events).await;
    pool.submit_tile(tile_request(3));
    let dropped = tokio::time::timeout(Duration::from_secs(20), async {
        loop {
            match events.recv().await {
                Some(PoolEvent::Tile(TileNews::Dropped { tile_id, .. })) => return tile_id,
                Some(PoolEvent::Renderers { .. }) => {}
                other => panic!("{other:?}"),
            }
        }
    });
    assert_eq!(dropped.await.expect("the lost tile is reported"), 3);
}
