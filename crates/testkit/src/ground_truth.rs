//! A view's ground truth (DESIGN.md §10): the renderer's own per-pixel image of the view, with the
//! estimator and bounce depth of the system's samples, at many paths per pixel; rendered once and
//! kept on disk, keyed by scene fingerprint, view, size and quality. It is rendered in-process
//! through the renderer library so that the EXR can carry the renderer's coverage as alpha (0 where
//! no camera ray of the pixel hit geometry): pixels that see no geometry are left out of every error.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use renderer::reference::{Image, ReferenceSettings, camera_for, render};
use renderer::world::World;

/// The ground truth's terms.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTruth {
    /// A scene TOML path or a built-in name.
    pub scene: String,
    pub view: String,
    pub width: u32,
    pub height: u32,
    /// Paths per pixel (§10: at least 256 for the benchmark).
    pub spp: u32,
    /// Bounce depth of the system's interactive preset (§10: 2).
    pub bounces: u32,
    pub seed: u64,
}

impl GroundTruth {
    /// The scene, loaded, and where its EXR is cached: the scene's fingerprint is in the name,
    /// so an edited scene never reads a stale image.
    fn cached_path(&self, cache: &Path) -> anyhow::Result<(scene::Scene, PathBuf)> {
        let scene =
            scene::load(&self.scene).with_context(|| format!("loading scene {}", self.scene))?;
        let key = &scene::fingerprint_hex(&scene.fingerprint)[..12];
        let name = format!(
            "{}-{}-{key}-{}x{}-{}spp-{}b.exr",
            scene.name, self.view, self.width, self.height, self.spp, self.bounces
        );
        Ok((scene, cache.join(name)))
    }

    /// The cached EXR, rendering it first when missing. Prints how long a render took.
    pub fn ensure(&self, cache: &Path) -> anyhow::Result<PathBuf> {
        Ok(self.ensure_timed(cache)?.0)
    }

    /// As [`ensure`](Self::ensure), with how long the render took (None: it was cached).
    pub fn ensure_timed(&self, cache: &Path) -> anyhow::Result<(PathBuf, Option<Duration>)> {
        let (scene, path) = self.cached_path(cache)?;
        if path.is_file() {
            return Ok((path, None));
        }
        std::fs::create_dir_all(cache)?;
        eprintln!(
            "ground truth {}: rendering {} paths per pixel (minutes at full size)…",
            path.display(),
            self.spp
        );
        let started = Instant::now();
        let world = World::new(scene);
        let camera = camera_for(&world, &self.view, self.width, self.height)?;
        let settings = ReferenceSettings {
            width: self.width,
            height: self.height,
            spp: self.spp,
            bounces: Some(self.bounces),
            seed: self.seed,
        };
        let (image, _) = render(&world, &camera, &settings, None);
        write_covered_exr(&path, &image)?;
        let took = started.elapsed();
        eprintln!("ground truth rendered in {:.0} s", took.as_secs_f64());
        Ok((path, Some(took)))
    }
}

/// Writes a per-pixel render as a ground truth EXR, its coverage as alpha (0 where no camera ray
/// of the pixel hit geometry). Written under a temporary name first: an interrupted render leaves
/// no truncated cache entry.
pub fn write_covered_exr(path: &Path, image: &Image) -> anyhow::Result<()> {
    let partial = path.with_extension("partial.exr");
    let width = image.width as usize;
    exr::prelude::write_rgba_file(&partial, width, image.height as usize, |x, y| {
        let i = y * width + x;
        let p = image.pixels[i];
        (p.x, p.y, p.z, if image.covered[i] { 1.0f32 } else { 0.0 })
    })
    .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, path)?;
    Ok(())
}
