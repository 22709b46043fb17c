//! Figures of the SMA service for BENCHMARKS.md (DESIGN.md §10 costs): the cost of one ID pass at 1024×768
//! against submitted triangles (fixed cost and slope, thesis §5.4: 137 triangles/ms plus 30 ms on
//! 2006 hardware), the two-level visibility of a built-in scene's named views, and, with renderer
//! and SMA processes started from the `walkthrough` binary, the end-to-end latencies and the SMA's
//! memory per leaf (see [`end_to_end`]).

use std::fmt::Write;
use std::time::Instant;

use glam::Vec3;
use protocol::types::Viewpoint;
use protocol::viewer_link::Camera;
use rand::{RngExt, SeedableRng};

use sma::mesh::{MeshParams, SubdivisionMesh};
use sma::visibility::{Gpu, IdPass, TriangleBuffer, View, Visibility};

use super::stats::{fit_line, median};

mod end_to_end;

const WIDTH: u32 = 1024;
const HEIGHT: u32 = 768;

pub fn section(quick: bool) -> anyhow::Result<String> {
    let gpu = Gpu::new()?;
    let runs = if quick { 3 } else { 10 };
    let mut md = String::from("## SMA service (crates/sma: visibility, schedule, pool)\n\n");
    writeln!(md, "Adapter: {}.\n", gpu.describe())?;
    write_pass_cost(&mut md, &gpu, runs, quick)?;
    drop(gpu);
    write_scene_views(&mut md, runs)?;
    match end_to_end::section(quick) {
        Ok(text) => md.push_str(&text),
        Err(e) => writeln!(md, "End-to-end figures not measured: {e:#}\n")?,
    }
    Ok(md)
}

/// `n` random triangles filling a 20-unit cube in front of the camera, sized so the total
/// projected area stays about the same whatever `n` (depth complexity ~ a few).
fn random_triangles(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let edge = 20.0 * 4.0 / (n.max(1) as f32).sqrt();
    let mut r = |s: f32| rng.random_range(-s..s);
    (0..n)
        .map(|_| {
            let c = Vec3::new(r(10.0), r(10.0), r(10.0) - 30.0);
            [
                c,
                c + Vec3::new(r(edge), r(edge), r(edge)),
                c + Vec3::new(r(edge), r(edge), r(edge)),
            ]
        })
        .collect()
}

fn bench_camera() -> Camera {
    let vp = Viewpoint {
        name: "bench".into(),
        eye: [0.0, 0.0, 0.0],
        target: [0.0, 0.0, -1.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 60.0,
    };
    Camera::from_viewpoint(&vp, 0, WIDTH, HEIGHT)
}

/// Median ms of render + readback + per-triangle coverage, per size (and of the coverage alone,
/// the CPU's share); then a least-squares line.
fn write_pass_cost(md: &mut String, gpu: &Gpu, runs: usize, quick: bool) -> anyhow::Result<()> {
    // 0: clear, copy and readback alone, the floor under the fitted fixed cost.
    let sizes: &[usize] = if quick {
        &[0, 10_000, 100_000, 300_000]
    } else {
        &[0, 10_000, 100_000, 1_000_000]
    };
    let camera = bench_camera();
    let view = View {
        camera: camera.pinhole(),
        near: 0.1,
        far: 100.0,
    };
    let mut pass = IdPass::new(gpu);
    writeln!(
        md,
        "### Visibility pass at {WIDTH}×{HEIGHT} (render + readback + per-triangle pixel counts)\n"
    )?;
    writeln!(
        md,
        "| submitted triangles | median ms ({runs} runs) | of which pixel counts (CPU) | visible triangles |\n|---:|---:|---:|---:|"
    )?;
    let mut points = Vec::new();
    for &n in sizes {
        let mut buffer = TriangleBuffer::default();
        buffer.upload(gpu, &random_triangles(n, n as u64), view.eye());
        let (mut times, mut counting) = (Vec::new(), Vec::new());
        let mut visible = 0;
        for _ in 0..runs + 1 {
            let t = Instant::now();
            let image = pass.render(gpu, &buffer, &view)?;
            let rendered = t.elapsed();
            visible = image.coverage(n).iter().filter(|c| c.pixels > 0).count();
            let total = t.elapsed();
            times.push(total.as_secs_f64() * 1e3);
            counting.push((total - rendered).as_secs_f64() * 1e3);
        }
        // The first run compiles pipelines and faults pages in.
        let (ms, counting_ms) = (median(times.split_off(1)), median(counting.split_off(1)));
        points.push((n as f64, ms));
        writeln!(md, "| {n} | {ms:.1} | {counting_ms:.1} | {visible} |")?;
    }
    let (fixed, slope) = fit_line(&points[1..]);
    writeln!(
        md,
        "\nLeast-squares fit over the non-empty sizes: fixed cost {fixed:.1} ms, slope {:.0} triangles/ms (targets: <= 10 ms, \
         >= 2,000 triangles/ms; thesis §5.4 on 2006 hardware: 30 ms, 137 triangles/ms). Uploading the \
         triangles is not counted: the base mesh is uploaded once, leaves when they change.\n",
        1.0 / slope.max(1e-12)
    )?;
    Ok(())
}

/// Both levels on each named view of the built-in scene, unrefined mesh.
fn write_scene_views(md: &mut String, runs: usize) -> anyhow::Result<()> {
    let scene = scene::load("bracara")?;
    let mesh = SubdivisionMesh::new(&scene.mesh, MeshParams::default());
    let mut visibility = Visibility::new(Gpu::new()?, &mesh, scene.mesh.bounds());
    writeln!(
        md,
        "### Two-level visibility on `bracara` ({} base triangles), {WIDTH}×{HEIGHT}\n",
        mesh.base_count()
    )?;
    writeln!(
        md,
        "| view | visible base | visible leaves | median ms ({runs} runs) |\n|---|---:|---:|---:|"
    )?;
    for vp in &scene.settings.viewpoints {
        let mut times = Vec::new();
        let mut last = None;
        for run in 0..runs + 1 {
            // A new camera each run (its sequence number), so that both levels render: a
            // camera seen before keeps its level 1.
            let camera = Camera {
                seq: run as u64,
                ..testkit::views::camera(vp, WIDTH, HEIGHT)
            };
            let t = Instant::now();
            last = Some(visibility.leaf_view(&mesh, &camera)?);
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.remove(0);
        let view = last.expect("at least one run");
        writeln!(
            md,
            "| {} | {} | {} | {:.1} |",
            vp.name,
            view.visible_bases,
            view.visible.leaves.len(),
            median(times)
        )?;
    }
    md.push('\n');
    Ok(())
}
