//! The SMA service in-process over loopback, against fake renderers that shade a known function
//! of position and record every request (`testkit::fake_renderer`), and the scripted viewer of
//! `testkit::probe`, which fails on any inconsistency of its triangle table. Needs a wgpu adapter
//! (Mesa without a GPU): without one the tests say so and return, unless
//! `WALKTHROUGH_REQUIRE_GPU` is set.

use std::collections::HashMap;
use std::time::Duration;

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey};
use protocol::viewer_link::{Camera, SmaToViewer, ViewerToSma};
use scene::{Material, Scene, SceneBuilder, SceneSettings, ViewpointSetting};
use sma::config::{Profile, SmaConfig};
use sma::criteria::CriterionKind;
use sma::server::Running;
use sma::visibility::Gpu;
use testkit::fake_renderer::{self, Fault, Log};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const W: u32 = 200;
const H: u32 = 150;
const WAIT: Duration = Duration::from_secs(60);
/// `Stats` intervals that must pass without work to show that a converged SMA asks for nothing
/// (at a `stats_every` of 10 ms, half a second of its turns at least).
const QUIET_INTERVALS: usize = 50;

fn gpu_available() -> bool {
    gpu_or_skip(Gpu::new()).is_some()
}

fn viewpoint(name: &str, eye: [f32; 3], target: [f32; 3]) -> ViewpointSetting {
    ViewpointSetting {
        name: name.into(),
        eye,
        target,
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    }
}

/// A floor and a free-standing wall (x in -1..1, y in 0..2, z = 0), seen from the front, from
/// the back, from the front a little to the side, and from in front looking away from it (nothing
/// in view). `wall` is its material.
fn wall_scene(wall: Material) -> Scene {
    let settings = SceneSettings {
        name: "wall".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun: None,
        sky: Default::default(),
        quality: Default::default(),
        viewpoints: vec![
            viewpoint("front", [0.3, 1.2, 4.0], [0.0, 0.8, 0.0]),
            viewpoint("side", [1.5, 1.2, 3.8], [0.0, 0.8, 0.0]),
            viewpoint("back", [-0.3, 1.2, -4.0], [0.0, 0.8, 0.0]),
            viewpoint("away", [0.3, 1.2, 4.0], [0.3, 1.2, 9.0]),
        ],
        textures: Default::default(),
    };
    let mut b = SceneBuilder::new(settings);
    let floor = b.material(Material::diffuse("floor", Vec3::splat(0.5)));
    let wall = b.material(wall);
    let quad = |b: &mut SceneBuilder, corners: [Vec3; 4], m: u32| {
        let v = corners.map(|p| b.vertex(p));
        b.triangle([v[0], v[1], v[2]], m);
        b.triangle([v[0], v[2], v[3]], m);
    };
    let f = |x, z| Vec3::new(x, 0.0, z);
    quad(
        &mut b,
        [f(-4.0, -4.0), f(-4.0, 4.0), f(4.0, 4.0), f(4.0, -4.0)],
        floor,
    );
    let w = |x, y| Vec3::new(x, y, 0.0);
    quad(
        &mut b,
        [w(-1.0, 0.0), w(1.0, 0.0), w(1.0, 2.0), w(-1.0, 2.0)],
        wall,
    );
    b.build().expect("valid test scene")
}

fn diffuse_wall() -> Scene {
    wall_scene(Material::diffuse("wall", Vec3::splat(0.7)))
}

/// What the fake renderer returns: a sharp "shadow" edge at x = 0.3 (something to refine), the
/// back side darker, the cheap quality dimmer, and a view-dependent point brighter the further
/// its eye is off x = 0, so each of those shows in the radiance.
fn radiance_at(p: Vec3, side: Side, quality: Quality, eye: Option<Vec3>) -> [f32; 3] {
    let lit = if p.x > 0.3 { 1.0 } else { 0.1 };
    let side = if side == Side::Back { 0.5 } else { 1.0 };
    let q = if quality == Quality::DIRECT { 0.8 } else { 1.0 };
    let gloss = eye.map_or(1.0, |e| 1.0 + 0.1 * e.x.abs());
    [lit * side * q * gloss; 3]
}

/// A renderer stand-in shading [`radiance_at`].
async fn fake_renderer(scene: Scene, fault: Fault) -> (String, Log) {
    fake_renderer::start(scene, radiance_at, fault).await
}

fn config(renderers: Vec<String>, refine: bool) -> SmaConfig {
    let mut config = SmaConfig {
        listen: "127.0.0.1:0".into(),
        renderers,
        ..SmaConfig::default()
    };
    config.schedule.refine = refine;
    // The schedule's tests refine with the object-space NLD_OS, which subdivides the fake
    // renderer's smooth gradients; today's default, nld-px, judges pixels of the shown image.
    config.schedule.criterion = CriterionKind::NldOs;
    config.schedule.rest = Duration::ZERO;
    config.schedule.stats_every = Duration::from_secs(60);
    config
}

/// Every (key, quality) requested at most once, for the same eye.
fn repeated_requests(log: &Log) -> Vec<(SampleKey, Quality)> {
    let mut count: HashMap<(SampleKey, (u32, u32)), (usize, Quality)> = HashMap::new();
    for (key, q, _) in log.lock().unwrap().iter() {
        count.entry((*key, q.rank())).or_insert((0, *q)).0 += 1;
    }
    count
        .into_iter()
        .filter(|(_, (n, _))| *n > 1)
        .map(|((k, _), (_, q))| (k, q))
        .collect()
}

/// The SMA service started with `config` on `scene`, and a probe viewer connected to it.
async fn start_with_probe(config: &SmaConfig, scene: &Scene) -> (Running, Probe) {
    let sma = sma::server::start(config.clone(), scene.clone(), std::future::pending())
        .await
        .unwrap();
    let probe = Probe::connect(&sma.addr.to_string()).await.unwrap();
    (sma, probe)
}

