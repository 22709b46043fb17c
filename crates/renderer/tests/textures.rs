//! Diffuse textures in the path tracer (DESIGN.md §5): the albedo at every path vertex is read
//! from the material's texture, in shading samples and reference images alike; a material
//! without one is shaded exactly as before, and so is one whose texture is missing. Past a
//! diffuse bounce the texture is read prefiltered over the path's cone (DESIGN.md §5, "Texture
//! detail past the first vertex").

mod common;

use std::collections::HashMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use common::*;
use glam::Vec3;
use protocol::renderer_link::Quality;
use renderer::reference::{Image, ReferenceSettings, camera_for, render};
use renderer::sampling::stream;
use renderer::{RayCounts, World, shade_point};
use scene::{Scene, load_scene_file_from};

/// Sun radiance; straight above, so every point of the quads receives radiance × solid angle.
const SUN: f32 = 2.0e4;
const SIZE: u32 = 32;

/// 4 × 4 texels in four 2 × 2 blocks (sRGB codes): red-ish, green-ish above; blue-ish, grey below.
const BLOCKS: [[u8; 3]; 4] = [[200, 40, 40], [40, 200, 40], [40, 40, 200], [128, 128, 128]];

fn texture_png() -> Vec<u8> {
    let texels: Vec<[u8; 3]> = (0..16).map(|i| BLOCKS[(i / 8) * 2 + (i % 4) / 2]).collect();
    png(&texels, 4, 4)
}

/// A PNG of `texels`, row by row from the top.
fn png(texels: &[[u8; 3]], width: u32, height: u32) -> Vec<u8> {
    let image = image::RgbImage::from_raw(width, height, texels.concat()).expect("sizes");
    let mut bytes = Cursor::new(Vec::new());
    image
        .write_to(&mut bytes, image::ImageFormat::Png)
        .expect("encodes");
    bytes.into_inner()
}

/// The vertices of two unit quads in the y = 0 plane, facing up: `textured` on x in 0..1 (u = x, v = 1 - z, so
/// the image's top edge lies along z = 0) and `plain` on x in 1..2. Coplanar, they exchange no
/// light. Viewpoints look straight down, with -z at the image's top: `textured` fills view
/// `top`; `both` sees the two quads side by side.
const OBJ: &str = "v 0 0 0
v 1 0 0
v 1 0 1
v 0 0 1
v 2 0 0
v 2 0 1
";

/// An OBJ of `vertices`, whose first four are a quad of material `textured` (texture
/// coordinates (0, 1), (1, 1), (1, 0), (0, 0) at its corners in turn), and the faces
/// `plain_faces` of material `plain`.
fn obj(vertices: &str, plain_faces: &str) -> String {
    format!(
        "mtllib m.mtl\n{vertices}vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\n\
         usemtl textured\nf 1/1 4/4 3/3\nf 1/1 3/3 2/2\nusemtl plain\n{plain_faces}"
    )
}

fn toml(textures: &str) -> String {
    format!(
        "name = \"textured\"\nobj = \"t.obj\"\n\
         [sun]\ndirection = [0.0, 1.0, 0.0]\nradiance = [{SUN}, {SUN}, {SUN}]\n\
         angular_diameter_deg = 0.53\n\
         [[viewpoint]]\nname = \"top\"\neye = [0.5, 1.0, 0.5]\ntarget = [0.5, 0.0, 0.5]\n\
         up = [0.0, 0.0, -1.0]\nfov_y_deg = 45.0\n\
         [[viewpoint]]\nname = \"both\"\neye = [1.0, 0.8, 0.5]\ntarget = [1.0, 0.0, 0.5]\n\
         up = [0.0, 0.0, -1.0]\nfov_y_deg = 60.0\n\
         [textures]\n{textures}\n"
    )
}

const MTL: &str = "newmtl textured\nKd 0.8 0.8 0.8\nmap_Kd blocks.png\n\
                   newmtl plain\nKd 0.3 0.5 0.7\n";

fn load(toml: &str, mtl: &str, texture: Option<Vec<u8>>) -> Scene {
    load_with_obj(&obj(OBJ, "f 2 3 6\nf 2 6 5\n"), toml, mtl, texture)
}

