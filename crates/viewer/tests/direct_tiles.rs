//! Per-pixel direct tiles drawn in place of the vertices' direct part (DESIGN.md §3 step 8): for
//! the resting camera only, dropped by a move, interpolating the rest per vertex, standing in
//! only where a tile's pixel is the better estimate, and in the headless binary's snapshots.

mod common;

use common::drawing::{H, L_WHITE, W, assert_close, expected, gpu, pixel, world_x};
use common::{StandIn, front_camera, known_triangles, scene};
use protocol::direct_tile::{TilePixel, TileRect, ViewerTile};
use protocol::viewer_link::{Camera, DirectShare, Epoch, ShownTriangle, SmaToViewer};
use viewer::direct_image::DirectImage;
use viewer::gpu::Gpu;
use viewer::{
    DrawSettings, Snapshot, ToneMap, render_offscreen_with, render_offscreen_with_direct,
};

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
    noisy_tile(camera_seq, rect, rgb, 0.0)
}

/// The drawing settings of these tests: the default tone map at their white point.
fn tone_mapped() -> DrawSettings {
    DrawSettings {
        l_white: L_WHITE,
        ..DrawSettings::default()
    }
}

#[test]
fn a_resting_viewer_draws_its_direct_tiles_and_a_camera_move_drops_them() {
    let Some(gpu) = gpu("a_resting_viewer_draws_its_direct_tiles_and_a_camera_move_drops_them")
    else {
        return;
    };
    let settings = tone_mapped();
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

/// A tile of direct radiance `rgb` with standard error `sigma` over `rect`.
fn noisy_tile(camera_seq: u64, rect: TileRect, rgb: [f32; 3], sigma: f32) -> ViewerTile {
    ViewerTile {
        camera_seq,
        rect,
        samples: 4,
        pixels: vec![TilePixel::new(rgb, sigma); rect.pixels()],
    }
}

#[test]
fn a_noisy_tile_stands_in_only_where_the_vertices_are_wrong_beyond_its_noise() {
    let Some(gpu) =
        gpu("a_noisy_tile_stands_in_only_where_the_vertices_are_wrong_beyond_its_noise")
    else {
        return;
    };
    let settings = tone_mapped();
    let triangles = half_direct_triangles();
    let camera = front_camera(1, W, H);
    let plain = render_offscreen_with(&gpu, &triangles, &camera, &settings).unwrap();
    let rect = |x| TileRect {
        x,
        y: 60,
        width: 6,
        height: 6,
    };
    // Over the flat square the vertices' direct part is (1, 0.4, 0.15), luminance about 0.51.
    let vertices = [1.0, 0.4, 0.15];
    let mut direct = DirectImage::default();
    direct.follow(&camera);
    // 5 % off with a standard error of a fifth: within its noise, so the vertices stay.
    let agreeing = vertices.map(|c| c * 1.05);
    assert!(direct.accept(&noisy_tile(1, rect(40), agreeing, 0.1)));
    // A shadow the mesh does not resolve, its noise a tenth of the pixel (so not precise) but
    // ten times below the difference: shown.
    let shadow = [0.05, 0.02, 0.01];
    assert!(direct.accept(&noisy_tile(1, rect(48), shadow, 0.05)));
    // 2 % off, within its noise, but precise (under 1 % of the pixel): shown.
    let precise = vertices.map(|c| c * 1.02);
    assert!(direct.accept(&noisy_tile(1, rect(56), precise, 0.008)));
    let s = render_offscreen_with_direct(&gpu, &triangles, &direct, &camera, &settings).unwrap();
    let linear = |s: &Snapshot, x: u32| s.linear[(62 * W + x) as usize];
    let rest = [2.0, 0.8, 0.3].map(|c| c * (1.0 - f32::from(128u8) / 255.0));
    for x in [40, 42, 45] {
        assert_eq!(linear(&s, x), linear(&plain, x), "agreeing tile at x={x}");
    }
    for (x, tile) in [(48, shadow), (53, shadow), (56, precise), (61, precise)] {
        let want: [f32; 3] = std::array::from_fn(|i| tile[i] + rest[i]);
        let found = linear(&s, x);
        assert!(
            found
                .iter()
                .zip(want)
                .all(|(f, w)| (f - w).abs() <= 2e-3 * w),
            "x={x}: {found:?}, expected the tile's {want:?}"
        );
    }
}
