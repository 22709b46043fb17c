//! The ray queries at each vector level (DESIGN.md §7), forced with `WALKTHROUGH_SIMD` on the
//! `renderer reference` binary: each level says in the log that it runs, and both render the
//! Cornell box to the same mean luminance. The rest of the suite runs on either level under the
//! same variable (`.ci/run` runs the renderer's tests once per level).

use std::process::Command;

use renderer::sampling::luminance;
use renderer::vector_level::{VAR, VectorLevel};

/// Mean luminance of a Cornell reference rendered by the binary with `level` forced, and the
/// binary's log.
fn render_forced(level: &str, dir: &std::path::Path) -> (f64, String) {
    let out = dir.join(format!("{level}.exr"));
    let run = Command::new(env!("CARGO_BIN_EXE_renderer"))
        .args(["reference", "--scene", "cornell", "--view", "main"])
        .args(["--width", "48", "--height", "48", "--spp", "16"])
        .args(["--bounces", "unbounded", "--threads", "2", "--out"])
        .arg(&out)
        .env(VAR, level)
        // The level is said at debug (the start-up lines a person reads stay few).
        .env("RUST_LOG", "debug")
        .env("NO_COLOR", "1")
        .output()
        .expect("run renderer reference");
    let log = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "{level}: {log}");
    let pixels = renderer::image_files::read_exr(&out)
        .expect("read the reference back")
        .pixels;
    let mean = pixels.iter().map(|&p| luminance(p) as f64).sum::<f64>() / pixels.len() as f64;
    (mean, log)
}

#[test]
fn both_levels_run_when_forced_and_agree() {
    let dir = tempfile::tempdir().unwrap();
    let (baseline, log) = render_forced("baseline", dir.path());
    assert!(log.contains("vector_level=\"baseline\""), "{log}");
    if !VectorLevel::V3.available() {
        eprintln!("this CPU lacks x86-64-v3: only the baseline was run");
        return;
    }
    let (v3, log) = render_forced("v3", dir.path());
    assert!(log.contains("vector_level=\"x86-64-v3\""), "{log}");
    // Same seeds, same paths: only the rounding of a few grazing rays may differ.
    assert!(
        (v3 - baseline).abs() <= 0.005 * baseline,
        "baseline {baseline} vs v3 {v3}"
    );
}

#[test]
fn a_level_the_binary_does_not_know_is_refused() {
    let run = Command::new(env!("CARGO_BIN_EXE_renderer"))
        .args(["reference", "--scene", "cornell", "--view", "main"])
        .args(["--width", "4", "--height", "4", "--spp", "1", "--out"])
        .arg(std::env::temp_dir().join("never-written.exr"))
        .env(VAR, "avx9000")
        .output()
        .expect("run renderer reference");
    assert!(!run.status.success());
    assert!(String::from_utf8_lossy(&run.stderr).contains(VAR));
}