fn load_with_obj(obj: &str, toml: &str, mtl: &str, texture: Option<Vec<u8>>) -> Scene {
    let dir = Path::new("s");
    let mut files: HashMap<PathBuf, Vec<u8>> = [
        ("t.toml", toml.as_bytes().to_vec()),
        ("t.obj", obj.as_bytes().to_vec()),
        ("m.mtl", mtl.as_bytes().to_vec()),
    ]
    .into_iter()
    .map(|(name, bytes)| (dir.join(name), bytes))
    .collect();
    if let Some(png) = texture {
        files.insert(dir.join("blocks.png"), png);
    }
    load_scene_file_from(&files, &dir.join("t.toml")).expect("the scene loads")
}

fn textured_world(textures: &str) -> World {
    World::new(load(&toml(textures), MTL, Some(texture_png())))
}

/// Radiance leaving a Lambertian surface of albedo `albedo` lit by the sun overhead.
fn lit(albedo: Vec3) -> Vec3 {
    // 1 - cos of the half angle, without cancellation.
    let half = 0.5 * 0.53f64.to_radians();
    let solid_angle = 2.0 * std::f64::consts::PI * 2.0 * (0.5 * half).sin().powi(2);
    albedo * (f64::from(SUN) * solid_angle / std::f64::consts::PI) as f32
}

fn lin(code: u8) -> f32 {
    conventions::tone_map::srgb_decode(f32::from(code) / 255.0)
}

fn reference(world: &World, view: &str, bounces: Option<u32>) -> Image {
    let camera = camera_for(world, view, SIZE, SIZE).expect("view");
    let settings = ReferenceSettings {
        width: SIZE,
        height: SIZE,
        spp: 8,
        bounces,
        seed: 11,
    };
    render(world, &camera, &settings, None).0
}

/// Mean of the pixels whose centres fall, in texture coordinates of view `top`, within the
/// middle of the block at column `bx`, row `by` (u, v plateaus where bilinear lookup reads only
/// that block's texels).
fn block_mean(image: &Image, bx: usize, by: usize) -> Vec3 {
    // View `top`: the quad spans 2 tan(22.5°) of its unit size across the image.
    let half = (22.5f32).to_radians().tan();
    let (mut sum, mut n) = (Vec3::ZERO, 0);
    for py in 0..SIZE {
        for px in 0..SIZE {
            let across = |p: u32| (2.0 * (p as f32 + 0.5) / SIZE as f32 - 1.0) * half + 0.5;
            // u grows to the right; image rows grow down toward +z, where v falls.
            let (u, down) = (across(px), across(py));
            let centre = |i: usize, t: f32| (t - (0.25 + 0.5 * i as f32)).abs() < 0.08;
            if centre(bx, u) && centre(by, down) {
                sum += image.pixels[(py * SIZE + px) as usize];
                n += 1;
            }
        }
    }
    assert!(n >= 4, "{n} pixels in block ({bx}, {by})");
    sum / n as f32
}

#[test]
fn a_textured_quad_under_the_sun_shows_its_texture_in_the_reference_image() {
    let world = textured_world("enabled = true");
    with_each_estimator(world, |w| {
        let image = reference(w, "top", Some(2));
        assert!(image.covered.iter().all(|&c| c));
        for (k, code) in BLOCKS.iter().enumerate() {
            let expected = lit(0.8 * Vec3::from(code.map(lin)));
            let got = block_mean(&image, k % 2, k / 2);
            let error = ((got - expected).abs() / expected.max(Vec3::splat(1e-3))).max_element();
            assert!(error < 1e-3, "block {k}: {got} vs {expected}");
        }
    });
}

#[test]
fn the_albedo_rule_texture_takes_the_texel_alone() {
    let world = textured_world("enabled = true\nalbedo = \"texture\"");
    let image = reference(&world, "top", Some(0));
    let expected = lit(Vec3::from(BLOCKS[1].map(lin)));
    let got = block_mean(&image, 1, 0);
    assert!(
        ((got - expected).abs() / expected.max(Vec3::splat(1e-3))).max_element() < 1e-3,
        "{got} vs {expected}"
    );
}

