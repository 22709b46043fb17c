//! The Cornell box: the measured geometry of the Cornell data page (millimetres, here in metres;
//! the light 0.8 mm under the ceiling, as embree and tinyobjloader ship it, so the two do not
//! coincide) with the RGB reflectances and light of McGuire's CornellBox-Original. The front is
//! open; the blocks' hidden bottoms are left out. Faces are wound toward the inside, so the
//! one-sided light shines down (DESIGN.md §7).

use glam::{Vec3, vec3};

use super::shapes::{prism, quad};
use crate::builder::SceneBuilder;
use crate::model::Material;
use crate::settings::{QualitySetting, SceneSettings, Sky, TextureSettings, ViewpointSetting};

/// Millimetres of the data page to metres.
fn mm(p: [f32; 3]) -> Vec3 {
    Vec3::from(p) * 1e-3
}

/// The data page's floor, light, ceiling, back, left and right walls, in mm.
#[rustfmt::skip]
const WALLS: [[[f32; 3]; 4]; 6] = [
    [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]],
    [[343.0, 548.0, 227.0], [343.0, 548.0, 332.0], [213.0, 548.0, 332.0], [213.0, 548.0, 227.0]],
    [[556.0, 548.8, 0.0], [556.0, 548.8, 559.2], [0.0, 548.8, 559.2], [0.0, 548.8, 0.0]],
    [[549.6, 0.0, 559.2], [0.0, 0.0, 559.2], [0.0, 548.8, 559.2], [556.0, 548.8, 559.2]],
    [[0.0, 0.0, 559.2], [0.0, 0.0, 0.0], [0.0, 548.8, 0.0], [0.0, 548.8, 559.2]],
    [[552.8, 0.0, 0.0], [549.6, 0.0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0.0]],
];

pub fn cornell() -> SceneBuilder {
    let mut b = SceneBuilder::new(settings());
    let white = b.material(Material::diffuse("white", vec3(0.725, 0.71, 0.68)));
    let red = b.material(Material::diffuse("red", vec3(0.63, 0.065, 0.05)));
    let green = b.material(Material::diffuse("green", vec3(0.14, 0.45, 0.091)));
    let light = b.material(Material::emitter(
        "light",
        Vec3::splat(0.78),
        vec3(17.0, 12.0, 4.0),
    ));
    for (corners, material) in WALLS
        .into_iter()
        .zip([white, light, white, white, green, red])
    {
        quad(&mut b, corners.map(mm), material);
    }
    block(
        &mut b,
        [(130.0, 65.0), (82.0, 225.0), (240.0, 272.0), (290.0, 114.0)],
        165.0,
        white,
    );
    block(
        &mut b,
        [
            (423.0, 247.0),
            (265.0, 296.0),
            (314.0, 456.0),
            (472.0, 406.0),
        ],
        330.0,
        white,
    );
    b
}

/// A block standing on the floor over a four-corner footprint (x, z in mm, counter-clockwise
/// seen from above): top and sides.
fn block(b: &mut SceneBuilder, footprint: [(f32, f32); 4], height: f32, material: u32) {
    prism(
        b,
        &footprint.map(|(x, z)| (x * 1e-3, z * 1e-3)),
        0.0,
        height * 1e-3,
        material,
    );
}

fn settings() -> SceneSettings {
    SceneSettings {
        name: "cornell".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun: None,
        sky: Sky::None,
        quality: QualitySetting::default(),
        // The data page's camera: 35 mm lens on 25 mm film, i.e. a 39.3° vertical field.
        viewpoints: vec![ViewpointSetting {
            name: "main".into(),
            eye: [0.278, 0.273, -0.8],
            target: [0.278, 0.273, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 39.3,
        }],
        textures: TextureSettings::default(),
    }
}
