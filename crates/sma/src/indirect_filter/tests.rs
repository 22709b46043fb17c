use glam::Vec3;
use protocol::renderer_link::{Quality, SampleKey};
use protocol::{PartEstimate, SampleParts, Side};
use rand::{RngExt, SeedableRng};
use scene::{Mesh, Triangle};

use super::*;
use crate::cache::{CachedSample, ShadingCache};
use crate::mesh::{MeshParams, SubdivisionMesh, grid_mesh};
use crate::sample::mean_and_variance;
use crate::visible_set::VisibleSet;

/// Grid cells per side of the test patches (unit cells).
const N: u32 = 16;

/// Settings whose radius is 2.5 grid cells at 64 paths on an `N` × `N` patch (diagonal N√2).
fn settings() -> IndirectFilterSettings {
    IndirectFilterSettings {
        enabled: true,
        radius: 2.5 / (N as f32 * std::f32::consts::SQRT_2),
        ..IndirectFilterSettings::default()
    }
}

fn front(vertex: u32) -> SampleKey {
    SampleKey {
        vertex,
        side: Side::Front,
    }
}

fn all_leaves(mesh: &SubdivisionMesh) -> VisibleSet {
    VisibleSet::of_front_leaves(&mesh.leaves().collect::<Vec<_>>())
}

/// A diffuse sample of `paths` paths: a direct part of `direct`, an indirect part of mean
/// `indirect` whose mean has the standard error `mean_error`.
fn sample(direct: f32, indirect: f32, mean_error: f32, paths: u32) -> CachedSample {
    let part = |l: f32, error: f32| PartEstimate {
        rgb: [l; 3],
        luminance_variance: error * error * paths as f32,
    };
    CachedSample {
        parts: SampleParts {
            direct: part(direct, 0.0),
            indirect: part(indirect, mean_error),
            view_dependent: PartEstimate::default(),
        },
        quality: Quality {
            paths,
            bounces: Some(2),
        },
        view_dependent: false,
        eye: None,
        last_seen: 0,
    }
}

/// Fills the cache with `shade(position)`'s sample for every vertex of `mesh`.
fn shade(mesh: &SubdivisionMesh, shade: impl Fn(u32, Vec3) -> CachedSample) -> ShadingCache {
    let mut cache = ShadingCache::new(usize::MAX);
    for v in 0..mesh.vertex_count() as u32 {
        cache.insert(front(v), shade(v, mesh.vertex(v).position));
    }
    cache
}

fn shown_indirect(cache: &ShadingCache, v: u32) -> f32 {
    cache.get(front(v)).unwrap().parts.indirect.rgb[0]
}

/// The indirect part as the cache stores the answer (its means within 2^-9: `cache::quantised`).
fn answered_indirect(cache: &ShadingCache, v: u32) -> f32 {
    cache.answered(front(v)).unwrap().0.parts.indirect.rgb[0]
}

fn filter(
    settings: IndirectFilterSettings,
    mesh: &SubdivisionMesh,
    cache: &mut ShadingCache,
) -> FilterRun {
    let view = all_leaves(mesh);
    IndirectFilter::new(settings, mesh).run(mesh, [&view], cache)
}

#[test]
fn a_flat_evenly_lit_patch_is_less_noisy_filtered_with_the_same_mean() {
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    let (truth, error) = (0.5f32, 0.05f32);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(11);
    // Each vertex's mean off the truth by its own noise (a sum of 12 uniforms: nearly normal).
    let noisy: Vec<f32> = (0..mesh.vertex_count())
        .map(|_| truth + error * ((0..12).map(|_| rng.random::<f32>()).sum::<f32>() - 6.0))
        .collect();
    let mut cache = shade(&mesh, |v, _| sample(0.3, noisy[v as usize], error, 64));
    let before: Vec<f32> = (0..mesh.vertex_count() as u32)
        .map(|v| shown_indirect(&cache, v))
        .collect();
    let run = filter(settings(), &mesh, &mut cache);
    assert_eq!(run.filtered, mesh.vertex_count());
    assert!(run.borrowed > mesh.vertex_count() * 9 / 10, "{run:?}");
    let after: Vec<f32> = (0..mesh.vertex_count() as u32)
        .map(|v| shown_indirect(&cache, v))
        .collect();
    let (mean_before, var_before) = mean_and_variance(&before);
    let (mean_after, var_after) = mean_and_variance(&after);
    assert!(
        var_after < 0.25 * var_before,
        "variance {var_before} unfiltered, {var_after} filtered"
    );
    // The same mean within noise: the vertices' mean is known to error / sqrt(vertices).
    let noise_of_mean = f64::from(error) / (mesh.vertex_count() as f64).sqrt();
    assert!((mean_before - f64::from(truth)).abs() < 4.0 * noise_of_mean);
    assert!(
        (mean_after - mean_before).abs() < 4.0 * noise_of_mean,
        "{mean_before} → {mean_after}"
    );
    // The shown uncertainty is the reduced one, and the direct part is untouched.
    let centre = (0..mesh.vertex_count() as u32)
        .min_by(|&a, &b| {
            let d = |v: u32| {
                mesh.vertex(v)
                    .position
                    .distance(Vec3::splat(N as f32 / 2.0))
            };
            d(a).total_cmp(&d(b))
        })
        .unwrap();
    let shown = cache.get(front(centre)).unwrap().estimate();
    let (answered, _) = cache.answered(front(centre)).unwrap();
    assert!(shown.standard_error() < 0.5 * answered.standard_error());
    assert_eq!(shown.parts.direct, answered.parts.direct);
}