/// Pixels of view `both` (columns right of the middle, with a margin) see only `plain`.
fn plain_pixels(image: &Image) -> Vec<Vec3> {
    (0..SIZE)
        .flat_map(|y| (SIZE / 2 + 2..SIZE).map(move |x| (y * SIZE + x) as usize))
        .map(|i| image.pixels[i])
        .collect()
}

fn textured_pixels(image: &Image) -> Vec<Vec3> {
    (0..SIZE)
        .flat_map(|y| (0..SIZE / 2 - 2).map(move |x| (y * SIZE + x) as usize))
        .map(|i| image.pixels[i])
        .collect()
}

#[test]
fn a_material_without_a_texture_keeps_its_colour_exactly_beside_a_textured_one() {
    let on = textured_world("enabled = true");
    let off = textured_world("enabled = false");
    assert!(off.scene.materials.iter().all(|m| m.diffuse_map.is_none()));
    for estimator in renderer::estimator::Estimator::ALL {
        let (mut on, mut off) = (textured_world("enabled = true"), textured_world(""));
        on.estimator = estimator;
        off.estimator = estimator;
        let with = reference(&on, "both", Some(2));
        let without = reference(&off, "both", Some(2));
        assert_eq!(plain_pixels(&with), plain_pixels(&without), "{estimator:?}");
        assert_ne!(textured_pixels(&with), textured_pixels(&without));
        assert!(with.covered.iter().all(|&c| c));
        let expected = lit(Vec3::new(0.3, 0.5, 0.7));
        for p in plain_pixels(&with) {
            assert!(
                p.abs_diff_eq(expected, 1e-3 * expected.x),
                "{p} vs {expected}"
            );
        }
    }
    // Shading samples alike: a point on `plain`, and one on `textured` in the red block.
    let quality = Quality {
        paths: 16,
        bounces: Some(2),
    };
    let shade = |w: &World, x: f32, z: f32| {
        let p = point_hit_by(w, Vec3::new(x, 1.0, z), Vec3::NEG_Y);
        let mut counts = RayCounts::default();
        shade_point(w, &p, quality, &mut stream(5, 0), &mut counts).rgb
    };
    assert_eq!(shade(&on, 1.5, 0.5), shade(&off, 1.5, 0.5));
    let red = shade(&on, 0.25, 0.25);
    let expected = lit(0.8 * Vec3::from(BLOCKS[0].map(lin)));
    assert!(
        red.abs_diff_eq(expected, 1e-3 * expected.max_element()),
        "{red} vs {expected}"
    );
    let untextured = shade(&off, 0.25, 0.25);
    assert!(untextured.abs_diff_eq(lit(Vec3::splat(0.8)), 1e-3 * untextured.x));
}

#[test]
fn a_missing_texture_falls_back_to_kd() {
    let missing = load(&toml("enabled = true"), MTL, None);
    assert_eq!(
        missing.report.warnings.len(),
        1,
        "{:?}",
        missing.report.warnings
    );
    assert!(missing.report.warnings[0].contains("blocks.png"));
    let without_map = load(
        &toml("enabled = true"),
        &MTL.replace("map_Kd blocks.png\n", ""),
        None,
    );
    let (missing, without_map) = (World::new(missing), World::new(without_map));
    let a = reference(&missing, "both", Some(2));
    let b = reference(&without_map, "both", Some(2));
    assert_eq!(a.pixels, b.pixels);
}

/// The vertices of a 4 m floor under a 256 × 256 texture, and 2 m above it a 1 m plain board facing down, lit by
/// the sun overhead: the board sees the floor only through a diffuse bounce.
const BOARD_OVER_FLOOR: &str = "v -2 0 -2
v 2 0 -2
v 2 0 2
v -2 0 2
v -0.5 2 -0.5
v 0.5 2 -0.5
v 0.5 2 0.5
v -0.5 2 0.5
";

