//! The two-level pass keeps level 1 (the visible base triangles) per camera (DESIGN.md §3 steps
//! 2–3): a pass after a refinement round, the camera unchanged, renders level 2 only, and must
//! find exactly what a fresh pass finds; a camera that moved, or came back, must too.
//! Needs a wgpu adapter (Mesa without a GPU): when none is found the test says so and returns,
//! unless `WALKTHROUGH_REQUIRE_GPU` is set, where it fails.

use glam::Vec3;
use protocol::viewer_link::Camera;
use sma::mesh::{MeshParams, NodeId, SubdivisionMesh};
use sma::visibility::{Gpu, LeafView, Visibility};
use testkit::gpu::gpu_or_skip;

const W: u32 = 256;
const H: u32 = 192;

fn camera(vp: &scene::ViewpointSetting) -> Camera {
    testkit::views::camera(vp, W, H)
}

/// Each visible (leaf, side) with its pixels.
type Seen = Vec<(NodeId, protocol::Side, u32)>;

/// What a pass found, in a form two passes can be compared by.
fn found(view: &LeafView) -> (Seen, &[Option<NodeId>]) {
    let leaves = view
        .visible
        .leaves
        .iter()
        .map(|l| (l.leaf, l.side, l.pixels))
        .collect();
    (leaves, &view.pixel_leaves)
}

/// `kept`'s pass for `cam` against that of a `Visibility` that has seen no camera.
fn assert_as_fresh(
    kept: &mut Visibility,
    mesh: &SubdivisionMesh,
    (gpu, bounds): (&Gpu, (Vec3, Vec3)),
    cam: &Camera,
    what: &str,
) {
    let mut fresh = Visibility::new(gpu.clone(), mesh, bounds);
    let (a, b) = (
        kept.leaf_view(mesh, cam).expect("a pass"),
        fresh.leaf_view(mesh, cam).expect("a pass"),
    );
    assert!(!a.visible.leaves.is_empty(), "{what}: something is seen");
    assert!(
        found(&a) == found(&b),
        "{what}: the kept level 1 changed the result"
    );
}

#[test]
fn a_pass_with_level_1_kept_finds_what_a_fresh_pass_finds() {
    let Some(gpu) = gpu_or_skip(Gpu::new()) else {
        return;
    };
    let scene = scene::load("bracara").expect("built-in scene");
    let cameras: Vec<Camera> = scene.settings.viewpoints.iter().map(camera).collect();
    assert!(cameras.len() >= 2, "bracara has several viewpoints");
    let mut mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
    let bounds = scene.mesh.bounds();
    let mut kept = Visibility::new(gpu.clone(), &mesh, bounds);
    let first = kept.leaf_view(&mesh, &cameras[0]).expect("a pass");
    let seen: Vec<NodeId> = first.visible.leaves.iter().map(|l| l.leaf).collect();
    mesh.refine(&seen, &|_| false);
    let device = (&gpu, bounds);
    assert_as_fresh(
        &mut kept,
        &mesh,
        device,
        &cameras[0],
        "same camera, leaves refined",
    );
    assert_as_fresh(&mut kept, &mesh, device, &cameras[1], "another camera");
    assert_as_fresh(
        &mut kept,
        &mesh,
        device,
        &cameras[0],
        "the first camera again",
    );
}
