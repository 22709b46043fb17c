//! One measured run of the whole system on loopback (DESIGN.md §2): renderer(s), the SMA and a
//! headless viewer as real separate processes of the `walkthrough` binary, as a user would start
//! them on three machines. Each server binds port 0 and reports its address (`crate::child`).
//! Every child is killed when the run is dropped, on every exit path.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use conventions::logging::HEADLESS_RUN_OVER;

use crate::child::{Process, start_renderer, start_sma, strings};

/// What the SMA and its renderers run.
#[derive(Clone, Debug)]
pub struct SystemConfig {
    /// The `walkthrough` binary.
    pub exe: PathBuf,
    /// A scene TOML path or a built-in name.
    pub scene: String,
    pub criterion: String,
    pub refine: bool,
    pub seed: u64,
    pub renderers: usize,
    /// More `walkthrough sma` flags, e.g. `--max-selections 256` for a parameter sweep.
    pub sma_flags: Vec<String>,
}

/// What the headless viewer records (its `--snapshot-*` flags).
#[derive(Clone, Debug)]
pub struct ViewerConfig {
    pub view: String,
    pub width: u32,
    pub height: u32,
    /// `--seconds`: the run's length; without it the viewer stops once every snapshot is taken.
    pub seconds: Option<f64>,
    /// The viewer is killed, and the run fails, past this (its start on Mesa included).
    pub time_limit: Duration,
    /// `--snapshot-every`: a snapshot at 0, s, 2s, … seconds.
    pub every_seconds: Option<f64>,
    /// `--snapshot-at-samples`.
    pub at_samples: Vec<u64>,
    /// `--snapshot-when-idle`: a snapshot whenever the SMA reports no request outstanding.
    pub when_idle: bool,
}

/// The running system: renderer(s) and SMA, killed when dropped.
pub struct System {
    exe: PathBuf,
    logs: PathBuf,
    sma_addr: SocketAddr,
    servers: Vec<Process>,
    /// See [`System::sma_rss`].
    sma_rss: Vec<(f64, u64)>,
}

/// How often a viewer run samples the SMA's resident memory.
pub const RSS_EVERY: Duration = Duration::from_millis(250);

impl System {
    /// Starts the renderer(s), waits for their addresses, then the SMA, and waits for its address,
    /// so the viewer's clock starts against a ready system (t = 0 at the first camera, §10).
    pub fn start(config: &SystemConfig, logs: &Path) -> anyhow::Result<System> {
        std::fs::create_dir_all(logs)?;
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(2);
        let threads = (cores / config.renderers.max(1)).max(1);
        let mut servers = Vec::new();
        let mut renderers = Vec::new();
        for n in 0..config.renderers.max(1) {
            let log = logs.join(format!("renderer{n}.log"));
            let renderer = start_renderer(&config.exe, &config.scene, Some(threads), Some(&log))?;
            servers.push(renderer.process);
            renderers.push(renderer.addr);
        }
        let mut flags = strings(&["--criterion", &config.criterion]);
        flags.extend(["--seed".to_string(), config.seed.to_string()]);
        if !config.refine {
            flags.push("--no-refine".into());
        }
        flags.extend(config.sma_flags.iter().cloned());
        let log = logs.join("sma.log");
        let sma = start_sma(&config.exe, &config.scene, &renderers, &flags, Some(&log))?;
        servers.push(sma.process);
        Ok(System {
            exe: config.exe.clone(),
            logs: logs.to_path_buf(),
            sma_addr: sma.addr,
            servers,
            sma_rss: Vec::new(),
        })
    }

    /// The SMA's viewer address (a second, in-process viewer may connect to it).
    pub fn sma_addr(&self) -> SocketAddr {
        self.sma_addr
    }

    /// Runs a headless viewer to its end, writing snapshots into `out`, and tells the CPU time
    /// each process used meanwhile. Fails when the viewer fails, overruns, or a server dies.
    pub fn run_viewer(&mut self, config: &ViewerConfig, out: &Path) -> anyhow::Result<CpuShares> {
        self.run_viewer_with(config, &[], out)
    }

