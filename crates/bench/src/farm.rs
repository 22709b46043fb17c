//! The renderer farm under faults and uneven hosts (DESIGN.md §2, §8), with real processes started
//! from the `walkthrough` binary that runs this benchmark and the scripted viewer of
//! `testkit::probe`, the SMA at its default liveness rule:
//! - **a hung renderer**: two renderers (one worker thread each), one stopped with SIGSTOP while it
//!   holds batches; the view's completion time against the other renderer's alone, and how long
//!   the SMA took to call the stopped one lost;
//! - **a fast and a slow renderer**: paths traced per second by both together against the sum of
//!   their rates alone. This machine has two cores, so each renderer is given a host of its own
//!   by CPU affinity: the fast one a whole core, the slow one half of the other (it shares it
//!   with a busy loop), the same 2 : 1 as two worker threads against one. The SMA and the viewer
//!   run where the system puts them, as in every configuration.

use std::fmt::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use protocol::liveness::Liveness;
use testkit::child::{Server, pin_thread, start_renderer, start_sma, strings};
use testkit::probe::Probe;

use crate::stats::median;

/// The hung renderer's view: large enough that the view takes several times the silence limit.
const HUNG_VIEW: (u32, u32) = (1024, 768);
/// The uneven renderers' view: its first picture comes quickly; the ladder then keeps them busy.
const THROUGHPUT_VIEW: (u32, u32) = (512, 384);
const WAIT: Duration = Duration::from_secs(600);
/// The SMA's statistics period while throughput is read from them.
const STATS_SECS: &str = "0.5";

pub fn section(quick: bool) -> anyhow::Result<String> {
    let Ok(exe) = crate::product::walkthrough_exe() else {
        return Ok(
            "## Renderer farm\n\nRun after `cargo build --release --workspace` (it starts the \
                   renderer and SMA processes).\n\n"
                .into(),
        );
    };
    // Sponza when its files are there (DESIGN.md §11): a view long enough that a few seconds of
    // detection are a fair share of it; else the built-in town.
    let (scene, view) = if scene::load("scenes/sponza.toml").is_ok() {
        ("scenes/sponza.toml", "S1")
    } else {
        ("bracara", "VT")
    };
    let runs = if quick { 1 } else { 3 };
    let logs = std::env::temp_dir().join(format!("walkthrough-farm-{}", std::process::id()));
    std::fs::create_dir_all(&logs)?;
    let farm = Farm {
        exe: &exe,
        logs: &logs,
        scene,
        view,
    };
    let runtime = tokio::runtime::Runtime::new()?;
    let mut md = format!(
        "## Renderer farm\n\nScene {scene}, view {view}, unrefined mesh; \
         real processes on loopback; the SMA at its default liveness rule (heartbeat {:?}, \
         {:?} of silence); medians of {runs} runs. Load average when the run started: {}.\n\n",
        Liveness::default().heartbeat,
        Liveness::default().silence,
        crate::machine::load_average()
    );
    runtime.block_on(hung_renderer(&farm, runs, &mut md))?;
    runtime.block_on(uneven_renderers(&farm, runs, quick, &mut md))?;
    let _ = std::fs::remove_dir_all(&logs);
    Ok(md)
}

/// What every run of this benchmark starts its processes with.
struct Farm<'a> {
    exe: &'a Path,
    logs: &'a Path,
    scene: &'a str,
    view: &'a str,
}