/// Asks `probe` for viewpoint `name` and waits until that view is complete.
async fn view_completely(probe: &mut Probe, name: &str) -> Camera {
    let camera = probe.view(name, W, H).await.unwrap();
    probe.complete(camera.seq, WAIT).await.unwrap();
    camera
}

fn coverage(scene: &Scene, tris: &[[Vec3; 3]], camera: &Camera) -> Vec<bool> {
    sma::visibility::coverage(&Gpu::new().unwrap(), tris, camera, scene.mesh.bounds()).unwrap()
}

fn scene_coverage(scene: &Scene, camera: &Camera) -> Vec<bool> {
    let tris: Vec<[Vec3; 3]> = (0..scene.mesh.triangles.len())
        .map(|t| scene.mesh.triangle_positions(t))
        .collect();
    coverage(scene, &tris, camera)
}

/// What the triangles shown to `probe` cover from `camera`.
fn shown_coverage(scene: &Scene, probe: &Probe, camera: &Camera) -> Vec<bool> {
    coverage(scene, &probe.triangles(), camera)
}

fn differing(a: &[bool], b: &[bool]) -> usize {
    a.iter().zip(b).filter(|(x, y)| x != y).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn first_picture_then_refinement_stays_consistent_and_covers_the_visible_surface() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::None).await;
    let (sma, mut probe) = start_with_probe(&config(vec![renderer], true), &scene).await;
    probe.send(ViewerToSma::Pause).await.unwrap();
    let camera = probe.view("front", W, H).await.unwrap();
    let first = probe.complete(camera.seq, WAIT).await.unwrap();
    let base_coverage = scene_coverage(&scene, &camera);
    assert_eq!(
        differing(&base_coverage, &shown_coverage(&scene, &probe, &camera)),
        0,
        "unrefined: shown = visible surface"
    );
    assert!(probe.overlaps().is_empty());
    // Progressive quality: every shown vertex carries the full-quality value by now.
    assert!(
        log.lock()
            .unwrap()
            .iter()
            .any(|(_, q, _)| *q == Quality::DIRECT)
    );
    for t in probe.table.values() {
        for (p, rgb) in t.positions.iter().zip(probe.radiance(t)) {
            let lit: f32 = if p[0] > 0.3 { 1.0 } else { 0.1 };
            // The cache stores means within 1/511 of their largest channel (`cache::quantised`).
            let near = |want: f32| (rgb[0] - want).abs() <= want / 511.0;
            assert!(near(lit) || near(0.5 * lit), "{p:?}: {rgb:?}");
        }
    }

    probe.send(ViewerToSma::Resume).await.unwrap();
    // Many refinement rounds; at each complete epoch on the way, no two shown leaves overlap.
    let mut refined = first;
    while refined.shown < 20 * first.shown {
        refined = probe
            .until(WAIT, |e| e.outstanding == 0 && e.shown > refined.shown)
            .await
            .unwrap();
        assert!(
            probe.overlaps().is_empty(),
            "shown leaves overlap at {refined:?}"
        );
    }
    assert!(
        probe.overlaps().is_empty(),
        "shown leaves overlap after refinement"
    );
    let diff = differing(&base_coverage, &shown_coverage(&scene, &probe, &camera));
    // Subdivided edges are rasterised from midpoints rounded to f32: a few edge pixels may flip.
    assert!(
        diff <= (W * H) as usize / 1000,
        "{diff} pixels of coverage changed with refinement"
    );
    assert!(refined.shown > first.shown, "refinement added triangles");
    assert!(
        repeated_requests(&log).is_empty(),
        "a diffuse sample was requested twice"
    );

    // A camera change mid-refinement is answered (and the table stays consistent).
    view_completely(&mut probe, "side").await;
    assert!(probe.overlaps().is_empty());
    sma.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn walking_around_a_wall_shows_its_other_side() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let (sma, mut probe) = start_with_probe(&config(vec![renderer], false), &scene).await;
    let wall_sides = |probe: &Probe| -> Vec<(Side, f32)> {
        probe
            .table
            .values()
            .filter(|t| t.positions.iter().all(|p| p[2].abs() < 1e-6))
            .filter(|t| t.positions.iter().any(|p| p[1] > 1e-6))
            .map(|t| {
                (
                    sma::visible_set::split_shown_id(t.id).1,
                    probe.radiance(t)[0][0],
                )
            })
            .collect()
    };
    view_completely(&mut probe, "front").await;
    let seen = wall_sides(&probe);
    assert!(!seen.is_empty());
    view_completely(&mut probe, "back").await;
    let other = wall_sides(&probe);
    assert!(!other.is_empty());
    let sides: Vec<Side> = seen.iter().chain(&other).map(|s| s.0).collect();
    assert!(
        sides.contains(&Side::Front) && sides.contains(&Side::Back),
        "{sides:?}"
    );
    // Each view shows the wall with the samples of the side facing it: one side per view.
    assert!(seen.iter().all(|s| s.0 == seen[0].0) && other.iter().all(|s| s.0 == other[0].0));
    assert_ne!(seen[0].0, other[0].0);
    // The fake shades the back at half the front's radiance.
    let (front_max, back_max) = if seen[0].0 == Side::Front {
        (&seen, &other)
    } else {
        (&other, &seen)
    };
    let max = |v: &Vec<(Side, f32)>| v.iter().map(|s| s.1).fold(0.0, f32::max);
    assert!((max(front_max) - 2.0 * max(back_max)).abs() < 1e-6);
    sma.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mirror_samples_are_retaken_after_the_eye_moves_and_diffuse_ones_never() {
    if !gpu_available() {
        return;
    }
    for mirror in [false, true] {
        let scene = if mirror {
            wall_scene(Material::mirror("mirror", Vec3::ZERO, Vec3::splat(0.9)))
        } else {
            diffuse_wall()
        };
        let (renderer, log) = fake_renderer(scene.clone(), Fault::None).await;
        let (sma, mut probe) = start_with_probe(&config(vec![renderer], false), &scene).await;
        for view in ["front", "side", "front"] {
            view_completely(&mut probe, view).await;
        }
        let repeated = repeated_requests(&log);
        if mirror {
            assert!(
                !repeated.is_empty(),
                "no mirror sample was retaken after the eye moved"
            );
            let log = log.lock().unwrap();
            // Only mirror vertices (those given an eye) are retaken.
            let eyed: std::collections::HashSet<SampleKey> = log
                .iter()
                .filter(|(_, _, e)| e.is_some())
                .map(|(k, _, _)| *k)
                .collect();
            assert!(
                repeated.iter().all(|(k, _)| eyed.contains(k)),
                "a diffuse sample was retaken"
            );
        } else {
            assert!(
                repeated.is_empty(),
                "diffuse samples re-requested: {repeated:?}"
            );
        }
        sma.stop().await.unwrap();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_viewers_at_one_mirror_each_see_it_from_their_own_eye() {
    if !gpu_available() {
        return;
    }
    let scene = wall_scene(Material::mirror("mirror", Vec3::ZERO, Vec3::splat(0.9)));
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let (sma, mut a) = start_with_probe(&config(vec![renderer], false), &scene).await;
    let mut b = Probe::connect(&sma.addr.to_string()).await.unwrap();
    let ca = a.view("front", W, H).await.unwrap();
    let cb = b.view("side", W, H).await.unwrap();
    // With one eye per mirror sample, each viewer's samples replaced the other's and neither
    // view ever completed.
    a.complete(ca.seq, WAIT).await.unwrap();
    b.complete(cb.seq, WAIT).await.unwrap();
    for (probe, camera) in [(&a, &ca), (&b, &cb)] {
        let mirror: Vec<_> = (probe.table.values())
            .filter(|t| t.positions.iter().all(|p| p[2] == 0.0))
            .collect();
        assert!(!mirror.is_empty(), "the mirror wall is in view");
        for t in mirror {
            for (p, rgb) in t.positions.iter().zip(probe.radiance(t)) {
                let p = Vec3::from(*p);
                let want =
                    radiance_at(p, Side::Front, Quality::INTERACTIVE, Some(camera.eye_vec()));
                assert!(
                    (rgb[0] - want[0]).abs() < 1e-6,
                    "{rgb:?} at {p}, want {want:?}"
                );
            }
        }
    }
    sma.stop().await.unwrap();
}

/// Refines the wall from the front, pauses, looks away for four passes, looks back: the
/// number of triangles then shown.
async fn shown_after_looking_away(coarsen_after_passes: u64) -> usize {
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![renderer], true);
    config.schedule.coarsen_after_passes = coarsen_after_passes;
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    probe.view("front", W, H).await.unwrap();
    let refined = probe.until(WAIT, |e| e.shown >= 12 && e.outstanding == 0);
    refined.await.unwrap();
    probe.send(ViewerToSma::Pause).await.unwrap();
    for _ in 0..4 {
        let away = probe.view("away", W, H).await.unwrap();
        let epoch = probe.complete(away.seq, WAIT).await.unwrap();
        assert_eq!(epoch.shown, 0, "something is in view looking away");
    }
    view_completely(&mut probe, "front").await;
    let shown = probe.table.len();
    sma.stop().await.unwrap();
    shown
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subdivision_out_of_view_long_enough_is_coarsened_back_to_the_base_mesh() {
    if !gpu_available() {
        return;
    }
    // The wall and the floor: two base triangles each, all four in view from the front.
    assert_eq!(shown_after_looking_away(3).await, 4);
    // Control: without coarsening the refinement is still there when the viewer looks back.
    assert!(shown_after_looking_away(0).await >= 12);
}

/// Flat shading but for a darker back side: nothing to refine but what the large-triangle rule
/// splits (§4.3.5).
fn flat(_: Vec3, side: Side, _: Quality, _: Option<Vec3>) -> [f32; 3] {
    [if side == Side::Back { 0.25 } else { 0.5 }; 3]
}

/// What a view showed at its stated end.
struct StatedEnd {
    /// The mesh's leaves.
    leaves: u64,
    /// Shown triangles across the fake renderer's shadow edge at x = 0.3.
    across_the_edge: usize,
}

/// Refines the wall and the floor from the front, shaded by `shading`, until the view's stated
/// end, with coarsening by uniformity (`--merge-uniform`) on or off, checking that the table is
/// then conforming and covers the visible surface.
async fn stated_end(shading: fake_renderer::Shading, merge_uniform: bool) -> StatedEnd {
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer::start(scene.clone(), shading, Fault::None).await;
    let mut config = config(vec![renderer], true);
    config.schedule.merge_uniform = merge_uniform;
    config.schedule.max_paths = 4 * Quality::INTERACTIVE.paths;
    config.schedule.stats_every = Duration::from_millis(10);
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    let camera = probe.view("front", W, H).await.unwrap();
    let stats = probe.until_converged(WAIT).await.unwrap();
    if let Some(problem) = probe.conformity_problem() {
        panic!("not conforming at the stated end: {problem}");
    }
    let holes = differing(
        &scene_coverage(&scene, &camera),
        &shown_coverage(&scene, &probe, &camera),
    );
    assert!(
        holes <= (W * H) as usize / 1000,
        "{holes} pixels differ from the visible surface"
    );
    let across_the_edge = probe
        .triangles()
        .iter()
        .filter(|t| t.iter().any(|p| p.x < 0.3) && t.iter().any(|p| p.x > 0.3))
        .count();
    sma.stop().await.unwrap();
    StatedEnd {
        leaves: stats.leaves,
        across_the_edge,
    }
}

/// The thesis's future work (§6): a split of a flat surface brings nothing, which is known only
/// once it is made. On flat shading every split is the large-triangle rule's, and merging by
/// uniformity takes most of them back; across a shadow edge (`radiance_at`) the splits that
/// found it stay.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn splits_that_showed_nothing_are_merged_back_only_with_merging_by_uniformity() {
    if !gpu_available() {
        return;
    }
    let (off, on) = (stated_end(flat, false).await, stated_end(flat, true).await);
    eprintln!(
        "flat: {} leaves without merging, {} with it",
        off.leaves, on.leaves
    );
    assert!(
        on.leaves * 2 < off.leaves,
        "{} leaves merging, {} without",
        on.leaves,
        off.leaves
    );
    let (off, on) = (
        stated_end(radiance_at, false).await,
        stated_end(radiance_at, true).await,
    );
    eprintln!(
        "shadow edge: {} leaves ({} across it) without merging, {} ({}) with it",
        off.leaves, off.across_the_edge, on.leaves, on.across_the_edge
    );
    assert!(on.leaves < off.leaves);
    assert!(on.across_the_edge * 10 >= off.across_the_edge * 9);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_renderer_killed_mid_batch_loses_no_request() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (dying, _) = fake_renderer(scene.clone(), Fault::Die(2)).await;
    let (healthy, _) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![dying, healthy], false);
    config.schedule.batch_points = 2; // many small batches, so the dying one holds some
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    let cam = view_completely(&mut probe, "front").await;
    let shown = shown_coverage(&scene, &probe, &cam);
    assert_eq!(differing(&scene_coverage(&scene, &cam), &shown), 0);
    sma.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_renderer_link_reconnects_and_its_batch_is_reissued() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (flaky, log) = fake_renderer(scene.clone(), Fault::Drop(2)).await;
    let mut config = config(vec![flaky], false);
    config.schedule.batch_points = 2;
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    // Only the one renderer: completing needs the reconnection and the re-issued batch.
    let cam = view_completely(&mut probe, "front").await;
    let shown = shown_coverage(&scene, &probe, &cam);
    assert_eq!(differing(&scene_coverage(&scene, &cam), &shown), 0);
    assert!(
        repeated_requests(&log).is_empty(),
        "an answered sample was asked again"
    );
    sma.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_viewers_share_one_cache_and_a_bad_frame_closes_only_its_viewer() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::None).await;
    let (sma, mut a) = start_with_probe(&config(vec![renderer], false), &scene).await;
    let addr = sma.addr.to_string();
    let mut b = Probe::connect(&addr).await.unwrap();
    let ca = a.view("front", W, H).await.unwrap();
    let cb = b.view("side", W, H).await.unwrap();
    a.complete(ca.seq, WAIT).await.unwrap();
    b.complete(cb.seq, WAIT).await.unwrap();
    let common: Vec<_> = a
        .table
        .keys()
        .filter(|id| b.table.contains_key(id))
        .collect();
    assert!(!common.is_empty());
    for id in common {
        assert_eq!(
            a.table[id], b.table[id],
            "one cache, one radiance per triangle"
        );
    }
    assert!(
        repeated_requests(&log).is_empty(),
        "a sample was shaded twice for two viewers"
    );

    // A viewer sending garbage gets an Error and is closed; the other goes on.
    let mut bad = Probe::connect(&addr).await.unwrap();
    bad.send(ViewerToSma::Camera(Camera {
        width: 0,
        ..ca.clone()
    }))
    .await
    .unwrap();
    let err = bad.next_epoch().await.unwrap_err().to_string();
    assert!(err.contains("error"), "{err}");
    view_completely(&mut a, "side").await;

    // SetCriterion, Pause and Resume are acknowledged.
    a.send(ViewerToSma::SetCriterion { name: "rnd".into() })
        .await
        .unwrap();
    a.send(ViewerToSma::SetCriterion {
        name: "no-such".into(),
    })
    .await
    .unwrap();
    let e = a.next_epoch().await;
    assert!(e.is_err_and(|e| e.to_string().contains("unknown criterion")));
    assert!(a.refinement.iter().any(|(c, _)| c == "rnd"));
    sma.stop().await.unwrap();
}

