//! Reference images (DESIGN.md §7, §10): the same estimator per pixel for a named viewpoint (the
//! world's `Estimator`, as for shade batches), a box filter over each pixel, written as linear EXR plus a Drago-tone-mapped PNG beside it. They are
//! the ground truth of the convergence benchmark, like the Radiance images of thesis appendix B.

use std::path::Path;

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use rayon::prelude::*;

use crate::counters::{RayCounts, RayKind};
use crate::estimator::{Estimator, path_radiance};
use crate::image_files;
use crate::sampling::{Rng, stream, uniform2};
use crate::wavefront::{Start, WAVE_PATHS, trace_paths};
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
            crate::subnormals::flush_on_this_thread();
            let mut counts = RayCounts::default();
            let mut rngs: Vec<Rng> = (0..s.width)
                .map(|x| stream(s.seed, y as u64 * width as u64 + x as u64))
                .collect();
            let row = match world.estimator {
                Estimator::Path => (0..s.width)
                    .map(|x| pixel(world, camera, s, x, y, &mut rngs[x as usize], &mut counts))
                    .collect(),
                Estimator::Wavefront => row_as_waves(world, camera, s, y, &mut rngs, &mut counts),
            };
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
    let strata = world.first_bounce.strata(rng);
    for k in 0..spp {
        let dir = jittered_ray(camera, x, y, rng);
        let l = match world.trace(origin, dir, RayKind::Camera, counts) {
            None => world.lights.escaped_radiance(dir, true),
            Some(hit) => {
                covered = true;
                let surface = world.surface_at(origin, dir, hit);
                world.emission(hit.triangle, dir)
                    + path_radiance(
                        world,
                        surface,
                        -dir,
                        s.bounces,
                        strata.map(|s| s.point(k)),
                        rng,
                        counts,
                    )
                    .radiance(world.albedo_at(&surface))
            }
        };
        add_finite(&mut sum, l);
    }
    (sum / spp as f32, covered)
}

/// The direction of a camera ray through a point of pixel (x, y) drawn uniformly over it: the
/// box filter of a reference image's pixels, and of a direct tile's (`direct_tile`).
pub(crate) fn jittered_ray(camera: &Camera, x: u32, y: u32, rng: &mut Rng) -> Vec3 {
    let [jx, jy] = uniform2(rng);
    camera.ray_direction(x as f32 + jx, y as f32 + jy)
}

/// A non-finite sample is dropped (counted as black), a negative channel clamped.
fn add_finite(sum: &mut Vec3, l: Vec3) {
    if l.is_finite() {
        *sum += l.max(Vec3::ZERO);
    }
}

/// Row `y` as [`pixel`] computes it, with the paths scheduled as waves (`wavefront`): a group of
/// pixels' camera rays traced as one stream, then the paths from what they hit. `rngs` holds one
/// stream per pixel of the row.
fn row_as_waves(
    world: &World,
    camera: &Camera,
    s: &ReferenceSettings,
    y: u32,
    rngs: &mut [Rng],
    counts: &mut RayCounts,
) -> Vec<(Vec3, bool)> {
    let spp = s.spp.max(1);
    let mut row = vec![(Vec3::ZERO, false); s.width as usize];
    let group = (WAVE_PATHS / spp as usize).max(1);
    for first in (0..s.width as usize).step_by(group) {
        let pixels = first..(first + group).min(row.len());
        let (starts, emitted) = camera_paths(world, camera, y, pixels, spp, rngs, &mut row, counts);
        let albedos: Vec<Vec3> = starts.iter().map(|s| world.albedo_at(&s.surface)).collect();
        trace_paths(world, &starts, s.bounces, rngs, counts, |i, l| {
            add_finite(
                &mut row[starts[i].stream].0,
                emitted[i] + l.radiance(albedos[i]),
            );
        });
    }
    for (sum, _) in &mut row {
        *sum /= spp as f32;
    }
    row
}

