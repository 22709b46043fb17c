//! The viewer tests' scene and triangles, for the SMA stand-in of `testkit::fake_sma`.
#![allow(dead_code)] // each test binary uses its own part of this helper

use protocol::renderer_link::Quality;
use protocol::types::{Bounds, Viewpoint};
use protocol::viewer_link::{CornerShading, SceneInfo, ShownTriangle, SkyInfo, SunInfo};
#[allow(unused_imports)] // as above: not every test binary starts a stand-in
pub use testkit::fake_sma::{Seen, StandIn};

pub mod drawing;

/// A scene with two viewpoints looking at the origin from +Z.
pub fn scene() -> SceneInfo {
    let vp = |name: &str, eye: [f32; 3]| Viewpoint {
        name: name.into(),
        eye,
        target: [0.0, 0.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    SceneInfo {
        name: "stand-in".into(),
        fingerprint: [7; 32],
        bounds: Bounds {
            min: [-2.0, -2.0, -2.0],
            max: [2.0, 2.0, 2.0],
        },
        viewpoints: vec![vp("front", [0.0, 0.0, 3.0]), vp("side", [3.0, 0.0, 0.0])],
        criteria: vec!["nld_os".into(), "nld_is".into(), "rnd".into()],
        sky: SKY,
        quality: Quality {
            paths: 64,
            bounces: Some(2),
        },
        textures: false,
        materials: vec![],
        texture_table: vec![],
    }
}

/// A triangle lit by `illumination` per corner, of material 0: with no materials listed, an
/// albedo of one, so it shows that radiance.
pub fn lit_triangle(
    id: u64,
    positions: [[f32; 3]; 3],
    illumination: [[f32; 3]; 3],
) -> ShownTriangle {
    ShownTriangle {
        id,
        positions,
        material: 0,
        texcoords: Default::default(),
        shading: CornerShading {
            illumination,
            ..CornerShading::default()
        },
    }
}

/// A blue sky with a large sun 25° above the front view's centre, above the known triangles.
pub const SKY: SkyInfo = SkyInfo {
    radiance: [0.3, 0.5, 1.0],
    sun: Some(SunInfo {
        direction: [0.0, 0.422_618_3, -0.906_307_8],
        radiance: [50.0, 45.0, 40.0],
        angular_diameter_deg: 5.0,
    }),
};

/// Known triangles for image checks, seen from the "front" viewpoint: a red-orange square on the
/// left (two triangles, one radiance), a square on the right whose radiance varies along x, and a
/// green triangle in front of part of the left square (it must hide it: depth test).
pub fn known_triangles() -> Vec<ShownTriangle> {
    let quad = |id: u64, x0: f32, x1: f32, z: f32, left: [f32; 3], right: [f32; 3]| {
        let (a, b, c, d) = ([x0, -0.6, z], [x1, -0.6, z], [x1, 0.6, z], [x0, 0.6, z]);
        vec![
            lit_triangle(id, [a, b, c], [left, right, right]),
            lit_triangle(id + 1, [a, c, d], [left, right, left]),
        ]
    };
    // The occluder comes first, so only the depth test can keep it in front.
    let mut t = vec![lit_triangle(
        30,
        [[-1.3, 0.1, 0.5], [-0.9, 0.1, 0.5], [-1.1, 0.5, 0.5]],
        [[0.1, 0.9, 0.1]; 3],
    )];
    t.extend(quad(10, -1.4, -0.2, 0.0, [2.0, 0.8, 0.3], [2.0, 0.8, 0.3]));
    t.extend(quad(20, 0.2, 1.4, 0.0, [0.2, 0.2, 0.2], [4.0, 4.0, 4.0]));
    t
}

/// The camera of the "front" viewpoint at a given size.
pub fn front_camera(seq: u64, width: u32, height: u32) -> protocol::viewer_link::Camera {
    protocol::viewer_link::Camera::from_viewpoint(&scene().viewpoints[0], seq, width, height)
}
