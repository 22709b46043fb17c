//! The launcher's default action (DESIGN.md §2): renderer(s), SMA and viewer as separate child
//! processes of this same binary, wired over loopback, on the built-in scene. In a window when a
//! display is there; headless otherwise, writing snapshots into a folder.

use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::process::Stdio;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use tokio::process::{Child, Command};

#[derive(Args, Debug, Clone)]
pub struct LaunchArgs {
    /// Scene: a TOML file or a built-in name.
    #[arg(long, default_value = "bracara")]
    pub scene: String,
    /// Viewpoint to start at (default: the scene's first).
    #[arg(long)]
    pub view: Option<String>,
    /// Refinement criterion (rnd, nld-is, nld-os, …).
    #[arg(long, default_value = "nld-os")]
    pub criterion: String,
    /// Number of renderer processes; the cores are shared among them.
    #[arg(long, default_value_t = 1)]
    pub renderers: usize,
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Stop after this many seconds (headless default: 20; a window runs until closed).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Run headless even when a display is there.
    #[arg(long)]
    pub headless: bool,
    /// Where headless snapshots go (default: out/run-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// A display is there when X11 or Wayland says so.
fn has_display() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var_os(v).is_some_and(|s| !s.is_empty()))
}

/// A free loopback port, asked of the OS (the tiny window until the child binds it is harmless:
/// the SMA and the viewer reconnect with backoff).
pub fn free_loopback_addr() -> anyhow::Result<SocketAddr> {
    Ok(TcpListener::bind("127.0.0.1:0")?.local_addr()?)
}

fn child(args: &[String]) -> anyhow::Result<Child> {
    let exe = std::env::current_exe().context("locating the walkthrough binary")?;
    Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .kill_on_drop(true)
        .spawn()
        .with_context(|| format!("starting walkthrough {}", args.join(" ")))
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

pub fn run(args: LaunchArgs) -> anyhow::Result<()> {
    tokio::runtime::Runtime::new()?.block_on(run_async(args))
}

async fn run_async(args: LaunchArgs) -> anyhow::Result<()> {
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(2);
    let threads = (cores / args.renderers.max(1)).max(1).to_string();
    let mut servers = Vec::new();
    let mut renderer_flags = Vec::new();
    for _ in 0..args.renderers.max(1) {
        let addr = free_loopback_addr()?.to_string();
        let a = [
            "renderer",
            "serve",
            "--scene",
            &args.scene,
            "--listen",
            &addr,
            "--threads",
            &threads,
        ];
        servers.push(child(&strings(&a))?);
        renderer_flags.extend(["--renderer".to_string(), addr]);
    }
    let sma_addr = free_loopback_addr()?.to_string();
    let mut sma = strings(&[
        "sma",
        "--scene",
        &args.scene,
        "--listen",
        &sma_addr,
        "--criterion",
        &args.criterion,
    ]);
    sma.extend(renderer_flags);
    servers.push(child(&sma)?);

    let headless = args.headless || !has_display();
    let mut viewer = strings(&["viewer", "--connect", &sma_addr]);
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
        println!(
            "no display: running headless; snapshots go to {}",
            out.display()
        );
        viewer.extend(strings(&[
            "--headless",
            "--snapshot-every",
            "1",
            "--out",
            &out.to_string_lossy(),
        ]));
    }
    let mut viewer = child(&viewer)?;

    let (outcome, interrupted) = tokio::select! {
        status = viewer.wait() => (status.map(|s| s.success()), false),
        signal = termination_signal() => {
            println!("{signal}: stopping the viewer, the SMA and the renderers…");
            (Ok(true), true)
        }
    };
    if interrupted {
        servers.push(viewer);
    }
    stop_all(&mut servers, interrupted).await;
    match outcome? {
        true => Ok(()),
        false => anyhow::bail!("the viewer exited with an error"),
    }
}

/// Resolves at the first SIGINT or SIGTERM, naming it.
async fn termination_signal() -> &'static str {
    use tokio::signal::unix::{SignalKind, signal};
    let mut term = signal(SignalKind::terminate()).ok();
    tokio::select! {
        _ = tokio::signal::ctrl_c() => "interrupted",
        Some(_) = async { term.as_mut()?.recv().await } => "terminated",
    }
}

/// Ends every child. After a signal each is asked to stop (SIGINT: the renderer and the SMA shut
/// down their listeners, the viewer simply exits) and all together get a few seconds before the
/// rest are killed; a signal sent to the launcher alone, not to its process group as a terminal's
/// Ctrl-C is, thus still reaches them. When the viewer ended the run, the servers are killed at
/// once: they hold nothing worth saving.
async fn stop_all(children: &mut [Child], ask_first: bool) {
    if ask_first {
        for pid in children.iter().filter_map(Child::id) {
            // SAFETY: kill(2) only sends a signal, to a child of ours not yet reaped.
            unsafe {
                libc::kill(pid as libc::pid_t, libc::SIGINT);
            }
        }
    }
    let deadline = tokio::time::Instant::now() + Duration::from_secs(3);
    for child in children {
        if ask_first
            && tokio::time::timeout_at(deadline, child.wait())
                .await
                .is_ok()
        {
            continue;
        }
        if ask_first {
            eprintln!("walkthrough: a child did not stop within 3 s: killing it");
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
