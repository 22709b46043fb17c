//! The cache file's revisit (DESIGN.md §5, persistence: a site walked yesterday appears at once
//! today), with real processes: a renderer and an SMA with a fresh `--cache-file`, and the
//! scripted viewer of `testkit::probe` at one view. The first visit runs until the SMA says it
//! has converged (or a time limit); the SMA is then stopped cleanly (SIGINT: its last save) and
//! started again on the same file, with a fresh renderer, and the same view asked for. Counted
//! from each start: the samples traced until the first epoch with every visible leaf shown (the
//! first complete picture), and until convergence. Each of those pictures is the probe's table
//! drawn by the viewer's own offscreen renderer, its FLIP taken against the view's ground truth
//! as `bench convergence` takes it. Targets: the revisit's first complete picture costs <= 2 %
//! of the first visit's samples, and its FLIP is within 0.005 of the converged picture's.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use protocol::viewer_link::{Camera, Epoch, ShownTriangle};
use testkit::child::{Process, start_renderer, start_sma, strings};
use testkit::ground_truth::GroundTruth;
use testkit::probe::Probe;
use viewer::looks::Looks;

use crate::convergence::{GROUND_TRUTH_SEED, INTERACTIVE_BOUNCES};
use crate::metrics::{LinearImage, Reference};

/// Where the section is kept (`report` assembles it into BENCHMARKS.md).
pub const SECTION: &str = "docs/bench/cache-file-revisit.md";

/// What the revisit measures.
#[derive(Clone, Debug)]
pub struct RevisitConfig {
    pub scene: String,
    pub view: String,
    pub width: u32,
    pub height: u32,
    /// Paths per pixel of the ground truth (found in `gt_cache`, rendered there when missing).
    pub gt_spp: u32,
    pub gt_cache: PathBuf,
    /// How long each visit may run before it is taken as it stands, unconverged.
    pub limit: Duration,
    /// Runs, each with a fresh file: the figures are medians over them, the targets judged on
    /// the worst.
    pub runs: usize,
    /// The control, in the restarted SMA once it has converged: a look at this other view and
    /// back, the return's first complete picture counted as the revisit's is (None: skipped).
    pub away: Option<String>,
    /// More `walkthrough sma` flags for both visits.
    pub sma_flags: Vec<String>,
    /// BENCHMARKS.md, reassembled with the section.
    pub out: PathBuf,
}

/// One moment of a visit: what the SMA had done since its start, and the picture then (its
/// triangles, then its FLIP once drawn).
struct Moment {
    time_s: f64,
    epoch: Epoch,
    triangles: Vec<ShownTriangle>,
    flip: f64,
}

/// The control: back at the view after a look elsewhere, in a running SMA that holds its
/// leaves and samples. Counts from the return.
#[derive(Clone, Copy)]
struct Back {
    complete_s: f64,
    complete: Epoch,
    end_s: f64,
    end: Epoch,
    converged: bool,
}

/// Whether `e` is the first complete picture of camera `seq`: every visible leaf shown.
fn complete_for(e: &Epoch, seq: u64) -> bool {
    e.camera_seq == seq && e.visible_leaves > 0 && e.shown == e.visible_leaves
}

/// A look at `away` until its first complete picture, then back to the view: the return's
/// first complete picture and convergence, counted from the return.
async fn away_and_back(
    probe: &mut Probe,
    config: &RevisitConfig,
    away: &str,
) -> anyhow::Result<Back> {
    let away_seq = probe.view(away, config.width, config.height).await?.seq;
    probe
        .until(config.limit, |e| complete_for(e, away_seq))
        .await?;
    let t = Instant::now();
    let seq = probe
        .view(&config.view, config.width, config.height)
        .await?
        .seq;
    let mut at_return: Option<Epoch> = None;
    let complete = probe
        .until(config.limit, |e| {
            at_return.get_or_insert(*e);
            complete_for(e, seq)
        })
        .await?;
    let complete_s = t.elapsed().as_secs_f64();
    let converged = probe.until_converged(config.limit).await.is_ok();
    let end = *probe.epochs.last().expect("an epoch came");
    let end_s = t.elapsed().as_secs_f64();
    // Counted from the epoch before the return's first: what the look away had asked for.
    let base = probe
        .epochs
        .iter()
        .rev()
        .find(|e| e.camera_seq == away_seq)
        .copied()
        .or(at_return)
        .expect("an epoch came");
    let since = |e: Epoch| Epoch {
        samples: e.samples - base.samples,
        paths: e.paths - base.paths,
        ..e
    };
    Ok(Back {
        complete_s,
        complete: since(complete),
        end_s,
        end: since(end),
        converged,
    })
}

