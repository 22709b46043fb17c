//! The ID pass against a CPU ray cast on a hand-made scene (DESIGN.md §3 steps 2–3: "visibility on a hand-made
//! scene returns exactly the triangles a CPU check says are visible"), on both id paths.
//! Needs a wgpu adapter (Mesa without a GPU): when none is found the test says so and returns,
//! unless `WALKTHROUGH_REQUIRE_GPU` is set, where it fails.

use glam::Vec3;
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use sma::visibility::{Gpu, IdPass, LuminancePass, TriangleBuffer, View, id_pass::reversed_z};
use testkit::gpu::gpu_or_skip;

const W: u32 = 160;
const H: u32 = 120;

fn gpu(primitive_index: bool) -> Option<Gpu> {
    gpu_or_skip(Gpu::with_primitive_index(primitive_index))
}

fn quad(min: Vec3, u: Vec3, v: Vec3) -> [[Vec3; 3]; 2] {
    [[min, min + u, min + u + v], [min, min + u + v, min + v]]
}

/// A wall in front, a floor, a panel half hidden behind the wall, one fully hidden behind it,
/// one outside the view, one behind the eye, and one tilted so it is seen from its back.
fn scene() -> Vec<[Vec3; 3]> {
    let x = Vec3::X;
    let y = Vec3::Y;
    let z = Vec3::Z;
    [
        quad(Vec3::new(-1.0, -1.0, -4.0), 2.0 * x, 1.5 * y), // wall
        quad(Vec3::new(-6.0, -1.0, -20.0), 12.0 * x, 19.0 * z), // floor (y = -1)
        quad(Vec3::new(0.5, -0.9, -7.0), 2.5 * x, 1.8 * y),  // half behind the wall
        quad(Vec3::new(-0.4, -0.5, -6.0), 0.8 * x, 0.6 * y), // fully hidden
        quad(Vec3::new(30.0, 0.0, -5.0), x, y),              // off to the side
        quad(Vec3::new(-0.5, -0.5, 3.0), x, y),              // behind the eye
        quad(Vec3::new(-3.0, 0.6, -5.0), 1.5 * x - 0.7 * z, 1.0 * y), // back-facing, upper left
    ]
    .into_iter()
    .flatten()
    .collect()
}