/// The viewer link's heartbeat (DESIGN.md §8): a viewer that reads everything but answers no
/// ping is lost after the silence limit; one that answers stays, however long it rests.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewer_that_answers_no_heartbeat_is_lost_and_one_that_answers_stays() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _log) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![renderer], false);
    config.liveness.heartbeat = Duration::from_millis(100);
    config.viewer_silence = Duration::from_millis(500);
    let (sma, mut live) = start_with_probe(&config, &scene).await;
    let mut hung = Probe::connect(&sma.addr.to_string()).await.unwrap();
    hung.stop_answering_pings();
    // Both read everything; only `live` answers pings, and it rests meanwhile.
    let started = std::time::Instant::now();
    let closed = tokio::time::timeout(WAIT, async {
        loop {
            if let Err(e) = hung.next_epoch().await {
                return e;
            }
        }
    })
    .await
    .expect("the SMA kept a viewer that answers no heartbeat");
    let after = started.elapsed();
    eprintln!("lost after {after:?}: {closed:#}");
    // Its last ping may have gone out just before it stopped answering.
    assert!(after >= config.viewer_silence / 2, "lost after {after:?}");
    // Far past the silence limit, the viewer that answers is still served.
    tokio::time::sleep(6 * config.viewer_silence).await;
    view_completely(&mut live, "front").await;
    sma.stop().await.unwrap();
}

