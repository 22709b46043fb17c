//! Ray throughput on Sponza for the renderer's section (DESIGN.md §10 costs): obvhs one ray at a
//! time as the baseline, and our queries at each vector level the CPU runs, in the same run and
//! build, so every figure is also a ratio.

use std::fmt::Write as _;
use std::time::Instant;

use glam::{Vec3, Vec3A};
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle as BvhTriangle;
use rayon::prelude::*;

use renderer::internals::{RayOrder, SceneBvh, Traversal};
use renderer::reference::camera_for;
use renderer::sampling::{cosine_hemisphere, stream, uniform_cone, uniform2};
use renderer::vector_level::VectorLevel;
use renderer::world::World;
use scene::bvh::{BuildPreset, build_cwbvh, bvh_triangles};

use super::renderer::Config;
use super::stats::median;

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
}

/// Cells per axis of the origins' grid (a power of two) by which `ordered` groups the rays: with
/// the octant, 32,768 buckets for about a million rays.
const ORDER_BITS_PER_AXIS: u32 = 4;

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
                    primary.origin.push(world.to_local(cam.eye_vec()));
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

/// One way of tracing a set of rays once; returns the seconds it took, all its work included.
type Pass<'a> = &'a dyn Fn() -> f64;

/// Seconds to trace `rays` once with `trace`, in parallel chunks, in `sequence`'s order when
/// given.
fn trace_secs(rays: &Rays, sequence: Option<&[u32]>, trace: TraceFn) -> f64 {
    let start = Instant::now();
    let at = |k: usize| sequence.map_or(k, |s| s[k] as usize);
    let hits: usize = (0..rays.len())
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(at)
        .filter(|&i| trace(rays.origin[i], rays.dir[i], rays.tmax[i]))
        .count();
    std::hint::black_box(hits);
    start.elapsed().as_secs_f64()
}

/// Traces a slice of rays (origins, directions, tmaxs) with a packet query; returns how many
/// hit.
type PacketTraceFn<'a> = &'a (dyn Fn(&[Vec3], &[Vec3], &[f32]) -> usize + Sync);

/// Seconds to trace `rays` once with `trace`, in parallel chunks of consecutive rays (the
/// packets are consecutive rays: a primary tile's rows, shadow rays in the order they come).
fn packet_secs(rays: &Rays, trace: PacketTraceFn) -> f64 {
    let start = Instant::now();
    let hits: usize = rays
        .origin
        .par_chunks(CHUNK)
        .zip(rays.dir.par_chunks(CHUNK))
        .zip(rays.tmax.par_chunks(CHUNK))
        .map(|((o, d), t)| trace(o, d, t))
        .sum();
    std::hint::black_box(hits);
    start.elapsed().as_secs_f64()
}

/// A packet query that counts the closest hits found.
fn closest_packets(bvh: &SceneBvh) -> impl Fn(&[Vec3], &[Vec3], &[f32]) -> usize + Sync + '_ {
    |o, d, t| {
        let mut hits = vec![None; o.len()];
        bvh.closest_hit_packet(o, d, t, &mut hits);
        hits.iter().filter(|h| h.is_some()).count()
    }
}

/// A packet query that counts the blocked rays.
fn occluded_packets(bvh: &SceneBvh) -> impl Fn(&[Vec3], &[Vec3], &[f32]) -> usize + Sync + '_ {
    |o, d, t| {
        let mut blocked = vec![false; o.len()];
        bvh.occluded_packet(o, d, t, &mut blocked);
        blocked.iter().filter(|&&b| b).count()
    }
}

/// Seconds to regroup `rays` (`RayOrder`, one thread) and trace them in that order: the sort is
/// part of the cost.
fn ordered_secs(rays: &Rays, bounds: (Vec3, Vec3), trace: TraceFn) -> f64 {
    let start = Instant::now();
    let mut sequence = Vec::new();
    RayOrder::new(bounds, ORDER_BITS_PER_AXIS).order(
        rays.len(),
        |i| (rays.origin[i], rays.dir[i]),
        &mut sequence,
    );
    let sort = start.elapsed().as_secs_f64();
    sort + trace_secs(rays, Some(&sequence), trace)
}

/// M rays/s of each variant in each run; the variants are timed in turn within a run, so a
/// change of machine load (other processes) hits all alike.
struct Comparison<const N: usize> {
    per_run: Vec<[f64; N]>,
}

impl<const N: usize> Comparison<N> {
    fn measure(runs: usize, rays: usize, variants: [Pass; N]) -> Comparison<N> {
        let per_run = (0..runs)
            .map(|_| variants.map(|pass| rays as f64 / pass() / 1e6))
            .collect();
        Comparison { per_run }
    }

    /// Median M rays/s of each variant.
    fn rates(&self) -> [f64; N] {
        std::array::from_fn(|k| median(self.per_run.iter().map(|r| r[k]).collect()))
    }

    /// Median over the runs of variant `k`'s rate over variant `base`'s.
    fn ratio(&self, k: usize, base: usize) -> f64 {
        median(self.per_run.iter().map(|r| r[k] / r[base]).collect())
    }
}