impl Farm<'_> {
    fn log(&self, name: &str) -> PathBuf {
        let path = self.logs.join(format!("{name}.log"));
        let _ = std::fs::remove_file(&path);
        path
    }

    /// A renderer with one worker thread.
    fn renderer(&self, name: &str) -> anyhow::Result<Server> {
        start_renderer(self.exe, self.scene, Some(1), Some(&self.log(name)))
    }

    /// An SMA on `renderers`, no refinement, with more `flags`.
    fn sma(&self, renderers: &[&Server], flags: &[&str]) -> anyhow::Result<Server> {
        let addrs: Vec<_> = renderers.iter().map(|r| r.addr).collect();
        let mut all = strings(&["--no-refine", "--stats-secs", STATS_SECS]);
        all.extend(strings(flags));
        start_sma(self.exe, self.scene, &addrs, &all, Some(&self.log("sma")))
    }

    /// Waits until every renderer is connected to `sma`, then a viewer on it.
    async fn viewer(&self, sma: &Server, renderers: usize) -> anyhow::Result<Probe> {
        let start = Instant::now();
        while count_lines(&sma.process.log_text(), &["renderer connected"]) < renderers {
            if start.elapsed() > WAIT {
                return Err(sma.process.failure("not every renderer connected"));
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Probe::connect(&sma.addr.to_string()).await
    }
}

/// Seconds from the camera to the view's completion (every visible sample at the ladder's cap,
/// nothing outstanding, every visible triangle shown).
async fn completion(probe: &mut Probe, view: &str) -> anyhow::Result<f64> {
    let start = Instant::now();
    let camera = probe.view(view, HUNG_VIEW.0, HUNG_VIEW.1).await?;
    let done = probe.complete(camera.seq, WAIT).await?;
    anyhow::ensure!(
        done.shown > 0 && done.shown == done.visible_leaves,
        "complete without every visible triangle: {done:?}"
    );
    Ok(start.elapsed().as_secs_f64())
}

async fn hung_renderer(farm: &Farm<'_>, runs: usize, md: &mut String) -> anyhow::Result<()> {
    let preset = scene::load(farm.scene)?.settings.quality.paths;
    writeln!(
        md,
        "### A renderer that hangs while it holds batches\n\n{}×{}; the quality ladder is capped \
         at the scene's preset, then at the next rung: complete means every visible sample at that \
         many paths. Detection: from SIGSTOP to the SMA's `renderer lost` line.\n\n\
         | paths per sample | one renderer alone (s) | two, one stopped after the first answers (s) \
         | ratio (target ≤ 2) | detection (s) |\n|---:|---:|---:|---:|---:|",
        HUNG_VIEW.0, HUNG_VIEW.1,
    )?;
    for cap in [preset, 4 * preset] {
        let (mut alone, mut hung, mut detection) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            alone.push(alone_completion(farm, cap).await?);
            let (total, detected) = hung_completion(farm, cap).await?;
            hung.push(total);
            detection.push(detected);
        }
        let (alone, hung, detection) = (median(alone), median(hung), median(detection));
        writeln!(
            md,
            "| {cap} | {alone:.1} | {hung:.1} | {:.2} | {detection:.1} |",
            hung / alone
        )?;
    }
    writeln!(
        md,
        "\nThe stopped renderer's batches go to the other once it is lost; the silence limit \
         ({:?}) sets the detection.\n",
        Liveness::default().silence
    )?;
    Ok(())
}

/// The ladder capped at `cap` paths per sample.
fn capped(cap: u32) -> [String; 2] {
    ["--max-paths".into(), cap.to_string()]
}

/// Seconds one renderer alone takes to complete the view.
async fn alone_completion(farm: &Farm<'_>, cap: u32) -> anyhow::Result<f64> {
    let b = farm.renderer("b")?;
    let flags = capped(cap);
    let sma = farm.sma(&[&b], &[&flags[0], &flags[1]])?;
    let mut probe = farm.viewer(&sma, 1).await?;
    completion(&mut probe, farm.view).await
}

/// Seconds two renderers take to complete the view when one is stopped after the first answers,
/// and seconds from the stop until the SMA called it lost.
async fn hung_completion(farm: &Farm<'_>, cap: u32) -> anyhow::Result<(f64, f64)> {
    let a = farm.renderer("a")?;
    let b = farm.renderer("b")?;
    let flags = capped(cap);
    let sma = farm.sma(&[&a, &b], &[&flags[0], &flags[1]])?;
    let mut probe = farm.viewer(&sma, 2).await?;
    let start = Instant::now();
    let camera = probe.view(farm.view, HUNG_VIEW.0, HUNG_VIEW.1).await?;
    // Both hold batches once the first answers are in.
    probe
        .until(WAIT, |e| e.camera_seq == camera.seq && e.samples > 0)
        .await?;
    a.process.pause();
    let stopped = Instant::now();
    let lost_line = vec!["renderer lost".to_string(), a.addr.to_string()];
    let log = farm.logs.join("sma.log");
    let watcher = std::thread::spawn(move || wait_for_line(&log, &lost_line));
    probe.complete(camera.seq, WAIT).await?;
    let total = start.elapsed().as_secs_f64();
    let lost = watcher.join().expect("the log watcher")?;
    a.process.resume();
    Ok((total, (lost - stopped).as_secs_f64()))
}

