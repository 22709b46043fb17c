//! The renderer's section of BENCHMARKS.md (DESIGN.md §10 costs): ray throughput on Sponza against a naive baseline in
//! the same run and build, BVH build times, shading samples per second at the interactive and
//! direct-light qualities, and what accuracy costs in time. Medians of several runs, on every
//! core of the machine.

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::Context;
use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadeBatch, ShadePoint};

use renderer::estimator::Estimator;
use renderer::internals::{SceneBvh, Traversal};
use renderer::point::front_point_hit_by;
use renderer::reference::Image;
use renderer::reference::{ReferenceSettings, camera_for, render};
use renderer::sampling::luminance;
use renderer::vector_level::VectorLevel;
use renderer::world::World;
use renderer::{FirstBounce, shade_batch};
use scene::bvh::BuildPreset;

use super::ray_throughput::ray_throughput;
use super::stats::{median, median_seconds};

/// Sponza's scene file, relative to the repository root (it reads ../shared/scenes).
pub const SPONZA: &str = "scenes/sponza.toml";

/// Sizes of one benchmark run.
pub(super) struct Config {
    pub(super) runs: usize,
    /// Image whose pixels give the rays (primary rays and the points they hit).
    pub(super) width: u32,
    pub(super) height: u32,
    /// Shading points for samples per second.
    points: usize,
    /// Points, reference paths and path levels of the error/time table.
    error_points: usize,
    reference_paths: u32,
    path_levels: &'static [u32],
    /// Size and paths per pixel of the timed reference renders, and how many runs of them.
    image: (u32, u32, u32),
    image_runs: usize,
    /// Size and paths per pixel of the Cornell box renders whose answers old and new must share.
    cornell: (u32, u32, u32),
}

const FULL: Config = Config {
    runs: 5,
    width: 1024,
    height: 768,
    points: 2000,
    error_points: 200,
    reference_paths: 16_384,
    path_levels: &[4, 16, 64, 256, 1024],
    image: (1024, 768, 64),
    image_runs: 3,
    cornell: (256, 256, 1024),
};

const QUICK: Config = Config {
    runs: 3,
    width: 160,
    height: 120,
    points: 100,
    error_points: 12,
    reference_paths: 256,
    path_levels: &[4, 16, 64],
    image: (64, 48, 4),
    image_runs: 3,
    cornell: (32, 32, 16),
};

const BOUNCE_LEVELS: [Option<u32>; 4] = [Some(0), Some(1), Some(2), None];

/// The renderer's section of BENCHMARKS.md.
pub fn section(quick: bool) -> anyhow::Result<String> {
    let cfg = if quick { &QUICK } else { &FULL };
    let mut md = String::from("## Renderer\n\n");
    writeln!(
        md,
        "{} worker threads; built for {}; ray queries at run time: {} (the best level this CPU runs); medians of {} runs{}.\n",
        rayon::current_num_threads(),
        cpu_level(),
        VectorLevel::detected().name(),
        cfg.runs,
        if quick {
            " (quick: small sizes, figures indicative only)"
        } else {
            ""
        }
    )?;
    // Other processes on the machine change every figure: say how busy it was.
    writeln!(
        md,
        "Load average when the run started: {}.\n",
        super::machine::load_average()
    )?;
    let sponza = match scene::load(SPONZA) {
        Ok(s) => Some(World::new(s)),
        Err(e) => {
            writeln!(md, "Sponza not available ({e}): its parts are skipped.\n")?;
            None
        }
    };
    if let Some(sponza) = &sponza {
        md += &ray_throughput(&sponza.scene, "S1", cfg)?;
        md += &bvh_build_times(&sponza.scene, cfg);
        md += &hidden_vertices(sponza, cfg)?;
    }
    let bracara = World::new(scene::load("bracara").context("loading bracara")?);
    let mut scenes: Vec<Subject> = sponza.into_iter().map(|s| Subject::new(s, "S1")).collect();
    scenes.push(Subject::new(bracara, "VR"));
    md += &samples_per_second(&mut scenes, cfg)?;
    md += &reference_times(&mut scenes, cfg)?;
    md += &cornell_agreement(cfg)?;
    for subject in &scenes {
        md += &error_and_time(&subject.world, subject.view, cfg)?;
    }
    Ok(md)
}

