//! Reference images (DESIGN.md §7, §10): the same estimator per pixel for a named viewpoint, a box
//! filter over each pixel, written as linear EXR plus a Drago-tone-mapped PNG beside it. They are
//! the ground truth of the convergence benchmark, like the Radiance images of thesis appendix B.

use std::path::Path;

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use rayon::prelude::*;

use crate::counters::{RayCounts, RayKind};
use crate::estimator::path_radiance;
use crate::sampling::{Rng, stream, uniform2};
use crate::tonemap;
use crate::world::World;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceSettings {
    pub width: u32,
    pub height: u32,
    /// Paths per pixel.
    pub spp: u32,
    /// Bounce depth, as in `protocol::renderer_link::Quality::bounces`.
    pub bounces: Option<u32>,
    pub seed: u64,
}

/// A linear RGB image, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
    /// Per pixel: whether any of its camera rays hit geometry (error metrics leave the others out,
    /// DESIGN.md §10).
    pub covered: Vec<bool>,
}

/// The camera of the scene's viewpoint `name` at the given size (the protocol's convention, so the
/// image matches the viewer pixel for pixel).
pub fn camera_for(world: &World, name: &str, width: u32, height: u32) -> anyhow::Result<Camera> {
    let settings = &world.scene.settings;
    let Some(vp) = settings.viewpoints.iter().find(|v| v.name == name) else {
        let names: Vec<&str> = settings
            .viewpoints
            .iter()
            .map(|v| v.name.as_str())
            .collect();
        bail!(
            "scene {} has no viewpoint {name:?} (it has {names:?})",
            world.scene.name
        );
    };
    let vp = Viewpoint {
        name: vp.name.clone(),
        eye: vp.eye,
        target: vp.target,
        up: vp.up,
        fov_y_deg: vp.fov_y_deg,
    };
    Ok(Camera::from_viewpoint(&vp, 0, width, height))
}

/// Renders the image; `progress` advances by one per row.
pub fn render(
    world: &World,
    camera: &Camera,
    s: &ReferenceSettings,
    progress: Option<&ProgressBar>,
) -> (Image, RayCounts) {
    let width = s.width as usize;
    let rows: Vec<(Vec<(Vec3, bool)>, RayCounts)> = (0..s.height)
        .into_par_iter()
        .map(|y| {
            let mut counts = RayCounts::default();
            let row = (0..s.width)
                .map(|x| {
                    let mut rng = stream(s.seed, y as u64 * width as u64 + x as u64);
                    pixel(world, camera, s, x, y, &mut rng, &mut counts)
                })
                .collect();
            if let Some(bar) = progress {
                bar.inc(1);
            }
            (row, counts)
        })
        .collect();
    let mut counts = RayCounts::default();
    let mut pixels = Vec::with_capacity(width * s.height as usize);
    let mut covered = Vec::with_capacity(pixels.capacity());
    for (row, c) in rows {
        counts += c;
        for (p, hit) in row {
            pixels.push(p);
            covered.push(hit);
        }
    }
    (
        Image {
            width: s.width,
            height: s.height,
            pixels,
            covered,
        },
        counts,
    )
}

/// Mean radiance over `spp` jittered camera rays through pixel (x, y) (a box filter).
fn pixel(
    world: &World,
    camera: &Camera,
    s: &ReferenceSettings,
    x: u32,
    y: u32,
    rng: &mut Rng,
    counts: &mut RayCounts,
) -> (Vec3, bool) {
    let origin = world.to_local(camera.eye_vec());
    let mut sum = Vec3::ZERO;
    let mut covered = false;
    let spp = s.spp.max(1);
    for _ in 0..spp {
        let [jx, jy] = uniform2(rng);
        let dir = camera.ray_direction(x as f32 + jx, y as f32 + jy);
        let l = match world.trace(origin, dir, RayKind::Camera, counts) {
            None => world.lights.escaped_radiance(dir, true),
            Some(hit) => {
                covered = true;
                let surface = world.surface_at(origin, dir, hit);
                world.emission(hit.triangle, dir)
                    + path_radiance(world, surface, -dir, s.bounces, rng, counts)
            }
        };
        if l.is_finite() {
            sum += l.max(Vec3::ZERO);
        }
    }
    (sum / spp as f32, covered)
}

/// Renders viewpoint `view` and writes `out` (EXR) and the PNG beside it (same name, `.png`).
/// `l_white`: the tone-mapping white; when `None`, the largest luminance of the pixels that see
/// geometry.
pub fn render_to_files(
    world: &World,
    view: &str,
    s: &ReferenceSettings,
    out: &Path,
    l_white: Option<f32>,
) -> anyhow::Result<(Image, RayCounts)> {
    let camera = camera_for(world, view, s.width, s.height)?;
    let bar = ProgressBar::new(s.height as u64).with_style(
        ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} rows (eta {eta})",
        )
        .context("progress template")?,
    );
    bar.set_message(format!(
        "{} {view} {}x{} {} spp",
        world.scene.name, s.width, s.height, s.spp
    ));
    let (image, counts) = render(world, &camera, s, Some(&bar));
    bar.finish();
    tonemap::write_exr(out, s.width, s.height, &image.pixels)?;
    // The white of the geometry, like the SMA's L_white (the largest cached sample, DESIGN.md §6):
    // a visible sun disc or sky must not darken the whole picture.
    let l_white = l_white.unwrap_or_else(|| {
        let seen = image.pixels.iter().zip(&image.covered).filter(|(_, c)| **c);
        tonemap::max_luminance(seen.map(|(p, _)| *p))
    });
    tonemap::write_png(
        &out.with_extension("png"),
        s.width,
        s.height,
        &image.pixels,
        l_white,
    )?;
    Ok((image, counts))
}