/// One visit: its first complete picture and its last (converged, or at the limit).
struct Visit {
    camera: Camera,
    /// The first epoch showing as many triangles as `shown_before` (the first visit's last
    /// picture), and when: the restored mesh on screen, whatever refinement does next.
    as_many: Option<(f64, Epoch)>,
    complete: Moment,
    end: Moment,
    converged: bool,
    /// The control's figures, in the restarted SMA.
    back: Option<Back>,
    /// The cache file's size after the visit's clean stop.
    file_bytes: u64,
    /// The SMA's log lines about its cache file.
    file_log: Vec<String>,
    /// The scene's materials and textures as the probe received them: a picture multiplies
    /// the albedo into the illumination the SMA sends, as a viewer does (DESIGN.md §5).
    looks: Looks,
}

pub fn run(config: &RevisitConfig) -> anyhow::Result<()> {
    let exe = crate::product::walkthrough_exe()?;
    let gpu = viewer::gpu::headless_or_skip("cache-file revisit")?
        .ok_or_else(|| anyhow::anyhow!("the pictures need a graphics adapter (Mesa will do)"))?;
    let truth = GroundTruth {
        scene: config.scene.clone(),
        view: config.view.clone(),
        width: config.width,
        height: config.height,
        spp: config.gt_spp,
        bounces: INTERACTIVE_BOUNCES,
        seed: GROUND_TRUTH_SEED,
    }
    .ensure(&config.gt_cache)?;
    let reference = Reference::read_exr(&truth)?;
    let dir =
        std::env::temp_dir().join(format!("walkthrough-bench-revisit-{}", std::process::id()));
    let runtime = tokio::runtime::Runtime::new()?;
    let measured = crate::machine::measured_stamp();
    let load = crate::machine::load_average();
    let mut runs = Vec::new();
    for run in 1..=config.runs.max(1) {
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir)?;
        let file = dir.join("cache.redb");
        eprintln!("revisit {run}: first visit, empty cache file…");
        let mut first = runtime.block_on(visit(&exe, &dir, config, &file, "first", None))?;
        eprintln!("revisit {run}: the SMA stopped; again on its cache file…");
        let mut again = runtime.block_on(visit(
            &exe,
            &dir,
            config,
            &file,
            "again",
            Some(first.end.epoch.shown),
        ))?;
        let camera = first.camera.clone();
        for visit in [&mut first, &mut again] {
            for moment in [&mut visit.complete, &mut visit.end] {
                moment.flip = flip(&gpu, &reference, &camera, &visit.looks, moment)?;
            }
        }
        runs.push((first, again));
    }
    let md = section(config, &runs, &measured, &load)?;
    std::fs::write(SECTION, &md)?;
    crate::report::assemble(&config.out)?;
    let _ = std::fs::remove_dir_all(&dir);
    eprintln!("{md}");
    Ok(())
}

/// The FLIP of `moment`'s picture, seen by `camera`, against the ground truth; its triangles
/// are let go.
fn flip(
    gpu: &viewer::gpu::Gpu,
    reference: &Reference,
    camera: &Camera,
    looks: &Looks,
    moment: &mut Moment,
) -> anyhow::Result<f64> {
    let triangles = std::mem::take(&mut moment.triangles);
    let snapshot = viewer::render_offscreen_with_looks(
        gpu,
        &triangles,
        (looks, &viewer::direct_image::DirectImage::default()),
        camera,
        &viewer::DrawSettings::default(),
    )?;
    let image = LinearImage {
        width: snapshot.width,
        height: snapshot.height,
        rgb: snapshot.linear,
        alpha: None,
    };
    Ok(reference.error_of(&image)?.flip)
}