/// The stated end of DESIGN.md §5: a resting viewer's noisy samples get more paths, rung by rung
/// up to the ladder's cap, with the renderer kept busy meanwhile; the SMA then says `converged`
/// and asks for nothing more.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_resting_viewer_gets_more_paths_until_converged_then_nothing() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::Noisy).await;
    let mut config = config(vec![renderer], true);
    config.schedule.max_paths = 4 * Quality::INTERACTIVE.paths;
    config.schedule.stats_every = Duration::from_millis(10);
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    let camera = probe.view("front", W, H).await.unwrap();
    probe.complete(camera.seq, WAIT).await.unwrap();
    let stats = probe.until_converged(WAIT).await.unwrap();
    assert!(stats.converged);
    let working: Vec<_> = probe.stats_seen.iter().filter(|s| !s.converged).collect();
    assert!(
        working
            .iter()
            .any(|s| s.renderer_busy > 0.0 && s.paths_per_sec > 0.0),
        "no interval before the end had the renderer busy: {working:?}"
    );
    let last = probe.epochs.last().unwrap();
    assert!(
        last.paths >= last.samples * u64::from(Quality::DIRECT.paths),
        "{} paths for {} samples",
        last.paths,
        last.samples
    );
    let rung = Quality {
        paths: 3 * Quality::INTERACTIVE.paths,
        ..Quality::INTERACTIVE
    };
    let requests: Vec<Quality> = log.lock().unwrap().iter().map(|r| r.1).collect();
    let climbed = requests.iter().filter(|q| **q == rung).count();
    assert!(climbed > 0, "no sample got the ladder's next rung");
    assert!(
        requests.iter().all(|q| q.paths <= rung.paths),
        "a request went past the cap"
    );
    // After the stated end the renderer is left alone: each `Stats` closes an interval of the
    // schedule's turns, and the next ones all find it converged with nothing traced (a request
    // would be outstanding, or answered, within its interval), while the renderer is asked for
    // nothing.
    let settled = log.lock().unwrap().len();
    let (mut quiet, mut working) = (0, Vec::new());
    probe
        .until_stats(WAIT, |s| {
            if s.converged && s.paths_per_sec == 0.0 {
                quiet += 1;
            } else {
                working.push(*s);
            }
            quiet == QUIET_INTERVALS || !working.is_empty()
        })
        .await
        .unwrap();
    assert!(working.is_empty(), "work after convergence: {working:?}");
    assert_eq!(
        log.lock().unwrap().len(),
        settled,
        "requests after convergence"
    );
    sma.stop().await.unwrap();
}

