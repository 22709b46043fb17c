//! Textures through the whole system (DESIGN.md §5, "Parts, and textures"): the real renderer,
//! SMA and headless viewer, started by the launcher on the built-in `bracara-textured`, write a
//! snapshot whose paving shows its texture per pixel (the viewer multiplies each pixel's texel
//! into the illumination it interpolates), where the same run on untextured `bracara` shows
//! smooth shading over the same region.
//!
//! The viewer draws with wgpu: without an adapter the launcher's run fails and so does this
//! test, whether or not `WALKTHROUGH_REQUIRE_GPU` is set (Mesa's llvmpipe through GL, or
//! lavapipe with `WGPU_BACKEND=vulkan`, serves on a machine without a GPU).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

const WIDTH: u32 = 320;
const HEIGHT: u32 = 240;

/// Runs the launcher headless on `scene` for a few seconds in `dir` and returns its last
/// snapshot, decoded.
fn last_snapshot(dir: &Path, scene: &str) -> image::RgbImage {
    let out = dir.join(scene);
    let output = Command::new(env!("CARGO_BIN_EXE_walkthrough"))
        .args([
            "--headless",
            "--no-cache-file",
            "--seconds",
            "5",
            "--scene",
            scene,
        ])
        .args([
            "--width",
            &WIDTH.to_string(),
            "--height",
            &HEIGHT.to_string(),
        ])
        .arg("--out")
        .arg(&out)
        .current_dir(dir)
        .env("XDG_CACHE_HOME", dir.join("cache"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .stdin(Stdio::null())
        .output()
        .expect("starting the launcher");
    assert!(
        output.status.success(),
        "walkthrough on {scene} exited with {}:\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr),
    );
    let mut shots: Vec<PathBuf> = std::fs::read_dir(&out)
        .expect("the snapshot folder")
        .filter_map(|f| f.ok().map(|f| f.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    shots.sort();
    let last = shots.last().expect("a snapshot");
    let image = image::open(last).expect("a PNG snapshot").to_rgb8();
    assert_eq!(image.dimensions(), (WIDTH, HEIGHT));
    image
}

/// Per-pixel detail over the bottom fifth of the image, its middle half across (the paving in
/// front of the first viewpoint): the mean absolute difference of horizontally adjacent pixels'
/// green codes. Smooth shading changes by a fraction of a code from pixel to pixel; a texture
/// by tens of codes at its joints and grain.
fn detail(image: &image::RgbImage) -> f64 {
    let (mut sum, mut n) = (0.0, 0u32);
    for y in HEIGHT * 4 / 5..HEIGHT {
        for x in WIDTH / 4..WIDTH * 3 / 4 {
            let a = f64::from(image.get_pixel(x, y)[1]);
            let b = f64::from(image.get_pixel(x + 1, y)[1]);
            sum += (a - b).abs();
            n += 1;
        }
    }
    sum / f64::from(n)
}

#[test]
fn a_textured_surface_shows_its_texture_per_pixel() {
    let dir = tempfile::tempdir().expect("a temporary folder");
    let textured = detail(&last_snapshot(dir.path(), "bracara-textured"));
    let plain = detail(&last_snapshot(dir.path(), "bracara"));
    eprintln!("detail: textured {textured:.2}, untextured {plain:.2} codes per pixel");
    assert!(
        textured > 3.0 * plain.max(0.25),
        "the textured paving shows {textured:.2} codes of detail per pixel, the untextured \
         {plain:.2}"
    );
}