    /// As [`run_viewer`](Self::run_viewer), with more `walkthrough viewer` flags (e.g. a
    /// `--camera-path`), and the SMA's resident memory sampled meanwhile ([`Self::sma_rss`]).
    pub fn run_viewer_with(
        &mut self,
        config: &ViewerConfig,
        more_flags: &[String],
        out: &Path,
    ) -> anyhow::Result<CpuShares> {
        let started = Instant::now();
        let servers_before: Vec<f64> = self.server_cpu();
        let mut args = viewer_args(config, self.sma_addr, out);
        args.extend(more_flags.iter().cloned());
        let mut viewer = Process::spawn(
            &self.exe,
            "viewer",
            &args,
            Some(&self.logs.join("viewer.log")),
        )?;
        self.sma_rss.clear();
        let deadline = Instant::now() + config.time_limit;
        let mut viewer_cpu = 0.0;
        // The CPU times and wall time when the viewer's run ended, once its log says so: after
        // it, the viewer only writes the snapshots left, which the run must not be charged with.
        let mut at_run_end: Option<CpuShares> = None;
        loop {
            // Read while the viewer runs: once it is reaped, /proc no longer has it.
            viewer_cpu = viewer.cpu_seconds().unwrap_or(viewer_cpu);
            self.sample_sma_rss(started);
            if at_run_end.is_none() && viewer.log_text().contains(HEADLESS_RUN_OVER) {
                at_run_end = Some(self.shares_since(started, &servers_before, viewer_cpu));
            }
            if let Some(status) = viewer.exited() {
                return if status.success() {
                    Ok(at_run_end
                        .unwrap_or_else(|| self.shares_since(started, &servers_before, viewer_cpu)))
                } else {
                    Err(viewer.failure(&format!("failed ({status})")))
                };
            }
            if let Some(dead) = self
                .servers
                .iter_mut()
                .find_map(|p| p.exited().is_some().then_some(p))
            {
                return Err(dead.failure("died during the run"));
            }
            if Instant::now() > deadline {
                let overran = format!("overran its time limit of {:?}", config.time_limit);
                // The servers' logs say why the viewer waited (e.g. samples never answered).
                let servers: Vec<String> = self
                    .servers
                    .iter()
                    .map(|p| p.failure("was running").to_string())
                    .collect();
                return Err(viewer.failure(&overran).context(servers.join("\n")));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl System {
    /// The SMA's resident set size during the last viewer run, sampled every
    /// [`RSS_EVERY`]: (seconds since the viewer was started, bytes).
    pub fn sma_rss(&self) -> &[(f64, u64)] {
        &self.sma_rss
    }

    fn sample_sma_rss(&mut self, started: Instant) {
        let t = started.elapsed().as_secs_f64();
        if self
            .sma_rss
            .last()
            .is_some_and(|(last, _)| t - last < RSS_EVERY.as_secs_f64())
        {
            return;
        }
        let sma = self.servers.last().expect("an SMA");
        if let Some(bytes) = sma.resident_bytes() {
            self.sma_rss.push((t, bytes));
        }
    }

    /// Where the time went since `started`, given the servers' CPU seconds then and the
    /// viewer's now.
    fn shares_since(&self, started: Instant, servers_before: &[f64], viewer_s: f64) -> CpuShares {
        let used: Vec<f64> = self
            .server_cpu()
            .iter()
            .zip(servers_before)
            .map(|(after, before)| after - before)
            .collect();
        let (sma, renderers) = used.split_last().expect("an SMA");
        CpuShares {
            wall_s: started.elapsed().as_secs_f64(),
            renderers_s: renderers.iter().sum(),
            sma_s: *sma,
            viewer_s,
        }
    }

    /// CPU seconds of each server so far: the renderers, then the SMA (the order started).
    fn server_cpu(&self) -> Vec<f64> {
        self.servers
            .iter()
            .map(|p| p.cpu_seconds().unwrap_or(0.0))
            .collect()
    }
}

/// Where the machine's time went during a viewer's run (DESIGN.md §10: rest time is meant for the
/// renderer): CPU seconds of each kind of process, and the wall time.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CpuShares {
    pub wall_s: f64,
    pub renderers_s: f64,
    pub sma_s: f64,
    pub viewer_s: f64,
}

fn viewer_args(c: &ViewerConfig, sma: SocketAddr, out: &Path) -> Vec<String> {
    let mut args = strings(&[
        "viewer",
        "--connect",
        &sma.to_string(),
        "--headless",
        "--view",
        &c.view,
    ]);
    args.extend(strings(&[
        "--width",
        &c.width.to_string(),
        "--height",
        &c.height.to_string(),
    ]));
    // A measured run: its snapshots are drawn after it, not beside the system it measures.
    args.extend(strings(&[
        "--out",
        &out.to_string_lossy(),
        "--hold-snapshots",
    ]));
    if let Some(seconds) = c.seconds {
        args.extend(strings(&["--seconds", &seconds.to_string()]));
    }
    if let Some(every) = c.every_seconds {
        args.extend(strings(&["--snapshot-every", &every.to_string()]));
    }
    if !c.at_samples.is_empty() {
        let list: Vec<String> = c.at_samples.iter().map(u64::to_string).collect();
        args.extend(strings(&["--snapshot-at-samples", &list.join(",")]));
    }
    if c.when_idle {
        args.push("--snapshot-when-idle".into());
    }
    args
}
