//! The launcher's default action (DESIGN.md §2): renderer(s), SMA and viewer as separate child
//! processes of this same binary, wired over loopback, on the built-in scene. In a window when a
//! display is there; headless otherwise, writing snapshots into a folder. The servers bind port 0
//! and report the port they got (`conventions::listening`), which the launcher passes on.
//!
//! The launcher's terminal shows the children's log lines (one format, `conventions::logging`)
//! and one progress line that the viewer feeds through its stdout (`viewer::progress`): the
//! launcher reads a line protocol instead of joining the SMA link itself.

use std::path::PathBuf;
use std::process::Stdio;
use std::time::Duration;

use anyhow::Context;
use tokio::process::{Child, Command};

/// What the launcher starts (the `walkthrough` flags without a subcommand).
#[derive(Debug, Clone)]
pub struct LaunchConfig {
    /// Scene: a TOML file or a built-in name.
    pub scene: String,
    /// Viewpoint to start at (default: the scene's first).
    pub view: Option<String>,
    /// Refinement criterion (rnd, nld-is, nld-os, …).
    pub criterion: String,
    /// Which system the SMA runs (`sma::config::Profile`), passed on as `--profile`.
    pub profile: sma::config::Profile,
    /// The SMA's object-space filter of the indirect light, passed on as `--indirect-filter`;
    /// `None`: the profile's default.
    pub indirect_filter: Option<bool>,
    /// Number of renderer processes; the cores are shared among them.
    pub renderers: usize,
    pub width: u32,
    pub height: u32,
    /// Stop after this many seconds (headless default: 20; a window runs until closed).
    pub seconds: Option<f64>,
    /// Run headless even when a display is there.
    pub headless: bool,
    /// Where headless snapshots go (default: out/run-<unix time>).
    pub out: Option<PathBuf>,
    /// Where the SMA keeps its cache file, one per scene (`sma --cache-dir`); none: no file.
    pub cache_dir: Option<PathBuf>,
}

/// The launcher's cache files: `$XDG_CACHE_HOME/walkthrough`, or `~/.cache/walkthrough` (the XDG
/// base directory rule: a relative `XDG_CACHE_HOME` is ignored). None without either.
pub fn user_cache_dir() -> Option<PathBuf> {
    let absolute = |v: &str| {
        std::env::var_os(v)
            .map(PathBuf::from)
            .filter(|p| p.is_absolute())
    };
    let base = absolute("XDG_CACHE_HOME").or_else(|| absolute("HOME").map(|h| h.join(".cache")));
    base.map(|b| b.join("walkthrough"))
}

/// The SMA's `--indirect-filter` flag, when the launcher was given one.
pub(crate) fn indirect_filter_args(args: &LaunchConfig) -> Vec<String> {
    args.indirect_filter
        .map(|on| strings(&["--indirect-filter", if on { "on" } else { "off" }]))
        .unwrap_or_default()
}

/// A display is there when X11 or Wayland says so.
fn has_display() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// How long a server may take to report its address (scene load, BVH build, wgpu start on Mesa).
const START_TIMEOUT: Duration = Duration::from_secs(120);

fn spawn(args: &[String], stdout: Stdio) -> anyhow::Result<Child> {
    let exe = std::env::current_exe().context("locating the walkthrough binary")?;
    Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(stdout)
        .kill_on_drop(true)
        .spawn()
        .with_context(|| format!("starting walkthrough {}", args.join(" ")))
}

/// Starts a server told `--listen 127.0.0.1:0`; [`listening_addr`] reads where it listens.
fn server(args: &[String]) -> anyhow::Result<Child> {
    spawn(args, Stdio::piped())
}

