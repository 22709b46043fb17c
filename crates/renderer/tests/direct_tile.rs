//! A camera's direct light per pixel (`renderer::direct_tile`, DESIGN.md §5): a tile over a flat
//! sunlit floor agrees with the vertices' direct part there (times the floor's albedo), and a tile over a shadow's edge
//! keeps it sharp.

mod common;

use common::*;
use glam::Vec3;
use protocol::direct_tile::{DirectLights, TileAnswer, TileRect, TileRequest};
use protocol::renderer_link::Quality;
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use renderer::direct_tile::trace_tile;
use renderer::sampling::stream;
use renderer::{RayCounts, World, shade_point};
use scene::{SceneBuilder, Sky};

const SKY: [f32; 3] = [0.5; 3];
/// The albedo of every surface of [`sunlit_box`]: a vertex's direct part is illumination, a
/// tile's is radiance (the albedo at the pixel times it).
const ALBEDO: f32 = 0.5;

/// A floor with a box on it under a sun and a uniform sky.
fn sunlit_box() -> World {
    let mut b = SceneBuilder::new(settings(
        Some(sun(Vec3::new(0.3, 1.0, 0.2), 1.0e5)),
        Sky::Uniform { radiance: SKY },
    ));
    let g = b.material(grey(ALBEDO));
    floor(&mut b, Vec3::ZERO, 5.0, g);
    cube(
        &mut b,
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 1.0, 1.0),
        false,
        g,
    );
    world(b)
}

/// A camera looking straight down at `target` on the floor from 3 m above it.
fn looking_down(target: Vec3, fov_y_deg: f32, side: u32) -> Camera {
    let vp = Viewpoint {
        name: "down".into(),
        eye: (target + Vec3::Y * 3.0).to_array(),
        target: target.to_array(),
        up: [0.0, 0.0, -1.0],
        fov_y_deg,
    };
    Camera::from_viewpoint(&vp, 7, side, side)
}

fn whole_image(
    world: &World,
    camera: &Camera,
    lights: DirectLights,
    spp: u32,
    pass: u32,
) -> TileAnswer {
    let request = TileRequest {
        tile_id: 1,
        camera: camera.clone(),
        rect: TileRect {
            x: 0,
            y: 0,
            width: camera.width,
            height: camera.height,
        },
        samples_per_pixel: spp,
        pass,
        lights,
    };
    let (answer, _) = trace_tile(world, &request);
    answer
}

/// The tile's luminance averaged over its pixels, with the standard error of that mean.
fn mean_luminance(tile: &TileAnswer) -> (f64, f64) {
    let n = tile.pixels.len() as f64;
    let mean = tile
        .pixels
        .iter()
        .map(|p| f64::from(conventions::luminance(p.rgb)))
        .sum::<f64>()
        / n;
    let variance_of_mean = tile
        .pixels
        .iter()
        .map(|p| f64::from(p.luminance_variance) / f64::from(tile.samples_per_pixel))
        .sum::<f64>()
        / (n * n);
    (mean, variance_of_mean.sqrt())
}

#[test]
fn a_tile_on_a_flat_sunlit_floor_matches_the_vertex_direct_part() {
    let w = sunlit_box();
    let spot = Vec3::new(3.0, 0.0, 3.0);
    let camera = looking_down(spot, 4.0, 16);
    let point = point_hit_by(&w, spot + Vec3::Y * 2.0, Vec3::NEG_Y);
    let paths = 4096;
    let quality = Quality {
        paths,
        bounces: Some(0),
    };
    let mut counts = RayCounts::default();
    let vertex = shade_point(&w, &point, quality, &mut stream(1, 0), &mut counts).parts;
    let albedo = f64::from(ALBEDO);
    let vertex_mean = albedo * f64::from(conventions::luminance(vertex.direct.rgb));
    let vertex_error =
        albedo * (f64::from(vertex.direct.luminance_variance) / f64::from(paths)).sqrt();

    let all = whole_image(&w, &camera, DirectLights::All, 16, 0);
    all.check(camera.width, camera.height)
        .expect("a valid answer");
    let (tile_mean, tile_error) = mean_luminance(&all);
    let bound = 4.0 * tile_error.hypot(vertex_error) + 1e-4 * vertex_mean;
    assert!(
        (tile_mean - vertex_mean).abs() <= bound,
        "tile {tile_mean} ± {tile_error}, vertex {vertex_mean} ± {vertex_error}"
    );
    assert!(vertex_mean > 0.5, "the spot is sunlit: {vertex_mean}");

    // Without emitters, the sun and the sky are all the direct light there is; the sun alone
    // leaves the sky's part out.
    let (sun_sky, sun_sky_error) =
        mean_luminance(&whole_image(&w, &camera, DirectLights::SunSky, 16, 0));
    assert!(
        (sun_sky - tile_mean).abs() <= 4.0 * sun_sky_error.hypot(tile_error) + 1e-4 * tile_mean,
        "sun and sky {sun_sky}, all {tile_mean}"
    );
    let (sun_only, _) = mean_luminance(&whole_image(&w, &camera, DirectLights::Sun, 16, 0));
    let sky_part = f64::from(conventions::luminance(SKY)) * 0.5 * 0.5;
    assert!(
        sun_only < tile_mean - 0.5 * sky_part,
        "the sun alone {sun_only}, all {tile_mean}"
    );
}

#[test]
fn a_tile_over_a_shadow_edge_keeps_it_sharp_and_passes_differ() {
    let w = sunlit_box();
    // The box's top edge at x = -1 casts its shadow's edge near x = -1.3 on the floor.
    let camera = looking_down(Vec3::new(-1.3, 0.0, 0.0), 10.0, 16);
    let sun = whole_image(&w, &camera, DirectLights::Sun, 4, 0);
    let luminance: Vec<f32> = sun
        .pixels
        .iter()
        .map(|p| conventions::luminance(p.rgb))
        .collect();
    let dark = luminance.iter().filter(|&&l| l == 0.0).count();
    let lit = luminance.iter().filter(|&&l| l > 0.5).count();
    assert!(dark >= 32 && lit >= 32, "{dark} dark and {lit} lit pixels");

    let again = whole_image(&w, &camera, DirectLights::All, 4, 0);
    assert_eq!(
        again.pixels,
        whole_image(&w, &camera, DirectLights::All, 4, 0).pixels
    );
    assert_ne!(
        again.pixels,
        whole_image(&w, &camera, DirectLights::All, 4, 1).pixels
    );
}