/// A step of the indirect light well beyond the samples' noise: every vertex keeps its own
/// side's value, and a direct-light shadow edge is never touched.
#[test]
fn an_edge_beyond_the_noise_is_not_blurred_across() {
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    let half = N as f32 / 2.0;
    let lit = |p: Vec3| p.x < half;
    let step = |error: f32| {
        shade(&mesh, |_, p| {
            let (direct, indirect) = if lit(p) { (2.0, 1.0) } else { (0.0, 0.2) };
            sample(direct, indirect, error, 64)
        })
    };
    let mut cache = step(0.01);
    filter(settings(), &mesh, &mut cache);
    for v in 0..mesh.vertex_count() as u32 {
        let p = mesh.vertex(v).position;
        let want = answered_indirect(&cache, v);
        assert!((want - if lit(p) { 1.0 } else { 0.2 }).abs() < 1e-3);
        assert!(
            (shown_indirect(&cache, v) - want).abs() < 1e-5,
            "{p}: {}",
            shown_indirect(&cache, v)
        );
        let direct = cache.get(front(v)).unwrap().parts.direct.rgb[0];
        assert_eq!(direct, if lit(p) { 2.0 } else { 0.0 });
    }
    // The same step within the noise the samples claim is borrowed across: the test above can
    // fail.
    let mut noisy = step(1.0);
    filter(settings(), &mesh, &mut noisy);
    let beside_the_edge = (0..mesh.vertex_count() as u32)
        .find(|&v| (mesh.vertex(v).position.x - (half - 1.0)).abs() < 1e-4)
        .unwrap();
    assert!(shown_indirect(&noisy, beside_the_edge) < 0.95);
}

/// A floor and a wall meeting at a crease, with indirect light that differs by less than its
/// noise: the floor's vertices borrow only from the floor.
#[test]
fn a_crease_is_not_blurred_across() {
    let floor = grid_mesh(N);
    let offset = floor.positions.len() as u32;
    // The wall stands at x = -0.25, facing +x, over the floor's y range.
    let wall_positions = floor
        .positions
        .iter()
        .map(|p| Vec3::new(-0.25, p.y, p.x + 0.25));
    let mesh = Mesh {
        positions: floor
            .positions
            .iter()
            .copied()
            .chain(wall_positions)
            .collect(),
        normals: std::iter::repeat_n(Vec3::Z, offset as usize)
            .chain(std::iter::repeat_n(Vec3::X, offset as usize))
            .collect(),
        triangles: floor
            .triangles
            .iter()
            .copied()
            .chain(floor.triangles.iter().map(|t| Triangle {
                vertices: t.vertices.map(|v| v + offset),
                ..*t
            }))
            .collect(),
    };
    let mesh = SubdivisionMesh::new(&mesh, MeshParams::default());
    let on_floor = |p: Vec3| p.z.abs() < 1e-4 && p.x >= 0.0;
    let with = |settings: IndirectFilterSettings| {
        let mut cache = shade(&mesh, |_, p| {
            sample(1.0, if on_floor(p) { 1.0 } else { 1.1 }, 0.1, 64)
        });
        filter(settings, &mesh, &mut cache);
        cache
    };
    let cache = with(settings());
    let floor_vertices: Vec<u32> = (0..mesh.vertex_count() as u32)
        .filter(|&v| on_floor(mesh.vertex(v).position))
        .collect();
    assert!(!floor_vertices.is_empty());
    for &v in &floor_vertices {
        assert!((shown_indirect(&cache, v) - 1.0).abs() < 1e-5);
    }
    // Without the normals' test the floor beside the crease borrows from the wall.
    let careless = with(IndirectFilterSettings {
        min_normal_cos: -1.0,
        ..settings()
    });
    assert!(
        floor_vertices
            .iter()
            .any(|&v| shown_indirect(&careless, v) > 1.01)
    );
}