/// A renderer and an SMA on `file`, the view asked for, its first complete picture and its
/// convergence awaited; then the SMA stopped cleanly.
async fn visit(
    exe: &Path,
    dir: &Path,
    config: &RevisitConfig,
    file: &Path,
    label: &str,
    shown_before: Option<u64>,
) -> anyhow::Result<Visit> {
    let sma_log = dir.join(format!("sma-{label}.log"));
    let renderer = start_renderer(
        exe,
        &config.scene,
        None,
        Some(&dir.join(format!("renderer-{label}.log"))),
    )?;
    let mut flags = strings(&["--cache-file", &file.to_string_lossy()]);
    flags.extend(config.sma_flags.iter().cloned());
    let mut sma = start_sma(exe, &config.scene, &[renderer.addr], &flags, Some(&sma_log))?;
    let _renderer: Process = renderer.process;
    let mut probe = Probe::connect(&sma.addr.to_string()).await?;
    let t0 = Instant::now();
    let camera = probe
        .view(&config.view, config.width, config.height)
        .await?;
    let seq = camera.seq;
    let mut as_many: Option<(f64, Epoch)> = None;
    let complete = probe
        .until(config.limit, |e| {
            if as_many.is_none() && shown_before.is_some_and(|n| e.shown >= n) {
                as_many = Some((t0.elapsed().as_secs_f64(), *e));
            }
            complete_for(e, seq)
        })
        .await?;
    let complete = Moment {
        time_s: t0.elapsed().as_secs_f64(),
        epoch: complete,
        triangles: probe.table.values().cloned().collect(),
        flip: f64::NAN,
    };
    let left = config.limit.saturating_sub(t0.elapsed());
    let converged = probe.until_converged(left).await.is_ok();
    let end = Moment {
        time_s: t0.elapsed().as_secs_f64(),
        epoch: *probe.epochs.last().expect("an epoch came"),
        triangles: probe.table.values().cloned().collect(),
        flip: f64::NAN,
    };
    let back = match (&config.away, shown_before) {
        (Some(away), Some(_)) => Some(away_and_back(&mut probe, config, away).await?),
        _ => None,
    };
    let mut looks = Looks::of(&probe.scene);
    for texture in probe.textures.iter().flatten() {
        looks.accept(texture);
    }
    drop(probe);
    let status = sma.process.interrupt_and_wait(Duration::from_secs(120))?;
    anyhow::ensure!(status.success(), "the SMA's clean stop failed ({status})");
    let file_log = std::fs::read_to_string(&sma_log)
        .unwrap_or_default()
        .lines()
        .filter(|l| l.contains("cache file"))
        .map(str::to_string)
        .collect();
    Ok(Visit {
        camera,
        as_many,
        complete,
        end,
        converged,
        back,
        file_bytes: std::fs::metadata(file).map(|m| m.len()).unwrap_or(0),
        file_log,
        looks,
    })
}

/// One row of the section's table: run, visit and moment, then the epoch's counts and the
/// picture's FLIP where it was judged.
fn moment_row(
    md: &mut String,
    [run, visit, moment]: [&str; 3],
    time_s: f64,
    e: &Epoch,
    flip: Option<f64>,
) -> std::fmt::Result {
    let flip = flip.map_or(String::new(), |f| format!("{f:.4}"));
    writeln!(
        md,
        "| {run} | {visit} | {moment} | {time_s:.1} | {} | {:.1} M | {} / {} | {flip} |",
        e.samples,
        e.paths as f64 / 1e6,
        e.shown,
        e.visible_leaves,
    )
}

