//! Both wgpu backends give the same visibility (DESIGN.md §3 steps 2–3): on the test scenes and
//! views, the two-level pass finds the same visible (leaf, side) set on GL and on Vulkan, and the
//! same pixel counts per leaf. A fresh machine has only GL (Mesa's llvmpipe through EGL), CI has
//! both; a difference between them once hid a failing test behind a green CI.
//!
//! Each backend missing here is reported and the comparison skipped, unless the
//! `WALKTHROUGH_REQUIRE_BACKENDS` list (e.g. `gl,vulkan`, as `.ci/run` sets it) names it, where the
//! test fails.

use std::collections::HashMap;

use protocol::Side;
use protocol::viewer_link::Camera;
use sma::mesh::{MeshParams, NodeId, SubdivisionMesh};
use sma::visibility::{Gpu, LeafView, Visibility};

const REQUIRE_VAR: &str = "WALKTHROUGH_REQUIRE_BACKENDS";
const W: u32 = 256;
const H: u32 = 192;
/// Largest share of a leaf's pixels that may differ between the backends, and of all covered
/// pixels. The backends round the viewport transform differently in the last bit, so a pixel
/// centre within a rounding error of an edge may go to either neighbour: one pixel per leaf is
/// always allowed, and a leaf seen in one pixel by one backend only is such a tie, not a
/// difference of visible sets. A depth test that fails on one backend moves many pixels at once.
const PIXEL_TOLERANCE: f64 = 1e-3;

fn open(name: &str, backends: wgpu::Backends) -> Option<Gpu> {
    let required = std::env::var(REQUIRE_VAR)
        .unwrap_or_default()
        .split(',')
        .any(|b| b.trim().eq_ignore_ascii_case(name));
    match Gpu::on_backends(backends) {
        Ok(gpu) => Some(gpu),
        Err(e) if required => panic!("{REQUIRE_VAR} names {name}, but it has no adapter: {e}"),
        Err(e) => {
            eprintln!("SKIPPED: no {name} adapter ({e}); set {REQUIRE_VAR}={name} to fail");
            None
        }
    }
}

fn camera(vp: &scene::ViewpointSetting) -> Camera {
    testkit::views::camera(vp, W, H)
}

/// Pixels per visible (leaf, side).
fn counts(view: &LeafView) -> HashMap<(NodeId, Side), u32> {
    view.visible
        .leaves
        .iter()
        .map(|l| ((l.leaf, l.side), l.pixels))
        .collect()
}

/// Every difference between the two views beyond a rounding tie, described; empty when they agree.
fn differences(gl: &LeafView, vulkan: &LeafView) -> Vec<String> {
    let (a, b) = (counts(gl), counts(vulkan));
    let mut out = Vec::new();
    let mut moved = 0u64;
    let keys: std::collections::BTreeSet<_> = a.keys().chain(b.keys()).collect();
    for key in keys {
        let (pa, pb) = (a.get(key).copied(), b.get(key).copied());
        let (na, nb) = (pa.unwrap_or(0), pb.unwrap_or(0));
        moved += u64::from(na.abs_diff(nb));
        let allowed = ((PIXEL_TOLERANCE * na.max(nb) as f64) as u32).max(1);
        if na.abs_diff(nb) > allowed || (pa.is_none() || pb.is_none()) && na.max(nb) > 1 {
            out.push(format!("{key:?}: {pa:?} px on GL, {pb:?} px on Vulkan"));
        }
    }
    let covered: u64 = a.values().map(|&p| u64::from(p)).sum();
    if moved as f64 > PIXEL_TOLERANCE * covered as f64 {
        out.push(format!("{moved} of {covered} pixels differ"));
    }
    out
}

/// One red split of every leaf seen from `camera`, twice: a mesh of leaves at three depths.
fn refine_where_seen(mesh: &mut SubdivisionMesh, visibility: &mut Visibility, camera: &Camera) {
    for _ in 0..2 {
        let view = visibility
            .leaf_view(mesh, camera)
            .expect("a visibility pass");
        let seen: Vec<NodeId> = view.visible.leaves.iter().map(|l| l.leaf).collect();
        mesh.refine(&seen, &|_| false);
    }
}

fn compare_scene(name: &str, scene: &scene::Scene, gl: &Gpu, vulkan: &Gpu) -> Vec<String> {
    let mut failures = Vec::new();
    for vp in &scene.settings.viewpoints {
        let cam = camera(vp);
        let mut mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
        let bounds = scene.mesh.bounds();
        let mut on_gl = Visibility::new(gl.clone(), &mesh, bounds);
        let mut on_vulkan = Visibility::new(vulkan.clone(), &mesh, bounds);
        for stage in ["base mesh", "refined"] {
            if stage == "refined" {
                refine_where_seen(&mut mesh, &mut on_vulkan, &cam);
            }
            let a = on_gl.leaf_view(&mesh, &cam).expect("GL pass");
            let b = on_vulkan.leaf_view(&mesh, &cam).expect("Vulkan pass");
            let diff = differences(&a, &b);
            eprintln!(
                "{name} {} {stage}: {} leaves on GL, {} on Vulkan, {} differences",
                vp.name,
                a.visible.leaves.len(),
                b.visible.leaves.len(),
                diff.len()
            );
            for d in diff.iter().take(10) {
                failures.push(format!("{name} {} {stage}: {d}", vp.name));
            }
        }
    }
    failures
}

#[test]
fn gl_and_vulkan_see_the_same_leaves_with_the_same_pixel_counts() {
    let (Some(gl), Some(vulkan)) = (
        open("gl", wgpu::Backends::GL),
        open("vulkan", wgpu::Backends::VULKAN),
    ) else {
        return;
    };
    eprintln!("GL: {}\nVulkan: {}", gl.describe(), vulkan.describe());
    let mut scenes = vec![
        ("bracara", scene::load("bracara").expect("built-in scene")),
        ("cornell", scene::load("cornell").expect("built-in scene")),
    ];
    let sponza = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/sponza.toml");
    match scene::load(sponza) {
        Ok(s) => scenes.push(("sponza", s)),
        Err(e) => eprintln!("sponza left out: {e}"),
    }
    let failures: Vec<String> = scenes
        .iter()
        .flat_map(|(name, s)| compare_scene(name, s, &gl, &vulkan))
        .collect();
    assert!(
        failures.is_empty(),
        "the backends disagree:\n{}",
        failures.join("\n")
    );
}