/// Longer than any gap between two cameras of a walk on a loaded machine: a walking camera
/// never rests.
const WALK_REST: Duration = Duration::from_secs(1);

/// A fake renderer's time per thousand paths: 5 M paths a second, a few times a real
/// renderer's rate on two cores, and slow enough that work queues up in the SMA.
const SLOW: Duration = Duration::from_micros(200);

/// A viewer walking slowly to the right from the front viewpoint, as a person does: a camera
/// every 33 ms, its eye and target 5 mm further each step, for `steps` steps, reading what the
/// SMA sends between them (and checking the table at every epoch). Refinement is resumed once
/// the first step's camera is sent, so a camera that waits for rest is never refined before
/// the walk. Returns the most visible leaves an epoch reported meanwhile.
async fn walk_right(probe: &mut Probe, steps: u32) -> u64 {
    let front = probe.scene.viewpoints.iter().find(|v| v.name == "front");
    let front = front.expect("the front viewpoint").clone();
    let mut most = 0;
    for step in 1..=steps {
        let shifted = |p: [f32; 3]| [p[0] + 0.005 * step as f32, p[1], p[2]];
        let at = protocol::types::Viewpoint {
            eye: shifted(front.eye),
            target: shifted(front.target),
            ..front.clone()
        };
        probe
            .camera(Camera::from_viewpoint(&at, 0, W, H))
            .await
            .unwrap();
        if step == 1 {
            probe.send(ViewerToSma::Resume).await.unwrap();
        }
        let next_step = tokio::time::Instant::now() + Duration::from_millis(33);
        while let Ok(epoch) = tokio::time::timeout_at(next_step, probe.next_epoch()).await {
            most = most.max(epoch.unwrap().visible_leaves);
        }
    }
    most
}

/// What one walk showed: the visible leaves before it and the most during it, and the requests
/// made during it.
struct Walked {
    leaves_before: u64,
    most_leaves: u64,
    requests: Vec<(SampleKey, Quality, Option<[f32; 3]>)>,
}

/// Two seconds of [`walk_right`] from the front view, complete and unrefined, with work while
/// walking `on` or off.
async fn walk_for_two_seconds(on: bool) -> Walked {
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::NoisyTaking(SLOW)).await;
    let mut config = config(vec![renderer], true);
    config.schedule.rest = WALK_REST;
    config.schedule.work_while_walking = on;
    config.schedule.coarsen_after_passes = 0;
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    probe.send(ViewerToSma::Pause).await.unwrap();
    let front = view_completely(&mut probe, "front").await;
    let leaves_before = probe.epochs.last().unwrap().visible_leaves;
    assert_eq!(probe.epochs.last().unwrap().camera_seq, front.seq);
    let mark = log.lock().unwrap().len();
    let most_leaves = walk_right(&mut probe, 60).await;
    let requests = log.lock().unwrap()[mark..].to_vec();
    sma.stop().await.unwrap();
    Walked {
        leaves_before,
        most_leaves,
        requests,
    }
}

/// DESIGN.md §3 step 9: a camera that keeps moving (never resting) still gets refinement for
/// what stays in view, and better samples for it: refinement samples, then their paths up to
/// the scene's quality. With work while walking off, refinement waits for a rest that never
/// comes, as in the thesis.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_walking_viewer_gets_refinement_and_better_samples_for_what_stays_in_view() {
    if !gpu_available() {
        return;
    }
    let on = walk_for_two_seconds(true).await;
    assert!(
        on.most_leaves > on.leaves_before,
        "not refined while walking: {} leaves, {} before",
        on.most_leaves,
        on.leaves_before
    );
    // A sample asked for again at more paths: it got better while the camera moved.
    let mut first: HashMap<SampleKey, Quality> = HashMap::new();
    let mut upgraded = 0;
    for (key, quality, _) in &on.requests {
        match first.get(key) {
            Some(q) if q.bounces == quality.bounces => upgraded += 1,
            Some(_) => {}
            None => {
                first.insert(*key, *quality);
            }
        }
    }
    assert!(upgraded > 0, "no sample got more paths while walking");
    let off = walk_for_two_seconds(false).await;
    assert_eq!(
        off.most_leaves, off.leaves_before,
        "refined while walking with work while walking off"
    );
}