async fn uneven_renderers(
    farm: &Farm<'_>,
    runs: usize,
    quick: bool,
    md: &mut String,
) -> anyhow::Result<()> {
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cpus < 2 {
        writeln!(
            md,
            "### A fast and a slow renderer\n\nNot measured: one CPU.\n"
        )?;
        return Ok(());
    }
    let window = Duration::from_secs(if quick { 5 } else { 10 });
    let hog = Hog::start(1)?;
    let configurations: [(&str, &[Host]); 3] = [
        ("fast alone", &[Host::Fast]),
        ("slow alone", &[Host::Slow]),
        ("both", &[Host::Fast, Host::Slow]),
    ];
    let mut measured = Vec::new();
    for _ in 0..runs {
        for (i, (_, hosts)) in configurations.iter().enumerate() {
            measured.push((i, throughput(farm, hosts, window).await?));
        }
    }
    drop(hog);
    writeln!(
        md,
        "### A fast and a slow renderer\n\n\
         {}×{}. Paths traced per second, read from the SMA's statistics over {} s once every \
         visible triangle is shown (the quality ladder, uncapped and with no stated end, then \
         keeps both busy), and the CPU seconds per second the renderers and the SMA used meanwhile. \
         Fast: one worker thread with CPU 0 to itself; slow: one worker thread on CPU 1, which a \
         busy loop shares.\n\n\
         | renderers | paths/s | renderers' CPU | SMA's CPU |\n|---|---:|---:|---:|",
        THROUGHPUT_VIEW.0,
        THROUGHPUT_VIEW.1,
        window.as_secs(),
    )?;
    let mut rates = [0.0; 3];
    for (i, (name, _)) in configurations.iter().enumerate() {
        let of = |f: fn(&Throughput) -> f64| {
            median(
                measured
                    .iter()
                    .filter(|(j, _)| *j == i)
                    .map(|(_, t)| f(t))
                    .collect(),
            )
        };
        rates[i] = of(|t| t.paths_per_sec);
        writeln!(
            md,
            "| {name} | {:.0} | {:.2} | {:.2} |",
            rates[i],
            of(|t| t.renderers_cpu),
            of(|t| t.sma_cpu)
        )?;
    }
    writeln!(
        md,
        "\nBoth together reach {:.0} % of the sum of their rates alone (target ≥ 90 %).\n",
        100.0 * rates[2] / (rates[0] + rates[1])
    )?;
    Ok(())
}

#[derive(Clone, Copy)]
enum Host {
    Fast,
    Slow,
}

impl Host {
    fn cpu(self) -> usize {
        match self {
            Host::Fast => 0,
            Host::Slow => 1,
        }
    }
}

/// What one configuration of renderers did over the window.
struct Throughput {
    /// Median of the SMA's paths/s.
    paths_per_sec: f64,
    /// CPU seconds per second of the renderers together, and of the SMA.
    renderers_cpu: f64,
    sma_cpu: f64,
}

/// What a renderer on each of `hosts` did over `window`, once every visible triangle is shown.
async fn throughput(
    farm: &Farm<'_>,
    hosts: &[Host],
    window: Duration,
) -> anyhow::Result<Throughput> {
    let renderers = hosts
        .iter()
        .enumerate()
        .map(|(i, host)| {
            let r = farm.renderer(&format!("r{i}"))?;
            r.process.pin_to_cpu(host.cpu())?;
            Ok(r)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let refs: Vec<&Server> = renderers.iter().collect();
    // No stated end: more paths are always wanted, up to a cap far above a window's worth.
    let sma = farm.sma(&refs, &["--display-error", "0", "--max-paths", "1048576"])?;
    let mut probe = farm.viewer(&sma, hosts.len()).await?;
    let camera = probe
        .view(farm.view, THROUGHPUT_VIEW.0, THROUGHPUT_VIEW.1)
        .await?;
    probe
        .until(WAIT, |e| {
            e.camera_seq == camera.seq && e.shown > 0 && e.shown == e.visible_leaves
        })
        .await?;
    let cpu = || -> f64 {
        renderers
            .iter()
            .filter_map(|r| r.process.cpu_seconds())
            .sum()
    };
    let (renderers_before, sma_before) = (cpu(), sma.process.cpu_seconds().unwrap_or(0.0));
    let seen = probe.stats_seen.len();
    let start = Instant::now();
    probe
        .until_stats(WAIT, |_| start.elapsed() >= window)
        .await?;
    let seconds = start.elapsed().as_secs_f64();
    let rates = probe.stats_seen[seen..]
        .iter()
        .map(|s| f64::from(s.paths_per_sec))
        .collect();
    Ok(Throughput {
        paths_per_sec: median(rates),
        renderers_cpu: (cpu() - renderers_before) / seconds,
        sma_cpu: (sma.process.cpu_seconds().unwrap_or(0.0) - sma_before) / seconds,
    })
}

/// A busy loop on one CPU, until dropped: half of that CPU for whatever else runs there.
struct Hog {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Hog {
    fn start(cpu: usize) -> anyhow::Result<Hog> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let (pinned_tx, pinned) = std::sync::mpsc::channel();
        let thread = std::thread::spawn(move || {
            let _ = pinned_tx.send(pin_thread(0, cpu));
            while !flag.load(Ordering::Relaxed) {
                std::hint::spin_loop();
            }
        });
        pinned.recv()??;
        Ok(Hog {
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for Hog {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// Lines of `text` holding every one of `parts`.
fn count_lines<S: AsRef<str>>(text: &str, parts: &[S]) -> usize {
    text.lines()
        .filter(|l| parts.iter().all(|p| l.contains(p.as_ref())))
        .count()
}

/// Waits until the log at `path` has a line holding every one of `parts`; the instant it did.
fn wait_for_line(path: &Path, parts: &[String]) -> anyhow::Result<Instant> {
    let start = Instant::now();
    loop {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if count_lines(&text, parts) > 0 {
            return Ok(Instant::now());
        }
        anyhow::ensure!(
            start.elapsed() < WAIT,
            "{} logged no line with {parts:?}",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}
