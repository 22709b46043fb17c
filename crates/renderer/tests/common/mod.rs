//! Small scenes built in code for the renderer's tests, and helpers to name points on them.
#![allow(dead_code)] // each test binary uses its own subset

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{SampleKey, ShadePoint};
use renderer::World;
use renderer::point::surface_of;
use scene::settings::QualitySetting;
use scene::{Material, SceneBuilder, SceneSettings, Sky, Sun};

pub fn settings(sun: Option<Sun>, sky: Sky) -> SceneSettings {
    SceneSettings {
        name: "test".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun,
        sky,
        quality: QualitySetting {
            paths: 16,
            bounces: Some(2),
        },
        viewpoints: Vec::new(),
    }
}

/// A sun toward `dir` with the given radiance and the real sun's 0.53° diameter.
pub fn sun(dir: Vec3, radiance: f32) -> Sun {
    Sun {
        direction: dir.to_array(),
        radiance: [radiance; 3],
        angular_diameter_deg: 0.53,
    }
}

/// A quad whose counter-clockwise side is the side its corners turn around (p, q, r, s).
pub fn quad(b: &mut SceneBuilder, corners: [Vec3; 4], material: u32) {
    let [p, q, r, s] = corners.map(|c| b.vertex(c));
    b.triangle([p, q, r], material);
    b.triangle([p, r, s], material);
}

/// A horizontal square at height `y`, centred on (cx, cz), facing +Y.
pub fn floor(b: &mut SceneBuilder, centre: Vec3, half: f32, material: u32) {
    let c = |dx: f32, dz: f32| centre + Vec3::new(dx, 0.0, dz);
    quad(
        b,
        [
            c(-half, -half),
            c(-half, half),
            c(half, half),
            c(half, -half),
        ],
        material,
    );
}

/// The six faces of an axis-aligned box, facing inward (`inward`) or outward.
pub fn cube(b: &mut SceneBuilder, min: Vec3, max: Vec3, inward: bool, material: u32) {
    let k = |x: bool, y: bool, z: bool| {
        Vec3::new(
            if x { max.x } else { min.x },
            if y { max.y } else { min.y },
            if z { max.z } else { min.z },
        )
    };
    let (f, t) = (false, true);
    // Outward-facing, counter-clockwise seen from outside.
    let faces = [
        [k(f, t, f), k(f, t, t), k(t, t, t), k(t, t, f)],
        [k(f, f, f), k(t, f, f), k(t, f, t), k(f, f, t)],
        [k(f, f, t), k(t, f, t), k(t, t, t), k(f, t, t)],
        [k(t, f, f), k(f, f, f), k(f, t, f), k(t, t, f)],
        [k(t, f, t), k(t, f, f), k(t, t, f), k(t, t, t)],
        [k(f, f, f), k(f, f, t), k(f, t, t), k(f, t, f)],
    ];
    for mut face in faces {
        if inward {
            face.reverse();
        }
        quad(b, face, material);
    }
}

pub fn grey(albedo: f32) -> Material {
    Material::diffuse("grey", Vec3::splat(albedo))
}

pub fn world(b: SceneBuilder) -> World {
    World::new(b.build().expect("test scene builds"))
}

/// The side of `p` whose normal points toward `facing`.
pub fn with_side_facing(world: &World, mut p: ShadePoint, facing: Vec3) -> ShadePoint {
    p.side = Side::Front;
    let s = surface_of(world, &p).expect("valid point");
    if s.normal.dot(facing) < 0.0 {
        p.side = Side::Back;
        p.key.side = Side::Back;
    }
    p
}

/// The shading point where the ray from `origin` along `dir` first hits, on the side facing the
/// ray's origin.
pub fn point_hit_by(world: &World, origin: Vec3, dir: Vec3) -> ShadePoint {
    let hit = world
        .bvh
        .closest_hit(origin, dir, f32::INFINITY)
        .expect("ray hits the scene");
    let q = origin + dir * hit.t;
    let [a, b, c] = world.scene.mesh.triangle_positions(hit.triangle as usize);
    let bary = barycentrics(q, a, b, c);
    let p = ShadePoint {
        key: SampleKey {
            vertex: 0,
            side: Side::Front,
        },
        base_triangle: hit.triangle,
        bary,
        side: Side::Front,
        eye: None,
    };
    with_side_facing(world, p, -dir)
}

/// Barycentric weights of vertices 1 and 2 for `q` in the plane of (a, b, c).
pub fn barycentrics(q: Vec3, a: Vec3, b: Vec3, c: Vec3) -> [f32; 2] {
    let (e1, e2, d) = (b - a, c - a, q - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let det = d11 * d22 - d12 * d12;
    [(d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det]
}

/// Mean and standard error of per-path samples of one channel.
pub fn mean_and_standard_error(samples: &[f64]) -> (f64, f64) {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    let var = samples.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}
