use glam::{Vec2, Vec3};
use scene::settings::AlbedoRule;
use scene::{DiffuseMap, Material, Scene, SceneBuilder, SceneSettings, Texture, TextureSettings};

use super::*;

/// A 64 × 64 black-and-white checker of one-texel cells.
fn checker() -> Texture {
    let texels: Vec<[u8; 3]> = (0..64 * 64)
        .map(|i| {
            if (i % 64 + i / 64) % 2 == 0 {
                [0; 3]
            } else {
                [255; 3]
            }
        })
        .collect();
    Texture::from_srgb8(64, 64, &texels)
}

/// A 1 m square at z = 0 carrying `texture` once (texels of 1/64 m), and beside it a plain one.
fn squares(texture: Texture, uv_scale: f32) -> Scene {
    let settings = SceneSettings {
        name: "squares".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun: None,
        sky: Default::default(),
        quality: Default::default(),
        viewpoints: Vec::new(),
        textures: TextureSettings {
            enabled: true,
            albedo: AlbedoRule::Texture,
        },
    };
    let mut b = SceneBuilder::new(settings);
    let mut material = Material::diffuse("checker", Vec3::ONE);
    material.diffuse_map = Some(DiffuseMap::generated(
        texture,
        "checker.png".into(),
        AlbedoRule::Texture,
    ));
    let textured = b.material(material);
    let plain = b.material(Material::diffuse("plain", Vec3::splat(0.5)));
    let corners = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]].map(Vec2::from);
    let v = corners.map(|p| b.vertex(p.extend(0.0)));
    b.textured_triangle(
        [v[0], v[1], v[2]],
        textured,
        [0, 1, 2].map(|c| corners[c] * uv_scale),
    );
    let w = [[2.0, 0.0], [3.0, 0.0], [3.0, 1.0]].map(|p| b.vertex(Vec2::from(p).extend(0.0)));
    b.triangle(w, plain);
    b.build().expect("valid test scene")
}

/// Triangle `t`'s corners.
fn at(scene: &Scene, t: usize) -> [Vec3; 3] {
    scene.mesh.triangle_positions(t)
}

#[test]
fn a_diffuse_bounce_opens_the_cone_and_a_mirror_carries_it_on() {
    let point = Footprint::POINT;
    assert_eq!(point.after(RayKind::Mirror, 5.0).width(), 0.0);
    assert_eq!(point.after(RayKind::Glossy, 5.0).width(), 0.0);
    let bounced = point.after(RayKind::Bounce, 4.0);
    assert_eq!(bounced.width(), 4.0 * DIFFUSE_SPREAD);
    // Past the bounce the cone keeps widening, through a mirror too, and never narrows.
    let mirrored = bounced.after(RayKind::Mirror, 2.0);
    assert_eq!(mirrored.width(), 6.0 * DIFFUSE_SPREAD);
    assert_eq!(mirrored.after(RayKind::Bounce, 0.0), mirrored);
}

#[test]
fn the_level_is_the_one_whose_texels_are_as_wide_as_the_footprint() {
    let scene = squares(checker(), 1.0);
    let lod = TextureLod::new(&scene);
    let texel = 1.0 / 64.0;
    assert!((texel_side(&scene, 0, at(&scene, 0)) - texel).abs() < 1e-6);
    // Under two texels across: the full resolution.
    for width in [0.0, texel, 1.9 * texel] {
        assert_eq!(lod.level(&scene, 0, at(&scene, 0), width), None, "{width}");
    }
    assert_eq!(lod.level(&scene, 0, at(&scene, 0), 2.0 * texel), Some(0));
    assert_eq!(lod.level(&scene, 0, at(&scene, 0), 5.0 * texel), Some(1));
    // Past the whole texture, its single-texel level.
    assert_eq!(lod.level(&scene, 0, at(&scene, 0), 10.0), Some(5));
    // A plain triangle is read at full resolution whatever the footprint.
    assert_eq!(lod.level(&scene, 1, at(&scene, 1), 10.0), None);
}

#[test]
fn a_wide_footprint_reads_the_checker_s_mean_and_a_point_its_texel() {
    let scene = squares(checker(), 1.0);
    let lod = TextureLod::new(&scene);
    let mean = checker().mean();
    for bary in [[0.3, 0.2], [0.51, 0.1], [0.05, 0.9]] {
        let far = lod.albedo_at(&scene, 0, at(&scene, 0), bary, 1.0);
        assert!((far - mean).abs().max_element() < 0.01, "{far} vs {mean}");
        let near = lod.albedo_at(&scene, 0, at(&scene, 0), bary, 0.0);
        assert_eq!(near, scene.albedo_at(0, bary));
    }
}

#[test]
fn texture_coordinates_that_span_no_area_stay_at_full_resolution() {
    // Every corner at one texel: the whole triangle reads it, never the checker's mean.
    let scene = squares(checker(), 0.0);
    let lod = TextureLod::new(&scene);
    assert_eq!(texel_side(&scene, 0, at(&scene, 0)), f32::INFINITY);
    assert_eq!(lod.level(&scene, 0, at(&scene, 0), 100.0), None);
}