pub(super) fn ray_throughput(
    scene: &scene::Scene,
    view: &str,
    cfg: &Config,
) -> anyhow::Result<String> {
    let ours_world = World::new(scene.clone());
    let best = VectorLevel::detected();
    let ours = |preset, traversal, level| {
        let mut bvh = SceneBvh::build(&scene.mesh, preset);
        bvh.set_traversal(traversal);
        bvh.set_vector_level(level);
        bvh
    };
    // The compressed traversal on the tree it ran on before the wide one came.
    let compressed = ours(BuildPreset::Slow, Traversal::Compressed, best);
    let portable = ours(World::PRESET, Traversal::Wide, VectorLevel::Baseline);
    let fastest = ours(World::PRESET, Traversal::Wide, best);
    let naive = NaiveBvh::build(&scene.mesh);
    let (primary, bounce, shadow) = view_rays(&ours_world, view, cfg)?;
    // The rays are in the world's local frame, and so must the grid be.
    let bounds = ours_world.scene.mesh.bounds();
    let sort_start = Instant::now();
    for rays in [&bounce, &shadow] {
        RayOrder::new(bounds, ORDER_BITS_PER_AXIS).order(
            rays.len(),
            |i| (rays.origin[i], rays.dir[i]),
            &mut Vec::new(),
        );
    }
    let sort_ms = sort_start.elapsed().as_secs_f64() * 1e3;
    let closest_compressed = |o, d, t| compressed.closest_hit(o, d, t).is_some();
    let any_compressed = |o, d, t| compressed.occluded(o, d, t);
    let closest_portable = |o, d, t| portable.closest_hit(o, d, t).is_some();
    let closest = |o, d, t| fastest.closest_hit(o, d, t).is_some();
    let any_portable = |o, d, t| portable.occluded(o, d, t);
    let any = |o, d, t| fastest.occluded(o, d, t);
    let naive_trace = |o, d, t| naive.hits(o, d, t);
    let (closest_packets_portable, closest_packets_fastest) =
        (closest_packets(&portable), closest_packets(&fastest));
    let (any_packets_portable, any_packets_fastest) =
        (occluded_packets(&portable), occluded_packets(&fastest));
    let mut md = String::new();
    writeln!(
        md,
        "### Ray throughput, Sponza view {view} ({}×{} primary rays; M rays/s)\n",
        cfg.width, cfg.height
    )?;
    let best = best.name();
    writeln!(
        md,
        "obvhs: one ray at a time, default (medium) preset, triangles through `primitive_indices`, closest hit for every ray, baseline instructions. Ours: triangles stored in BVH order, early-exit shadow query. \"compressed\": obvhs's traversal of its compressed nodes inside our entry points at {best}, on a slow-preset tree (spatial splits): the renderer's traversal and tree before the wide one. \"wide\" (the renderer's): a very-slow-preset tree (spatial splits, then reinsertion over every node) decoded into full-precision eight-wide nodes, nearest child first, a node's leaf children tested as soon as it is visited (before its inner children are taken up) with obvhs's triangle test, at the baseline vector level (SSE) and at the best one this CPU runs ({best}, AVX2), chosen at run time by the same binary; \"ordered\" first regroups the rays by direction octant and the Morton order of their origin's cell on a 16³ grid (`RayOrder`: a counting sort, one thread; {sort_ms:.0} ms for all bounce and shadow rays), its time included, then traces them in that order (primary rays are already in 8×8 pixel tiles). \"packets\": the wide nodes walked by eight consecutive rays at once (a row of a primary tile, eight shadow rays in the order they come; a packet whose rays are not all of one direction octant, as most bounce rays' are not, is traced one ray at a time), eight rays per vector step, each ray getting its one-ray answer. All are timed in turn within each run; ratios are medians of the per-run ratios.\n"
    )?;
    writeln!(
        md,
        "| rays | count | obvhs | compressed, {best} | wide, baseline | wide, {best} | wide, {best}, ordered | packets, baseline | packets, {best} | compressed / obvhs | wide baseline / obvhs | wide {best} / obvhs | ordered / obvhs | packets {best} / obvhs | packets / wide, baseline | packets / wide, {best} | wide {best} / compressed |"
    )?;
    writeln!(
        md,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )?;
    for (name, rays, closest_hit) in [
        ("primary", &primary, true),
        ("bounce", &bounce, true),
        ("shadow (sun)", &shadow, false),
    ] {
        let (c, p, f): (TraceFn, TraceFn, TraceFn) = if closest_hit {
            (&closest_compressed, &closest_portable, &closest)
        } else {
            (&any_compressed, &any_portable, &any)
        };
        let (pp, pf): (PacketTraceFn, PacketTraceFn) = if closest_hit {
            (&closest_packets_portable, &closest_packets_fastest)
        } else {
            (&any_packets_portable, &any_packets_fastest)
        };
        let variants: [Pass; 7] = [
            &|| trace_secs(rays, None, &naive_trace),
            &|| trace_secs(rays, None, c),
            &|| trace_secs(rays, None, p),
            &|| trace_secs(rays, None, f),
            &|| ordered_secs(rays, bounds, f),
            &|| packet_secs(rays, pp),
            &|| packet_secs(rays, pf),
        ];
        let runs = Comparison::measure(cfg.runs, rays.len(), variants);
        let [
            obvhs,
            compressed,
            portable,
            fastest,
            ordered,
            packets_portable,
            packets_fastest,
        ] = runs.rates();
        let [r_compressed, r_portable, r_fastest, r_ordered, r_packets] =
            [1, 2, 3, 4, 6].map(|k| runs.ratio(k, 0));
        let packets_over_wide = [runs.ratio(5, 2), runs.ratio(6, 3)];
        let wide_over_compressed = runs.ratio(3, 1);
        writeln!(
            md,
            "| {name} | {} | {obvhs:.2} | {compressed:.2} | {portable:.2} | {fastest:.2} | {ordered:.2} | {packets_portable:.2} | {packets_fastest:.2} | {r_compressed:.2}× | {r_portable:.2}× | {r_fastest:.2}× | {r_ordered:.2}× | {r_packets:.2}× | {:.2}× | {:.2}× | {wide_over_compressed:.2}× |",
            rays.len(),
            packets_over_wide[0],
            packets_over_wide[1],
        )?;
    }
    md.push('\n');
    Ok(md)
}