/// A new view's missing samples come before every upgrade of what the viewer already had in
/// view, while refinement, top-ups and more paths were going on during the walk (DESIGN.md §3
/// step 9). The wall's back side was never seen before the jump: from its first request on,
/// nothing but first samples (direct light) is asked until the last of its first samples.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_new_views_missing_samples_are_asked_for_before_any_upgrade_of_the_last_view() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::NoisyTaking(SLOW)).await;
    let mut config = config(vec![renderer], true);
    config.schedule.rest = WALK_REST;
    config.schedule.coarsen_after_passes = 0;
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    probe.send(ViewerToSma::Pause).await.unwrap();
    view_completely(&mut probe, "front").await;
    walk_right(&mut probe, 20).await;
    let mark = log.lock().unwrap().len();
    let before: Vec<Quality> = log.lock().unwrap().iter().map(|r| r.1).collect();
    assert!(
        before.iter().any(|q| q.paths > Quality::DIRECT.paths),
        "no upgrade was going on"
    );
    let back = probe.view("back", W, H).await.unwrap();
    probe
        .until(WAIT, |e| e.camera_seq == back.seq && e.shown > 0)
        .await
        .unwrap();
    let settle = tokio::time::Instant::now() + Duration::from_millis(500);
    while let Ok(epoch) = tokio::time::timeout_at(settle, probe.next_epoch()).await {
        epoch.unwrap();
    }
    let after = log.lock().unwrap()[mark..].to_vec();
    let back_side = |r: &(SampleKey, Quality, _)| r.0.side == Side::Back;
    let first = after
        .iter()
        .position(back_side)
        .expect("the back side asked for");
    let last = after
        .iter()
        .rposition(|r| back_side(r) && r.1 == Quality::DIRECT)
        .expect("first samples of the back side");
    let ahead_of_them: Vec<_> = after[first..=last]
        .iter()
        .filter(|r| r.1 != Quality::DIRECT)
        .collect();
    assert!(
        ahead_of_them.is_empty(),
        "{} requests beyond first samples came before the new view's last first sample: {:?}",
        ahead_of_them.len(),
        &ahead_of_them[..ahead_of_them.len().min(5)]
    );
    assert!(
        after[last..].iter().any(|r| r.1 != Quality::DIRECT),
        "the upgrades went on after them"
    );
    sma.stop().await.unwrap();
}

/// The thesis as published, end to end: every request is at the scene's quality preset (no
/// ladder: no direct-light first sample, no more paths for the noise the renderer reports), the
/// viewer is offered the thesis's criteria only and refused `nld-px` without losing its link,
/// L_white is the maximum of what it is shown, and the view still reaches its stated end, the
/// shadow edge refined, and is then left alone.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_thesis_profile_refines_at_fixed_quality_to_its_stated_end() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, log) = fake_renderer(scene.clone(), Fault::Noisy).await;
    let mut config = config(vec![renderer], true);
    config.schedule.criterion = Profile::Thesis.default_criterion();
    let mut config = config.with_profile(Profile::Thesis).unwrap();
    config.schedule.stats_every = Duration::from_millis(10);
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    assert_eq!(
        probe.scene.criteria,
        ["nld-os-thesis", "rnd", "nld-is-thesis", "nld-mm"]
    );
    view_completely(&mut probe, "front").await;
    let stats = probe.until_converged(WAIT).await.unwrap();
    assert!(stats.converged);
    let preset = Quality {
        paths: scene.settings.quality.paths,
        bounces: scene.settings.quality.bounces,
    };
    let requests: Vec<Quality> = log.lock().unwrap().iter().map(|r| r.1).collect();
    assert!(!requests.is_empty());
    assert!(
        requests.iter().all(|q| *q == preset),
        "a request off the preset {preset:?}: {:?}",
        requests.iter().find(|q| **q != preset)
    );
    assert_eq!(repeated_requests(&log), vec![], "a sample shaded twice");
    assert!(
        stats.leaves > scene.mesh.triangles.len() as u64,
        "the shadow edge at x = 0.3 was not refined: {} leaves",
        stats.leaves
    );
    // L_white is the maximum luminance shown (the fake renderer's lit side, 1.0).
    let shown_max = probe
        .table
        .values()
        .flat_map(|t| probe.radiance(t).map(conventions::luminance))
        .fold(0.0, f32::max);
    let l_white = probe.l_white.expect("a tone map");
    assert!(
        (l_white - shown_max).abs() <= 1e-6 * shown_max,
        "{l_white} against {shown_max}"
    );
    // After the stated end nothing more is asked: no further paths for the reported noise.
    let settled = log.lock().unwrap().len();
    let mut quiet = 0;
    probe
        .until_stats(WAIT, |s| {
            quiet += usize::from(s.converged && s.paths_per_sec == 0.0);
            quiet == QUIET_INTERVALS || !s.converged
        })
        .await
        .unwrap();
    assert_eq!(quiet, QUIET_INTERVALS, "work after the stated end");
    assert_eq!(log.lock().unwrap().len(), settled, "requests after the end");
    // `nld-px` is refused with an error, and the link stays.
    probe
        .send(ViewerToSma::SetCriterion {
            name: "nld-px".into(),
        })
        .await
        .unwrap();
    let refused = tokio::time::timeout(WAIT, async {
        loop {
            match probe.read().await.unwrap() {
                SmaToViewer::Error { message } => return message,
                _ => continue,
            }
        }
    })
    .await
    .unwrap();
    assert!(refused.contains("nld-px"), "{refused}");
    assert_eq!(next_criterion(&mut probe).await, "nld-os-thesis", "kept");
    // `nld-is` runs as the thesis has it.
    probe
        .send(ViewerToSma::SetCriterion {
            name: "nld-is".into(),
        })
        .await
        .unwrap();
    assert_eq!(next_criterion(&mut probe).await, "nld-is-thesis");
    sma.stop().await.unwrap();
}

/// The criterion the next `Refinement` reply names, read off the link.
async fn next_criterion(probe: &mut Probe) -> String {
    tokio::time::timeout(WAIT, async {
        loop {
            if let SmaToViewer::Refinement { criterion, .. } = probe.read().await.unwrap() {
                return criterion;
            }
        }
    })
    .await
    .unwrap()
}

