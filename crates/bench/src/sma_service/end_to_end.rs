//! End-to-end figures with real processes: one `renderer serve` (all cores) and one `sma`,
//! started from the `walkthrough` binary that runs this benchmark, and the scripted viewer of
//! `testkit::probe` at 1024×768:
//! - first complete picture from an empty cache: every visible triangle shown (direct-light
//!   quality or better), then every sample at the scene's quality (`outstanding == 0`);
//! - camera change to the viewer's matching `Epoch`, every sample cached;
//! - the SMA's memory per leaf during a long refinement (its own stats line: mesh + cache).

use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use testkit::child::{Process, start_renderer, start_sma, strings};
use testkit::probe::Probe;

use crate::stats::median;

const WIDTH: u32 = 1024;
const HEIGHT: u32 = 768;
const WAIT: Duration = Duration::from_secs(600);

pub fn section(quick: bool) -> anyhow::Result<String> {
    let Ok(exe) = crate::product::walkthrough_exe() else {
        return Ok(
            "End-to-end figures: run after `cargo build --release --workspace` (it starts the \
                   renderer and SMA processes).\n\n"
                .into(),
        );
    };
    // Sponza when its files are there (DESIGN.md §11), else the built-in town.
    let (scene, view, other) = if scene::load("scenes/sponza.toml").is_ok() {
        ("scenes/sponza.toml", "S1", "S2")
    } else {
        ("bracara", "VT", "VR")
    };
    let logs = std::env::temp_dir().join(format!("walkthrough-bench-{}", std::process::id()));
    std::fs::create_dir_all(&logs)?;
    let runtime = tokio::runtime::Runtime::new()?;
    let mut md = String::new();
    runtime.block_on(latencies(&exe, &logs, scene, view, other, quick, &mut md))?;
    runtime.block_on(memory_per_leaf(&exe, &logs, scene, view, quick, &mut md))?;
    let _ = std::fs::remove_dir_all(&logs);
    Ok(md)
}

/// A renderer and an SMA with `sma_flags`, as child processes logging into `logs`; the SMA's
/// viewer address.
fn system(
    exe: &Path,
    logs: &Path,
    scene: &str,
    sma_flags: &[&str],
) -> anyhow::Result<(Process, Process, String)> {
    let log = |name: &str| -> PathBuf { logs.join(format!("{name}.log")) };
    let renderer = start_renderer(exe, scene, None, Some(&log("renderer")))?;
    let _ = std::fs::remove_file(log("sma"));
    let flags = strings(sma_flags);
    let sma = start_sma(exe, scene, &[renderer.addr], &flags, Some(&log("sma")))?;
    Ok((renderer.process, sma.process, sma.addr.to_string()))
}

async fn latencies(
    exe: &Path,
    logs: &Path,
    scene: &str,
    view: &str,
    other: &str,
    quick: bool,
    md: &mut String,
) -> anyhow::Result<()> {
    let (_renderer, _sma, addr) = system(exe, logs, scene, &["--no-refine"])?;
    let mut probe = Probe::connect(&addr).await?;
    let t0 = Instant::now();
    let camera = probe.view(view, WIDTH, HEIGHT).await?;
    let seq = camera.seq;
    let all_shown = probe
        .until(WAIT, |e| e.camera_seq == seq && e.shown == e.visible_leaves)
        .await?;
    let t_direct = t0.elapsed().as_secs_f64();
    let complete = match all_shown.outstanding {
        0 => all_shown,
        _ => probe.complete(seq, WAIT).await?,
    };
    let t_full = t0.elapsed().as_secs_f64();
    // Both views cached, then camera changes back and forth.
    let o = probe.view(other, WIDTH, HEIGHT).await?;
    probe.complete(o.seq, WAIT).await?;
    let mut times = Vec::new();
    let mut complete_answers = 0;
    for i in 0..if quick { 4 } else { 10 } {
        let name = if i % 2 == 0 { view } else { other };
        let t = Instant::now();
        let c = probe.view(name, WIDTH, HEIGHT).await?;
        let answer = probe.until(WAIT, |e| e.camera_seq == c.seq).await?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        complete_answers += usize::from(answer.outstanding == 0);
        if answer.outstanding != 0 {
            probe.complete(c.seq, WAIT).await?;
        }
    }
    writeln!(
        md,
        "### End to end on `{scene}` view `{view}`, {WIDTH}×{HEIGHT}, one renderer, no refinement\n"
    )?;
    writeln!(md, "| measure | value | target |\n|---|---:|---:|")?;
    writeln!(
        md,
        "| first complete picture (all {} visible triangles shown, direct light), empty cache | {:.2} s | <= 1 s |",
        all_shown.visible_leaves, t_direct
    )?;
    writeln!(
        md,
        "| every sample at the scene's quality ({} samples) | {:.2} s | <= 5 s |",
        complete.samples, t_full
    )?;
    writeln!(
        md,
        "| camera change to its `Epoch`, all cached (median of {}; {} of them complete at once) | {:.1} ms | <= 100 ms |\n",
        times.len(),
        complete_answers,
        median(times)
    )?;
    Ok(())
}

/// Refines for a while and reads the SMA's last stats line: leaves, mesh and cache MiB.
async fn memory_per_leaf(
    exe: &Path,
    logs: &Path,
    scene: &str,
    view: &str,
    quick: bool,
    md: &mut String,
) -> anyhow::Result<()> {
    let (_renderer, sma, addr) = system(
        exe,
        logs,
        scene,
        &["--criterion", "nld-os", "--stats-secs", "1"],
    )?;
    let mut probe = Probe::connect(&addr).await?;
    probe.view(view, WIDTH, HEIGHT).await?;
    let run = Duration::from_secs(if quick { 10 } else { 60 });
    let _ = tokio::time::timeout(run, async {
        loop {
            if probe.next_epoch().await.is_err() {
                break;
            }
        }
    })
    .await;
    let log = sma.log_text();
    let line = log
        .lines()
        .rfind(|line| line.contains(" stats"))
        .context("no stats line from the SMA")?;
    let field = |name: &str| -> Option<f64> {
        let rest = line.split(&format!(" {name}=")).nth(1)?;
        rest.split_whitespace()
            .next()?
            .trim_matches('"')
            .parse()
            .ok()
    };
    let (leaves, mesh, cache) = (
        field("leaves").context("leaves")?,
        field("mesh_mib").context("mesh_mib")?,
        field("cache_mib").context("cache_mib")?,
    );
    writeln!(
        md,
        "SMA memory after {} s of `nld-os` refinement on `{scene}` `{view}`: {leaves:.0} leaves, mesh \
         {mesh:.1} MiB + cache {cache:.1} MiB = {:.0} bytes per leaf.\n",
        run.as_secs(),
        (mesh + cache) * (1u64 << 20) as f64 / leaves.max(1.0)
    )?;
    Ok(())
}
