//! Intel Open Image Denoise for the denoised per-pixel competitor (DESIGN.md §10): PyPI's
//! `pyoidn` ships the library and a NumPy API, driven by `denoise.py` (kept in the binary and
//! written to a temporary folder), with raw float images between the two. Only this benchmark
//! needs it; the README's commands do not.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use anyhow::Context;

use crate::metrics::LinearImage;

const SCRIPT: &str = include_str!("denoise.py");

/// How to install what the denoiser needs, for the error that says it is missing.
pub(crate) const INSTALL: &str = "the denoised competitor needs Python 3 with Intel Open Image \
                                  Denoise from PyPI: `pip install pyoidn numpy` (or run \
                                  `walkthrough-bench accuracy --no-denoise`)";

/// A Python that imports `pyoidn`, and the script it runs.
pub(crate) struct Denoiser {
    python: PathBuf,
    dir: tempfile::TempDir,
}

impl Denoiser {
    /// The denoiser, or an error that says how to install it.
    pub(crate) fn find() -> anyhow::Result<Denoiser> {
        let python = PathBuf::from(std::env::var_os("PYTHON").unwrap_or_else(|| "python3".into()));
        let found = Command::new(&python)
            .args(["-c", "import numpy, pyoidn"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        anyhow::ensure!(
            found,
            "{} cannot import pyoidn: {INSTALL}",
            python.display()
        );
        let dir = tempfile::tempdir()?;
        std::fs::write(dir.path().join("denoise.py"), SCRIPT)?;
        Ok(Denoiser { python, dir })
    }

    /// `color` denoised with its feature images, and the seconds of the denoiser's warm call.
    pub(crate) fn denoise(
        &self,
        color: &LinearImage,
        albedo: &LinearImage,
        normal: &LinearImage,
    ) -> anyhow::Result<(LinearImage, f64)> {
        let (w, h) = (color.width, color.height);
        for (name, image) in [("albedo", albedo), ("normal", normal)] {
            anyhow::ensure!(
                (image.width, image.height) == (w, h),
                "the {name} image is {}×{}, the colour {w}×{h}",
                image.width,
                image.height
            );
        }
        let path = |name: &str| self.dir.path().join(format!("{name}.f32"));
        for (name, image) in [("color", color), ("albedo", albedo), ("normal", normal)] {
            write_raw(&path(name), image)?;
        }
        let output = Command::new(&self.python)
            .arg(self.dir.path().join("denoise.py"))
            .args([w.to_string(), h.to_string()])
            .args(["color", "albedo", "normal", "out"].map(path))
            .stdin(Stdio::null())
            .output()
            .context("starting the denoiser")?;
        anyhow::ensure!(
            output.status.success(),
            "the denoiser failed ({}): {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        );
        let seconds: f64 = String::from_utf8_lossy(&output.stdout)
            .trim()
            .parse()
            .context("the denoiser's time")?;
        Ok((read_raw(&path("out"), w, h)?, seconds))
    }
}

fn write_raw(path: &Path, image: &LinearImage) -> anyhow::Result<()> {
    let bytes: Vec<u8> = image
        .rgb
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_le_bytes()))
        .collect();
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

fn read_raw(path: &Path, width: u32, height: u32) -> anyhow::Result<LinearImage> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let pixels = width as usize * height as usize;
    anyhow::ensure!(
        bytes.len() == pixels * 12,
        "the denoised image has {} bytes, not {}",
        bytes.len(),
        pixels * 12
    );
    let rgb = bytes
        .chunks_exact(12)
        .map(|p| {
            let c = |k: usize| f32::from_le_bytes(p[4 * k..4 * k + 4].try_into().expect("4 bytes"));
            [c(0), c(1), c(2)]
        })
        .collect();
    Ok(LinearImage {
        width,
        height,
        rgb,
        alpha: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_images_round_trip() {
        let image = LinearImage {
            width: 2,
            height: 1,
            rgb: vec![[0.5, 1.0, 2.0], [0.0, 1e-3, 7.25]],
            alpha: None,
        };
        let path = std::env::temp_dir().join(format!("raw-{}.f32", std::process::id()));
        write_raw(&path, &image).unwrap();
        assert_eq!(read_raw(&path, 2, 1).unwrap(), image);
        assert!(read_raw(&path, 3, 1).is_err());
        std::fs::remove_file(path).unwrap();
    }
}
