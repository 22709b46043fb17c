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

use testkit::child::{Server, pin_thread, start_renderer, start_sma, strings};
use testkit::probe::Probe;

use crate::bench::stats::median;

/// The hung renderer's view: large enough that the view takes several times the silence limit.
const HUNG_VIEW: (u32, u32) = (1024, 768);
/// The uneven renderers' view: its first picture comes quickly; the ladder then keeps them busy.
const THROUGHPUT_VIEW: (u32, u32) = (512, 384);
const WAIT: Duration = Duration::from_secs(600);
/// The SMA's statistics period while throughput is read from them.
const STATS_SECS: &str = "0.5";

pub fn section(quick: bool) -> anyhow::Result<String> {
    let exe = std::env::current_exe()?;
    if exe.file_stem().and_then(|s| s.to_str()) != Some("walkthrough") {
        return Ok(
            "## Renderer farm\n\nRun through `walkthrough bench report` (it starts the \
                   renderer and SMA processes).\n\n"
                .into(),
        );
    }
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
         real processes on loopback; the SMA at its default liveness rule (heartbeat 500 ms, \
         3 s of silence); medians of {runs} runs. Load average when the run started: {}.\n\n",
        crate::bench::machine::load_average()
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

/// Seconds from the camera to the view's completion (every sample at the scene's quality: the
/// SMA runs with the quality ladder capped there).
async fn completion(probe: &mut Probe, view: &str) -> anyhow::Result<f64> {
    let start = Instant::now();
    let camera = probe.view(view, HUNG_VIEW.0, HUNG_VIEW.1).await?;
    probe.complete(camera.seq, WAIT).await?;
    Ok(start.elapsed().as_secs_f64())
}

async fn hung_renderer(farm: &Farm<'_>, runs: usize, md: &mut String) -> anyhow::Result<()> {
    let (mut alone, mut hung, mut detection) = (Vec::new(), Vec::new(), Vec::new());
    let preset = scene::load(farm.scene)?.settings.quality.paths.to_string();
    let at_preset = ["--max-paths", preset.as_str()];
    for _ in 0..runs {
        let b = farm.renderer("b")?;
        let sma = farm.sma(&[&b], &at_preset)?;
        let mut probe = farm.viewer(&sma, 1).await?;
        alone.push(completion(&mut probe, farm.view).await?);
        drop((probe, sma, b));

        let a = farm.renderer("a")?;
        let b = farm.renderer("b")?;
        let sma = farm.sma(&[&a, &b], &at_preset)?;
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
        hung.push(start.elapsed().as_secs_f64());
        let lost = watcher.join().expect("the log watcher")?;
        detection.push((lost - stopped).as_secs_f64());
        a.process.resume();
    }
    let (alone, hung, detection) = (median(alone), median(hung), median(detection));
    writeln!(
        md,
        "### A renderer that hangs while it holds batches\n\n{}×{}, the quality ladder capped at \
         the scene's preset: complete means every visible sample at the scene's quality.\n\n\
         | configuration | view complete (s) |\n|---|---:|\n\
         | one renderer alone | {alone:.1} |\n\
         | two, one stopped with SIGSTOP after the first answers | {hung:.1} |\n\n\
         Ratio {:.2} (target ≤ 2). The SMA called the stopped renderer lost {detection:.1} s \
         after SIGSTOP (the silence limit is 3 s), and re-issued its batches to the other.\n",
        HUNG_VIEW.0,
        HUNG_VIEW.1,
        hung / alone
    )?;
    Ok(())
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
    let (mut fast, mut slow, mut both) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        fast.push(throughput(farm, &[Host::Fast], window).await?);
        slow.push(throughput(farm, &[Host::Slow], window).await?);
        both.push(throughput(farm, &[Host::Fast, Host::Slow], window).await?);
    }
    drop(hog);
    let (fast, slow, both) = (median(fast), median(slow), median(both));
    writeln!(
        md,
        "### A fast and a slow renderer\n\n\
         {}×{}. Paths traced per second, read from the SMA's statistics over {} s once every visible \
         triangle is shown (the quality ladder, uncapped and with no stated end, then keeps both \
         busy). Fast: one worker thread with CPU 0 \
         to itself; slow: one worker thread on CPU 1, which a busy loop shares.\n\n\
         | renderers | paths/s |\n|---|---:|\n\
         | fast alone | {fast:.0} |\n| slow alone | {slow:.0} |\n| both | {both:.0} |\n\n\
         Both together reach {:.0} % of the sum of their rates alone (target ≥ 90 %).\n",
        THROUGHPUT_VIEW.0,
        THROUGHPUT_VIEW.1,
        window.as_secs(),
        100.0 * both / (fast + slow)
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

/// Median paths/s over `window` with a renderer on each of `hosts`, once the view is complete.
async fn throughput(farm: &Farm<'_>, hosts: &[Host], window: Duration) -> anyhow::Result<f64> {
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
    let seen = probe.stats_seen.len();
    let start = Instant::now();
    probe
        .until_stats(WAIT, |_| start.elapsed() >= window)
        .await?;
    let rates = probe.stats_seen[seen..]
        .iter()
        .map(|s| f64::from(s.paths_per_sec))
        .collect();
    Ok(median(rates))
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
