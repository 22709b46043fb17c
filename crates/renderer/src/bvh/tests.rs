//! The ray queries against known answers, and the traversals and packet queries against one
//! another, ray by ray, at every vector level the CPU runs.

use super::*;
use scene::Triangle;

fn quad_mesh(y: f32) -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(-1.0, y, -1.0),
            Vec3::new(1.0, y, -1.0),
            Vec3::new(1.0, y, 1.0),
            Vec3::new(-1.0, y, 1.0),
        ],
        normals: vec![Vec3::Y; 4],
        triangles: vec![
            Triangle {
                vertices: [0, 2, 1],
                material: 0,
            },
            Triangle {
                vertices: [0, 3, 2],
                material: 0,
            },
        ],
    }
}

#[test]
fn closest_hit_finds_the_nearer_plane_and_its_distance() {
    let mut mesh = quad_mesh(0.0);
    let upper = quad_mesh(2.0);
    let base = mesh.positions.len() as u32;
    mesh.positions.extend(upper.positions);
    mesh.normals.extend(upper.normals);
    mesh.triangles
        .extend(upper.triangles.iter().map(|t| Triangle {
            vertices: t.vertices.map(|v| v + base),
            material: 0,
        }));
    for preset in [
        BuildPreset::Fast,
        BuildPreset::Medium,
        BuildPreset::Slow,
        BuildPreset::VerySlow,
    ] {
        let bvh = SceneBvh::build(&mesh, preset);
        let hit = bvh
            .closest_hit(Vec3::new(0.3, 5.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
            .unwrap();
        assert!((hit.t - 3.0).abs() < 1e-5);
        assert!(hit.triangle >= 2, "upper plane is triangles 2 and 3");
        let hit = bvh
            .closest_hit(Vec3::new(0.3, 1.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
            .unwrap();
        assert!((hit.t - 1.0).abs() < 1e-5 && hit.triangle < 2);
        assert!(
            bvh.closest_hit(Vec3::new(3.0, 1.0, 0.2), Vec3::NEG_Y, f32::INFINITY)
                .is_none()
        );
    }
}

#[test]
fn occlusion_respects_the_segment_length() {
    let bvh = SceneBvh::build(&quad_mesh(0.0), BuildPreset::Slow);
    let o = Vec3::new(0.1, 1.0, 0.1);
    assert!(bvh.occluded(o, Vec3::NEG_Y, 2.0));
    assert!(!bvh.occluded(o, Vec3::NEG_Y, 0.5));
    assert!(!bvh.occluded(o, Vec3::Y, 10.0));
}

#[test]
fn an_occluder_found_blocks_its_segment_and_not_a_shorter_one() {
    let bvh = SceneBvh::build(&quad_mesh(0.0), BuildPreset::Slow);
    let o = Vec3::new(0.1, 1.0, 0.1);
    let prim = bvh.occluder(o, Vec3::NEG_Y, 2.0).expect("the quad blocks");
    assert!(bvh.blocks(prim, o, Vec3::NEG_Y, 2.0));
    assert!(!bvh.blocks(prim, o, Vec3::NEG_Y, 0.5));
    assert!(!bvh.blocks(prim, o, Vec3::Y, 10.0));
    assert_eq!(bvh.occluder(o, Vec3::Y, 10.0), None);
}

/// A crumpled sheet of triangles over several scales, for comparing traversals.
fn crumpled_mesh() -> Mesh {
    let n = 40;
    let mut mesh = Mesh::default();
    for i in 0..=n {
        for j in 0..=n {
            let (x, z) = (i as f32 * 0.25, j as f32 * 0.25);
            let y = (x * 1.7).sin() * (z * 1.3).cos() + ((i * 31 + j * 17) % 7) as f32 * 0.02;
            mesh.positions.push(Vec3::new(x, y, z));
            mesh.normals.push(Vec3::Y);
        }
    }
    let at = |i: usize, j: usize| (i * (n + 1) + j) as u32;
    for i in 0..n {
        for j in 0..n {
            for vertices in [
                [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
            ] {
                mesh.triangles.push(Triangle {
                    vertices,
                    material: 0,
                });
            }
        }
    }
    mesh
}

#[test]
fn both_traversals_give_the_same_answers_at_every_level() {
    let mesh = crumpled_mesh();
    let mut rng = crate::sampling::stream(7, 0);
    let rays: Vec<(Vec3, Vec3, f32)> = (0..4000)
        .map(|k| {
            let u = crate::sampling::uniform2(&mut rng);
            let v = crate::sampling::uniform2(&mut rng);
            let origin = Vec3::new(u[0] * 10.0, 2.5 * v[0] - 0.5, u[1] * 10.0);
            let w = crate::sampling::uniform2(&mut rng);
            // A cone of half-angle π is the whole sphere.
            let dir = crate::sampling::uniform_cone(Vec3::Y, 2.0, w);
            // Some axis-parallel rays and some short segments too.
            let dir = if k % 10 == 0 { Vec3::NEG_Y } else { dir };
            let tmax = if k % 3 == 0 { 1.5 } else { f32::INFINITY };
            (origin, dir, tmax)
        })
        .collect();
    for preset in [
        BuildPreset::Medium,
        BuildPreset::Slow,
        BuildPreset::VerySlow,
    ] {
        let mut bvh = SceneBvh::build(&mesh, preset);
        assert_eq!(bvh.traversal(), Traversal::Wide, "x86-64 runs the wide one");
        for level in [VectorLevel::Baseline, VectorLevel::V3] {
            if !level.available() {
                continue;
            }
            bvh.set_vector_level(level);
            let mut hits = 0;
            for &(o, d, tmax) in &rays {
                bvh.set_traversal(Traversal::Compressed);
                let (expected, blocked) = (bvh.closest_hit(o, d, tmax), bvh.occluded(o, d, tmax));
                bvh.set_traversal(Traversal::Wide);
                let got = bvh.closest_hit(o, d, tmax);
                assert_eq!(got.map(|h| h.t), expected.map(|h| h.t), "{o} {d} {tmax}");
                assert_eq!(bvh.occluded(o, d, tmax), blocked, "{o} {d} {tmax}");
                if let Some(prim) = bvh.occluder(o, d, tmax) {
                    assert!(bvh.blocks(prim, o, d, tmax));
                }
                hits += usize::from(got.is_some());
            }
            assert!(
                hits > 1000 && hits < 3900,
                "{hits} of 4000 rays hit: a poor test set"
            );
        }
    }
}

#[test]
fn empty_mesh_hits_nothing() {
    let bvh = SceneBvh::build(&Mesh::default(), BuildPreset::Slow);
    assert!(
        bvh.closest_hit(Vec3::ZERO, Vec3::X, f32::INFINITY)
            .is_none()
    );
    assert!(!bvh.occluded(Vec3::ZERO, Vec3::X, 1.0));
}

/// Every level this CPU runs.
fn levels() -> impl Iterator<Item = VectorLevel> {
    [VectorLevel::Baseline, VectorLevel::V3]
        .into_iter()
        .filter(|level| level.available())
}

/// Rays as the packet queries take them: origins, directions, tmaxs.
#[derive(Default)]
struct RaySet {
    origin: Vec<Vec3>,
    dir: Vec<Vec3>,
    tmax: Vec<f32>,
}

impl RaySet {
    fn push(&mut self, origin: Vec3, dir: Vec3, tmax: f32) {
        self.origin.push(origin);
        self.dir.push(dir);
        self.tmax.push(tmax);
    }
}

/// Asserts that the packet queries give each ray of `rays` its one-ray answers at every level;
/// returns how many rays hit something.
fn assert_packets_match_single_rays(bvh: &mut SceneBvh, rays: &RaySet) -> usize {
    let n = rays.origin.len();
    let mut hits = 0;
    for level in levels() {
        bvh.set_vector_level(level);
        let mut closest = vec![None; n];
        let mut blocked = vec![false; n];
        bvh.closest_hit_packet(&rays.origin, &rays.dir, &rays.tmax, &mut closest);
        bvh.occluded_packet(&rays.origin, &rays.dir, &rays.tmax, &mut blocked);
        hits = 0;
        for k in 0..n {
            let (o, d, tmax) = (rays.origin[k], rays.dir[k], rays.tmax[k]);
            let level = level.name();
            let single = bvh.closest_hit(o, d, tmax);
            let t = |hit: Option<Hit>| hit.map(|h| h.t);
            assert_eq!(t(closest[k]), t(single), "{level}: {o} {d} {tmax}");
            if let (Some(got), Some(expected)) = (closest[k], single)
                && got.triangle != expected.triangle
            {
                // A tie: both triangles at the same distance, the one visited first kept.
                assert!(hits_at(bvh, got, o, d, tmax), "{level}: {o} {d} {tmax}");
            }
            assert_eq!(
                blocked[k],
                bvh.occluded(o, d, tmax),
                "{level}: {o} {d} {tmax}"
            );
            hits += usize::from(closest[k].is_some());
        }
    }
    hits
}

/// Whether the ray meets `hit`'s triangle at `hit.t` (a tie with another triangle's hit).
fn hits_at(bvh: &SceneBvh, hit: Hit, origin: Vec3, dir: Vec3, tmax: f32) -> bool {
    let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
    let prims = bvh.prim_triangle.iter().enumerate();
    prims
        .filter(|&(_, &triangle)| triangle == hit.triangle)
        .any(|(prim, _)| bvh.prims[prim].intersect(&ray) == hit.t)
}

/// Tiles of 8×8 directions (a pinhole's pixels) from random eyes above the sheet, the last tile
/// cut short so that a partial packet is traced too.
fn tiles_from_one_eye(tiles: usize, tmax: f32) -> RaySet {
    let mut rng = crate::sampling::stream(11, 0);
    let mut rays = RaySet::default();
    for _ in 0..tiles {
        let [u, v] = crate::sampling::uniform2(&mut rng);
        let eye = Vec3::new(u * 10.0, 3.0, v * 10.0);
        let [a, b] = crate::sampling::uniform2(&mut rng);
        let centre = Vec3::new(a - 0.5, -1.0, b - 0.5);
        for y in 0..8 {
            for x in 0..8 {
                let pixel = Vec3::new(x as f32, 0.0, y as f32) * 0.01;
                rays.push(eye, (centre + pixel).normalize(), tmax);
            }
        }
    }
    let cut = rays.origin.len() - 3;
    rays.origin.truncate(cut);
    rays.dir.truncate(cut);
    rays.tmax.truncate(cut);
    rays
}

/// Rays of nearly one direction (a narrow cone: 1 − cos of its half-angle is 0.01, the sun's is
/// about 1e-5) from scattered points on and
/// around the sheet, some with short segments.
fn parallel_from_scattered_origins(n: usize, toward: Vec3) -> RaySet {
    let mut rng = crate::sampling::stream(13, 0);
    let mut rays = RaySet::default();
    for k in 0..n {
        let [u, v] = crate::sampling::uniform2(&mut rng);
        let [h, _] = crate::sampling::uniform2(&mut rng);
        let origin = Vec3::new(u * 10.0, 2.0 * h - 0.8, v * 10.0);
        let dir = crate::sampling::uniform_cone(toward, 0.01, crate::sampling::uniform2(&mut rng));
        let tmax = if k % 3 == 0 { 0.7 } else { f32::INFINITY };
        rays.push(origin, dir, tmax);
    }
    rays
}

#[test]
fn packets_of_one_eye_give_each_ray_its_single_ray_answers() {
    let mut bvh = SceneBvh::build(&crumpled_mesh(), BuildPreset::VerySlow);
    for tmax in [f32::INFINITY, 3.0] {
        let rays = tiles_from_one_eye(40, tmax);
        let hits = assert_packets_match_single_rays(&mut bvh, &rays);
        assert!(
            hits > 500 && hits < rays.origin.len(),
            "{hits} rays hit: a poor test set"
        );
    }
}

#[test]
fn packets_of_parallel_rays_give_each_ray_its_single_ray_answers() {
    let mut bvh = SceneBvh::build(&crumpled_mesh(), BuildPreset::VerySlow);
    for toward in [
        Vec3::new(0.3, 1.0, 0.2),
        Vec3::new(-0.5, 0.4, 0.1),
        Vec3::NEG_Y,
    ] {
        let rays = parallel_from_scattered_origins(3000, toward.normalize());
        let hits = assert_packets_match_single_rays(&mut bvh, &rays);
        assert!(
            hits > 300 && hits < 2900,
            "{hits} rays hit: a poor test set"
        );
    }
}

#[test]
fn rays_of_mixed_octants_get_their_single_ray_answers() {
    let mut bvh = SceneBvh::build(&crumpled_mesh(), BuildPreset::VerySlow);
    let mut rng = crate::sampling::stream(17, 0);
    let mut rays = parallel_from_scattered_origins(1000, Vec3::Y);
    for k in (0..rays.dir.len()).step_by(5) {
        rays.dir[k] =
            crate::sampling::uniform_cone(Vec3::Y, 2.0, crate::sampling::uniform2(&mut rng));
    }
    assert_packets_match_single_rays(&mut bvh, &rays);
    bvh.set_traversal(Traversal::Compressed);
    assert_packets_match_single_rays(&mut bvh, &rays);
}

#[test]
fn packet_queries_on_an_empty_mesh_find_nothing() {
    let bvh = SceneBvh::build(&Mesh::default(), BuildPreset::Slow);
    let (origin, dir, tmax) = ([Vec3::ZERO; 3], [Vec3::X; 3], [1.0; 3]);
    let mut hits = [Some(Hit {
        triangle: 0,
        t: 0.0,
    }); 3];
    let mut blocked = [true; 3];
    bvh.closest_hit_packet(&origin, &dir, &tmax, &mut hits);
    bvh.occluded_packet(&origin, &dir, &tmax, &mut blocked);
    assert_eq!((hits, blocked), ([None; 3], [false; 3]));
}

/// Sponza from `../shared/scenes` (not redistributed: the test passes without checking anything
/// when it is absent).
fn sponza() -> Option<crate::world::World> {
    let toml = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/sponza.toml");
    let obj = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/scenes/sponza/sponza.obj"
    );
    if !std::path::Path::new(obj).is_file() {
        eprintln!("skipped: {obj} is not present");
        return None;
    }
    Some(crate::world::World::new(
        scene::load(toml).expect("sponza loads"),
    ))
}

#[test]
fn packets_on_sponza_give_each_ray_its_single_ray_answers() {
    let Some(mut world) = sponza() else { return };
    let (width, height) = (128, 96);
    let camera = crate::reference::camera_for(&world, "S1", width, height).expect("view S1");
    let eye = world.to_local(camera.eye_vec());
    let mut primary = RaySet::default();
    for tile_y in (0..height).step_by(8) {
        for tile_x in (0..width).step_by(8) {
            for y in tile_y..tile_y + 8 {
                for x in tile_x..tile_x + 8 {
                    let dir = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
                    primary.push(eye, dir, f32::INFINITY);
                }
            }
        }
    }
    let sun = world.scene.settings.sun.as_ref().expect("Sponza has a sun");
    let sun = Vec3::from(sun.direction).normalize();
    let mut rng = crate::sampling::stream(19, 0);
    let mut shadow = RaySet::default();
    for k in 0..primary.origin.len() {
        let (o, d) = (primary.origin[k], primary.dir[k]);
        let Some(hit) = world.bvh.closest_hit(o, d, f32::INFINITY) else {
            continue;
        };
        let s = world.surface_at(o, d, hit);
        let dir = crate::sampling::uniform_cone(sun, 1e-5, crate::sampling::uniform2(&mut rng));
        shadow.push(
            world.offset.origin(s.position, s.normal),
            dir,
            f32::INFINITY,
        );
    }
    let hits = assert_packets_match_single_rays(&mut world.bvh, &primary);
    assert!(hits > primary.origin.len() / 2, "S1 sees mostly geometry");
    assert_packets_match_single_rays(&mut world.bvh, &shadow);
}