fn section(
    config: &RevisitConfig,
    runs: &[(Visit, Visit)],
    measured: &str,
    load: &str,
) -> anyhow::Result<String> {
    let mut md = String::from("## Cache file: a revisit\n\n");
    writeln!(
        md,
        "`walkthrough-bench cache-file-revisit`: `{}` view `{}` at {}×{}, one renderer (all cores) \
         and the SMA with `--cache-file` (default criterion and save period{}), the probe as the \
         viewer. A first visit from an empty file until the SMA says it converged (limit {:.0} \
         s), a clean stop (SIGINT: the last save), then a fresh renderer and SMA on the same file \
         and the same view; {} run(s), each with a fresh file. Samples and paths are counted from \
         each start; FLIP (67 ppd, over the pixels that see geometry) against the {}-spp ground \
         truth of `bench convergence`, of the probe's table drawn by the viewer's offscreen \
         renderer. Measured {measured} on this shared 2-core machine (one-minute load average \
         {load} at the start: other builds and benchmarks beside it; the counts hardly depend on \
         it, the times do).\n",
        config.scene,
        config.view,
        config.width,
        config.height,
        if config.sma_flags.is_empty() {
            String::new()
        } else {
            format!("; more flags: `{}`", config.sma_flags.join(" "))
        },
        config.limit.as_secs_f64(),
        runs.len(),
        config.gt_spp,
    )?;
    writeln!(
        md,
        "| run | visit | moment | time (s) | samples | paths | shown / visible | FLIP |\n|---:|---|---|---:|---:|---:|---:|---:|"
    )?;
    for (k, (first, again)) in runs.iter().enumerate() {
        for (label, visit) in [("first", first), ("again", again)] {
            let end = if visit.converged {
                "converged"
            } else {
                "at the limit, not converged"
            };
            for (what, m) in [
                ("first complete picture", &visit.complete),
                (end, &visit.end),
            ] {
                moment_row(
                    &mut md,
                    [&(k + 1).to_string(), label, what],
                    m.time_s,
                    &m.epoch,
                    Some(m.flip),
                )?;
            }
        }
    }
    for (k, (_, again)) in runs.iter().enumerate() {
        if let Some((time_s, e)) = again.as_many {
            moment_row(
                &mut md,
                [
                    &(k + 1).to_string(),
                    "again",
                    "as many triangles shown as the first visit's last picture",
                ],
                time_s,
                &e,
                None,
            )?;
        }
    }
    for (k, (_, again)) in runs.iter().enumerate() {
        let Some(back) = again.back else { continue };
        let away = config.away.as_deref().unwrap_or_default();
        let end = if back.converged {
            "converged"
        } else {
            "at the limit, not converged"
        };
        for (what, time_s, e) in [
            ("first complete picture", back.complete_s, back.complete),
            (end, back.end_s, back.end),
        ] {
            let visit = format!("again, back from `{away}` (counted from the return)");
            moment_row(
                &mut md,
                [&(k + 1).to_string(), &visit, what],
                time_s,
                &e,
                None,
            )?;
        }
    }
    let share = |(first, again): &(Visit, Visit), of: fn(&Epoch) -> u64| {
        100.0 * of(&again.complete.epoch) as f64 / of(&first.end.epoch).max(1) as f64
    };
    let samples: Vec<f64> = runs.iter().map(|r| share(r, |e| e.samples)).collect();
    let paths: Vec<f64> = runs.iter().map(|r| share(r, |e| e.paths)).collect();
    let deltas: Vec<f64> = runs
        .iter()
        .map(|(first, again)| again.complete.flip - first.end.flip)
        .collect();
    let worst = |v: &[f64]| v.iter().copied().fold(0.0, |w: f64, x| w.max(x.abs()));
    let all_converged = runs.iter().all(|(first, _)| first.converged);
    writeln!(
        md,
        "\nThe revisit's first complete picture cost {:.2} % of the samples the first visit traced \
         to converge (median; at most {:.2} %; target <= 2 %: {}), {:.2} % of its paths (median); \
         its FLIP differs from the first visit's converged picture's by {:+.4} (median; at most \
         {:.4} either way; target within 0.005: {}). It came {:.1} s after the camera (median), \
         the first visit's converged picture {:.1} s. Cache file after the first visit: {:.1} MiB.\n",
        crate::stats::median(samples.clone()),
        worst(&samples),
        if worst(&samples) <= 2.0 {
            "met"
        } else {
            "missed"
        },
        crate::stats::median(paths),
        crate::stats::median(deltas.clone()),
        worst(&deltas),
        if worst(&deltas) <= 0.005 {
            "met"
        } else {
            "missed"
        },
        crate::stats::median(runs.iter().map(|r| r.1.complete.time_s).collect()),
        crate::stats::median(runs.iter().map(|r| r.0.end.time_s).collect()),
        runs[0].0.file_bytes as f64 / 1048576.0,
    )?;
    let backs: Vec<Back> = runs.iter().filter_map(|(_, again)| again.back).collect();
    if !backs.is_empty() {
        let of_first = |e: fn(&Back) -> u64| -> Vec<f64> {
            runs.iter()
                .filter_map(|(first, again)| {
                    let back = again.back?;
                    Some(100.0 * e(&back) as f64 / first.end.epoch.samples.max(1) as f64)
                })
                .collect()
        };
        let complete = of_first(|b| b.complete.samples);
        let end = of_first(|b| b.end.samples);
        writeln!(
            md,
            "The control, in the restarted SMA once converged: a look at `{}` and back, every leaf \
             and sample in memory. The return's first complete picture cost {:.2} % of the first \
             visit's samples (median; at most {:.2} %), its convergence {:.2} % (median): what a \
             running SMA does on coming back to a view, beside what the restart from the file \
             costs.\n",
            config.away.as_deref().unwrap_or_default(),
            crate::stats::median(complete.clone()),
            complete.iter().copied().fold(0.0, f64::max),
            crate::stats::median(end),
        )?;
    }
    if !all_converged {
        writeln!(
            md,
            "A first visit did not converge within the limit: its comparison is with the picture \
             it had then.\n"
        )?;
    }
    let lines = &runs[0].1.file_log;
    if !lines.is_empty() {
        writeln!(
            md,
            "The restarted SMA's log about its cache file (first run; `RUST_LOG` as the bench was \
             started with):\n\n```"
        )?;
        for line in lines.iter().take(6) {
            writeln!(md, "{line}")?;
        }
        writeln!(md, "```\n")?;
    }
    Ok(md)
}