/// Which x86-64 level the binary was compiled for (code outside the ray queries runs at it).
fn cpu_level() -> &'static str {
    if cfg!(target_feature = "avx2") && cfg!(target_feature = "fma") {
        "x86-64-v3 or above (AVX2, FMA)"
    } else {
        "generic x86-64 (no AVX2)"
    }
}

fn bvh_build_times(scene: &scene::Scene, cfg: &Config) -> String {
    let mut md = format!(
        "### BVH build, Sponza ({} triangles; ms, median of {})\n\n| preset | build ms | references |\n|---|---:|---:|\n",
        scene.mesh.triangles.len(),
        cfg.runs
    );
    for (name, preset) in [
        ("fast", BuildPreset::Fast),
        ("medium", BuildPreset::Medium),
        ("slow (the renderer before)", BuildPreset::Slow),
        ("very slow (used)", BuildPreset::VerySlow),
    ] {
        let mut refs = 0;
        let ms = median(
            (0..cfg.runs)
                .map(|_| {
                    let b = SceneBvh::build(&scene.mesh, preset);
                    refs = b.primitive_count();
                    b.build_time().as_secs_f64() * 1e3
                })
                .collect(),
        );
        let _ = writeln!(md, "| {name} | {ms:.1} | {refs} |");
    }
    md.push('\n');
    md
}

/// Shading points where the view's pixels (a regular grid) see geometry, on the side facing the
/// eye: the points an SMA would ask for.
fn visible_points(world: &World, view: &str, n: usize) -> anyhow::Result<Vec<ShadePoint>> {
    let aspect = 4.0 / 3.0;
    let h = ((n as f32 / aspect).sqrt().ceil() as u32).max(1) * 2;
    let w = (h as f32 * aspect) as u32;
    let cam = camera_for(world, view, w, h)?;
    let mut points = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let dir = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
            let Some(mut p) = front_point_hit_by(world, cam.eye_vec(), dir, Some(cam.eye)) else {
                continue;
            };
            if renderer::point::surface_of(world, &p).is_ok_and(|s| s.normal.dot(dir) > 0.0) {
                p.side = Side::Back;
                p.key.side = Side::Back;
            }
            points.push(p);
        }
    }
    // Spread the kept points over the image rather than taking its top rows.
    let step = (points.len() / n.max(1)).max(1);
    Ok(points.into_iter().step_by(step).take(n).collect())
}

/// One way the renderer may trace: tree, estimator, traversal, vector level, first-bounce
/// sampling.
#[derive(Clone, Copy)]
struct Variant {
    /// The build preset of the tree it traces.
    preset: BuildPreset,
    estimator: Estimator,
    traversal: Traversal,
    level: VectorLevel,
    first_bounce: FirstBounce,
    /// `World::packets`: the wavefront estimator's coherent rays as packets.
    packets: bool,
}

impl Variant {
    /// The renderer before its own wide traversal, stratified first bounces and very slow
    /// preset: one path at a time, each sampled independently, over obvhs's compressed nodes of
    /// a slow-preset tree, at the best vector level.
    fn old() -> Variant {
        Variant {
            preset: BuildPreset::Slow,
            estimator: Estimator::Path,
            traversal: Traversal::Compressed,
            level: VectorLevel::detected(),
            first_bounce: FirstBounce::Independent,
            packets: false,
        }
    }

    fn wide(estimator: Estimator, level: VectorLevel) -> Variant {
        Variant {
            preset: World::PRESET,
            estimator,
            traversal: Traversal::Wide,
            level,
            first_bounce: FirstBounce::default(),
            packets: true,
        }
    }

    /// The same, every ray traced one at a time.
    fn single_rays(self) -> Variant {
        Variant {
            packets: false,
            ..self
        }
    }
}