/// A reply with one NaN point keeps its other points; that point is asked for again, a few
/// times, then given up on, and its triangles are shown with their other vertices' radiance,
/// never black.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_nan_point_is_asked_again_and_never_shown_black() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    // A corner of the wall, seen from the front.
    let poisoned = scene.mesh.triangles[2].vertices[0];
    let (renderer, log) = fake_renderer(scene.clone(), Fault::NanAt(poisoned)).await;
    let (sma, mut probe) = start_with_probe(&config(vec![renderer], false), &scene).await;
    let camera = probe.view("front", W, H).await.unwrap();
    probe.complete(camera.seq, WAIT).await.unwrap();
    let asked = log
        .lock()
        .unwrap()
        .iter()
        .filter(|r| r.0.vertex == poisoned)
        .count();
    assert!(
        (3..=6).contains(&asked),
        "the NaN point was asked for {asked} times"
    );
    assert!(!probe.table.is_empty());
    for t in probe.table.values() {
        for rgb in probe.radiance(t) {
            assert!(
                rgb.iter().all(|c| c.is_finite()) && rgb.iter().any(|&c| c > 0.0),
                "a shown vertex is {rgb:?}"
            );
        }
    }
    let differs = differing(
        &scene_coverage(&scene, &camera),
        &shown_coverage(&scene, &probe, &camera),
    );
    assert_eq!(differs, 0, "every visible triangle is shown");
    sma.stop().await.unwrap();
}

