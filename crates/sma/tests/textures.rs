//! Textures reaching viewers (DESIGN.md §5, "Parts, and textures"): the SMA lists the scene's
//! materials and textures in `SceneInfo`, sends each texture once to every viewer before any
//! `Insert` (a viewer that joins late too: `testkit::probe` fails on a triangle inserted before
//! its texture), and gives each inserted triangle its material and its corners' texture
//! coordinates, read from its scene triangle's at the corner's place. Needs a wgpu adapter (Mesa
//! without a GPU): without one the test says so and returns, unless `WALKTHROUGH_REQUIRE_GPU` is
//! set.

use std::time::Duration;

use glam::{Vec2, Vec3};
use protocol::Side;
use protocol::renderer_link::Quality;
use scene::settings::AlbedoRule;
use scene::{DiffuseMap, Material, Scene, SceneBuilder, SceneSettings, Texture, ViewpointSetting};
use sma::config::SmaConfig;
use sma::criteria::CriterionKind;
use sma::visibility::Gpu;
use testkit::fake_renderer::{self, Fault};
use testkit::gpu::gpu_or_skip;
use testkit::probe::Probe;

const WAIT: Duration = Duration::from_secs(60);

/// The wall's texture coordinates: 1.5 periods per metre, so its texture repeats.
fn wall_uv(p: Vec3) -> Vec2 {
    Vec2::new(p.x, p.y) * 1.5
}

/// An untextured floor and a wall (x in -1..1, y in 0..2, z = 0) with a 4×4 checker, textures on.
fn textured_wall() -> Scene {
    let settings = SceneSettings {
        name: "textured wall".into(),
        obj: String::new(),
        units: "m".into(),
        crease_angle_deg: 45.0,
        sun: None,
        sky: Default::default(),
        quality: Default::default(),
        viewpoints: vec![ViewpointSetting {
            name: "front".into(),
            eye: [0.3, 1.2, 4.0],
            target: [0.0, 0.8, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 60.0,
        }],
        textures: scene::TextureSettings {
            enabled: true,
            albedo: AlbedoRule::KdTimesTexture,
        },
    };
    let checker: Vec<[u8; 3]> = (0..16u32)
        .map(|i| {
            if (i % 4 + i / 4).is_multiple_of(2) {
                [230, 40, 20]
            } else {
                [20, 60, 200]
            }
        })
        .collect();
    let mut wall = Material::diffuse("wall", Vec3::splat(0.8));
    wall.diffuse_map = Some(DiffuseMap::generated(
        Texture::from_srgb8(4, 4, &checker),
        "checker.png".into(),
        AlbedoRule::KdTimesTexture,
    ));
    let mut b = SceneBuilder::new(settings);
    let floor = b.material(Material::diffuse("floor", Vec3::splat(0.5)));
    let wall = b.material(wall);
    let f = |x, z| Vec3::new(x, 0.0, z);
    let v = [f(-4.0, -4.0), f(-4.0, 4.0), f(4.0, 4.0), f(4.0, -4.0)].map(|p| b.vertex(p));
    b.triangle([v[0], v[1], v[2]], floor);
    b.triangle([v[0], v[2], v[3]], floor);
    let w = |x, y| Vec3::new(x, y, 0.0);
    let corners = [w(-1.0, 0.0), w(1.0, 0.0), w(1.0, 2.0), w(-1.0, 2.0)];
    let v = corners.map(|p| b.vertex(p));
    for [i, j, k] in [[0, 1, 2], [0, 2, 3]] {
        let uv = [i, j, k].map(|c| wall_uv(corners[c]));
        b.textured_triangle([v[i], v[j], v[k]], wall, uv);
    }
    b.build().expect("valid test scene")
}

/// A sharp "shadow" edge at x = 0.3: something to refine, so that leaves inside the wall's
/// triangles are shown.
fn shadow_edge(p: Vec3, _: Side, _: Quality, _: Option<Vec3>) -> [f32; 3] {
    if p.x > 0.3 { [1.0; 3] } else { [0.1; 3] }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn textures_reach_every_viewer_before_their_triangles_and_coordinates_follow_the_leaves() {
    if gpu_or_skip(Gpu::new()).is_none() {
        return;
    }
    let scene = textured_wall();
    let (renderer, _) = fake_renderer::start(scene.clone(), shadow_edge, Fault::None).await;
    let mut config = SmaConfig {
        listen: "127.0.0.1:0".into(),
        renderers: vec![renderer],
        ..SmaConfig::default()
    };
    config.schedule.criterion = CriterionKind::NldOs;
    config.schedule.rest = Duration::ZERO;
    let sma = sma::server::start(config, scene.clone(), std::future::pending())
        .await
        .unwrap();
    let addr = sma.addr.to_string();
    let mut first = Probe::connect(&addr).await.unwrap();
    assert_eq!(first.scene.materials.len(), 2);
    assert!(first.scene.materials[0].texture.is_none());
    assert_eq!(first.scene.texture_table.len(), 1);
    let camera = first.view("front", 200, 150).await.unwrap();
    first.complete(camera.seq, WAIT).await.unwrap();
    assert!(
        first.textures.iter().all(Option::is_some),
        "every texture arrived"
    );

    // Every wall corner's coordinates are the wall's mapping at its position, less whole
    // periods, within the quantisation; the floor's are none.
    let mut wall_triangles = 0;
    for t in first.table.values() {
        let uv = t.texcoords.decode();
        if t.material == 0 {
            assert_eq!(uv, [[0.0; 2]; 3]);
            continue;
        }
        wall_triangles += 1;
        for (p, uv) in t.positions.iter().zip(uv) {
            let want = wall_uv(Vec3::from(*p));
            let off = want - Vec2::from(uv);
            let whole = off.round();
            assert!(
                (off - whole).abs().max_element() < 1e-3,
                "corner {p:?}: {uv:?}, want {want} less whole periods"
            );
        }
    }
    assert!(wall_triangles > 2, "the wall was shown, refined");

    // A viewer that joins once the first has been sent everything gets the textures too,
    // before its first triangle, the same bytes.
    let mut late = Probe::connect(&addr).await.unwrap();
    let camera = late.view("front", 200, 150).await.unwrap();
    late.complete(camera.seq, WAIT).await.unwrap();
    assert!(!late.table.is_empty());
    assert_eq!(late.textures, first.textures);
    sma.stop().await.unwrap();
}