/// The camera rays of `pixels` of row `y` (`spp` jittered each), traced as one stream (each
/// pixel's as packets where `World::packets` says so): a ray that escapes adds what it sees to
/// its pixel of `row` at once; one that hits marks the pixel covered and becomes a path start
/// (its stream is the pixel), returned with the emission the camera sees there.
#[allow(clippy::too_many_arguments)]
fn camera_paths(
    world: &World,
    camera: &Camera,
    y: u32,
    pixels: std::ops::Range<usize>,
    spp: u32,
    rngs: &mut [Rng],
    row: &mut [(Vec3, bool)],
    counts: &mut RayCounts,
) -> (Vec<Start>, Vec<Vec3>) {
    let origin = world.to_local(camera.eye_vec());
    let mut starts = Vec::with_capacity(pixels.len() * spp as usize);
    let mut emitted = Vec::with_capacity(starts.capacity());
    let origins = vec![origin; spp as usize];
    let mut dirs = vec![Vec3::ZERO; spp as usize];
    let mut hits = vec![None; spp as usize];
    for x in pixels {
        // The pixel's paths stratify their first bounces together, as in [`pixel`].
        let strata = world.first_bounce.strata(&mut rngs[x]);
        for dir in &mut dirs {
            *dir = jittered_ray(camera, x as u32, y, &mut rngs[x]);
        }
        // A pixel's rays, from one eye through one pixel, are as coherent as rays get: traced
        // together as packets (`World::trace_packet`). The jitters come first, then the traces,
        // which draw nothing, so the answers are those of tracing each ray as it is drawn.
        world.trace_packet(&origins, &dirs, RayKind::Camera, &mut hits, counts);
        for (k, (&dir, &hit)) in (0..spp).zip(dirs.iter().zip(&hits)) {
            let Some(hit) = hit else {
                add_finite(&mut row[x].0, world.lights.escaped_radiance(dir, true));
                continue;
            };
            row[x].1 = true;
            starts.push(Start {
                surface: world.surface_at(origin, dir, hit),
                wo: -dir,
                paths: 1,
                stream: x,
                strata,
                first_index: k,
            });
            emitted.push(world.emission(hit.triangle, dir));
        }
    }
    (starts, emitted)
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
    image_files::write_exr(out, s.width, s.height, &image.pixels)?;
    // The white of the geometry, like the SMA's L_white (the largest cached sample, DESIGN.md §6):
    // a visible sun disc or sky must not darken the whole picture.
    let l_white = l_white.unwrap_or_else(|| {
        let seen = image.pixels.iter().zip(&image.covered).filter(|(_, c)| **c);
        image_files::max_luminance(seen.map(|(p, _)| *p))
    });
    image_files::write_png(
        &out.with_extension("png"),
        s.width,
        s.height,
        &image.pixels,
        l_white,
    )?;
    Ok((image, counts))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wavefront_images_are_the_same_with_and_without_packets() {
        let mut world = World::new(scene::load("bracara").expect("built-in bracara"));
        world.estimator = Estimator::Wavefront;
        let view = world.scene.settings.viewpoints[0].name.clone();
        let s = ReferenceSettings {
            width: 48,
            height: 32,
            spp: 8,
            bounces: Some(1),
            seed: 5,
        };
        let camera = camera_for(&world, &view, s.width, s.height).expect("the view");
        let [packets, single] = [true, false].map(|packets| {
            world.packets = packets;
            render(&world, &camera, &s, None)
        });
        assert_eq!(packets.1.total(), single.1.total(), "the same rays");
        assert_eq!(packets.0.covered, single.0.covered);
        // Only the order in which a path's shadow rays add their light may differ: rounding.
        for (a, b) in packets.0.pixels.iter().zip(&single.0.pixels) {
            let scale = a.max_element().max(1e-3);
            assert!((*a - *b).abs().max_element() <= 1e-5 * scale, "{a} vs {b}");
        }
        assert!(
            packets.0.covered.iter().any(|&c| c),
            "the view sees the scene"
        );
    }
}