#[test]
fn the_radius_shrinks_as_paths_are_added_and_the_estimate_becomes_the_vertexs_own() {
    let s = settings();
    let radii: Vec<f32> = [16, 64, 256, 1024, 1 << 16]
        .iter()
        .map(|&paths| radius_at(&s, 10.0, 0.0, paths))
        .collect();
    assert!(radii.windows(2).all(|w| w[1] < w[0]), "{radii:?}");
    assert!((radius_at(&s, 10.0, 0.0, 64) - s.radius * 10.0).abs() < 1e-6);
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    // The same noisy patch at ever more paths (a smaller error, claimed and actual, with the
    // same pattern of noise).
    let borrowed = |paths: u32| {
        let error = 0.4 / (paths as f32).sqrt();
        let mut cache = shade(&mesh, |v, _| {
            let wobble = ((v * 7919) % 13) as f32 / 13.0 - 0.5;
            sample(0.0, 0.5 + error * wobble, error, paths)
        });
        let run = filter(s, &mesh, &mut cache);
        let own = (0..mesh.vertex_count() as u32).all(|v| {
            cache.get(front(v)).unwrap().parts.indirect
                == cache.answered(front(v)).unwrap().0.parts.indirect
        });
        (run.borrowed, own)
    };
    let (at_64, own_64) = borrowed(64);
    let (at_4096, _) = borrowed(4096);
    let (at_many, own_many) = borrowed(1 << 20);
    assert!(at_64 > 0 && !own_64);
    assert!(at_4096 <= at_64);
    assert_eq!(at_many, 0, "a radius below one grid cell borrows nothing");
    assert!(own_many, "the filtered estimate is the vertex's own");
}

/// With a leaf radius, a vertex among fine leaves borrows only from near ones, while one among
/// coarse leaves reaches as far as the scene's radius lets it.
#[test]
fn a_leaf_radius_follows_the_leaves_around_the_vertex() {
    let s = IndirectFilterSettings {
        leaf_radius: 2.0,
        ..settings()
    };
    let diagonal = N as f32 * std::f32::consts::SQRT_2;
    // Coarse leaves (edges of 4): the scene's 2.5 cells are the smaller bound.
    assert!((radius_at(&s, diagonal, 4.0, 64) - 2.5).abs() < 1e-4);
    // Fine ones (edges of 0.5): twice that, shrinking with the paths as the other does.
    assert!((radius_at(&s, diagonal, 0.5, 64) - 1.0).abs() < 1e-6);
    assert!((radius_at(&s, diagonal, 0.5, 1024) - 0.5).abs() < 1e-6);
    // On the unit grid (longest leaf edge √2) at 64 paths, 1.5 leaf edges are 2.12 cells,
    // against 2.5 by the scene: fewer neighbours than without the bound (those √5 away are
    // left out), but some.
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    let noisy = |settings| {
        let mut cache = shade(&mesh, |v, _| {
            sample(0.0, 0.5 + (v % 3) as f32 * 0.01, 0.05, 64)
        });
        filter(settings, &mesh, &mut cache)
    };
    let (by_scene, by_leaves) = (
        noisy(settings()),
        noisy(IndirectFilterSettings {
            leaf_radius: 1.5,
            ..settings()
        }),
    );
    let tight = noisy(IndirectFilterSettings {
        leaf_radius: 0.5,
        ..settings()
    });
    assert!(by_leaves.neighbours > 0, "{by_leaves:?}");
    assert!(
        by_leaves.neighbours < by_scene.neighbours,
        "{by_leaves:?} {by_scene:?}"
    );
    assert_eq!(tight.borrowed, 0, "a radius under one cell borrows nothing");
}

#[test]
fn off_leaves_every_sample_as_answered() {
    let mesh = SubdivisionMesh::new(&grid_mesh(4), MeshParams::default());
    let mut cache = shade(&mesh, |v, _| sample(0.0, v as f32 * 0.01, 1.0, 64));
    let run = filter(
        IndirectFilterSettings {
            enabled: false,
            ..settings()
        },
        &mesh,
        &mut cache,
    );
    assert_eq!(run, FilterRun::default());
    for v in 0..mesh.vertex_count() as u32 {
        assert_eq!(shown_indirect(&cache, v), answered_indirect(&cache, v));
        assert!((shown_indirect(&cache, v) - v as f32 * 0.01).abs() < 1e-3);
    }
}

