//! Ground truths of the walk's cameras (DESIGN.md §10): the renderer's per-pixel image of a camera
//! of the path at the interactive depth, rendered once and cached like the views' ground truths
//! (`testkit::ground_truth`), keyed by the scene's name and fingerprint, the camera, size and
//! quality. How long each took is kept beside it, so that a report read from the cache can still
//! say what the ground truths cost.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use renderer::reference::{ReferenceSettings, render};
use renderer::world::World;

use super::route::WalkCamera;
use crate::convergence::{GROUND_TRUTH_SEED, INTERACTIVE_BOUNCES};

/// A scene loaded once for its walk's ground truths and for the per-pixel competitor.
pub(crate) struct Scene {
    pub world: World,
    /// `<name>-<first 12 hex digits of the fingerprint>`.
    key: String,
    pub fov_y_deg: f32,
}

impl Scene {
    pub fn load(spec: &str, fov_y_deg: f32) -> anyhow::Result<Scene> {
        let scene = scene::load(spec).with_context(|| format!("loading scene {spec}"))?;
        let key = format!(
            "{}-{}",
            scene.name,
            &scene::fingerprint_hex(&scene.fingerprint)[..12]
        );
        Ok(Scene {
            world: World::new(scene),
            key,
            fov_y_deg,
        })
    }

    /// The protocol's camera of a walk camera at the given size, as the viewer makes it from
    /// the path (`Camera::from_viewpoint`), so that images match pixel for pixel.
    pub fn camera(&self, c: &WalkCamera, width: u32, height: u32) -> Camera {
        let vp = Viewpoint {
            name: "walk".into(),
            eye: c.eye.to_array(),
            target: c.target.to_array(),
            up: [0.0, 1.0, 0.0],
            fov_y_deg: self.fov_y_deg,
        };
        Camera::from_viewpoint(&vp, 0, width, height)
    }
}

/// Where a scene's walk ground truths are kept, at one size.
pub(crate) struct Truths<'a> {
    pub scene: &'a Scene,
    pub cache: PathBuf,
    pub width: u32,
    pub height: u32,
}

/// A ground truth on disk and the seconds its render took (when it was rendered).
pub(crate) struct Truth {
    pub exr: PathBuf,
    pub render_s: f64,
}

impl Truths<'_> {
    fn path(&self, c: &WalkCamera, spp: u32) -> PathBuf {
        let camera = format!(
            "{:?} {:?} {}",
            c.eye.to_array(),
            c.target.to_array(),
            self.scene.fov_y_deg
        );
        self.cache.join(format!(
            "{}-walk-{:012x}-{}x{}-{spp}spp-{}b.exr",
            self.scene.key,
            fnv1a(camera.as_bytes()) & 0xffff_ffff_ffff,
            self.width,
            self.height,
            INTERACTIVE_BOUNCES
        ))
    }

    /// The camera's ground truth at `spp` paths per pixel, rendered first when not cached.
    pub fn ensure(&self, c: &WalkCamera, spp: u32) -> anyhow::Result<Truth> {
        let exr = self.path(c, spp);
        let seconds_file = exr.with_extension("seconds");
        if exr.is_file() {
            let render_s = std::fs::read_to_string(&seconds_file)
                .ok()
                .and_then(|s| s.trim().parse().ok())
                .unwrap_or(0.0);
            return Ok(Truth { exr, render_s });
        }
        std::fs::create_dir_all(&self.cache)?;
        let started = Instant::now();
        let settings = ReferenceSettings {
            width: self.width,
            height: self.height,
            spp,
            bounces: Some(INTERACTIVE_BOUNCES),
            seed: GROUND_TRUTH_SEED,
        };
        let camera = self.scene.camera(c, self.width, self.height);
        let (image, _) = render(&self.scene.world, &camera, &settings, None);
        testkit::ground_truth::write_covered_exr(&exr, &image)?;
        let render_s = started.elapsed().as_secs_f64();
        std::fs::write(&seconds_file, format!("{render_s}\n"))?;
        eprintln!(
            "  ground truth at step {} ({spp} spp): {render_s:.1} s",
            c.step
        );
        Ok(Truth { exr, render_s })
    }
}

/// FNV-1a, 64 bits: a stable name for a camera (std's hasher may change between releases).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::vec3;

    #[test]
    fn a_camera_is_rendered_once_and_read_back_from_the_cache() {
        let scene = Scene::load("cornell", 40.0).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let truths = Truths {
            scene: &scene,
            cache: dir.path().to_path_buf(),
            width: 16,
            height: 12,
        };
        let c = WalkCamera {
            step: 3,
            eye: vec3(0.0, 1.0, 3.0),
            target: vec3(0.0, 1.0, 0.0),
        };
        let first = truths.ensure(&c, 2).unwrap();
        let name = first
            .exr
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        assert!(name.starts_with("cornell-") && name.contains("-walk-") && first.render_s > 0.0);
        let again = truths.ensure(&c, 2).unwrap();
        assert_eq!(
            (again.exr.clone(), again.render_s),
            (first.exr.clone(), first.render_s)
        );
        let other = WalkCamera {
            eye: vec3(0.1, 1.0, 3.0),
            ..c
        };
        assert_ne!(truths.ensure(&other, 2).unwrap().exr, first.exr);
    }
}
