//! The cache file's crash trials (DESIGN.md §5, persistence: a kill during a save leaves the
//! previous or the new commit, never a corrupt file): a child process saving view after view is
//! killed with SIGKILL, and the file it leaves is opened.

use std::path::Path;
use std::time::{Duration, Instant};

use super::{GRID, fresh, open, refine_one_view, shade};

/// The child of a crash trial (`walkthrough-bench cache-file-crash-child`): loads the file,
/// then refines view after view from `first_view` on (each view's leaves within 4 units split to
/// [`CRASH_FINEST`]) and saves after each, saying on stdout how many leaves each save holds,
/// before it starts (`saving N`) and once committed (`saved N`), until it is killed.
pub fn crash_child(path: &Path, first_view: u32) -> anyhow::Result<()> {
    use std::io::Write as _;
    let (mut mesh, mut cache) = fresh();
    let mut file = open(path, &mut mesh, &mut cache)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "saved {}", mesh.leaf_count())?;
    for view in first_view.. {
        let centre = glam::Vec3::new(
            (view * 7 % GRID) as f32 + 0.5,
            (view * 3 % GRID) as f32 + 0.5,
            0.0,
        );
        refine_one_view(&mut mesh, centre, 4.0, CRASH_FINEST);
        let shaded = shade(&mesh, &mut cache);
        file.samples_changed(shaded);
        writeln!(out, "saving {}", mesh.leaf_count())?;
        out.flush()?;
        file.save_now(&mut mesh, &cache);
        writeln!(out, "saved {}", mesh.leaf_count())?;
        out.flush()?;
    }
    Ok(())
}

/// How deep a crash trial's child splits what its views see: the whole grid at this depth is
/// 4,050 × 64 = 259,200 leaves, so a child's load stays short.
const CRASH_FINEST: u32 = 3;

/// What a crash trial's child said: each line as it came, when it came; each `saving` is also
/// signalled as it comes.
fn said_by(
    stdout: std::process::ChildStdout,
    saving: std::sync::mpsc::Sender<()>,
) -> std::thread::JoinHandle<Vec<(Instant, String)>> {
    use std::io::BufRead as _;
    std::thread::spawn(move || {
        let mut lines = Vec::new();
        for line in std::io::BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if line.starts_with("saving ") {
                let _ = saving.send(());
            }
            lines.push((Instant::now(), line));
        }
        lines
    })
}

/// How long each save the child finished took, from its `saving` to its `saved`.
fn save_times(said: &[(Instant, String)]) -> impl Iterator<Item = Duration> + '_ {
    said.windows(2).filter_map(|pair| {
        let ((began, first), (ended, second)) = (&pair[0], &pair[1]);
        (first.starts_with("saving ") && second.starts_with("saved ")).then(|| *ended - *began)
    })
}

/// The crash trials' outcome.
pub(super) struct CrashTrials {
    pub trials: usize,
    pub good: usize,
    /// Kills that landed between a child's `saving` and its `saved`: during a commit.
    pub during_save: usize,
    pub failures: Vec<String>,
}

/// Crash trials: a child saving view after view is killed with SIGKILL at a random moment of a
/// save: after its first, second or third `saving`, a random time shorter than the longest save
/// seen so far (so most kills land inside a commit, some just after); the file must then open (not refused)
/// with the leaves of the last commit the child finished or of the one it was making, never
/// anything else. Each trial's child walks other views, so the file grows across trials.
pub(super) fn crash_trials(dir: &Path, trials: usize) -> anyhow::Result<CrashTrials> {
    use rand::{RngExt, SeedableRng};
    let exe = std::env::current_exe()?;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let mut outcome = CrashTrials {
        trials,
        good: 0,
        during_save: 0,
        failures: Vec::new(),
    };
    let path = dir.join("crash.redb");
    let _ = std::fs::remove_file(&path);
    // The leaves the file held after the previous trial: all a child killed before its first
    // commit can leave there.
    let mut previous = fresh().0.leaf_count();
    // Until a save is seen: a guess at one.
    let mut longest_save = Duration::from_millis(50);
    for trial in 0..trials {
        let mut child = std::process::Command::new(&exe)
            .arg("cache-file-crash-child")
            .arg(&path)
            .arg("--first-view")
            .arg((trial * 5).to_string())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()?;
        let (saving, first_save) = std::sync::mpsc::channel();
        let reader = said_by(child.stdout.take().expect("piped"), saving);
        let nth = rng.random_range(1..=3);
        let started = (0..nth).all(|_| first_save.recv_timeout(Duration::from_secs(120)).is_ok());
        std::thread::sleep(longest_save.mul_f64(rng.random_range(0.0..1.0)));
        child.kill()?;
        child.wait()?;
        let said = reader
            .join()
            .map_err(|_| anyhow::anyhow!("the reader thread panicked"))?;
        longest_save = save_times(&said).fold(longest_save, Duration::max);
        let said: Vec<String> = said.into_iter().map(|(_, line)| line).collect();
        let counts = |word: &str| -> Vec<usize> {
            said.iter()
                .filter_map(|l| l.strip_prefix(word)?.trim().parse().ok())
                .collect()
        };
        let (saved, saving) = (counts("saved "), counts("saving "));
        if said.last().is_some_and(|l| l.starts_with("saving ")) {
            outcome.during_save += 1;
        }
        let allowed: Vec<usize> = [saved.last().copied().unwrap_or(previous)]
            .into_iter()
            .chain(saving.last().copied())
            .collect();
        let (mut mesh, mut cache) = fresh();
        let opened = open(&path, &mut mesh, &mut cache);
        let refused = sma_rejected(&path).exists();
        match opened {
            Ok(_) if started && !refused && allowed.contains(&mesh.leaf_count()) => {
                outcome.good += 1
            }
            _ => outcome.failures.push(format!(
                "trial {trial}: {} leaves after the kill, the child said {allowed:?}, refused: {refused}, saves began: {started}",
                mesh.leaf_count()
            )),
        }
        previous = mesh.leaf_count();
        if refused {
            let _ = std::fs::remove_file(sma_rejected(&path));
        }
    }
    Ok(outcome)
}

fn sma_rejected(path: &Path) -> std::path::PathBuf {
    std::path::PathBuf::from(format!("{}.rejected", path.display()))
}
