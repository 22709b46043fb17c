//! The README's first command, run as a newcomer runs it: `walkthrough` with no arguments, on a
//! machine without a display, starts the renderer, the SMA and a headless viewer, writes
//! snapshots, exits 0 and leaves no process behind; a SIGINT sent to the launcher alone stops all
//! of them, cleanly.
//!
//! Every process the launcher starts inherits a marker in its environment, so a process left
//! behind is found in /proc whoever adopted it. The viewer draws with wgpu: without an adapter
//! the runs fail, so these tests need Mesa (llvmpipe through GL is on every Debian machine).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

const MARKER: &str = "WALKTHROUGH_LAUNCHER_TEST";
/// What the default run may print besides the progress line: the headless notice, the
/// connections, where snapshots go, the first picture, convergence, the end, and the two
/// servers' word that they stop (asked to, so that the SMA saves its cache file).
const MAX_LINES: usize = 12;

/// The launcher in `dir` (its default snapshot folder is relative), without a display. Its cache
/// directory is in `dir` too: a test never touches the user's cache file, whatever its flags.
fn launcher(dir: &Path, marker: &str, args: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_walkthrough"));
    cmd.args(args)
        .current_dir(dir)
        .env("XDG_CACHE_HOME", dir.join("cache"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .env_remove("RUST_LOG")
        .env(MARKER, marker)
        .stdin(Stdio::null());
    cmd
}

/// Processes whose environment holds `MARKER=marker`.
fn marked_processes(marker: &str) -> Vec<u32> {
    let needle = format!("{MARKER}={marker}");
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            std::fs::read(format!("/proc/{pid}/environ"))
                .is_ok_and(|env| env.split(|&b| b == 0).any(|var| var == needle.as_bytes()))
        })
        .collect()
}

/// Waits up to `limit` for the processes of `marker` to be gone (a killed child may take a moment
/// to be reaped); returns those still there.
fn left_behind(marker: &str, limit: Duration) -> Vec<u32> {
    let start = Instant::now();
    loop {
        let left = marked_processes(marker);
        if left.is_empty() || start.elapsed() > limit {
            return left;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn wait_with_limit(child: &mut Child, limit: Duration) -> ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("waiting for the launcher") {
            return status;
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("the launcher did not exit within {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// PNG snapshots under `dir/out/run-*/`.
fn snapshots(dir: &Path) -> Vec<PathBuf> {
    let Ok(runs) = std::fs::read_dir(dir.join("out")) else {
        return Vec::new();
    };
    runs.filter_map(|r| r.ok())
        .filter(|r| r.file_name().to_string_lossy().starts_with("run-"))
        .flat_map(|r| std::fs::read_dir(r.path()).into_iter().flatten())
        .filter_map(|f| f.ok().map(|f| f.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect()
}

fn unique_marker(name: &str) -> String {
    format!("{name}-{}", std::process::id())
}

#[test]
fn no_arguments_runs_headless_writes_snapshots_and_leaves_nothing_behind() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let marker = unique_marker("no-arguments");
    let output = launcher(dir.path(), &marker, &[])
        .output()
        .expect("starting the launcher");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "walkthrough exited with {}:\n{stdout}\n{stderr}",
        output.status,
    );
    // Not a terminal here: the progress line stays hidden, and what is left is all a person
    // reads of the run (DESIGN.md §2: one command shows the system working).
    let lines: Vec<&str> = stdout.lines().chain(stderr.lines()).collect();
    assert!(
        lines.len() <= MAX_LINES,
        "{} lines, more than a handful:\n{}",
        lines.len(),
        lines.join("\n")
    );
    let said = |words: &str| lines.iter().any(|l| l.contains(words));
    assert!(said("running headless"), "no word of the headless run");
    assert!(
        said("snapshots go to out/run-"),
        "no word of where the snapshots go"
    );
    assert!(said("first picture"), "no word of the first picture");
    assert!(
        !stderr.contains('\x1b'),
        "colour codes in a log that is not a terminal"
    );
    let shots = snapshots(dir.path());
    assert!(
        shots.len() >= 5,
        "a 20-s headless run wrote {} snapshots",
        shots.len()
    );
    // By default the SMA keeps its cache file in the user's cache directory, one per scene.
    let cache_files: Vec<_> = std::fs::read_dir(dir.path().join("cache/walkthrough"))
        .map(|d| {
            d.filter_map(|e| e.ok()?.file_name().into_string().ok())
                .collect()
        })
        .unwrap_or_default();
    assert!(
        cache_files
            .iter()
            .any(|f| f.starts_with("bracara-") && f.ends_with(".redb")),
        "no cache file for bracara in the cache directory: {cache_files:?}"
    );
    assert_eq!(
        left_behind(&marker, Duration::from_secs(5)),
        Vec::<u32>::new()
    );
}

#[test]
fn headless_flag_runs_without_a_display_even_when_one_is_named() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let marker = unique_marker("headless-flag");
    // A display that does not exist: a window would fail to open.
    let status = launcher(
        dir.path(),
        &marker,
        &["--headless", "--seconds", "3", "--no-cache-file"],
    )
    .env("DISPLAY", ":4711")
    .stdout(Stdio::null())
    .status()
    .expect("starting the launcher");
    assert!(
        status.success(),
        "walkthrough --headless exited with {status}"
    );
    assert!(!snapshots(dir.path()).is_empty(), "no snapshot written");
    assert_eq!(
        left_behind(&marker, Duration::from_secs(5)),
        Vec::<u32>::new()
    );
}

#[test]
fn sigint_to_the_launcher_stops_every_child_cleanly() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let marker = unique_marker("sigint");
    // A file, not a pipe: a pipe nobody reads could fill and stall the children writing to it.
    let log = dir.path().join("stderr.log");
    let mut child = launcher(
        dir.path(),
        &marker,
        &["--seconds", "120", "--no-cache-file"],
    )
    .stdout(Stdio::null())
    .stderr(std::fs::File::create(&log).expect("a log file"))
    .spawn()
    .expect("starting the launcher");
    let start = Instant::now();
    while snapshots(dir.path()).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no snapshot within 60 s"
        );
        assert!(
            child.try_wait().expect("polling").is_none(),
            "the launcher ended early"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    assert!(
        marked_processes(&marker).len() >= 4,
        "launcher, renderer, SMA and viewer should all be running"
    );
    // SAFETY: kill(2) only sends a signal, to our own child.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
    let status = wait_with_limit(&mut child, Duration::from_secs(15));
    let stderr = std::fs::read_to_string(&log).expect("reading the launcher's stderr");
    assert!(
        status.success(),
        "after SIGINT the launcher exited with {status}:\n{stderr}"
    );
    assert!(
        !stderr.contains("killing it"),
        "a child had to be killed instead of stopping on SIGINT:\n{stderr}"
    );
    assert_eq!(
        left_behind(&marker, Duration::from_secs(5)),
        Vec::<u32>::new()
    );
}
