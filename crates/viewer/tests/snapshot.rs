//! Offscreen drawing of known triangles: expected pixel colours from the Rust tone maps of
//! `conventions::tone_map` (thesis eq. 4.1, 4.2), so the WGSL shader, which cannot import them, is
//! held to their values (luminance, both operators, sRGB) on a real wgpu device; Gouraud
//! interpolation; the depth test; the wireframe overlay; per-pixel direct tiles in place of the
//! vertices' direct part, for the resting camera only; and the headless binary writing its
//! snapshot files.

mod common;

use common::{StandIn, front_camera, known_triangles, scene};
use protocol::direct_tile::{TilePixel, TileRect, ViewerTile};
use protocol::viewer_link::{Camera, DirectShare, Epoch, ShownTriangle, SmaToViewer, ViewerToSma};
use viewer::direct_image::DirectImage;
use viewer::gpu::{Gpu, headless_or_skip};
use viewer::{
    DrawSettings, Snapshot, ToneMap, render_offscreen_with, render_offscreen_with_direct,
};

const W: u32 = 160;
const H: u32 = 120;
const L_WHITE: f32 = 4.0;

/// What the shader must draw: the Rust tone map of `conventions`, then 8-bit sRGB (unrounded, so
/// a tolerance of one level covers the GPU's rounding).
fn expected(rgb: [f32; 3], op: ToneMap) -> [f32; 3] {
    op.display_rgb(rgb, L_WHITE)
        .map(|c| conventions::tone_map::srgb_encode(c) * 255.0)
}

