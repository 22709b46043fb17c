//! The SMA's cache file with real processes (DESIGN.md §5, persistence): `walkthrough sma
//! --cache-file PATH` saves what it learnt, is killed, and a new SMA on the same file shows the
//! same leaves, every one with its samples, before any renderer answers (there is none), but
//! for guards of its view whose hidden corners the first never sampled; a file of another scene
//! is refused with one warning and set aside as `PATH.rejected`; a file another SMA holds is left
//! alone with one warning, and the SMA serves without it; a disk that fills during the saves
//! costs the file its later saves, with one warning, and the view nothing. Needs a wgpu adapter
//! for the SMA's visibility: without one the tests say so and return, unless
//! `WALKTHROUGH_REQUIRE_GPU` is set.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use protocol::viewer_link::ViewerToSma;
use sma::visibility::Gpu;
use testkit::child::{Server, start_renderer, start_server, start_sma, strings};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const W: u32 = 256;
const H: u32 = 192;
const WAIT: Duration = Duration::from_secs(120);
/// The SMA saves this often here, so a kill after a few periods finds everything saved.
const SAVE_PERIOD: Duration = Duration::from_millis(500);
/// Where writes start to fail once the disk is full: past the log's first lines, before any
/// page the cache file's next commits would write.
const FULL_FILE_CAP: u64 = 64 << 10;
/// The SMA's one warning when a save fails.
const FAILED_SAVE: &str = "saving the cache file failed";

fn exe() -> &'static Path {
    Path::new(env!("CARGO_BIN_EXE_walkthrough"))
}

/// An SMA for `scene` keeping its cache in `file`, logging to `log`; without renderers, a port
/// for them that none joins.
fn sma(scene: &str, file: &Path, renderers: &[SocketAddr], log: &Path) -> Server {
    let mut flags = cache_file_flags(file);
    if renderers.is_empty() {
        flags.extend(strings(&["--renderer-listen", "127.0.0.1:0"]));
    }
    start_sma(exe(), scene, renderers, &flags, Some(log))
        .unwrap_or_else(|e| panic!("sma for {scene}: {e:#}"))
}

