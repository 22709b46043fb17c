//! The fuzz inputs kept on disk, per target: `corpus/<target>/` holds the seeds (written by the
//! `write_seed_corpus` tests, never by a fuzz run), `regressions/<target>/` the inputs that once
//! crashed a target, and `artifacts/<target>/` (not committed) what a local fuzz run found. The
//! stable `fuzz_corpus` tests of the protocol and scene crates include this file to replay them.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

/// What a target does with one input: true when it accepted it.
pub type Target = fn(&[u8]) -> bool;

/// Where inputs are read from, in this order.
pub const INPUT_DIRS: [&str; 3] = ["corpus", "regressions", "artifacts"];

/// The `fuzz/` folder, seen from a crate in `crates/`.
pub fn fuzz_dir(crate_dir: &str) -> PathBuf {
    Path::new(crate_dir).join("../../fuzz")
}

/// Replays every target of a crate's test (`crate_dir`: its manifest folder); each must have at
/// least `min_seeds` seeds, or the seeds were lost.
pub fn replay_targets(crate_dir: &str, targets: &[(&str, Target)], min_seeds: usize) {
    let dir = fuzz_dir(crate_dir);
    for &(target, run) in targets {
        let ran = replay(&dir, target, run);
        assert!(
            ran >= min_seeds,
            "{target}: only {ran} seeds; write them again"
        );
    }
}

/// Seeds named so are inputs the target must refuse; every other seed it must accept, so the
/// corpus keeps reaching past the first check.
pub const REFUSED_PREFIXES: [&str; 2] = ["malformed-", "rejected-"];

/// Runs `run` (true: the input was accepted) on every input of `target`; panics naming each input
/// that made it panic, and each seed accepted or refused against its name. Returns how many
/// inputs ran.
pub fn replay(fuzz_dir: &Path, target: &str, run: Target) -> usize {
    let mut ran = 0;
    let mut crashed = Vec::new();
    let mut misjudged = Vec::new();
    for (i, dir) in INPUT_DIRS.iter().enumerate() {
        let Ok(entries) = std::fs::read_dir(fuzz_dir.join(dir).join(target)) else {
            continue;
        };
        let mut files: Vec<PathBuf> = entries.map(|e| e.expect("corpus entry").path()).collect();
        files.sort();
        for file in files {
            let bytes = std::fs::read(&file).expect("readable corpus file");
            match catch_unwind(AssertUnwindSafe(|| run(&bytes))) {
                Err(_) => crashed.push(file.display().to_string()),
                Ok(accepted) if i == 0 && accepted == is_named_refused(&file) => {
                    misjudged.push(file.display().to_string());
                }
                Ok(_) => {}
            }
            ran += 1;
        }
    }
    assert!(crashed.is_empty(), "{target} crashed on {crashed:#?}");
    assert!(
        misjudged.is_empty(),
        "{target} accepted a seed named refused, or refused one named accepted: {misjudged:#?}"
    );
    ran
}

fn is_named_refused(file: &Path) -> bool {
    let name = file.file_name().unwrap_or_default().to_string_lossy();
    REFUSED_PREFIXES.iter().any(|p| name.starts_with(p))
}

/// Replaces the seeds of `target` with `seeds` (file name, bytes).
pub fn write_seeds(fuzz_dir: &Path, target: &str, seeds: &[(String, Vec<u8>)]) {
    let dir = fuzz_dir.join("corpus").join(target);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create the corpus folder");
    for (name, bytes) in seeds {
        std::fs::write(dir.join(name), bytes).expect("write a seed");
    }
}