fn camera() -> Camera {
    let vp = Viewpoint {
        name: "test".into(),
        eye: [0.0, 0.2, 1.0],
        target: [0.0, 0.0, -5.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    Camera::from_viewpoint(&vp, 1, W, H)
}

fn view(cam: &Camera) -> View {
    View {
        camera: cam.pinhole(),
        near: 0.01,
        far: 100.0,
    }
}

/// Möller–Trumbore, two-sided: distance along the ray, if hit.
fn hit(o: Vec3, d: Vec3, [a, b, c]: [Vec3; 3]) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some(t)
}

/// The triangle seen through each pixel centre (index + 1, 0 for none).
fn cpu_ids(tris: &[[Vec3; 3]], cam: &Camera) -> Vec<u32> {
    let mut ids = Vec::with_capacity((W * H) as usize);
    for py in 0..H {
        for px in 0..W {
            let d = cam.ray_direction(px as f32 + 0.5, py as f32 + 0.5);
            let nearest = tris
                .iter()
                .enumerate()
                .filter_map(|(i, t)| hit(cam.eye_vec(), d, *t).map(|t| (t, i)))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            ids.push(nearest.map_or(0, |(_, i)| i as u32 + 1));
        }
    }
    ids
}

fn check_path(primitive_index: bool) {
    let Some(gpu) = gpu(primitive_index) else {
        return;
    };
    eprintln!("adapter: {}", gpu.describe());
    let tris = scene();
    let cam = camera();
    let mut pass = IdPass::new(&gpu);
    let mut buffer = TriangleBuffer::default();
    buffer.upload(&gpu, &tris, view(&cam).eye());
    let image = pass.render(&gpu, &buffer, &view(&cam)).unwrap();
    let cpu = cpu_ids(&tris, &cam);

    let gpu_cov = image.coverage(tris.len());
    let cpu_cov = sma::visibility::IdImage {
        width: W,
        height: H,
        ids: cpu.clone(),
    }
    .coverage(tris.len());
    let seen = |c: &[sma::visibility::Coverage]| -> Vec<usize> {
        (0..tris.len()).filter(|&i| c[i].pixels > 0).collect()
    };
    assert_eq!(
        seen(&gpu_cov),
        seen(&cpu_cov),
        "visible triangles differ from the CPU ray cast"
    );
    // The scene is built so each visible triangle shows, hidden ones do not.
    let visible = seen(&gpu_cov);
    for t in [0, 1, 2, 3, 4, 5, 12, 13] {
        assert!(
            visible.contains(&t),
            "triangle {t} should be visible: {visible:?}"
        );
    }
    for t in [6, 7, 8, 9, 10, 11] {
        assert!(
            !visible.contains(&t),
            "triangle {t} should be hidden: {visible:?}"
        );
    }
    // Pixels differ only on shared edges, where rasterisation and ray casting may round apart.
    let differing = image.ids.iter().zip(&cpu).filter(|(a, b)| a != b).count();
    assert!(
        differing < (W * H) as usize / 100,
        "{differing} pixels differ"
    );
}

#[test]
fn id_pass_matches_cpu_ray_cast_with_primitive_index() {
    check_path(true);
}

#[test]
fn id_pass_matches_cpu_ray_cast_with_vertex_index() {
    check_path(false);
}

#[test]
fn luminance_pass_interpolates_vertex_luminance() {
    let Some(gpu) = gpu(true) else { return };
    let cam = camera();
    let wall = quad(Vec3::new(-1.0, -1.0, -4.0), 2.0 * Vec3::X, 1.5 * Vec3::Y);
    let tris: Vec<_> = wall.iter().map(|t| (*t, t.map(|p| p.x + 2.0))).collect();
    let mut pass = LuminancePass::new(&gpu);
    let lum = pass.render(&gpu, &tris, &view(&cam)).unwrap();
    // Along the centre row, luminance is x + 2 of the wall point seen there.
    let row = H / 2 + 10;
    let vp = reversed_z(cam.view_projection(0.01, 100.0));
    let mut checked = 0;
    for px in 0..W {
        let d = cam.ray_direction(px as f32 + 0.5, row as f32 + 0.5);
        let Some(t) = wall.iter().find_map(|tri| hit(cam.eye_vec(), d, *tri)) else {
            continue;
        };
        let p = cam.eye_vec() + d * t;
        let l = lum[(row * W + px) as usize];
        if (vp * p.extend(1.0)).w > 0.0 && l > 0.0 {
            assert!(
                (l - (p.x + 2.0)).abs() < 0.05,
                "pixel {px}: {l} vs {}",
                p.x + 2.0
            );
            checked += 1;
        }
    }
    assert!(checked > 20, "only {checked} pixels of the wall checked");
}

/// The hand-made scene and camera moved by (1e5, 0, 1e5), where f32 spacing is about 0.008,
/// give the ID image of the centred ones (DESIGN.md §7: also far from the origin). Both copies
/// are built from the same f32 positions (the centred one is the far one moved back, which is
/// exact), so the scenes are the same and any difference is the pass's own. Drawn with world
/// positions and a matrix holding the 1e5 translation, 5 to 6 of the 19,200 pixels changed (on
/// Mesa, both backends).
#[test]
fn a_scene_far_from_the_origin_gives_the_centred_id_image() {
    let Some(gpu) = gpu(true) else { return };
    let offset = Vec3::new(1.0e5, 0.0, 1.0e5);
    let far_tris: Vec<[Vec3; 3]> = scene().iter().map(|t| t.map(|p| p + offset)).collect();
    let near_tris: Vec<[Vec3; 3]> = far_tris.iter().map(|t| t.map(|p| p - offset)).collect();
    let far_cam = Camera {
        eye: (camera().eye_vec() + offset).to_array(),
        ..camera()
    };
    let near_cam = Camera {
        eye: (far_cam.eye_vec() - offset).to_array(),
        ..camera()
    };
    let mut pass = IdPass::new(&gpu);
    let mut image = |tris: &[[Vec3; 3]], cam: &Camera| {
        let mut buffer = TriangleBuffer::default();
        buffer.upload(&gpu, tris, view(cam).eye());
        pass.render(&gpu, &buffer, &view(cam)).unwrap().ids
    };
    let (near, far) = (image(&near_tris, &near_cam), image(&far_tris, &far_cam));
    assert!(near.iter().any(|&id| id != 0), "the centred scene is seen");
    let differing = near.iter().zip(&far).filter(|(a, b)| a != b).count();
    assert_eq!(
        differing, 0,
        "{differing} pixels differ far from the origin"
    );
}
