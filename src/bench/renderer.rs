//! The renderer's section of BENCHMARKS.md (DESIGN.md §10 costs): ray throughput on Sponza against a naive baseline in
//! the same run and build, BVH build times, shading samples per second at the interactive and
//! direct-light qualities, and what accuracy costs in time. Medians of several runs, on every
//! core of the machine.

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::Context;
use glam::{Vec3, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle as BvhTriangle;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadeBatch, ShadePoint};
use rayon::prelude::*;

use renderer::internals::SceneBvh;
use renderer::point::front_point_hit_by;
use renderer::reference::camera_for;
use renderer::sampling::{cosine_hemisphere, luminance, stream, uniform_cone, uniform2};
use renderer::shade_batch;
use renderer::world::World;
use scene::bvh::{BuildPreset, build_cwbvh, bvh_triangles};

use super::stats::{median, median_seconds};

/// Sponza's scene file, relative to the repository root (it reads ../shared/scenes).
pub const SPONZA: &str = "scenes/sponza.toml";

/// Sizes of one benchmark run.
struct Config {
    runs: usize,
    /// Image whose pixels give the rays (primary rays and the points they hit).
    width: u32,
    height: u32,
    /// Shading points for samples per second.
    points: usize,
    /// Points, reference paths and path levels of the error/time table.
    error_points: usize,
    reference_paths: u32,
    path_levels: &'static [u32],
}

const FULL: Config = Config {
    runs: 5,
    width: 1024,
    height: 768,
    points: 2000,
    error_points: 200,
    reference_paths: 16_384,
    path_levels: &[4, 16, 64, 256, 1024],
};

const QUICK: Config = Config {
    runs: 3,
    width: 160,
    height: 120,
    points: 100,
    error_points: 12,
    reference_paths: 256,
    path_levels: &[4, 16, 64],
};

const BOUNCE_LEVELS: [Option<u32>; 4] = [Some(0), Some(1), Some(2), None];

/// The renderer's section of BENCHMARKS.md.
pub fn section(quick: bool) -> anyhow::Result<String> {
    let cfg = if quick { &QUICK } else { &FULL };
    let mut md = String::from("## Renderer\n\n");
    writeln!(
        md,
        "{} worker threads; built for {}; medians of {} runs{}.\n",
        rayon::current_num_threads(),
        cpu_level(),
        cfg.runs,
        if quick {
            " (quick: small sizes, figures indicative only)"
        } else {
            ""
        }
    )?;
    // Other processes on the machine change every figure: say how busy it was.
    if let Ok(load) = std::fs::read_to_string("/proc/loadavg") {
        let one_minute = load.split_whitespace().next().unwrap_or("?");
        writeln!(md, "Load average when the run started: {one_minute}.\n")?;
    }
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
    let mut scenes: Vec<(&World, &str)> = Vec::new();
    if let Some(s) = &sponza {
        scenes.push((s, "S1"));
    }
    scenes.push((&bracara, "VR"));
    md += &samples_per_second(&scenes, cfg)?;
    for (world, view) in &scenes {
        md += &error_and_time(world, view, cfg)?;
    }
    Ok(md)
}

/// Which x86-64 level the code was compiled for (the throughput depends on it).
fn cpu_level() -> &'static str {
    if cfg!(target_feature = "avx2") && cfg!(target_feature = "fma") {
        "x86-64-v3 or above (AVX2, FMA)"
    } else {
        "generic x86-64 (no AVX2)"
    }
}

/// Rays of one kind: origin, direction, tmax.
struct Rays {
    origin: Vec<Vec3>,
    dir: Vec<Vec3>,
    tmax: Vec<f32>,
}

impl Rays {
    fn len(&self) -> usize {
        self.origin.len()
    }

    /// The same rays reordered by direction octant, then Morton order of the origin, so rays
    /// of one chunk traverse similar nodes.
    fn ordered(&self, lo: Vec3, hi: Vec3) -> Rays {
        let scale = 1023.0 / (hi - lo).max(Vec3::splat(1e-6));
        let key = |i: usize| {
            let q = ((self.origin[i] - lo) * scale)
                .clamp(Vec3::ZERO, Vec3::splat(1023.0))
                .as_uvec3();
            let d = self.dir[i];
            let octant = (d.x < 0.0) as u64 | ((d.y < 0.0) as u64) << 1 | ((d.z < 0.0) as u64) << 2;
            // 32 bits: the octant above the top 29 bits of the Morton code.
            octant << 29 | morton3(q.x, q.y, q.z) >> 1
        };
        // Keys computed once, sorted in parallel with the index in the low bits.
        let mut keyed: Vec<u64> = (0..self.len())
            .into_par_iter()
            .map(|i| key(i) << 32 | i as u64)
            .collect();
        keyed.par_sort_unstable();
        let idx: Vec<usize> = keyed.iter().map(|k| (k & 0xffff_ffff) as usize).collect();
        Rays {
            origin: idx.iter().map(|&i| self.origin[i]).collect(),
            dir: idx.iter().map(|&i| self.dir[i]).collect(),
            tmax: idx.iter().map(|&i| self.tmax[i]).collect(),
        }
    }
}