fn pixel(s: &Snapshot, x: u32, y: u32) -> [f32; 3] {
    let p = s.display.get_pixel(x, y).0;
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn assert_close(found: [f32; 3], want: [f32; 3], tol: f32, what: &str) {
    let ok = found.iter().zip(want).all(|(f, w)| (f - w).abs() <= tol);
    assert!(ok, "{what}: found {found:?}, expected {want:?} (±{tol})");
}

fn gpu(test: &str) -> Option<Gpu> {
    headless_or_skip(test).expect("a graphics adapter is required")
}

fn draw(gpu: &Gpu, op: ToneMap, wireframe: bool) -> Snapshot {
    let settings = DrawSettings {
        tone_map: op,
        l_white: L_WHITE,
        wireframe,
        ..DrawSettings::default()
    };
    render_offscreen_with(gpu, &known_triangles(), &front_camera(1, W, H), &settings).unwrap()
}

/// World x on the z = 0 plane seen through the centre of pixel column `px` (front camera).
fn world_x(px: u32) -> f32 {
    let half_width = 3.0 * 30f32.to_radians().tan() * W as f32 / H as f32;
    ((px as f32 + 0.5) / W as f32 * 2.0 - 1.0) * half_width
}

#[test]
fn known_triangles_have_the_expected_colours() {
    let Some(gpu) = gpu("known_triangles_have_the_expected_colours") else {
        return;
    };
    for op in [ToneMap::Drago, ToneMap::Reinhard] {
        let s = draw(&gpu, op, false);
        let flat = [2.0, 0.8, 0.3];
        assert_close(
            pixel(&s, 55, 70),
            expected(flat, op),
            1.0,
            &format!("{op:?} flat square"),
        );
        assert_close(
            pixel(&s, 34, 50),
            expected([0.1, 0.9, 0.1], op),
            1.0,
            "occluder in front",
        );
        assert_close(pixel(&s, 5, 5), [0.0; 3], 0.0, "background");
        // Gouraud: radiance grows linearly in x from 0.2 (x = 0.2) to 4.0 (x = 1.4).
        for px in [92, 105, 125] {
            let l = 0.2 + 3.8 * (world_x(px) - 0.2) / 1.2;
            assert_close(
                pixel(&s, px, 60),
                expected([l; 3], op),
                1.0,
                &format!("{op:?} ramp x={px}"),
            );
        }
    }
}

#[test]
fn the_linear_image_holds_the_radiance() {
    let Some(gpu) = gpu("the_linear_image_holds_the_radiance") else {
        return;
    };
    let s = draw(&gpu, ToneMap::Drago, true);
    let at = |x: u32, y: u32| s.linear[(y * W + x) as usize];
    // Relative 1e-3: GL draws linear radiance in half floats (Vulkan in full floats).
    let near = |c: f32, w: f32| (c - w).abs() <= 1e-3 * w;
    let flat = at(55, 70);
    assert!(
        flat.iter().zip([2.0, 0.8, 0.3]).all(|(&c, w)| near(c, w)),
        "{flat:?}"
    );
    assert_eq!(at(5, 5), [0.0; 3]);
    let l = 0.2 + 3.8 * (world_x(105) - 0.2) / 1.2;
    let ramp = at(105, 60);
    assert!(
        ramp.iter().all(|&c| (c - l).abs() < 2e-3 * l),
        "{ramp:?} vs {l}"
    );
}

#[test]
fn the_wireframe_marks_edges_only() {
    let Some(gpu) = gpu("the_wireframe_marks_edges_only") else {
        return;
    };
    let plain = draw(&gpu, ToneMap::Drago, false);
    let wire = draw(&gpu, ToneMap::Drago, true);
    // The left square's diagonal and borders change; its interior away from edges does not.
    let changed = (0..W)
        .flat_map(|x| (0..H).map(move |y| (x, y)))
        .filter(|&(x, y)| plain.display.get_pixel(x, y) != wire.display.get_pixel(x, y))
        .count();
    assert!(changed > 200, "only {changed} pixels show edges");
    assert_eq!(
        plain.display.get_pixel(62, 75),
        wire.display.get_pixel(62, 75)
    );
}

#[test]
fn headless_binary_writes_snapshots_when_the_sma_is_idle() {
    let Some(gpu) = gpu("headless_binary_writes_snapshots_when_the_sma_is_idle") else {
        return;
    };
    let sma = StandIn::start(scene());
    let out = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args([
            "--connect",
            &sma.addr,
            "--headless",
            "--view",
            "front",
            "--snapshot-when-idle",
        ])
        .args([
            "--width",
            &W.to_string(),
            "--height",
            &H.to_string(),
            "--seconds",
            "60",
        ])
        .args(["--criterion", "nld_is", "--no-refine", "--out"])
        .arg(out.path())
        .spawn()
        .unwrap();
    let camera = sma.expect_camera();
    assert_eq!(camera, front_camera(camera.seq, W, H));
    let criterion = sma.expect("criterion", |s| match s {
        common::Seen::Message(ViewerToSma::SetCriterion { name }) => Some(name),
        _ => None,
    });
    assert_eq!(criterion, "nld_is");
    sma.expect("pause", |s| {
        matches!(s, common::Seen::Message(ViewerToSma::Pause)).then_some(())
    });
    let triangles = known_triangles();
    let n = triangles.len() as u64;
    sma.send(SmaToViewer::Insert {
        triangles: triangles.clone(),
    });
    sma.send(SmaToViewer::ToneMap { l_white: L_WHITE });
    let epoch = Epoch {
        camera_seq: camera.seq,
        shown: n,
        inserted: n,
        samples: 42,
        paths: 2688,
        ..Epoch::default()
    };
    sma.send(SmaToViewer::Epoch(epoch));
    let status = child.wait().unwrap();
    assert!(status.success(), "viewer exited with {status}");

    let csv = std::fs::read_to_string(out.path().join("snapshots.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows.len(), 2, "{csv}");
    let fields: Vec<&str> = rows[1].split(',').collect();
    let (seq, n) = (camera.seq.to_string(), n.to_string());
    assert_eq!(
        fields[2..27],
        [
            seq.as_str(),
            &n,
            &n,
            "0",
            "42",
            "2688",
            "0",
            "0.000",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "0",
            "",
            "0",
            "",
            "",
            "0",
            "0"
        ]
    );

    let png = image::open(out.path().join(fields[27]))
        .unwrap()
        .into_rgb8();
    let settings = DrawSettings {
        tone_map: ToneMap::Drago,
        l_white: L_WHITE,
        wireframe: false,
        sky: common::SKY,
    };
    let want = render_offscreen_with(&gpu, &triangles, &camera, &settings).unwrap();
    assert_sky_pixels(&png, &want);
    let same = png
        .pixels()
        .zip(want.display.pixels())
        .all(|(a, b)| a.0[..3] == b.0[..3]);
    assert!(same, "the snapshot differs from the offscreen drawing");

    let exr = exr::prelude::read_first_rgba_layer_from_file(
        out.path().join(fields[28]),
        |size, _| vec![([0f32; 3], false); size.width() * size.height()],
        |pixels, pos, (r, g, b, a): (f32, f32, f32, f32)| {
            pixels[pos.y() * W as usize + pos.x()] = ([r, g, b], a > 0.5)
        },
    )
    .unwrap();
    let (linear, covered): (Vec<_>, Vec<_>) =
        exr.layer_data.channel_data.pixels.into_iter().unzip();
    assert_eq!(linear, want.linear);
    assert_eq!(covered, want.covered, "the EXR's alpha is the coverage");
}

/// The snapshot's sky: the scene's sky radiance tone-mapped like the geometry above the horizon,
/// black below it, the sun's disc white; those pixels count as seeing no geometry.
fn assert_sky_pixels(png: &image::RgbImage, drawn: &Snapshot) {
    let at = |x: u32, y: u32| png.get_pixel(x, y).0.map(f32::from);
    let sky = expected(common::SKY.radiance, ToneMap::Drago);
    assert!(sky.iter().all(|c| *c > 20.0), "the test's sky is not dark");
    assert_close(at(5, 5), sky, 1.0, "sky above the horizon");
    assert_close(at(W - 5, 50), sky, 1.0, "sky beside the triangles");
    assert_close(at(5, H - 5), [0.0; 3], 0.0, "below the horizon");
    // The sun 25° above the centre: tan 25° / tan 30° of the half height above it.
    let sun_row =
        (H as f32 / 2.0 * (1.0 - 25f32.to_radians().tan() / 30f32.to_radians().tan())) as u32;
    assert_close(at(W / 2, sun_row), [255.0; 3], 0.0, "the sun's disc");
    let covered = |x: u32, y: u32| drawn.covered[(y * W + x) as usize];
    assert!(!covered(5, 5) && !covered(W / 2, sun_row) && !covered(5, H - 5));
    assert!(covered(55, 70), "the flat square sees geometry");
}

#[test]
fn headless_binary_follows_a_camera_path_and_snapshots_periodically() {
    let test = "headless_binary_follows_a_camera_path_and_snapshots_periodically";
    let Some(_gpu) = gpu(test) else { return };
    let sma = StandIn::start(scene());
    let out = tempfile::tempdir().unwrap();
    let path = out.path().join("walk.txt");
    std::fs::write(&path, "# walk in\n0  0 0 3  0 0 0\n0.4  0 0 1  0 0 0  45\n").unwrap();
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args([
            "--connect",
            &sma.addr,
            "--headless",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .args(["--snapshot-every", "0.5", "--seconds", "1", "--camera-path"])
        .arg(&path)
        .arg("--out")
        .arg(out.path().join("snaps"))
        .status()
        .unwrap();
    assert!(status.success(), "viewer exited with {status}");
    // Everything the viewer sent, up to the end of its session.
    let mut cameras = Vec::new();
    sma.expect("the end of the session", |s| match s {
        common::Seen::Message(ViewerToSma::Camera(c)) => {
            cameras.push(c);
            None
        }
        common::Seen::Ended => Some(()),
        _ => None,
    });
    assert!(cameras.len() >= 2, "{cameras:?}");
    assert!(
        cameras
            .windows(2)
            .all(|w| w[1].seq > w[0].seq && w[1].eye[2] < w[0].eye[2])
    );
    let last = cameras.last().unwrap();
    assert_eq!(
        (last.eye, last.fov_y_deg),
        ([0.0, 0.0, 1.0], 45.0),
        "the walk ends where the path does"
    );

    let csv = std::fs::read_to_string(out.path().join("snaps/snapshots.csv")).unwrap();
    let times: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    assert!(
        times.len() >= 2 && times[0] < 0.5 && times.windows(2).all(|w| w[1] > w[0]),
        "{times:?}"
    );
}

/// The known triangles and the camera moved by (1e5, 0, 1e5), where f32 spacing is about 0.008,
/// draw the centred picture (DESIGN.md §7: also far from the origin). Both copies come from the
/// same f32 positions (the centred one is the far one moved back, which is exact), so any
/// difference is the drawing's. With world positions and a matrix holding the 1e5 translation,
/// 298 of the 19,200 pixels changed (on Mesa, both backends).
#[test]
fn a_scene_far_from_the_origin_draws_the_centred_picture() {
    let Some(gpu) = gpu("a_scene_far_from_the_origin_draws_the_centred_picture") else {
        return;
    };
    let offset = glam::Vec3::new(1.0e5, 0.0, 1.0e5);
    let moved = |triangles: &[protocol::viewer_link::ShownTriangle], by: glam::Vec3| {
        let mut triangles = triangles.to_vec();
        for t in &mut triangles {
            t.positions = t.positions.map(|p| (glam::Vec3::from(p) + by).to_array());
        }
        triangles
    };
    let far_triangles = moved(&known_triangles(), offset);
    let near_triangles = moved(&far_triangles, -offset);
    let camera = front_camera(1, W, H);
    let far_camera = protocol::viewer_link::Camera {
        eye: (camera.eye_vec() + offset).to_array(),
        ..camera
    };
    let near_camera = protocol::viewer_link::Camera {
        eye: (far_camera.eye_vec() - offset).to_array(),
        ..camera
    };
    let settings = DrawSettings {
        l_white: L_WHITE,
        ..DrawSettings::default()
    };
    let near = render_offscreen_with(&gpu, &near_triangles, &near_camera, &settings).unwrap();
    let far = render_offscreen_with(&gpu, &far_triangles, &far_camera, &settings).unwrap();
    assert!(
        near.covered.iter().any(|&c| c),
        "the centred triangles are seen"
    );
    let differing = near
        .display
        .pixels()
        .zip(far.display.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(
        differing, 0,
        "{differing} pixels differ far from the origin"
    );
}

/// The known triangles with half of every vertex's radiance direct.
fn half_direct_triangles() -> Vec<ShownTriangle> {
    let mut triangles = known_triangles();
    for t in &mut triangles {
        t.shading.direct_share = [DirectShare(128); 3];
    }
    triangles
}

/// A tile of one known direct radiance over `rect`, exact (no standard error).
fn constant_tile(camera_seq: u64, rect: TileRect, rgb: [f32; 3]) -> ViewerTile {
    ViewerTile {
        camera_seq,
        rect,
        samples: 16,
        pixels: vec![TilePixel::new(rgb, 0.0); rect.pixels()],
    }
}

#[test]
fn a_resting_viewer_draws_its_direct_tiles_and_a_camera_move_drops_them() {
    let Some(gpu) = gpu("a_resting_viewer_draws_its_direct_tiles_and_a_camera_move_drops_them")
    else {
        return;
    };
    let settings = DrawSettings {
        l_white: L_WHITE,
        ..DrawSettings::default()
    };
    let triangles = half_direct_triangles();
    let resting = front_camera(1, W, H);
    let mut direct = DirectImage::default();
    direct.follow(&resting);
    let draw = |direct: &DirectImage, camera| {
        render_offscreen_with_direct(&gpu, &triangles, direct, camera, &settings).unwrap()
    };
    let before = draw(&direct, &resting);
    // Over part of the flat square (radiance (2, 0.8, 0.3), half of it direct).
    let rect = TileRect {
        x: 48,
        y: 60,
        width: 16,
        height: 16,
    };
    let tile_direct = [0.5, 0.25, 1.0];
    assert!(direct.accept(&constant_tile(1, rect, tile_direct)));
    let after = draw(&direct, &resting);
    let linear = |s: &Snapshot, x: u32, y: u32| s.linear[(y * W + x) as usize];
    let rest = 1.0 - f32::from(128u8) / 255.0;
    let want: [f32; 3] = std::array::from_fn(|i| tile_direct[i] + [2.0, 0.8, 0.3][i] * rest);
    for (x, y) in [(48, 60), (55, 70), (63, 75)] {
        let found = linear(&after, x, y);
        assert!(
            found
                .iter()
                .zip(want)
                .all(|(f, w)| (f - w).abs() <= 2e-3 * w),
            "pixel ({x}, {y}) under the tile: {found:?}, expected {want:?}"
        );
        assert_close(
            pixel(&after, x, y),
            expected(want, ToneMap::Drago),
            1.0,
            "tile, tone-mapped",
        );
    }
    // Outside the tile (the same square, and across the tile's edges) nothing changed.
    for (x, y) in [(40, 70), (47, 70), (64, 70), (55, 59), (55, 76)] {
        assert_eq!(
            after.display.get_pixel(x, y),
            before.display.get_pixel(x, y),
            "pixel ({x}, {y}) outside the tile"
        );
    }
    let changed = (0..W)
        .flat_map(|x| (0..H).map(move |y| (x, y)))
        .filter(|&(x, y)| after.display.get_pixel(x, y) != before.display.get_pixel(x, y))
        .count();
    assert_eq!(changed, rect.pixels(), "exactly the tile's pixels change");
    ramp_rest_is_interpolated_per_vertex(&gpu, &settings, &resting);

    // The camera moves: the picture is the vertices' at once, before the move is even sent.
    let moved = Camera {
        eye: [0.05, 0.0, 3.0],
        ..resting.clone()
    };
    let moving = draw(&direct, &moved);
    let plain = draw(&DirectImage::default(), &moved);
    assert!(
        moving.display == plain.display,
        "a moved camera shows no tile"
    );
    // Once the move is sent, the old camera's tiles are dropped and refused.
    let sent = Camera { seq: 2, ..moved };
    direct.follow(&sent);
    assert!(!direct.accept(&constant_tile(1, rect, tile_direct)));
    assert!(draw(&direct, &sent).display == plain.display);
    // Back at rest, a tile of the new camera shows again.
    assert!(direct.accept(&constant_tile(2, rect, tile_direct)));
    assert!(draw(&direct, &sent).display != plain.display);
}

#[test]
fn headless_binary_draws_the_direct_tiles_of_its_camera_only() {
    let Some(gpu) = gpu("headless_binary_draws_the_direct_tiles_of_its_camera_only") else {
        return;
    };
    let sma = StandIn::start(scene());
    let out = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_viewer"))
        .args(["--connect", &sma.addr, "--headless", "--view", "front"])
        .args(["--width", &W.to_string(), "--height", &H.to_string()])
        .args(["--snapshot-when-idle", "--seconds", "60", "--out"])
        .arg(out.path())
        .spawn()
        .unwrap();
    let camera = sma.expect_camera();
    let triangles = half_direct_triangles();
    let n = triangles.len() as u64;
    sma.send(SmaToViewer::Insert {
        triangles: triangles.clone(),
    });
    sma.send(SmaToViewer::ToneMap { l_white: L_WHITE });
    let rect = |x| TileRect {
        x,
        y: 60,
        width: 16,
        height: 16,
    };
    // A tile of this camera, and one of an older camera elsewhere on the square.
    let shown = constant_tile(camera.seq, rect(48), [0.5, 0.25, 1.0]);
    let stale = constant_tile(camera.seq - 1, rect(24), [3.0, 0.0, 0.0]);
    sma.send(SmaToViewer::DirectTile(shown.clone()));
    sma.send(SmaToViewer::DirectTile(stale));
    sma.send(SmaToViewer::Epoch(Epoch {
        camera_seq: camera.seq,
        shown: n,
        inserted: n,
        ..Epoch::default()
    }));
    let status = child.wait().unwrap();
    assert!(status.success(), "viewer exited with {status}");

    let csv = std::fs::read_to_string(out.path().join("snapshots.csv")).unwrap();
    let row: Vec<&str> = csv
        .lines()
        .nth(1)
        .expect("one snapshot")
        .split(',')
        .collect();
    let png = image::open(out.path().join(row[27])).unwrap().into_rgb8();
    let settings = DrawSettings {
        l_white: L_WHITE,
        sky: common::SKY,
        ..DrawSettings::default()
    };
    let mut direct = DirectImage::default();
    direct.follow(&camera);
    assert!(direct.accept(&shown));
    let want = render_offscreen_with_direct(&gpu, &triangles, &direct, &camera, &settings).unwrap();
    let without = render_offscreen_with(&gpu, &triangles, &camera, &settings).unwrap();
    let same = |s: &Snapshot| {
        png.pixels()
            .zip(s.display.pixels())
            .all(|(a, b)| a.0[..3] == b.0[..3])
    };
    assert!(
        same(&want),
        "the snapshot differs from the drawing with the tile"
    );
    assert!(!same(&without), "the snapshot does not show the tile");
}

/// Across the ramp square, all direct at its left edge (radiance 0.2) and none at its right (4.0):
/// under a tile the rest of the vertices' radiance grows linearly from 0 to 4, as the product of
/// an interpolated share and an interpolated sum would not.
fn ramp_rest_is_interpolated_per_vertex(gpu: &Gpu, settings: &DrawSettings, camera: &Camera) {
    let mut triangles = known_triangles();
    for t in triangles.iter_mut().filter(|t| t.id == 20 || t.id == 21) {
        t.shading.direct_share = t
            .shading
            .illumination
            .map(|r| DirectShare(if r[0] < 1.0 { 255 } else { 0 }));
    }
    let mut direct = DirectImage::default();
    direct.follow(camera);
    let rect = TileRect {
        x: 96,
        y: 52,
        width: 16,
        height: 16,
    };
    assert!(direct.accept(&constant_tile(camera.seq, rect, [0.25; 3])));
    let s = render_offscreen_with_direct(gpu, &triangles, &direct, camera, settings).unwrap();
    for px in [98, 105, 110] {
        let rest = 4.0 * (world_x(px) - 0.2) / 1.2;
        let found = s.linear[(60 * W + px) as usize];
        let want = 0.25 + rest;
        assert!(
            found.iter().all(|&c| (c - want).abs() <= 2e-3 * want),
            "ramp x={px}: {found:?}, expected {want}"
        );
    }
}