/// Follows `probe`'s epochs until `done`, checking at every one, not only the idle ones, that the
/// table is a conforming set (no overlap, no T-junction) and, from the first epoch in which
/// `camera`'s view was complete on, that it covers what the base mesh covers from there
/// (DESIGN.md §3 step 6, §4: the viewer never shows a hole).
async fn epochs_without_holes(
    probe: &mut Probe,
    scene: &Scene,
    camera: &Camera,
    mut done: impl FnMut(&protocol::viewer_link::Epoch) -> bool,
) -> protocol::viewer_link::Epoch {
    let want = scene_coverage(scene, camera);
    let mut complete = false;
    loop {
        let epoch = tokio::time::timeout(WAIT, probe.next_epoch())
            .await
            .expect("an epoch")
            .unwrap();
        if let Some(problem) = probe.conformity_problem() {
            panic!("not conforming at {epoch:?}: {problem}");
        }
        complete |= epoch.camera_seq == camera.seq && epoch.outstanding == 0;
        if complete {
            let holes = differing(&want, &shown_coverage(scene, probe, camera));
            // As above: a few edge pixels of midpoints rounded to f32 may flip.
            assert!(
                holes <= (W * H) as usize / 1000,
                "{holes} pixels differ from the visible surface at {epoch:?}"
            );
        }
        if epoch.camera_seq == camera.seq && done(&epoch) {
            return epoch;
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_holes_at_any_epoch_while_refining_moving_and_coarsening() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![renderer], true);
    config.schedule.coarsen_after_passes = 3;
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    let front = probe.view("front", W, H).await.unwrap();
    let refined = epochs_without_holes(&mut probe, &scene, &front, |e| {
        e.outstanding == 0 && e.shown >= 40
    })
    .await;
    // Moving while refining: the side view refines on from what the front view left.
    let side = probe.view("side", W, H).await.unwrap();
    epochs_without_holes(&mut probe, &scene, &side, |e| {
        e.outstanding == 0 && e.shown > refined.shown
    })
    .await;
    // Looking away long enough coarsens everything back to the base mesh ...
    probe.send(ViewerToSma::Pause).await.unwrap();
    for _ in 0..4 {
        let away = probe.view("away", W, H).await.unwrap();
        epochs_without_holes(&mut probe, &scene, &away, |e| e.outstanding == 0).await;
    }
    let back = probe.view("front", W, H).await.unwrap();
    let coarse = epochs_without_holes(&mut probe, &scene, &back, |e| e.outstanding == 0).await;
    assert_eq!(coarse.shown, 4, "coarsened back to the base mesh");
    // ... and refinement starts again from there.
    probe.send(ViewerToSma::Resume).await.unwrap();
    epochs_without_holes(&mut probe, &scene, &back, |e| {
        e.outstanding == 0 && e.shown >= 40
    })
    .await;
    sma.stop().await.unwrap();
}

fn black(_: Vec3, _: Side, _: Quality, _: Option<Vec3>) -> [f32; 3] {
    [0.0; 3]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_all_black_scene_is_shown_black_under_every_criterion_without_a_stall() {
    if !gpu_available() {
        return;
    }
    // L_max = 0: eq. 4.3 divides by L_max², the tone map by log(1 + L_white).
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer::start(scene.clone(), black, Fault::None).await;
    let (sma, mut probe) = start_with_probe(&config(vec![renderer], true), &scene).await;
    for criterion in probe.scene.criteria.clone() {
        probe
            .send(ViewerToSma::SetCriterion { name: criterion })
            .await
            .unwrap();
        // Each view is answered in full while refinement runs on black samples.
        for name in ["front", "side"] {
            view_completely(&mut probe, name).await;
        }
        assert!(
            probe
                .table
                .values()
                .all(|t| probe.radiance(t) == [[0.0; 3]; 3])
        );
        assert!(probe.conformity_problem().is_none());
    }
    assert_eq!(probe.l_white, None, "no white point of 0 is ever sent");
    sma.stop().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cameras_at_the_extremes_are_answered_in_full() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let (sma, mut probe) = start_with_probe(&config(vec![renderer], true), &scene).await;
    let at = |eye: [f32; 3], target: [f32; 3], fov_y_deg: f32| protocol::types::Viewpoint {
        name: String::new(),
        eye,
        target,
        up: [0.0, 1.0, 0.0],
        fov_y_deg,
    };
    let cameras = [
        // fov at 1° and at 170°.
        at([0.3, 1.2, 4.0], [0.0, 0.8, 0.0], 1.0),
        at([0.3, 1.2, 4.0], [0.0, 0.8, 0.0], 170.0),
        // On the wall's surface, looking along it and away from it.
        at([0.0, 1.0, 0.0], [1.0, 1.0, 0.0], 60.0),
        at([0.0, 1.0, 0.0], [0.0, 1.0, 4.0], 60.0),
        // On the floor, and under it (inside the ground) looking up through it.
        at([0.5, 0.0, 2.0], [0.0, 0.8, 0.0], 60.0),
        at([0.5, -0.5, 2.0], [0.0, 0.8, 0.0], 60.0),
    ];
    for viewpoint in cameras {
        let camera = probe
            .camera(Camera::from_viewpoint(&viewpoint, 0, W, H))
            .await
            .unwrap();
        let epoch = probe
            .complete(camera.seq, WAIT)
            .await
            .unwrap_or_else(|e| panic!("{viewpoint:?}: {e:#}"));
        assert!(
            probe.conformity_problem().is_none(),
            "{viewpoint:?}: {epoch:?}"
        );
    }
    sma.stop().await.unwrap();
}

/// A run of the wall refined to its stated end under `budget` bytes (`--memory-mib`), eight
/// selections a round so a round's growth is small beside the wall's mesh: every `Stats` seen.
async fn refined_under(budget: usize) -> Vec<protocol::viewer_link::Stats> {
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![renderer], true);
    config.schedule.memory_budget_bytes = budget;
    config.schedule.max_selections = 8;
    config.schedule.stats_every = Duration::from_millis(10);
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    view_completely(&mut probe, "front").await;
    probe.until_converged(WAIT).await.unwrap();
    sma.stop().await.unwrap();
    std::mem::take(&mut probe.stats_seen)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_run_under_a_small_budget_stays_under_it_and_says_it_is_memory_bound() {
    if !gpu_available() {
        return;
    }
    let unbounded = refined_under(1 << 30).await;
    let peak = |stats: &[protocol::viewer_link::Stats]| {
        stats
            .iter()
            .map(|s| s.memory.accounted_bytes())
            .max()
            .unwrap()
    };
    let leaves = |stats: &[protocol::viewer_link::Stats]| stats.last().unwrap().leaves;
    assert!(unbounded.iter().all(|s| !s.memory.memory_bound));
    let first = unbounded[0].memory;
    let grown = peak(&unbounded) - first.accounted_bytes();
    // Half of what refinement added to the unbounded run (the view's pixels are most of the
    // rest, at this image size), so the budget must stop refinement.
    let budget = (peak(&unbounded) - grown / 2) as usize;
    let bounded = refined_under(budget).await;
    for s in &bounded {
        assert!(
            s.memory.accounted_bytes() <= budget as u64,
            "over the budget of {budget}: {:?}",
            s.memory
        );
        assert_eq!(s.memory.budget_bytes, budget as u64);
    }
    assert!(
        bounded.iter().any(|s| s.memory.memory_bound),
        "never said memory-bound"
    );
    assert!(leaves(&bounded) < leaves(&unbounded));
}

/// The wall refined from the front to its stated end, then out of view until its subdivision is
/// collapsed, three times over: the removed nodes are reused (the mesh's nodes do not grow past
/// the second time), and the viewer's table stays consistent at every epoch (the probe fails on
/// an insert of a shown id or a remove of an unknown one) and conforming (a reused id still
/// showing its old triangle would overlap the new ones).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn reused_node_ids_keep_the_viewers_table_consistent_at_every_epoch() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let mut config = config(vec![renderer], true);
    config.schedule.coarsen_after_passes = 2;
    config.schedule.stats_every = Duration::from_millis(10);
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    let mut nodes = Vec::new();
    for _ in 0..3 {
        view_completely(&mut probe, "front").await;
        probe.until_converged(WAIT).await.unwrap();
        assert!(probe.table.len() >= 12, "refined");
        assert_eq!(probe.conformity_problem(), None);
        nodes.push(probe.stats.unwrap().memory.nodes_bytes);
        for _ in 0..4 {
            let away = probe.view("away", W, H).await.unwrap();
            let epoch = probe.complete(away.seq, WAIT).await.unwrap();
            assert_eq!(epoch.shown, 0, "something is in view looking away");
        }
    }
    assert!(nodes[2] <= nodes[1], "nodes grew: {nodes:?}");
    sma.stop().await.unwrap();
}

/// With a cache file, the wall's subdivision out of view long enough goes to the file rather
/// than being coarsened away (`cache_file::evict`): while it is out of view the leaves and the
/// cached samples fall, and looking back loads it again, the leaves shown as before.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn subdivision_out_of_view_goes_to_the_cache_file_and_comes_back() {
    if !gpu_available() {
        return;
    }
    let scene = diffuse_wall();
    let (renderer, _) = fake_renderer(scene.clone(), Fault::None).await;
    let dir = tempfile::tempdir().unwrap();
    let mut config = config(vec![renderer], true);
    config.schedule.coarsen_after_passes = 2;
    config.schedule.stats_every = Duration::from_millis(10);
    config.cache_file = Some(sma::cache_file::CacheFileConfig::at(
        dir.path().join("wall.redb"),
    ));
    let (sma, mut probe) = start_with_probe(&config, &scene).await;
    view_completely(&mut probe, "front").await;
    probe.until_converged(WAIT).await.unwrap();
    let (refined, shown) = (probe.stats.unwrap(), probe.table.len());
    assert!(shown >= 12, "refined");
    for _ in 0..6 {
        let away = probe.view("away", W, H).await.unwrap();
        probe.complete(away.seq, WAIT).await.unwrap();
    }
    // The subdivision leaves once the writer's commit holding it is in the file.
    let away = probe
        .until_stats(WAIT, |s| s.leaves < refined.leaves)
        .await
        .unwrap_or_else(|e| panic!("{e:#}: refined {refined:?}"));
    assert!(
        away.cached_samples < refined.cached_samples,
        "{away:?}, refined {refined:?}"
    );
    view_completely(&mut probe, "front").await;
    probe.until_converged(WAIT).await.unwrap();
    assert_eq!(probe.table.len(), shown);
    assert_eq!(probe.conformity_problem(), None);
    sma.stop().await.unwrap();
}
