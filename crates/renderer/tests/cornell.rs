//! The built-in Cornell box (DESIGN.md §7): Monte Carlo error falls like 1/sqrt(paths), and
//! a reference image of view `main` has the regions the scene is known for.

mod common;

use common::*;
use glam::Vec3;
use protocol::renderer_link::Quality;
use renderer::estimator::Estimator;
use renderer::reference::{Image, ReferenceSettings, camera_for, render};
use renderer::sampling::{luminance, stream};
use renderer::{FirstBounce, RayCounts, World, shade_point};

fn cornell() -> World {
    World::new(scene::load("cornell").expect("built-in cornell"))
}

#[test]
fn error_falls_like_one_over_sqrt_paths() {
    with_each_estimator(cornell(), |w| {
        // A floor point in the open, lit directly and by the walls.
        let p = point_hit_by(w, Vec3::new(0.4, 0.3, 0.15), Vec3::NEG_Y);
        let bounces = Some(2);
        let estimate = |paths: u32, seed: u64| {
            let q = Quality { paths, bounces };
            luminance(shade_point(w, &p, q, &mut stream(seed, 0), &mut RayCounts::default()).rgb)
                as f64
        };
        let truth = estimate(65_536, 999);
        let levels = [4u32, 16, 64, 256];
        // Enough repetitions that the heavy tail of a 4-path estimate (a few paths find the
        // light) does not swing the slope.
        let repeats = 192;
        let rms: Vec<f64> = levels
            .iter()
            .map(|&paths| {
                let sq: f64 = (0..repeats)
                    .map(|r| (estimate(paths, 1000 + r) - truth).powi(2))
                    .sum();
                (sq / repeats as f64).sqrt()
            })
            .collect();
        // Least-squares slope of log(rms) against log(paths).
        let xs: Vec<f64> = levels.iter().map(|&p| (p as f64).ln()).collect();
        let ys: Vec<f64> = rms.iter().map(|r| r.ln()).collect();
        let (mx, my) = (xs.iter().sum::<f64>() / 4.0, ys.iter().sum::<f64>() / 4.0);
        let slope = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (x - mx) * (y - my))
            .sum::<f64>()
            / xs.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
        assert!((slope + 0.5).abs() < 0.12, "slope {slope}, rms {rms:?}");
    });
}

/// Stratified first bounces (`strata`) estimate the same radiance with less error at equal paths:
/// on a ceiling point beside the light, lit only by the room (all its light comes through the
/// first bounce), 64 stratified paths beat 64 independent ones, and their means over many
/// repetitions agree (no bias).
#[test]
fn stratified_first_bounces_lower_the_error_not_the_mean() {
    let mut w = cornell();
    for estimator in Estimator::ALL {
        w.estimator = estimator;
        let p = point_hit_by(&w, Vec3::new(0.15, 0.3, 0.2), Vec3::Y);
        let estimate = |w: &World, paths: u32, seed: u64| {
            let q = Quality {
                paths,
                bounces: Some(2),
            };
            luminance(shade_point(w, &p, q, &mut stream(seed, 0), &mut RayCounts::default()).rgb)
                as f64
        };
        w.first_bounce = FirstBounce::Independent;
        let truth = estimate(&w, 65_536, 999);
        let repeats = 256;
        let [independent, stratified] =
            [FirstBounce::Independent, FirstBounce::Stratified].map(|mode| {
                w.first_bounce = mode;
                let values: Vec<f64> = (0..repeats).map(|r| estimate(&w, 64, 5000 + r)).collect();
                let mean = values.iter().sum::<f64>() / repeats as f64;
                let rms = (values.iter().map(|v| (v - truth).powi(2)).sum::<f64>()
                    / repeats as f64)
                    .sqrt();
                (mean, rms)
            });
        eprintln!(
            "{}: independent {independent:?}, stratified {stratified:?}, truth {truth}",
            estimator.name()
        );
        assert!(
            stratified.1 < 0.9 * independent.1,
            "{}: stratified rms {} against independent {}",
            estimator.name(),
            stratified.1,
            independent.1
        );
        // The mean of 256 estimates has a standard error of rms / 16: four of them.
        assert!(
            (stratified.0 - truth).abs() < 4.0 * stratified.1 / 16.0,
            "{}: stratified mean {} against {truth}",
            estimator.name(),
            stratified.0
        );
    }
}