/// 30-bit Morton code of three 10-bit coordinates.
fn morton3(x: u32, y: u32, z: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = v as u64 & 0x3ff;
        v = (v | v << 16) & 0x0300_00ff;
        v = (v | v << 8) & 0x0300_f00f;
        v = (v | v << 4) & 0x030c_30c3;
        (v | v << 2) & 0x0924_9249
    }
    spread(x) | spread(y) << 1 | spread(z) << 2
}

/// Primary rays of a view through pixel centres (8×8 tiles, as a renderer would issue them),
/// then bounce and sun-shadow rays from the points they hit.
fn view_rays(world: &World, view: &str, cfg: &Config) -> anyhow::Result<(Rays, Rays, Rays)> {
    let cam = camera_for(world, view, cfg.width, cfg.height)?;
    let mut primary = Rays {
        origin: Vec::new(),
        dir: Vec::new(),
        tmax: Vec::new(),
    };
    for ty in (0..cfg.height).step_by(8) {
        for tx in (0..cfg.width).step_by(8) {
            for y in ty..(ty + 8).min(cfg.height) {
                for x in tx..(tx + 8).min(cfg.width) {
                    primary.origin.push(cam.eye_vec());
                    primary
                        .dir
                        .push(cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5));
                    primary.tmax.push(f32::INFINITY);
                }
            }
        }
    }
    let sun = world
        .scene
        .settings
        .sun
        .as_ref()
        .and_then(|s| Vec3::from(s.direction).try_normalize())
        .unwrap_or(Vec3::Y);
    let mut bounce = Rays {
        origin: Vec::new(),
        dir: Vec::new(),
        tmax: Vec::new(),
    };
    let mut shadow = Rays {
        origin: Vec::new(),
        dir: Vec::new(),
        tmax: Vec::new(),
    };
    let mut rng = stream(42, 0);
    for i in 0..primary.len() {
        let Some(hit) = world
            .bvh
            .closest_hit(primary.origin[i], primary.dir[i], f32::INFINITY)
        else {
            continue;
        };
        let s = world.surface_at(primary.origin[i], primary.dir[i], hit);
        let origin = world.offset.origin(s.position, s.normal);
        bounce.origin.push(origin);
        bounce
            .dir
            .push(cosine_hemisphere(s.normal, uniform2(&mut rng)));
        bounce.tmax.push(f32::INFINITY);
        let to_sun = uniform_cone(sun, 1e-5, uniform2(&mut rng));
        if to_sun.dot(s.normal) > 0.0 {
            shadow.origin.push(origin);
            shadow.dir.push(to_sun);
            shadow.tmax.push(f32::INFINITY);
        }
    }
    Ok((primary, bounce, shadow))
}

/// The baseline: obvhs as its example uses it: default (medium) preset, the triangle list looked
/// up through `primitive_indices`, closest hit for every ray, rays in the order they come.
struct NaiveBvh {
    bvh: CwBvh,
    tris: Vec<BvhTriangle>,
}

impl NaiveBvh {
    fn build(mesh: &scene::Mesh) -> NaiveBvh {
        let tris = bvh_triangles(mesh);
        let bvh = build_cwbvh(&tris, BuildPreset::Medium);
        NaiveBvh { bvh, tris }
    }

    fn hits(&self, o: Vec3, d: Vec3, tmax: f32) -> bool {
        let mut hit = RayHit::none();
        let ray = Ray::new(Vec3A::from(o), Vec3A::from(d), 0.0, tmax);
        self.bvh.ray_traverse(ray, &mut hit, |r, id| {
            self.tris[self.bvh.primitive_indices[id] as usize].intersect(r)
        })
    }
}

const CHUNK: usize = 4096;

type TraceFn<'a> = &'a (dyn Fn(Vec3, Vec3, f32) -> bool + Sync);

/// Seconds to trace `rays` once with `trace`, in parallel chunks.
fn trace_secs(rays: &Rays, trace: TraceFn) -> f64 {
    let start = Instant::now();
    let hits: usize = (0..rays.len())
        .into_par_iter()
        .with_min_len(CHUNK)
        .filter(|&i| trace(rays.origin[i], rays.dir[i], rays.tmax[i]))
        .count();
    std::hint::black_box(hits);
    start.elapsed().as_secs_f64()
}

