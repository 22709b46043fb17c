//! The SMA with real processes over loopback: `walkthrough renderer serve` ×2 and
//! `walkthrough sma`, driven by the scripted viewer of `testkit::probe`, which fails on any
//! inconsistency of its triangle table (duplicate insert, unknown remove or update, an epoch
//! whose count disagrees). Needs a wgpu adapter for the SMA's visibility (Mesa without a GPU):
//! without one the tests say so and return, unless `WALKTHROUGH_REQUIRE_GPU` is set.

use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use glam::Vec3;
use sma::visibility::{Gpu, coverage};
use testkit::child::{Process, start_renderer, start_sma, strings};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const W: u32 = 256;
const H: u32 = 192;
const WAIT: Duration = Duration::from_secs(120);

fn gpu() -> Option<Gpu> {
    gpu_or_skip(Gpu::new())
}

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_walkthrough"))
}

/// A renderer on one thread, and its address.
fn renderer(scene: &str) -> (Process, String) {
    let server = start_renderer(exe(), scene, Some(1), None)
        .unwrap_or_else(|e| panic!("renderer for {scene}: {e:#}"));
    (server.process, server.addr.to_string())
}

/// An SMA on `renderers` with more `extra` flags, and its viewer address.
fn sma(scene: &str, renderers: &[&str], extra: &[&str]) -> (Process, String) {
    let renderers: Vec<SocketAddr> = renderers.iter().map(|r| r.parse().unwrap()).collect();
    let mut flags = strings(&["--stats-secs", "60"]);
    flags.extend(strings(extra));
    let server = start_sma(exe(), scene, &renderers, &flags, None)
        .unwrap_or_else(|e| panic!("sma for {scene}: {e:#}"));
    (server.process, server.addr.to_string())
}

/// Pixels whose coverage differs between the probe's table and the scene's base mesh.
fn coverage_difference(gpu: &Gpu, probe: &Probe, camera: &protocol::viewer_link::Camera) -> usize {
    let scene = scene::load(&probe.scene.name).unwrap();
    let base: Vec<[Vec3; 3]> = (0..scene.mesh.triangles.len())
        .map(|t| scene.mesh.triangle_positions(t))
        .collect();
    let bounds = probe.bounds();
    let want = coverage(gpu, &base, camera, bounds).unwrap();
    let have = coverage(gpu, &probe.triangles(), camera, bounds).unwrap();
    want.iter().zip(&have).filter(|(a, b)| a != b).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refinement_keeps_the_table_consistent_and_the_visible_surface_covered() {
    let Some(gpu) = gpu() else { return };
    let (_r, raddr) = renderer("cornell");
    let (_s, saddr) = sma("cornell", &[&raddr], &["--criterion", "nld-os"]);
    let mut probe = Probe::connect(&saddr).await.unwrap();
    probe
        .send(protocol::viewer_link::ViewerToSma::Pause)
        .await
        .unwrap();
    let camera = probe.view("main", W, H).await.unwrap();
    let first = probe.complete(camera.seq, WAIT).await.unwrap();
    assert_eq!(
        coverage_difference(&gpu, &probe, &camera),
        0,
        "unrefined: shown = visible surface"
    );
    assert!(probe.overlaps().is_empty());
    assert!(probe.l_white.is_some_and(|l| l > 0.0), "a ToneMap came");

    probe
        .send(protocol::viewer_link::ViewerToSma::Resume)
        .await
        .unwrap();
    let refined = probe
        .until(WAIT, |e| e.outstanding == 0 && e.shown >= 8 * first.shown)
        .await
        .unwrap();
    assert!(
        probe.overlaps().is_empty(),
        "shown leaves overlap at {refined:?}"
    );
    let diff = coverage_difference(&gpu, &probe, &camera);
    assert!(
        diff <= (W * H) as usize / 1000,
        "{diff} pixels of coverage changed with refinement"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_of_two_renderers_killed_loses_no_request_and_two_viewers_agree() {
    let Some(gpu) = gpu() else { return };
    let (mut doomed, a) = renderer("bracara");
    let (_b, b) = renderer("bracara");
    // The ladder ends at the scene's quality: once the first viewer's picture is complete,
    // no more paths change what it shows while the second viewer's comes in. The indirect
    // filter is off: with it, the samples the second view adds are neighbours that change what
    // the first viewer is shown, which reaches it only at its next sync.
    let (_s, saddr) = sma(
        "bracara",
        &[&a, &b],
        &[
            "--no-refine",
            "--batch-points",
            "8",
            "--max-paths",
            "64",
            "--indirect-filter",
            "off",
        ],
    );
    let mut one = Probe::connect(&saddr).await.unwrap();
    let camera = one.view("VT", W, H).await.unwrap();
    // Kill one renderer once shading has begun, while it holds batches.
    one.until(WAIT, |e| e.samples > 0).await.unwrap();
    doomed.kill();
    let done = one.complete(camera.seq, WAIT).await.unwrap();
    assert!(
        one.epochs.iter().any(|e| e.samples < done.samples / 2),
        "killed before most shading"
    );
    assert_eq!(
        coverage_difference(&gpu, &one, &camera),
        0,
        "every visible triangle is shown"
    );

    // A second viewer with another camera gets the same radiance for what both show.
    let mut two = Probe::connect(&saddr).await.unwrap();
    let mut other = camera.clone();
    other.eye[0] += 0.1;
    let other = two.camera(other).await.unwrap();
    two.complete(other.seq, WAIT).await.unwrap();
    let common: Vec<_> = one
        .table
        .keys()
        .filter(|id| two.table.contains_key(id))
        .copied()
        .collect();
    assert!(!common.is_empty());
    for id in common {
        assert_eq!(one.table[&id].shading, two.table[&id].shading);
    }
}