/// A scene's world and the view measured, with the tree of the other preset kept aside, so that
/// each variant traces on its own renderer's tree.
struct Subject<'v> {
    world: World,
    view: &'v str,
    /// The tree not in `world.bvh` now: the old renderer's while today's is in place.
    spare: SceneBvh,
}

impl<'v> Subject<'v> {
    fn new(world: World, view: &'v str) -> Subject<'v> {
        // The world's mesh is already in its local frame, where trees are built.
        let spare = SceneBvh::build(&world.scene.mesh, Variant::old().preset);
        Subject { world, view, spare }
    }

    /// Sets the world up to trace as `variant` does.
    fn apply(&mut self, variant: Variant) {
        if self.world.bvh.preset() != variant.preset {
            std::mem::swap(&mut self.world.bvh, &mut self.spare);
        }
        let world = &mut self.world;
        assert_eq!(world.bvh.preset(), variant.preset, "a tree per preset");
        world.estimator = variant.estimator;
        world.first_bounce = variant.first_bounce;
        world.packets = variant.packets;
        world.bvh.set_traversal(variant.traversal);
        world.bvh.set_vector_level(variant.level);
    }

    /// Puts the renderer's defaults back after a comparison.
    fn restore_defaults(&mut self) {
        self.apply(Variant::wide(Estimator::default(), VectorLevel::detected()));
    }
}

/// Samples per second of the full estimator, the old renderer's and today's, one path at a time
/// and as ray streams, with the ray queries at the baseline and at the best vector level: all
/// timed in turn within each run; medians, and the medians of the per-run ratios.
fn samples_per_second(scenes: &mut [Subject], cfg: &Config) -> anyhow::Result<String> {
    let best = VectorLevel::detected();
    let name = best.name();
    let mut md = format!(
        "### Shading samples per second (points of the view's visible surfaces)\n\n\"path\": one path at a time; \"wavefront\": up to 4096 paths (64 points of 64 paths) advance together, their shadow rays then their continuation rays traced as streams, a shadow ray trying the previous one's blocker first (DESIGN.md §7), the sun shadow rays of a point's paths traced eight at a time as packets (\"single rays\": without packets). \"old\": the renderer before its wide traversal, stratified first bounces and very slow tree preset (one path at a time over obvhs's compressed nodes, {name}, on a slow-preset tree, every path's first bounce drawn independently); the others run the wide traversal on a very-slow-preset tree (`World::PRESET`) with stratified first bounces. All share the rest of today's code (sampling, materials, lights). Same points and seeds, same answers in distribution; each variant's figures include all of its work, and all are timed in turn within each run; ratios are medians of the per-run ratios.\n\n| scene | view | quality | points | old | path, baseline | path, {name} | wavefront, baseline | wavefront, {name} | wavefront, {name}, single rays | path {name} / old | {name} / baseline (path) | wavefront / path ({name}) | packets / single rays (wavefront, {name}) | rays/sample |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let variants = [
        Variant::old(),
        Variant::wide(Estimator::Path, VectorLevel::Baseline),
        Variant::wide(Estimator::Path, best),
        Variant::wide(Estimator::Wavefront, VectorLevel::Baseline),
        Variant::wide(Estimator::Wavefront, best),
        Variant::wide(Estimator::Wavefront, best).single_rays(),
    ];
    for subject in scenes.iter_mut() {
        let points = visible_points(&subject.world, subject.view, cfg.points)?;
        for (label, quality) in [
            ("interactive (64 paths, 2 bounces)", Quality::INTERACTIVE),
            ("direct (16 paths, 0 bounces)", Quality::DIRECT),
        ] {
            let batch = ShadeBatch {
                batch_id: 0,
                quality,
                seed: 1,
                points: points.clone(),
            };
            let mut rays = 0;
            let per_run: Vec<[f64; 6]> = (0..cfg.runs)
                .map(|_| {
                    variants.map(|variant| {
                        subject.apply(variant);
                        let start = Instant::now();
                        rays = shade_batch(&subject.world, &batch).1.total();
                        points.len() as f64 / start.elapsed().as_secs_f64()
                    })
                })
                .collect();
            subject.restore_defaults();
            let rates: [f64; 6] =
                std::array::from_fn(|k| median(per_run.iter().map(|r| r[k]).collect()));
            let ratio =
                |k: usize, base: usize| median(per_run.iter().map(|r| r[k] / r[base]).collect());
            writeln!(
                md,
                "| {} | {} | {label} | {} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.0} | {:.2}× | {:.2}× | {:.2}× | {:.2}× | {:.0} |",
                subject.world.scene.name,
                subject.view,
                points.len(),
                rates[0],
                rates[1],
                rates[2],
                rates[3],
                rates[4],
                rates[5],
                ratio(2, 0),
                ratio(2, 1),
                ratio(4, 2),
                ratio(4, 5),
                rays as f64 / points.len() as f64
            )?;
        }
    }
    md.push('\n');
    Ok(md)
}

/// Wall time and noise of a reference render of each view by the old renderer and by today's,
/// one path at a time and as ray streams, timed in turn within each run at the best vector level.
/// Run `r` renders with seed `r`, so two runs of a variant are independent images: their
/// difference gives the variant's noise, and the time at equal noise (time × noise², the inverse
/// of a Monte Carlo estimator's efficiency) compares variants whose noise differs.
fn reference_times(scenes: &mut [Subject], cfg: &Config) -> anyhow::Result<String> {
    let (width, height, spp) = cfg.image;
    let best = VectorLevel::detected();
    let variants = [
        Variant::old(),
        Variant::wide(Estimator::Path, best),
        Variant::wide(Estimator::Wavefront, best),
    ];
    let mut md = format!(
        "### Reference render time and noise ({width}×{height}, {spp} paths per pixel, 2 bounces; s, median of {})\n\n\"old\": one path at a time over obvhs's compressed nodes of a slow-preset tree, every path's first bounce drawn independently; \"path\" and \"wavefront\": the estimators over the wide traversal of a very-slow-preset tree, the first bounces of a pixel's paths stratified (`strata`), the wavefront one tracing each pixel's camera rays and each point's sun shadow rays as packets of eight; all at {}, timed in turn within each run. Run r uses seed r, so the runs of one variant are independent images. Noise: RMS of the luminance difference of the first two runs' images over √2, relative to the mean luminance. \"at equal noise\": old time × old noise² ÷ (time × noise²), the speed-up to the same noise (a Monte Carlo estimator's error falls as 1/√paths).\n\n| scene | view | old s | path s | wavefront s | old / path | old / wavefront | noise, old | path | wavefront | at equal noise, path | wavefront | mean luminance, old | path | wavefront |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        cfg.image_runs,
        best.name()
    );
    for subject in scenes.iter_mut() {
        let camera = camera_for(&subject.world, subject.view, width, height)?;
        let mut images: [Vec<Image>; 3] = Default::default();
        let per_run: Vec<[f64; 3]> = (0..cfg.image_runs)
            .map(|run| {
                let settings = ReferenceSettings {
                    width,
                    height,
                    spp,
                    bounces: Quality::INTERACTIVE.bounces,
                    seed: run as u64 + 1,
                };
                std::array::from_fn(|k| {
                    subject.apply(variants[k]);
                    let start = Instant::now();
                    let (image, _) = render(&subject.world, &camera, &settings, None);
                    let secs = start.elapsed().as_secs_f64();
                    images[k].push(image);
                    secs
                })
            })
            .collect();
        subject.restore_defaults();
        let times = [0, 1, 2].map(|k| median(per_run.iter().map(|r| r[k]).collect()));
        let ratio = |k: usize| median(per_run.iter().map(|r| r[0] / r[k]).collect());
        let noise = images
            .each_ref()
            .map(|runs| relative_noise(&runs[0], &runs[1]));
        let at_equal_noise = |k: usize| times[0] * noise[0].powi(2) / (times[k] * noise[k].powi(2));
        let means = images.each_ref().map(|runs| mean_luminance(&runs[0]));
        writeln!(
            md,
            "| {} | {} | {:.2} | {:.2} | {:.2} | {:.2}× | {:.2}× | {:.3} | {:.3} | {:.3} | {:.2}× | {:.2}× | {:.4} | {:.4} | {:.4} |",
            subject.world.scene.name,
            subject.view,
            times[0],
            times[1],
            times[2],
            ratio(1),
            ratio(2),
            noise[0],
            noise[1],
            noise[2],
            at_equal_noise(1),
            at_equal_noise(2),
            means[0],
            means[1],
            means[2]
        )?;
    }
    md.push('\n');
    Ok(md)
}

/// The estimator's answer, old against today's: the built-in Cornell box's mean luminance at
/// unbounded depth, rendered once by each (different sample patterns, so they differ by their
/// noise only where the answers agree).
fn cornell_agreement(cfg: &Config) -> anyhow::Result<String> {
    let (width, height, spp) = cfg.cornell;
    let world = World::new(scene::load("cornell").context("loading cornell")?);
    let mut subject = Subject::new(world, "main");
    let camera = camera_for(&subject.world, subject.view, width, height)?;
    let settings = ReferenceSettings {
        width,
        height,
        spp,
        bounces: None,
        seed: 1,
    };
    let [old, new] = [
        Variant::old(),
        Variant::wide(Estimator::default(), VectorLevel::detected()),
    ]
    .map(|variant| {
        subject.apply(variant);
        let start = Instant::now();
        let mean = mean_luminance(&render(&subject.world, &camera, &settings, None).0);
        (mean, start.elapsed().as_secs_f64())
    });
    let difference = (new.0 / old.0 - 1.0) * 100.0;
    Ok(format!(
        "### Same answers: the Cornell box ({width}×{height}, {spp} paths per pixel, unbounded depth; one render each)\n\n| renderer | mean luminance | s |\n|---|---:|---:|\n| old | {:.5} | {:.1} |\n| today's | {:.5} | {:.1} |\n\nDifference {difference:+.2} % (target: within 0.5 %: {}).\n\n",
        old.0,
        old.1,
        new.0,
        new.1,
        if difference.abs() <= 0.5 {
            "met"
        } else {
            "missed"
        }
    ))
}

fn mean_luminance(image: &Image) -> f64 {
    image
        .pixels
        .iter()
        .map(|&p| luminance(p) as f64)
        .sum::<f64>()
        / image.pixels.len() as f64
}

/// The per-pixel noise of two independent renders of one image: the RMS of their luminance
/// difference over √2 (the difference of two independent estimates has twice the variance of
/// one), relative to their mean luminance.
fn relative_noise(a: &Image, b: &Image) -> f64 {
    let squares: f64 = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .map(|(&p, &q)| (luminance(p) as f64 - luminance(q) as f64).powi(2))
        .sum();
    let rms = (squares / (2.0 * a.pixels.len() as f64)).sqrt();
    rms / (0.5 * (mean_luminance(a) + mean_luminance(b)))
}

/// How many mesh-vertex samples (both sides) lie hidden inside geometry, how many of those were
/// moved to a visible spot of their triangle, and how many could not be (that whole side of the
/// triangle is inside a solid: a side no eye can see, which the SMA does not ask for).
fn hidden_vertices(world: &World, cfg: &Config) -> anyhow::Result<String> {
    let mesh = &world.scene.mesh;
    let step = (mesh.triangles.len() / cfg.points.max(1)).max(1);
    let (mut n, mut hidden, mut moved) = (0usize, 0usize, 0usize);
    let mut counts = renderer::RayCounts::default();
    let start = Instant::now();
    for t in (0..mesh.triangles.len()).step_by(step) {
        for side in [Side::Front, Side::Back] {
            let p = ShadePoint {
                key: SampleKey { vertex: 0, side },
                base_triangle: t as u32,
                bary: [0.0, 0.0],
                side,
                eye: None,
            };
            let Ok(s) = renderer::point::surface_of(world, &p) else {
                continue;
            };
            n += 1;
            if renderer::point::is_hidden(world, &s, &mut counts) {
                hidden += 1;
                moved +=
                    renderer::point::locate(world, &p, &mut counts).is_ok_and(|l| l.moved) as usize;
            }
        }
    }
    let ms = start.elapsed().as_secs_f64() * 1e3;
    let pct = |k: usize| 100.0 * k as f64 / n.max(1) as f64;
    let mut md = String::new();
    writeln!(
        md,
        "### Hidden shading points, {} mesh vertices (first corner of every {step}th triangle, both sides)\n",
        world.scene.name
    )?;
    writeln!(
        md,
        "| samples | hidden at their spot | moved to a visible spot | face side wholly hidden | probe rays/sample | ms (one thread) |\n|---:|---:|---:|---:|---:|---:|"
    )?;
    writeln!(
        md,
        "| {n} | {hidden} ({:.1} %) | {moved} ({:.1} %) | {} ({:.1} %) | {:.1} | {ms:.0} |\n",
        pct(hidden),
        pct(moved),
        hidden - moved,
        pct(hidden - moved),
        counts.probe as f64 / n.max(1) as f64
    )?;
    Ok(md)
}

/// RMS error (relative to the mean luminance) against a many-path unbounded estimate at fixed
/// points, and time per sample, for paths × bounce depth, of what the cache holds (illumination
/// at a unit albedo, plus view-dependent radiance). The error includes a bounded depth's bias.
fn error_and_time(world: &World, view: &str, cfg: &Config) -> anyhow::Result<String> {
    let points = visible_points(world, view, cfg.error_points)?;
    // Luminances of one estimate, and the median time of `runs` estimates (same seed).
    let lum = |q: Quality, seed: u64, runs: usize| -> (Vec<f64>, f64) {
        let batch = ShadeBatch {
            batch_id: 0,
            quality: q,
            seed,
            points: points.clone(),
        };
        let mut parts = Vec::new();
        let secs = median_seconds(runs, || parts = shade_batch(world, &batch).0.parts);
        (
            parts
                .iter()
                .map(|p| luminance(Vec3::from(p.radiance([1.0; 3]))) as f64)
                .collect(),
            secs,
        )
    };
    let (truth, truth_secs) = lum(
        Quality {
            paths: cfg.reference_paths,
            bounces: None,
        },
        999,
        1,
    );
    let mean_truth = truth.iter().sum::<f64>() / truth.len() as f64;
    let mut md = String::new();
    writeln!(
        md,
        "### Error and time per sample, {} view {view}\n",
        world.scene.name
    )?;
    writeln!(
        md,
        "Relative RMS error of luminance at {} fixed visible points against a {}-path unbounded estimate (took {truth_secs:.1} s), and milliseconds per sample (both cores, median of 3). Rows: paths; columns: bounces; cells: error / time.\n",
        points.len(),
        cfg.reference_paths
    )?;
    writeln!(
        md,
        "| paths | 0 | 1 | 2 | unbounded |\n|---:|---|---|---|---|"
    )?;
    for &paths in cfg.path_levels {
        let cells: Vec<String> = BOUNCE_LEVELS
            .iter()
            .map(|&bounces| {
                let (est, secs) = lum(Quality { paths, bounces }, 7, 3);
                let mse = est
                    .iter()
                    .zip(&truth)
                    .map(|(a, b)| (a - b).powi(2))
                    .sum::<f64>()
                    / est.len() as f64;
                format!(
                    "{:.3} / {:.3} ms",
                    mse.sqrt() / mean_truth.max(1e-12),
                    secs * 1e3 / points.len() as f64
                )
            })
            .collect();
        writeln!(md, "| {paths} | {} |", cells.join(" | "))?;
    }
    md.push('\n');
    Ok(md)
}