/// An SMA's flags for keeping its cache in `file`, saved every [`SAVE_PERIOD`].
fn cache_file_flags(file: &Path) -> Vec<String> {
    strings(&[
        "--stats-secs",
        "60",
        "--cache-file",
        &file.to_string_lossy(),
        "--cache-file-save-s",
        &SAVE_PERIOD.as_secs_f64().to_string(),
    ])
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

/// A view shown before a restart and after it: the first SMA's view was carried over from
/// round to round, the second's is drawn afresh, so they differ by slivers on the rasteriser's
/// sub-pixel grid (`visibility::carry_over`), never by more than a thousandth of the leaves here.
fn assert_nearly_the_same_leaves(before: &BTreeSet<Vec<u32>>, after: &BTreeSet<Vec<u32>>) {
    let (lost, new) = (
        before.difference(after).count(),
        after.difference(before).count(),
    );
    assert!(
        lost + new <= before.len() / 1000,
        "the same leaves as before the restart: {} before, {} after, {lost} lost, {new} new",
        before.len(),
        after.len()
    );
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
    // A guard of today's view (no pixels) whose hidden corner the first SMA's view never asked
    // for waits for a renderer (`pending::Group::waits_for_guards`); everything else is shown.
    let unshown = restored.visible_leaves - restored.shown;
    assert!(
        unshown <= restored.visible_leaves / 1000,
        "every visible leaf is shown, with its samples from the file: {} of {}\n{log}",
        restored.shown,
        restored.visible_leaves
    );
    assert_nearly_the_same_leaves(&before, &shown(&probe));
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

/// Bracara's other views one after another, each refined until every visible leaf is shown
/// and nothing is outstanding, while the file's size is capped (`FULL_FILE_CAP`): whether a
/// save failed, its saves given a few periods to catch up after each view, and a view after it
/// still came whole.
async fn views_after_a_full_disk(probe: &mut Probe, log: &impl Fn() -> String) -> bool {
    let failed = || count(&log(), FAILED_SAVE) > 0;
    let mut failed_before = false;
    for view in ["MC", "VR", "VT"] {
        let camera = probe.view(view, W, H).await.unwrap();
        probe
            .until(WAIT, |e| {
                e.camera_seq == camera.seq && e.outstanding == 0 && e.shown == e.visible_leaves
            })
            .await
            .unwrap_or_else(|e| panic!("{view}: {e:#}\n{}", log()));
        if failed_before {
            return true;
        }
        tokio::time::sleep(4 * SAVE_PERIOD).await;
        failed_before = failed();
    }
    false
}

/// `walkthrough sma` as [`sma`] starts it, through a shell that makes it ignore SIGXFSZ: once
/// its file size is capped (`Process::cap_file_size`), a write past the cap fails (EFBIG), as a
/// write to a full disk does (ENOSPC), instead of ending the process.
fn sma_ignoring_file_size_signals(
    scene: &str,
    file: &Path,
    renderers: &[SocketAddr],
    log: &Path,
) -> Server {
    let script = "trap '' XFSZ; exec \"$0\" \"$@\"";
    let mut args = strings(&["-c", script, &exe().to_string_lossy(), "sma"]);
    args.extend(strings(&["--scene", scene, "--listen", "127.0.0.1:0"]));
    args.extend(cache_file_flags(file));
    for renderer in renderers {
        args.extend(["--renderer".to_string(), renderer.to_string()]);
    }
    start_server(Path::new("/bin/bash"), "sma", &args, Some(log))
        .unwrap_or_else(|e| panic!("sma ignoring SIGXFSZ: {e:#}"))
}

/// The disk fills once the SMA has saved a first view: the first save of the next views that no
/// longer fits fails with one warning, the views go on refining and show every leaf, and the
/// file keeps its last good commit, which a new SMA opens and shows from.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_during_saves_costs_the_file_its_news_and_the_view_nothing() {
    let Some(_gpu) = gpu_or_skip(Gpu::new()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bracara.redb");
    let renderer = start_renderer(exe(), "bracara", Some(1), None).unwrap();
    let capped = sma_ignoring_file_size_signals(
        "bracara",
        &file,
        &[renderer.addr],
        &dir.path().join("capped.log"),
    );
    let log = || capped.process.log_text();
    let mut probe = Probe::connect(&capped.addr.to_string()).await.unwrap();
    probe.view("VT", W, H).await.unwrap();
    probe.until_converged(WAIT).await.unwrap();
    // The saves catch up (no epoch ends the wait); the probe's table holds the last leaves.
    let _ = probe.until(Duration::from_secs(4), |_| false).await;
    let first_view = shown(&probe);
    assert_eq!(count(&log(), FAILED_SAVE), 0, "{}", log());
    // The disk is full, and so is the file: no page of it is free for the next commits. (Capped
    // at its size, the file's free pages took the next views' saves whole in some runs.) The
    // cap leaves room for the log's few lines.
    let saved = std::fs::metadata(&file).unwrap().len();
    capped.process.cap_file_size(FULL_FILE_CAP).unwrap();

    // The next views' saves no longer fit once they outgrow the pages the file had free; the
    // views carry on, every visible leaf shown, also after a save failed.
    assert!(
        views_after_a_full_disk(&mut probe, &log).await,
        "no save failed past {FULL_FILE_CAP} bytes:\n{}",
        log()
    );
    assert_eq!(count(&log(), FAILED_SAVE), 1, "one warning:\n{}", log());
    let size = std::fs::metadata(&file).unwrap().len();
    assert!(
        size <= saved,
        "the file grew past the full disk: {saved} → {size} bytes"
    );
    assert_eq!(count(&log(), "panicked"), 0, "{}", log());
    drop(probe);
    drop(capped);

    // The last good commit opens: the first view comes back, without a renderer. (Not every
    // leaf of it: the second view's first saves, which fitted, hold base triangles it shares
    // with the first, split further and waiting for samples.)
    let second = sma("bracara", &file, &[], &dir.path().join("second.log"));
    let mut probe = Probe::connect(&second.addr.to_string()).await.unwrap();
    probe.send(ViewerToSma::Pause).await.unwrap();
    let camera = probe.view("VT", W, H).await.unwrap();
    let restored = probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.shown > 0)
        .await
        .unwrap_or_else(|e| panic!("{e:#}\n{}", second.process.log_text()));
    let log_text = second.process.log_text();
    assert_eq!(count(&log_text, "cache file refused"), 0, "{log_text}");
    assert_eq!(restored.samples, 0, "nothing traced: no renderer");
    let back = shown(&probe);
    let kept = back.intersection(&first_view).count();
    assert!(
        kept > 0,
        "the first view's leaves come back: {kept} of {} shown",
        back.len()
    );
}