/// The address `server` reports. Its stdout carries nothing else for a person (its log goes to
/// stderr), so the rest is drained and dropped.
fn listening_addr(server: &mut Child) -> anyhow::Result<String> {
    let stdout = server.stdout.take().context("the server's stdout")?;
    let stdout = std::fs::File::from(stdout.into_owned_fd()?);
    let addr = conventions::listening::read_addr(stdout, std::io::sink(), START_TIMEOUT)
        .context("waiting for a server's address")?;
    Ok(addr.to_string())
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

pub fn run(args: LaunchConfig) -> anyhow::Result<()> {
    tokio::runtime::Runtime::new()?.block_on(run_async(args))
}

async fn run_async(args: LaunchConfig) -> anyhow::Result<()> {
    let mut termination = Termination::listen()?;
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(2);
    let threads = (cores / args.renderers.max(1)).max(1).to_string();
    let mut servers = Vec::new();
    for _ in 0..args.renderers.max(1) {
        let a = [
            "renderer",
            "serve",
            "--scene",
            &args.scene,
            "--listen",
            "127.0.0.1:0",
            "--threads",
            &threads,
        ];
        servers.push(server(&strings(&a))?);
    }
    let mut sma = strings(&[
        "sma",
        "--scene",
        &args.scene,
        "--listen",
        "127.0.0.1:0",
        "--criterion",
        &args.criterion,
        "--profile",
        args.profile.name(),
    ]);
    sma.extend(indirect_filter_args(&args));
    if let Some(dir) = &args.cache_dir {
        sma.extend([
            "--cache-dir".to_string(),
            dir.to_string_lossy().into_owned(),
        ]);
    }
    // The renderers load their scenes side by side; then each reports its address.
    for renderer in &mut servers {
        sma.extend(["--renderer".to_string(), listening_addr(renderer)?]);
    }
    let mut sma = server(&sma)?;
    let sma_addr = listening_addr(&mut sma)?;
    servers.push(sma);

    let headless = args.headless || !has_display();
    let mut viewer = strings(&["viewer", "--connect", &sma_addr, "--progress"]);
    viewer.extend(strings(&[
        "--width",
        &args.width.to_string(),
        "--height",
        &args.height.to_string(),
    ]));
    if let Some(v) = &args.view {
        viewer.extend(strings(&["--view", v]));
    }
    if let Some(s) = args.seconds.or(headless.then_some(20.0)) {
        viewer.extend(strings(&["--seconds", &s.to_string()]));
    }
    if headless {
        let out = args.out.clone().unwrap_or_else(default_out_dir);
        std::fs::create_dir_all(&out)?;
        tracing::info!(
            "{}: running headless",
            if args.headless {
                "--headless"
            } else {
                "no display"
            }
        );
        viewer.extend(strings(&[
            "--headless",
            "--snapshot-every",
            "1",
            "--out",
            &out.to_string_lossy(),
        ]));
    }
    let mut viewer = spawn(&viewer, Stdio::piped())?;
    let progress = viewer.stdout.take().context("the viewer's stdout")?;
    let progress = std::fs::File::from(progress.into_owned_fd()?);
    let progress = std::thread::spawn(move || crate::progress_bar::show(progress));

    let (outcome, interrupted) = tokio::select! {
        status = viewer.wait() => (status.map(|s| s.success()), false),
        signal = termination.next() => {
            tracing::info!("{signal}: stopping the viewer, the SMA and the renderers…");
            (Ok(true), true)
        }
    };
    if interrupted {
        servers.push(viewer);
    }
    // An SMA with a cache file saves it at a clean stop: it is asked to stop, like after a signal.
    stop_all(&mut servers, interrupted || args.cache_dir.is_some()).await;
    if let Ok(Some(last)) = progress.join() {
        tracing::info!(
            samples = last.samples,
            shown = last.shown,
            state = %last.state,
            "the run is over"
        );
    }
    match outcome? {
        true => Ok(()),
        false => anyhow::bail!("the viewer exited with an error"),
    }
}

/// SIGINT and SIGTERM, listened for before any child starts. A handled signal goes back to its
/// default action in a child, an ignored one stays ignored: a launcher started with SIGINT
/// ignored (a background job of a non-interactive shell) would otherwise start a viewer that
/// the SIGINT it passes on cannot stop.
struct Termination {
    interrupt: tokio::signal::unix::Signal,
    terminate: tokio::signal::unix::Signal,
}

impl Termination {
    fn listen() -> anyhow::Result<Termination> {
        use tokio::signal::unix::{SignalKind, signal};
        Ok(Termination {
            interrupt: signal(SignalKind::interrupt()).context("listening for SIGINT")?,
            terminate: signal(SignalKind::terminate()).context("listening for SIGTERM")?,
        })
    }

    /// Resolves at the next SIGINT or SIGTERM, naming it.
    async fn next(&mut self) -> &'static str {
        tokio::select! {
            _ = self.interrupt.recv() => "interrupted",
            _ = self.terminate.recv() => "terminated",
        }
    }
}

/// How long the children together get to stop after SIGINT. On two cores loaded by other work,
/// with wgpu on a software rasteriser (lavapipe), a child has been seen to need just over three
/// seconds to close; one that is really stuck is still killed well before a person gives up.
const GRACEFUL_STOP: Duration = Duration::from_secs(8);

/// Ends every child. After a signal each is asked to stop (SIGINT: the renderer and the SMA shut
/// down their listeners, the viewer simply exits) and all together get a few seconds before the
/// rest are killed; a signal sent to the launcher alone, not to its process group as a terminal's
/// Ctrl-C is, thus still reaches them. When the viewer ended the run and the SMA keeps no cache
/// file, the servers are killed at once: they hold nothing worth saving.
async fn stop_all(children: &mut [Child], ask_first: bool) {
    if ask_first {
        for pid in children.iter().filter_map(Child::id) {
            // SAFETY: kill(2) only sends a signal, to a child of ours not yet reaped.
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGINT);
            }
        }
    }
    let deadline = tokio::time::Instant::now() + GRACEFUL_STOP;
    // Last started, first stopped: the SMA before its renderers, so it does not report them lost.
    for child in children.iter_mut().rev() {
        if ask_first
            && tokio::time::timeout_at(deadline, child.wait())
                .await
                .is_ok()
        {
            continue;
        }
        if ask_first {
            // One that ended just as the deadline passed is no child to kill.
            if matches!(child.try_wait(), Ok(Some(_))) {
                continue;
            }
            let program = child
                .id()
                .and_then(|pid| std::fs::read_to_string(format!("/proc/{pid}/cmdline")).ok())
                .map(|cmdline| cmdline.replace('\0', " "))
                .unwrap_or_default();
            tracing::warn!(
                %program,
                seconds = GRACEFUL_STOP.as_secs(),
                "a child did not stop in time: killing it"
            );
        }
        let _ = child.kill().await;
    }
}

fn default_out_dir() -> PathBuf {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    PathBuf::from("out").join(format!("run-{secs}"))
}