/// Indirect light carried by rare bright paths: of each vertex's 8 paths, each finds a bright
/// patch (8) with probability 1/8, else nothing, so many vertices saw none and estimate 0 with
/// no variance at all. Weighting by the estimated variances would trust those most and darken
/// the patch; pooled by paths, the filtered picture keeps the unfiltered mean.
#[test]
fn rare_bright_paths_are_not_weighed_down() {
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    let paths = 8u32;
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
    let hits: Vec<Vec<f32>> = (0..mesh.vertex_count())
        .map(|_| {
            (0..paths)
                .map(|_| {
                    if rng.random::<f32>() < 0.125 {
                        8.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    assert!(hits.iter().any(|h| h.iter().all(|&v| v == 0.0)));
    let mut cache = shade(&mesh, |v, _| {
        let (mean, variance) = mean_and_variance(&hits[v as usize]);
        let mean_error = (variance / f64::from(paths)).sqrt() as f32;
        sample(0.0, mean as f32, mean_error, paths)
    });
    let vertices = 0..mesh.vertex_count() as u32;
    let before: Vec<f32> = vertices
        .clone()
        .map(|v| shown_indirect(&cache, v))
        .collect();
    let run = filter(settings(), &mesh, &mut cache);
    assert!(run.borrowed > mesh.vertex_count() / 2, "{run:?}");
    let after: Vec<f32> = vertices.map(|v| shown_indirect(&cache, v)).collect();
    let (mean_before, _) = mean_and_variance(&before);
    let (mean_after, _) = mean_and_variance(&after);
    assert!((mean_before - 1.0).abs() < 0.25, "{mean_before}");
    assert!(
        (mean_after - mean_before).abs() < 0.1,
        "unfiltered {mean_before}, filtered {mean_after}"
    );
}

/// Samples of few paths (a radius several times the median) among many of 1024: each borrows
/// from exactly the neighbours a search over every sample finds, wherever they lie among the
/// hash's cells.
#[test]
fn a_sample_of_few_paths_finds_every_neighbour_its_radius_reaches() {
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    // Radii of 5, 2.5 and 1.25 grid cells: the first searches every sample, the second the
    // cells two away from its own.
    let paths = |v: u32| match (v % 29, v % 31) {
        (0, _) => 4,
        (_, 0) => 64,
        _ => 1024,
    };
    let cache = shade(&mesh, |v, _| sample(0.3, 0.5, 0.02, paths(v)));
    let view = all_leaves(&mesh);
    let mut job = IndirectFilter::new(settings(), &mesh)
        .start(&mesh, [&view], &cache)
        .unwrap();
    job.hash();
    assert!(
        job.candidates.iter().map(|c| c.radius).fold(0.0, f32::max) > 2.0 * job.cell_size,
        "the test needs radii beyond the cells around a sample's own"
    );
    for (i, me) in job.candidates.iter().enumerate() {
        let everywhere = (0..job.candidates.len())
            .filter(|&j| j != i && job.agrees(me, &job.candidates[j], me.radius))
            .count();
        assert_eq!(job.filtered(i).1, everywhere, "sample {:?}", me.key);
    }
    assert!(job.candidates.iter().any(|c| c.paths == 4));
    assert!(job.candidates.iter().any(|c| c.paths == 64));
}

/// A run filtered beside the schedule (`FilterWorker`) is set only on the samples that did not
/// change meanwhile: one that got paths keeps its own answer until the next run.
#[test]
fn a_sample_answered_while_its_run_was_filtered_keeps_its_own_value() {
    let mesh = SubdivisionMesh::new(&grid_mesh(N), MeshParams::default());
    let mut cache = shade(&mesh, |v, _| {
        sample(0.3, 0.4 + 0.01 * (v % 3) as f32, 0.05, 64)
    });
    let view = all_leaves(&mesh);
    let mut filter = IndirectFilter::new(settings(), &mesh);
    let job = filter.start(&mesh, [&view], &cache).unwrap();
    let (worker_done, mut done) = tokio::sync::mpsc::channel(1);
    let worker = FilterWorker::spawn(worker_done).unwrap();
    worker.submit(job).unwrap();
    let changed = 5;
    cache.insert(front(changed), sample(0.3, 0.42, 0.05, 128));
    let filtered = done.blocking_recv().unwrap();
    let run = filter.finish(filtered, &mesh, &mut cache);
    assert_eq!(run.filtered, mesh.vertex_count() - 1, "{run:?}");
    assert_eq!(
        shown_indirect(&cache, changed),
        answered_indirect(&cache, changed)
    );
    let kept = 6;
    assert_ne!(
        shown_indirect(&cache, kept),
        answered_indirect(&cache, kept),
        "the others borrowed from their neighbours"
    );
    // The next run sets it too.
    assert_eq!(
        filter.run(&mesh, [&view], &mut cache).filtered,
        mesh.vertex_count()
    );
    assert_ne!(
        shown_indirect(&cache, changed),
        answered_indirect(&cache, changed)
    );
}