/// The board's shading over a floor textured with `texels` (256 × 256, row by row).
fn board_shading(texels: &[[u8; 3]]) -> (Vec3, World) {
    let mtl = "newmtl textured\nKd 1 1 1\nmap_Kd blocks.png\nnewmtl plain\nKd 0.5 0.5 0.5\n";
    let scene = load_with_obj(
        &obj(BOARD_OVER_FLOOR, "f 5 6 7\nf 5 7 8\n"),
        &toml("enabled = true"),
        mtl,
        Some(png(texels, 256, 256)),
    );
    let world = World::new(scene);
    let p = point_hit_by(&world, Vec3::new(0.1, 1.0, 0.2), Vec3::Y);
    let quality = Quality {
        paths: 256,
        bounces: Some(2),
    };
    let mut counts = RayCounts::default();
    let rgb = shade_point(&world, &p, quality, &mut stream(3, 0), &mut counts).rgb;
    (rgb, world)
}

#[test]
fn past_a_diffuse_bounce_a_fine_checker_reads_as_its_mean() {
    // Black and white texels 1.6 cm wide: a floor vertex reached from the board, 2 m away or
    // more, stands for a cone some 6 cm wide there, where the checker is read as its mean.
    let checker: Vec<[u8; 3]> = (0..256 * 256)
        .map(|i| {
            if (i % 256 + i / 256) % 2 == 0 {
                [0; 3]
            } else {
                [255; 3]
            }
        })
        .collect();
    // The code of linear 0.5, the checker's mean as its prefiltered levels store it.
    let mean = [188; 3];
    let (through_checker, world) = board_shading(&checker);
    let (through_uniform, _) = board_shading(&vec![mean; 256 * 256]);
    assert!(through_checker.min_element() > 0.0);
    // The same paths, and at every floor vertex the same albedo: the same estimate exactly.
    // Read texel by texel, each path would see black or white and the two would differ by the
    // estimate's noise, several per cent at 256 paths.
    assert_eq!(through_checker, through_uniform);
    // Seen directly, the floor keeps its texels.
    // Near two neighbouring texels' centres (one texel is 4 m / 256), read bilinearly.
    let texel = 4.0 / 256.0;
    let floor = |x: f32| {
        let p = point_hit_by(&world, Vec3::new(x, 1.0, 0.5 * texel), Vec3::NEG_Y);
        let s = renderer::point::surface_of(&world, &p).expect("on the floor");
        world.albedo_at(&s)
    };
    let (a, b) = (floor(1.0 + 0.5 * texel), floor(1.0 + 1.5 * texel));
    assert!((a - b).abs().min_element() > 0.75, "{a} beside {b}");
}

/// A renderer and an SMA whose textures differ are refused at the handshake: one with textures
/// off, or one whose textures are other files. The same scene is welcome.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_sma_with_other_textures_is_refused_at_the_handshake() {
    use protocol::ProtocolError;
    use protocol::frame::DEFAULT_MAX_FRAME;
    use renderer::service::Service;

    let world = std::sync::Arc::new(textured_world("enabled = true"));
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let service = Service::new(std::sync::Arc::clone(&world), 1, DEFAULT_MAX_FRAME).unwrap();
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = tokio::spawn(service.serve(listener, async {
        let _ = stopped.await;
    }));

    // The same scene with textures off; and on, with another image in the texture's file.
    let untextured = identity(&load(&toml(""), MTL, Some(texture_png())));
    let grey = png(&[[128, 128, 128]; 16], 4, 4);
    let other_files = identity(&load(&toml("enabled = true"), MTL, Some(grey)));
    for (theirs, reason) in [
        (untextured, "textures mismatch: ours on, peer's off"),
        (other_files, "fingerprint mismatch"),
    ] {
        let refused = connect_as_sma(addr, theirs).await.err();
        assert!(
            matches!(&refused, Some(ProtocolError::Refused(r)) if r.contains(reason)),
            "expected a refusal naming {reason:?}, got {refused:?}"
        );
    }
    let welcome = connect_as_sma(addr, world.identity()).await;
    assert!(welcome.is_ok(), "{:?}", welcome.err());
    drop(welcome);
    stop.send(()).unwrap();
    tokio::time::timeout(std::time::Duration::from_secs(10), server)
        .await
        .expect("the server stops")
        .unwrap()
        .unwrap();
}