/// Baseline, ours and ours-ordered timed in turn within each run, so a change of machine load
/// (other processes) hits all three alike: median M rays/s of each, and the median of the
/// per-run ratios of the other two to the baseline.
fn compare(runs: usize, variants: [(&Rays, TraceFn); 3]) -> ([f64; 3], [f64; 2]) {
    let per_run: Vec<[f64; 3]> = (0..runs)
        .map(|_| variants.map(|(rays, trace)| rays.len() as f64 / trace_secs(rays, trace) / 1e6))
        .collect();
    let rates = [0, 1, 2].map(|k| median(per_run.iter().map(|r| r[k]).collect()));
    let ratios = [1, 2].map(|k| median(per_run.iter().map(|r| r[k] / r[0]).collect()));
    (rates, ratios)
}

fn ray_throughput(scene: &scene::Scene, view: &str, cfg: &Config) -> anyhow::Result<String> {
    let ours_world = World::with_preset(scene.clone(), BuildPreset::Slow);
    let naive = NaiveBvh::build(&scene.mesh);
    let (primary, bounce, shadow) = view_rays(&ours_world, view, cfg)?;
    let (lo, hi) = scene.mesh.bounds();
    let sort_start = Instant::now();
    let bounce_ordered = bounce.ordered(lo, hi);
    let shadow_ordered = shadow.ordered(lo, hi);
    let sort_ms = sort_start.elapsed().as_secs_f64() * 1e3;
    let bvh: &SceneBvh = &ours_world.bvh;
    let closest = |o, d, t| bvh.closest_hit(o, d, t).is_some();
    let any = |o, d, t| bvh.occluded(o, d, t);
    let naive_trace = |o, d, t| naive.hits(o, d, t);
    let rows = [
        (
            "primary",
            &primary,
            compare(
                cfg.runs,
                [
                    (&primary, &naive_trace),
                    (&primary, &closest),
                    (&primary, &closest),
                ],
            ),
        ),
        (
            "bounce",
            &bounce,
            compare(
                cfg.runs,
                [
                    (&bounce, &naive_trace),
                    (&bounce, &closest),
                    (&bounce_ordered, &closest),
                ],
            ),
        ),
        (
            "shadow (sun)",
            &shadow,
            compare(
                cfg.runs,
                [
                    (&shadow, &naive_trace),
                    (&shadow, &any),
                    (&shadow_ordered, &any),
                ],
            ),
        ),
    ];
    let mut md = String::new();
    writeln!(
        md,
        "### Ray throughput, Sponza view {view} ({}×{} primary rays; M rays/s)\n",
        cfg.width, cfg.height
    )?;
    writeln!(
        md,
        "Baseline: obvhs one ray at a time, default (medium) preset, triangles through `primitive_indices`, closest hit for every ray. Ours: slow preset (spatial splits), triangles stored in BVH order, early-exit shadow query; \"ordered\" adds sorting the rays by direction octant and Morton order of origin (primary rays are already in 8×8 pixel tiles; sorting took {sort_ms:.0} ms for all bounce and shadow rays, not included). The three are timed in turn within each run; ratios are medians of the per-run ratios.\n"
    )?;
    writeln!(
        md,
        "| rays | count | baseline | ours | ours, ordered | ours / baseline | ours ordered / baseline |"
    )?;
    writeln!(md, "|---|---:|---:|---:|---:|---:|---:|")?;
    for (name, rays, ([base, ours, ordered], [r_ours, r_ordered])) in rows {
        writeln!(
            md,
            "| {name} | {} | {base:.2} | {ours:.2} | {ordered:.2} | {r_ours:.2}× | {r_ordered:.2}× |",
            rays.len()
        )?;
    }
    md.push('\n');
    Ok(md)
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
        ("slow (used)", BuildPreset::Slow),
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

fn samples_per_second(scenes: &[(&World, &str)], cfg: &Config) -> anyhow::Result<String> {
    let mut md = String::from(
        "### Shading samples per second (points of the view's visible surfaces)\n\n| scene | view | quality | points | samples/s | rays/sample |\n|---|---|---|---:|---:|---:|\n",
    );
    for (world, view) in scenes {
        let points = visible_points(world, view, cfg.points)?;
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
            let secs = median_seconds(cfg.runs, || rays = shade_batch(world, &batch).1.total());
            writeln!(
                md,
                "| {} | {view} | {label} | {} | {:.0} | {:.0} |",
                world.scene.name,
                points.len(),
                points.len() as f64 / secs,
                rays as f64 / points.len() as f64
            )?;
        }
    }
    md.push('\n');
    Ok(md)
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
/// points, and time per sample, for paths × bounce depth. The error includes the bias of a
/// bounded depth: it is the error against the full solution.
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
        let mut rgb = Vec::new();
        let secs = median_seconds(runs, || rgb = shade_batch(world, &batch).0.rgb);
        (
            rgb.iter()
                .map(|c| luminance(Vec3::from(*c)) as f64)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton3(1, 0, 0), 1);
        assert_eq!(morton3(0, 1, 0), 2);
        assert_eq!(morton3(0, 0, 1), 4);
        assert_eq!(morton3(3, 0, 0), 0b1001);
        assert!(morton3(1023, 1023, 1023) < 1 << 30);
    }
}
