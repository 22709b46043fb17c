//! The SMA's cache file with real processes (DESIGN.md §5, persistence): `walkthrough sma
//! --cache-file PATH` saves what it learnt, is killed, and a new SMA on the same file shows the
//! same leaves, every one with its samples, before any renderer answers (there is none); a file
//! of another scene is refused with one warning and set aside as `PATH.rejected`; a file another
//! SMA holds is left alone with one warning, and the SMA serves without it. Needs a wgpu adapter
//! for the SMA's visibility: without one the tests say so and return, unless
//! `WALKTHROUGH_REQUIRE_GPU` is set.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use protocol::viewer_link::ViewerToSma;
use sma::visibility::Gpu;
use testkit::child::{Server, start_renderer, start_sma, strings};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const W: u32 = 256;
const H: u32 = 192;
const WAIT: Duration = Duration::from_secs(120);
/// The SMA saves this often here, so a kill after a few periods finds everything saved.
const SAVE_EVERY_S: &str = "0.5";

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_walkthrough"))
}

/// An SMA for `scene` keeping its cache in `file`, logging to `log`; without renderers, a port
/// for them that none joins.
fn sma(scene: &str, file: &Path, renderers: &[SocketAddr], log: &Path) -> Server {
    let mut flags = strings(&[
        "--stats-secs",
        "60",
        "--cache-file",
        &file.to_string_lossy(),
        "--cache-file-save-s",
        SAVE_EVERY_S,
    ]);
    if renderers.is_empty() {
        flags.extend(strings(&["--renderer-listen", "127.0.0.1:0"]));
    }
    start_sma(exe(), scene, renderers, &flags, Some(log))
        .unwrap_or_else(|e| panic!("sma for {scene}: {e:#}"))
}

/// The probe's shown triangles by their corners' bits: what a viewer shows, whatever the ids.
fn shown(probe: &Probe) -> BTreeSet<Vec<u32>> {
    probe
        .triangles()
        .iter()
        .map(|t| {
            t.iter()
                .flat_map(|v| v.to_array().map(f32::to_bits))
                .collect()
        })
        .collect()
}

fn count(text: &str, words: &str) -> usize {
    text.lines().filter(|l| l.contains(words)).count()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_killed_sma_restarts_showing_what_it_had_saved_without_a_renderer() {
    let Some(_gpu) = gpu_or_skip(Gpu::new()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("cornell.redb");
    let renderer = start_renderer(exe(), "cornell", Some(1), None).unwrap();
    let mut first = sma(
        "cornell",
        &file,
        &[renderer.addr],
        &dir.path().join("first.log"),
    );
    let mut probe = Probe::connect(&first.addr.to_string()).await.unwrap();
    probe.send(ViewerToSma::Pause).await.unwrap();
    let camera = probe.view("main", W, H).await.unwrap();
    let unrefined = probe.complete(camera.seq, WAIT).await.unwrap();
    probe.send(ViewerToSma::Resume).await.unwrap();
    probe
        .until(WAIT, |e| {
            e.outstanding == 0 && e.shown >= 2 * unrefined.shown
        })
        .await
        .unwrap();
    // No more refinement: the leaves stay as they are while the saves catch up. The probe reads
    // meanwhile (no epoch ends the wait), so its table holds the last of them.
    probe.send(ViewerToSma::Pause).await.unwrap();
    let _ = probe.until(Duration::from_secs(8), |_| false).await;
    let before = shown(&probe);
    drop(probe);
    first.process.kill();

    let second = sma("cornell", &file, &[], &dir.path().join("second.log"));
    let mut probe = Probe::connect(&second.addr.to_string()).await.unwrap();
    probe.send(ViewerToSma::Pause).await.unwrap();
    let camera = probe.view("main", W, H).await.unwrap();
    let restored = probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.shown > 0)
        .await
        .unwrap();
    let log = second.process.log_text();
    assert_eq!(
        restored.samples, 0,
        "nothing was traced: there is no renderer"
    );
    assert_eq!(
        restored.shown, restored.visible_leaves,
        "every visible leaf is shown, with its samples from the file:\n{log}"
    );
    let after = shown(&probe);
    let (lost, new) = (
        before.difference(&after).count(),
        after.difference(&before).count(),
    );
    // The first SMA's view was carried over from round to round, the second's is drawn afresh:
    // they differ by slivers on the rasteriser's sub-pixel grid (`visibility::carry_over`),
    // never by more than a thousandth of the leaves here.
    assert!(
        lost + new <= before.len() / 1000,
        "the same leaves as before the kill: {} before, {} after, {lost} lost, {new} new",
        before.len(),
        after.len()
    );
    assert_eq!(count(&log, "cache file refused"), 0, "{log}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_held_file_is_left_alone_and_a_foreign_one_is_refused_and_renamed() {
    let Some(_gpu) = gpu_or_skip(Gpu::new()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("site.redb");
    let rejected = PathBuf::from(format!("{}.rejected", file.display()));
    let mut holder = sma("cornell", &file, &[], &dir.path().join("holder.log"));

    // A second SMA on the same file: one warning, and it serves without the file.
    let second = sma("cornell", &file, &[], &dir.path().join("second.log"));
    let mut probe = Probe::connect(&second.addr.to_string()).await.unwrap();
    let camera = probe.view("main", W, H).await.unwrap();
    probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.visible_leaves > 0)
        .await
        .unwrap();
    let log = second.process.log_text();
    assert_eq!(count(&log, "another SMA has it open"), 1, "{log}");
    assert!(!rejected.exists(), "a held file is not refused");
    drop(probe);
    drop(second);
    holder.process.kill();

    // The file is cornell's: an SMA of another scene refuses it, once, and starts empty.
    let other = sma("bracara", &file, &[], &dir.path().join("other.log"));
    let mut probe = Probe::connect(&other.addr.to_string()).await.unwrap();
    let camera = probe.view("VT", W, H).await.unwrap();
    let epoch = probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.visible_leaves > 0)
        .await
        .unwrap();
    let log = other.process.log_text();
    assert_eq!(count(&log, "cache file refused"), 1, "{log}");
    assert_eq!(count(&log, "another scene"), 1, "{log}");
    assert!(rejected.exists(), "set aside as .rejected");
    assert!(file.exists(), "a fresh file in its place");
    assert_eq!(
        epoch.shown, 0,
        "an empty cache: nothing to show without a renderer"
    );
}