/// Mean colour of the pixels whose centre ray hits a triangle for which `select` holds.
fn region_mean(w: &World, img: &Image, select: impl Fn(u32, Vec3) -> bool) -> (Vec3, usize) {
    let cam = camera_for(w, "main", img.width, img.height).unwrap();
    let mut sum = Vec3::ZERO;
    let mut n = 0;
    for y in 0..img.height {
        for x in 0..img.width {
            let dir = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
            if let Some(hit) = w
                .bvh
                .closest_hit(w.to_local(cam.eye_vec()), dir, f32::INFINITY)
                && select(hit.triangle, cam.eye_vec() + dir * hit.t)
            {
                sum += img.pixels[(y * img.width + x) as usize];
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f32, n)
}

fn material_name(w: &World, t: u32) -> &str {
    &w.scene.material_of(t as usize).name
}

/// Distance in the floor plane from (x, z) to the footprint of the nearer block, negative inside.
fn distance_to_blocks(p: Vec3) -> f32 {
    let blocks = [
        [(130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0)],
        [
            (423.0, 247.0),
            (265.0, 296.0),
            (314.0, 456.0),
            (472.0, 406.0),
        ],
    ];
    let q = glam::Vec2::new(p.x, p.z) * 1e3;
    blocks
        .iter()
        .map(|b| {
            let corners: Vec<glam::Vec2> = b.iter().map(|&(x, z)| glam::Vec2::new(x, z)).collect();
            let edge_distance = (0..4)
                .map(|i| {
                    let (a, c) = (corners[i], corners[(i + 1) % 4]);
                    let t = ((q - a).dot(c - a) / (c - a).length_squared()).clamp(0.0, 1.0);
                    q.distance(a + (c - a) * t)
                })
                .fold(f32::INFINITY, f32::min);
            let inside = (0..4).all(|i| {
                let (a, c) = (corners[i], corners[(i + 1) % 4]);
                let s = (c - a).perp_dot(q - a);
                let s0 = (corners[1] - corners[0]).perp_dot(corners[2] - corners[0]);
                s * s0 >= 0.0
            });
            if inside {
                -edge_distance
            } else {
                edge_distance
            }
        })
        .fold(f32::INFINITY, f32::min)
        * 1e-3
}

#[test]
fn reference_image_of_main_has_the_known_regions() {
    with_each_estimator(cornell(), |w| {
        let settings = ReferenceSettings {
            width: 80,
            height: 80,
            spp: 48,
            bounces: Some(3),
            seed: 1,
        };
        let cam = camera_for(w, "main", settings.width, settings.height).unwrap();
        let (img, counts) = render(w, &cam, &settings, None);
        assert!(counts.camera >= 80 * 80 * 48);
        assert!(
            img.pixels
                .iter()
                .all(|p| p.is_finite() && p.min_element() >= 0.0)
        );
        let (left, nl) = region_mean(w, &img, |t, _| material_name(w, t) == "red");
        let (right, nr) = region_mean(w, &img, |t, _| material_name(w, t) == "green");
        assert!(nl > 100 && nr > 100, "{nl} {nr}");
        assert!(
            left.x > 2.0 * left.y && left.x > 2.0 * left.z,
            "left wall {left}"
        );
        assert!(
            right.y > 1.5 * right.x && right.y > 1.5 * right.z,
            "right wall {right}"
        );
        // The red wall is on the image's left: the camera looks along +z, so image-left is +x.
        let left_px = (0..img.width / 4)
            .map(|x| img.pixels[(40 * img.width + x) as usize])
            .sum::<Vec3>();
        assert!(left_px.x > left_px.y, "{left_px}");
        let is_floor = |t: u32| w.face_normal(t).y.abs() > 0.99 && material_name(w, t) == "white";
        let (near, nn) = region_mean(w, &img, |t, p| {
            is_floor(t) && p.y < 0.01 && (0.0..0.02).contains(&distance_to_blocks(p))
        });
        let (open, no) = region_mean(w, &img, |t, p| {
            is_floor(t) && p.y < 0.01 && distance_to_blocks(p) > 0.08
        });
        assert!(nn > 10 && no > 100, "{nn} {no}");
        assert!(
            luminance(near) < 0.85 * luminance(open),
            "floor at the blocks {near} vs open floor {open}"
        );
        // Mean luminance is stable across seeds.
        let other = render(
            w,
            &cam,
            &ReferenceSettings {
                seed: 2,
                ..settings
            },
            None,
        )
        .0;
        let mean = |i: &Image| {
            i.pixels.iter().map(|&p| luminance(p) as f64).sum::<f64>() / i.pixels.len() as f64
        };
        let (a, b) = (mean(&img), mean(&other));
        assert!((a - b).abs() < 0.02 * a, "{a} vs {b}");
    });
}

#[test]
fn reference_files_are_written_and_read_back() {
    let w = cornell();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("main.exr");
    let s = ReferenceSettings {
        width: 24,
        height: 16,
        spp: 2,
        bounces: None,
        seed: 3,
    };
    let (img, _) = renderer::reference::render_to_files(&w, "main", &s, &out, None).unwrap();
    let back = renderer::image_files::read_exr(&out).unwrap();
    assert_eq!((back.width, back.height), (24, 16));
    assert_eq!(back.pixels, img.pixels);
    let png = image::open(out.with_extension("png")).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (24, 16));
    assert!(png.pixels().any(|p| p.0.iter().any(|&c| c > 0)));
    assert!(renderer::reference::render_to_files(&w, "no-such-view", &s, &out, None).is_err());
}

/// The two schedules of the estimator (DESIGN.md §7) render the same image in distribution:
/// pixel by pixel, independent renders (different seeds) differ by noise only, so the mean of
/// the per-pixel differences lies within a few of its standard errors of zero, a bound held
/// below 2 % of the image's mean so that a real shift would show.
#[test]
fn both_estimators_render_the_same_mean_luminance() {
    let mut w = cornell();
    let settings = ReferenceSettings {
        width: 128,
        height: 128,
        spp: 64,
        bounces: None,
        seed: 11,
    };
    let cam = camera_for(&w, "main", settings.width, settings.height).unwrap();
    let [path, wavefront] = [Estimator::Path, Estimator::Wavefront].map(|estimator| {
        w.estimator = estimator;
        let seed = settings.seed + estimator as u64;
        let (img, _) = render(&w, &cam, &ReferenceSettings { seed, ..settings }, None);
        img.pixels
            .iter()
            .map(|&p| luminance(p) as f64)
            .collect::<Vec<f64>>()
    });
    let differences: Vec<f64> = wavefront.iter().zip(&path).map(|(a, b)| a - b).collect();
    let (mean_difference, se) = mean_and_standard_error(&differences);
    let mean = path.iter().sum::<f64>() / path.len() as f64;
    assert!(
        4.0 * se < 0.02 * mean,
        "too noisy to tell: se {se}, mean {mean}"
    );
    assert!(
        mean_difference.abs() <= 4.0 * se,
        "wavefront - path = {mean_difference} (se {se}) on a mean of {mean}"
    );
}

/// A Cornell floor point in parts (DESIGN.md §5, "Parts, and textures"): the direct part is what a
/// direct-light-only sample estimates, the indirect part is the room's light and is not
/// nothing, both are illumination (the floor's albedo left out), and the floor's albedo times
/// their sum plus the view-dependent part is the radiance an independent estimate finds, within
/// noise; the two estimators agree part by part.
#[test]
fn parts_sum_to_the_radiance_and_the_direct_part_is_direct_light() {
    let mut w = cornell();
    let p = point_hit_by(&w, Vec3::new(0.4, 0.3, 0.15), Vec3::NEG_Y);
    let located = renderer::point::locate(&w, &p, &mut RayCounts::default()).expect("a point");
    let albedo = w.albedo_at(&located.surface);
    let shade = |w: &World, bounces: Option<u32>, seed: u64| {
        let q = Quality {
            paths: 16_384,
            bounces,
        };
        shade_point(w, &p, q, &mut stream(seed, 0), &mut RayCounts::default())
    };
    // Mean luminance and its standard error.
    let lum = |part: &protocol::PartEstimate, paths: u32| {
        let l = luminance(Vec3::from(part.rgb)) as f64;
        (
            l,
            (f64::from(part.luminance_variance) / f64::from(paths)).sqrt(),
        )
    };
    let within = |(a, ea): (f64, f64), (b, eb): (f64, f64), what: &str| {
        assert!(
            (a - b).abs() <= 4.0 * ea.hypot(eb),
            "{what}: {a} ± {ea} vs {b} ± {eb}"
        );
    };
    let mut by_estimator = Vec::new();
    for estimator in Estimator::ALL {
        w.estimator = estimator;
        let full = shade(&w, Some(2), 11);
        let direct_only = shade(&w, Some(0), 12);
        let other = shade(&w, Some(2), 13);
        let (direct, indirect) = (
            lum(&full.parts.direct, full.paths),
            lum(&full.parts.indirect, full.paths),
        );
        within(
            direct,
            lum(&direct_only.parts.direct, direct_only.paths),
            "direct part vs direct light only",
        );
        assert_eq!(direct_only.parts.indirect.rgb, [0.0; 3]);
        assert_eq!(full.parts.view_dependent.rgb, [0.0; 3], "a diffuse floor");
        assert!(indirect.0 > 10.0 * indirect.1, "indirect {indirect:?}");
        // The parts' radiance, with its error: the albedo scales the illumination's luminance
        // by about the albedo's luminance.
        let radiance = |s: &renderer::Shaded| {
            let l = luminance(Vec3::from(s.parts.radiance(albedo.to_array()))) as f64;
            let variance = s.parts.direct.luminance_variance + s.parts.indirect.luminance_variance;
            let scale = f64::from(luminance(albedo));
            (l, scale * (f64::from(variance) / f64::from(s.paths)).sqrt())
        };
        assert_eq!(radiance(&full).0, luminance(full.rgb) as f64);
        within(
            radiance(&full),
            lum(
                &protocol::PartEstimate {
                    rgb: other.rgb.to_array(),
                    luminance_variance: (radiance(&other).1.powi(2) * f64::from(other.paths))
                        as f32,
                },
                other.paths,
            ),
            "the parts' radiance vs an independent estimate",
        );
        by_estimator.push((direct, indirect));
    }
    within(
        by_estimator[0].0,
        by_estimator[1].0,
        "direct, path vs wavefront",
    );
    within(
        by_estimator[0].1,
        by_estimator[1].1,
        "indirect, path vs wavefront",
    );
}
