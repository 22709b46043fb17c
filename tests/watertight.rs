//! Watertight drawing (DESIGN.md §3 step 3, §4): what a viewer draws of the shown triangles has
//! no crack, a pixel left to the background whose eight neighbours all show geometry and which
//! the renderer's coverage of the view marks as geometry.
//!
//! The six default views (bracara's MC, VR and VT; Sponza's S1, S2 and S3, read from
//! `../shared/scenes/sponza`: if that fails to load, bracara's views alone, and the test says
//! so) run on the whole system over loopback (`walkthrough renderer serve` and `walkthrough sma`,
//! with the scripted viewer of `testkit::probe` holding the table), each refined for a fixed
//! number of samples. The table is drawn as the viewer draws it (`viewer::render_offscreen_with`)
//! and compared with the renderer's coverage (a camera ray per pixel, in process). Before the SMA
//! sent guard leaves (`sma::visibility::guards`), drew the visible bases' neighbours at level 2
//! and stitched the scenes' T-junctions (`sma::mesh`), these views showed 1 to 18 crack pixels
//! each, 43 to 49 in all (llvmpipe, Vulkan and GL).
//!
//! Needs a wgpu adapter (Mesa's llvmpipe without a GPU): without one the test says so and
//! returns, unless `WALKTHROUGH_REQUIRE_GPU` is set, where it fails.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use protocol::viewer_link::{Camera, ShownTriangle};
use renderer::World;
use renderer::reference::{ReferenceSettings, render};
use testkit::loopback::{System, SystemConfig};
use testkit::probe::Probe;
use viewer::gpu::Gpu;

/// The size the cracks were reported at.
const WIDTH: u32 = 1024;
const HEIGHT: u32 = 768;
/// Samples each view is refined for, counted from its first epoch: 3 to 6 s a view on two
/// cores with llvmpipe, by when it shows 15 000 to 40 000 triangles.
const SAMPLES: u64 = 40_000;
/// A view that takes longer has failed.
const VIEW_LIMIT: Duration = Duration::from_secs(120);

struct Scene {
    name: &'static str,
    /// A built-in name or a TOML path.
    source: PathBuf,
    views: [&'static str; 3],
}

/// What one view showed.
#[derive(Debug)]
struct Findings {
    view: String,
    shown: usize,
    samples: u64,
    cracks: Vec<(u32, u32)>,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_default_views_show_no_crack_between_shown_triangles() {
    let gpu = match viewer::gpu::headless_or_skip("watertight") {
        Ok(Some(gpu)) => gpu,
        Ok(None) => return,
        Err(e) => panic!("{e:#}"),
    };
    let work = tempfile::tempdir().expect("a temporary folder");
    let scenes = [
        Scene {
            name: "bracara",
            source: "bracara".into(),
            views: ["MC", "VR", "VT"],
        },
        Scene {
            name: "sponza",
            source: Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sponza.toml"),
            views: ["S1", "S2", "S3"],
        },
    ];
    let mut findings = Vec::new();
    for scene in &scenes {
        let loaded = match scene::load(&scene.source.to_string_lossy()) {
            Ok(loaded) => loaded,
            Err(e) if scene.name == "sponza" => {
                eprintln!(
                    "watertight: Sponza did not load ({e:#}); only bracara's views are covered"
                );
                continue;
            }
            Err(e) => panic!("loading {}: {e:#}", scene.name),
        };
        findings.extend(run_scene(&gpu, scene, World::new(loaded), work.path()).await);
    }
    for f in &findings {
        eprintln!(
            "{}: {} shown after {} samples, {} crack pixels {:?}",
            f.view,
            f.shown,
            f.samples,
            f.cracks.len(),
            &f.cracks[..f.cracks.len().min(8)],
        );
    }
    let failed: Vec<&Findings> = findings.iter().filter(|f| !f.cracks.is_empty()).collect();
    assert!(failed.is_empty(), "cracks: {failed:#?}");
}

/// The scene's views, one after another on one running system.
async fn run_scene(gpu: &Gpu, scene: &Scene, world: World, work: &Path) -> Vec<Findings> {
    let config = SystemConfig {
        exe: Path::new(env!("CARGO_BIN_EXE_walkthrough")).to_path_buf(),
        scene: scene.source.to_string_lossy().into_owned(),
        criterion: "nld-os".into(),
        refine: true,
        seed: 1,
        renderers: 1,
        sma_flags: Vec::new(),
    };
    let system = System::start(&config, &work.join(scene.name))
        .unwrap_or_else(|e| panic!("starting the system on {}: {e:#}", scene.name));
    let mut probe = Probe::connect(&system.sma_addr().to_string())
        .await
        .expect("the probe viewer connects");
    let mut out = Vec::new();
    for view in scene.views {
        let started = Instant::now();
        let camera = probe.view(view, WIDTH, HEIGHT).await.expect("a camera");
        let first = probe
            .until(VIEW_LIMIT, |e| e.camera_seq == camera.seq)
            .await
            .unwrap_or_else(|e| panic!("{view}: {e:#}"));
        let last = probe
            .until(VIEW_LIMIT, |e| {
                e.camera_seq == camera.seq && e.samples >= first.samples + SAMPLES
            })
            .await
            .unwrap_or_else(|e| panic!("{view}: {e:#}"));
        let shown: Vec<ShownTriangle> = probe.table.values().cloned().collect();
        let drawn = viewer::render_offscreen_with(gpu, &shown, &camera, &Default::default())
            .expect("drawing the table");
        let covered = renderer_coverage(&world, view);
        out.push(Findings {
            view: format!("{} {view}", scene.name),
            shown: shown.len(),
            samples: last.samples - first.samples,
            cracks: cracks(&drawn.covered, &covered, &camera),
        });
        eprintln!(
            "{} {view}: {:.1} s",
            scene.name,
            started.elapsed().as_secs_f64()
        );
    }
    drop(system);
    out
}

/// Whether a camera ray through each pixel hits the scene (`renderer reference`'s coverage, one
/// ray per pixel).
fn renderer_coverage(world: &World, view: &str) -> Vec<bool> {
    let camera = renderer::reference::camera_for(world, view, WIDTH, HEIGHT)
        .unwrap_or_else(|e| panic!("{view}: {e:#}"));
    let settings = ReferenceSettings {
        width: WIDTH,
        height: HEIGHT,
        spp: 1,
        bounces: Some(0),
        seed: 1,
    };
    render(world, &camera, &settings, None).0.covered
}

/// Pixels the drawing leaves to the background though their eight neighbours show geometry
/// and the renderer sees geometry there.
fn cracks(drawn: &[bool], renderer: &[bool], camera: &Camera) -> Vec<(u32, u32)> {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let mut out = Vec::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let ring = [
                i - w - 1,
                i - w,
                i - w + 1,
                i - 1,
                i + 1,
                i + w - 1,
                i + w,
                i + w + 1,
            ];
            if !drawn[i] && renderer[i] && ring.iter().all(|&j| drawn[j]) {
                out.push((x as u32, y as u32));
            }
        }
    }
    out
}
