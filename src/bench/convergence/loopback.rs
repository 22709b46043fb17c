//! One measured run of the whole system on loopback (DESIGN.md §2): renderer(s), the SMA and a
//! headless viewer as real separate processes of the `walkthrough` binary, as a user would start
//! them on three machines. Every child is killed when the run is dropped, on every exit path.

use std::fs::File;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::launch::free_loopback_addr;

/// How long a child may take to bind its port (scene load, BVH build, wgpu start on Mesa).
const START_TIMEOUT: Duration = Duration::from_secs(120);

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

struct Process {
    name: &'static str,
    child: Child,
    log: PathBuf,
}

impl Process {
    fn spawn(
        exe: &Path,
        name: &'static str,
        args: &[String],
        logs: &Path,
    ) -> anyhow::Result<Process> {
        let log = logs.join(format!("{name}.log"));
        let out = File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let child = Command::new(exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(out.try_clone()?)
            .stderr(out)
            .env("NODEVICE_SELECT", "1")
            .spawn()
            .with_context(|| format!("starting {} {}", exe.display(), args.join(" ")))?;
        Ok(Process { name, child, log })
    }

    /// An error naming the process and the end of its log.
    fn failure(&self, what: &str) -> anyhow::Error {
        let log = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = log.lines().collect();
        let tail = &lines[lines.len().saturating_sub(15)..];
        anyhow::anyhow!(
            "{} {what} (log {}):\n{}",
            self.name,
            self.log.display(),
            tail.join("\n")
        )
    }

    fn exited(&mut self) -> Option<std::process::ExitStatus> {
        self.child.try_wait().ok().flatten()
    }
}

/// A child never outlives its handle, whatever way the run ends (a failure, a panic in a test).
impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The running system: renderer(s) and SMA, killed when dropped.
pub struct System {
    exe: PathBuf,
    logs: PathBuf,
    sma_addr: SocketAddr,
    servers: Vec<Process>,
}

impl System {
    /// Starts the renderer(s), waits for them to listen, then the SMA, and waits for it to listen,
    /// so the viewer's clock starts against a ready system (t = 0 at the first camera, §10).
    pub fn start(config: &SystemConfig, logs: &Path) -> anyhow::Result<System> {
        std::fs::create_dir_all(logs)?;
        let cores = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(2);
        let threads = (cores / config.renderers.max(1)).max(1).to_string();
        let mut system = System {
            exe: config.exe.clone(),
            logs: logs.to_path_buf(),
            sma_addr: free_loopback_addr()?,
            servers: vec![],
        };
        let mut sma_args = strings(&[
            "sma",
            "--scene",
            &config.scene,
            "--listen",
            &system.sma_addr.to_string(),
        ]);
        sma_args.extend(strings(&[
            "--criterion",
            &config.criterion,
            "--seed",
            &config.seed.to_string(),
        ]));
        if !config.refine {
            sma_args.push("--no-refine".into());
        }
        sma_args.extend(config.sma_flags.iter().cloned());
        for _ in 0..config.renderers.max(1) {
            let addr = free_loopback_addr()?;
            let args = strings(&[
                "renderer",
                "serve",
                "--scene",
                &config.scene,
                "--listen",
                &addr.to_string(),
                "--threads",
                &threads,
            ]);
            system.start_server("renderer", &args, addr)?;
            sma_args.extend(["--renderer".to_string(), addr.to_string()]);
        }
        system.start_server("sma", &sma_args, system.sma_addr)?;
        Ok(system)
    }

    fn start_server(
        &mut self,
        name: &'static str,
        args: &[String],
        addr: SocketAddr,
    ) -> anyhow::Result<()> {
        self.servers
            .push(Process::spawn(&self.exe, name, args, &self.logs)?);
        let started = Instant::now();
        while !is_bound(addr) {
            let process = self.servers.last_mut().expect("just pushed");
            if process.exited().is_some() {
                return Err(process.failure("exited before listening"));
            }
            if started.elapsed() > START_TIMEOUT {
                return Err(process.failure(&format!(
                    "did not listen on {addr} within {START_TIMEOUT:?}"
                )));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(())
    }

    /// The SMA's viewer address (a second, in-process viewer may connect to it).
    pub fn sma_addr(&self) -> SocketAddr {
        self.sma_addr
    }

    /// Runs a headless viewer to its end, writing snapshots into `out`. Fails when the viewer
    /// fails, overruns, or a server dies meanwhile.
    pub fn run_viewer(&mut self, config: &ViewerConfig, out: &Path) -> anyhow::Result<()> {
        let mut viewer = Process::spawn(
            &self.exe,
            "viewer",
            &viewer_args(config, self.sma_addr, out),
            &self.logs,
        )?;
        let deadline = Instant::now() + config.time_limit;
        loop {
            if let Some(status) = viewer.exited() {
                return if status.success() {
                    Ok(())
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
    args.extend(strings(&["--out", &out.to_string_lossy()]));
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

/// Whether some process listens on `addr`'s port, read from the kernel's socket tables: a probe
/// connection would be a peer without a handshake, and a probe bind could steal the port from the
/// child about to bind it.
fn is_bound(addr: SocketAddr) -> bool {
    let port = format!(":{:04X}", addr.port());
    ["/proc/net/tcp", "/proc/net/tcp6"].iter().any(|table| {
        std::fs::read_to_string(table)
            .unwrap_or_default()
            .lines()
            .skip(1)
            .any(|line| {
                let fields: Vec<&str> = line.split_whitespace().collect();
                // Columns: sl, local_address (hex ip:port), rem_address, st (0A = LISTEN), …
                fields.len() > 3 && fields[1].ends_with(&port) && fields[3] == "0A"
            })
    })
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}
