//! The two-level pass keeps level 1 (the visible base triangles) per camera (DESIGN.md §3 steps
//! 2–3): a pass after a refinement round, the camera unchanged, renders level 2 only, and must
//! find exactly what a fresh pass finds; a camera that moved, or came back, must too. A view
//! carried over to a refined or coarsened mesh without any pass must find it too, but for
//! slivers on the rasteriser's sub-pixel grid.
//! Needs a wgpu adapter (Mesa without a GPU): when none is found the test says so and returns,
//! unless `WALKTHROUGH_REQUIRE_GPU` is set, where it fails.

use std::collections::HashMap;

use glam::Vec3;
use protocol::viewer_link::Camera;
use sma::mesh::{MeshParams, NodeId, SubdivisionMesh};
use sma::visibility::{Gpu, LeafView, PixelLeaves, Visibility, carry_over};
use testkit::gpu::gpu_or_skip;

const W: u32 = 256;
const H: u32 = 192;

fn camera(vp: &scene::ViewpointSetting) -> Camera {
    testkit::views::camera(vp, W, H)
}

/// Each visible (leaf, side) with its pixels.
type Seen = Vec<(NodeId, protocol::Side, u32)>;

/// What a pass found, in a form two passes can be compared by.
fn found(view: &LeafView) -> (Seen, &PixelLeaves) {
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

/// How far a view carried over to a changed mesh is from a fresh pass: the share of covered
/// pixels given another leaf, and the most pixels a visible leaf that only one of them has
/// covers there.
fn carried_against_fresh(carried: &LeafView, fresh: &LeafView) -> (f64, u32) {
    let covered = fresh.pixel_leaves.iter().filter(|p| p.is_some()).count();
    let differ = carried
        .pixel_leaves
        .iter()
        .zip(fresh.pixel_leaves.iter())
        .filter(|(a, b)| a != b)
        .count();
    let leaves = |v: &LeafView| -> HashMap<(NodeId, protocol::Side), u32> {
        v.visible
            .leaves
            .iter()
            .map(|l| ((l.leaf, l.side), l.pixels))
            .collect()
    };
    let (a, b) = (leaves(carried), leaves(fresh));
    let only_in = |x: &HashMap<_, u32>, y: &HashMap<_, u32>| {
        x.iter()
            .filter(|(k, _)| !y.contains_key(*k))
            .map(|(_, &p)| p)
            .max()
            .unwrap_or(0)
    };
    (
        differ as f64 / covered.max(1) as f64,
        only_in(&a, &b).max(only_in(&b, &a)),
    )
}

/// Every other leaf seen at some pixel, from the first, until they cover `pixels`; guards (seen
/// at none) and leaves larger than that are left out.
fn leaves_covering(view: &LeafView, pixels: u32) -> Vec<NodeId> {
    let mut covered = 0;
    view.visible
        .leaves
        .iter()
        .filter(|l| (1..=pixels).contains(&l.pixels))
        .step_by(2)
        .take_while(|l| {
            covered += l.pixels;
            covered <= pixels
        })
        .map(|l| l.leaf)
        .collect()
}

/// Refinement and coarsening re-tile planar base triangles, so with the camera unchanged a view
/// carried over without a pass (DESIGN.md §3 step 3) must be a fresh pass's, but for pixels
/// whose centre lies on an edge two leaves share (the rasteriser's tie rule against the walk's).
#[test]
fn a_view_carried_over_to_a_changed_mesh_is_a_fresh_pass() {
    let Some(gpu) = gpu_or_skip(Gpu::new()) else {
        return;
    };
    let scene = scene::load("bracara").expect("built-in scene");
    let cam = camera(&scene.settings.viewpoints[0]);
    let mut mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
    let bounds = scene.mesh.bounds();
    let mut visibility = Visibility::new(gpu.clone(), &mesh, bounds);
    let mut view = visibility.leaf_view(&mesh, &cam).expect("a pass");
    // Two rounds of refinement (the second splits children of the first, and greens of its
    // closures, which red splits remove), then coarsening of what the first round split; each
    // round splits leaves covering about a twentieth of the image, so that it is carried over.
    let mut first_round = Vec::new();
    for round in 0..3 {
        let steps = if round < 2 {
            let chosen = leaves_covering(&view, W * H / 20);
            if round == 0 {
                first_round = chosen.clone();
            }
            mesh.refine(&chosen, &|_| false).len()
        } else {
            mesh.coarsen_many(&first_round).len()
        };
        assert!(steps > 0, "round {round} changed the mesh");
        let carried = carry_over(view.clone(), &mesh, &cam).expect("few pixels changed");
        let fresh = visibility.leaf_view(&mesh, &cam).expect("a pass");
        let (pixels, largest_unmatched) = carried_against_fresh(&carried, &fresh);
        assert!(
            pixels < 2e-3,
            "round {round}: {:.3} % of covered pixels differ",
            100.0 * pixels
        );
        // The rasteriser snaps vertices to a sub-pixel grid: a sliver whose few pixel centres
        // lie that close to its edges may be seen by one and not the other, nothing larger.
        assert!(
            largest_unmatched <= 4,
            "round {round}: a leaf of {largest_unmatched} pixels is seen by one view only"
        );
        for (v, c) in carried.visible.leaves.iter().zip(&carried.centroids) {
            let (x, y) = (c.0 as u32, c.1 as u32);
            assert!(
                x < W && y < H,
                "leaf {} centroid {c:?} in the image",
                v.leaf
            );
            assert!(mesh.is_leaf(v.leaf), "a carried entry is a live leaf");
        }
        view = carried;
    }
    // Splitting everything in sight leaves most pixels without their leaf: a pass is cheaper.
    let everything: Vec<NodeId> = view.visible.leaves.iter().map(|l| l.leaf).collect();
    mesh.refine(&everything, &|_| false);
    assert!(carry_over(view, &mesh, &cam).is_none());
}
