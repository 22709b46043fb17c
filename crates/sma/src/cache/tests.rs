//! Unit tests of the shading cache (DESIGN.md §5).
use super::*;
use protocol::SampleParts;
use protocol::renderer_link::Quality;
use rand::{RngExt, SeedableRng};

fn sample(l: f32, quality: Quality, seen: u64) -> CachedSample {
    CachedSample {
        parts: SampleParts::direct_only([l; 3], 0.25),
        quality,
        view_dependent: false,
        eye: None,
        last_seen: seen,
    }
}

fn key(vertex: u32) -> SampleKey {
    SampleKey {
        vertex,
        side: Side::Front,
    }
}

/// Same depth: the paths add up (DESIGN.md §5); deeper: replaces; shallower or invalid: ignored.
#[test]
fn same_depth_accumulates_deeper_replaces_shallower_is_ignored() {
    let mut cache = ShadingCache::new(1 << 20);
    assert_eq!(
        cache.insert(key(3), sample(1.0, Quality::DIRECT, 0)),
        CacheInsert::New
    );
    assert_eq!(
        cache.insert(key(3), sample(2.0, Quality::INTERACTIVE, 0)),
        CacheInsert::Upgraded,
        "a 2-bounce answer replaces direct light"
    );
    assert_eq!(cache.get(key(3)).unwrap().rgb(), [2.0; 3]);
    assert_eq!(
        cache.insert(key(3), sample(9.0, Quality::DIRECT, 0)),
        CacheInsert::Ignored,
        "direct light is never averaged into a 2-bounce estimate"
    );
    assert_eq!(
        cache.insert(key(3), sample(4.0, Quality::INTERACTIVE, 0)),
        CacheInsert::Upgraded
    );
    let s = cache.get(key(3)).unwrap();
    assert_eq!(
        (s.rgb(), s.quality.paths),
        ([3.0; 3], 128),
        "64 + 64 paths averaged"
    );
    for bad in [f32::NAN, -1.0, f32::INFINITY] {
        assert_eq!(
            cache.insert(key(3), sample(bad, Quality::INTERACTIVE, 0)),
            CacheInsert::Ignored
        );
    }
    let no_paths = Quality {
        paths: 0,
        ..Quality::INTERACTIVE
    };
    assert_eq!(
        cache.insert(key(4), sample(1.0, no_paths, 0)),
        CacheInsert::Ignored
    );
    assert_eq!(cache.get(key(3)).unwrap().quality.paths, 128);
    let glossy = |eye| CachedSample {
        view_dependent: true,
        eye: Some(eye),
        ..sample(1.0, Quality::INTERACTIVE, 0)
    };
    assert_eq!(cache.insert(key(3), glossy(Vec3::X)), CacheInsert::Upgraded);
    assert_eq!(cache.insert(key(3), glossy(Vec3::Y)), CacheInsert::Upgraded);
    assert!(
        cache
            .get(SampleKey {
                vertex: 3,
                side: Side::Back
            })
            .is_none()
    );
}

/// An accumulated sample's standard error falls as batches of paths are added.
#[test]
fn the_standard_error_falls_as_paths_are_added() {
    let mut cache = ShadingCache::new(1 << 20);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
    let mut errors = Vec::new();
    for _ in 0..6 {
        let l = 1.0 + rng.random_range(-0.2f32..0.2);
        cache.insert(key(0), sample(l, Quality::INTERACTIVE, 0));
        errors.push(cache.get(key(0)).unwrap().estimate().standard_error());
    }
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "{errors:?}");
    assert_eq!(cache.get(key(0)).unwrap().quality.paths, 6 * 64);
}

#[test]
fn leaf_radiance_needs_all_three_vertices_of_the_side() {
    let mesh = SubdivisionMesh::new(&crate::mesh::test_meshes::square(), Default::default());
    let mut cache = ShadingCache::new(1 << 20);
    for v in [0, 1] {
        cache.insert(key(v), sample(v as f32, Quality::DIRECT, 0));
    }
    assert_eq!(cache.leaf_radiance(&mesh, 0, Side::Front), None);
    assert_eq!(
        cache
            .missing_keys(&mesh, 0, Side::Front)
            .collect::<Vec<_>>(),
        vec![key(2)]
    );
    cache.insert(key(2), sample(4.0, Quality::DIRECT, 0));
    assert_eq!(
        cache.leaf_radiance(&mesh, 0, Side::Front),
        Some([[0.0; 3], [1.0; 3], [4.0; 3]])
    );
    assert_eq!(cache.leaf_radiance(&mesh, 0, Side::Back), None);
    let visible = VisibleSet {
        leaves: vec![crate::visible_set::VisibleLeaf {
            leaf: 0,
            side: Side::Front,
            pixels: 9,
        }],
        width: 4,
        height: 4,
    };
    assert!((cache.l_white(&mesh, &visible) - 4.0).abs() < 1e-6);
}

/// One glint among thousands of samples does not set L_white; the rest's maximum does.
#[test]
fn l_white_leaves_out_a_lone_outlier() {
    let mesh = SubdivisionMesh::new(&crate::mesh::grid_mesh(40), Default::default());
    let mut cache = ShadingCache::new(1 << 24);
    let visible = VisibleSet {
        leaves: (0..mesh.base_count() as NodeId)
            .map(|leaf| crate::visible_set::VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels: 9,
            })
            .collect(),
        width: 64,
        height: 64,
    };
    for v in 0..mesh.vertex_count() as u32 {
        let l = if v == 7 { 1e5 } else { 1.0 + v as f32 * 1e-4 };
        cache.insert(key(v), sample(l, Quality::DIRECT, 0));
    }
    // The largest but the outlier, as stored (`cache::quantised`).
    let stored = |v: u32| conventions::luminance(cache.get(key(v)).unwrap().rgb());
    let below = stored(mesh.vertex_count() as u32 - 1);
    assert!((cache.l_white(&mesh, &visible) - below).abs() < 2e-3);
    assert_eq!(ShadingCache::new(1).l_white(&mesh, &visible), 0.0);
}

/// The thesis profile's L_white (§2.3, appendix A): the maximum of the visible samples, glint
/// and all.
#[test]
fn l_white_without_outliers_is_the_maximum() {
    let mesh = SubdivisionMesh::new(&crate::mesh::grid_mesh(40), Default::default());
    let mut cache = ShadingCache::new(1 << 24).with_l_white_outliers(0.0);
    let visible = VisibleSet {
        leaves: (0..mesh.base_count() as NodeId)
            .map(|leaf| crate::visible_set::VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels: 9,
            })
            .collect(),
        width: 64,
        height: 64,
    };
    for v in 0..mesh.vertex_count() as u32 {
        let l = if v == 7 { 1e5 } else { 1.0 + v as f32 * 1e-4 };
        cache.insert(key(v), sample(l, Quality::DIRECT, 0));
    }
    // As stored (`cache::quantised`).
    let lum = |v: u32| conventions::luminance(cache.get(key(v)).unwrap().rgb());
    assert_eq!(cache.l_white(&mesh, &visible), lum(7));
    // Not visible, not counted.
    let one = VisibleSet {
        leaves: visible.leaves[1..2].to_vec(),
        ..visible
    };
    let most = mesh
        .node(1)
        .vertices
        .map(lum)
        .into_iter()
        .fold(0.0, f32::max);
    assert_eq!(cache.l_white(&mesh, &one), most);
}

/// A long random walk of visible sets: after each eviction the cache is within budget
/// unless everything left is visible now, and nothing visible now is evicted.
#[test]
fn eviction_keeps_memory_under_budget_over_a_long_walk() {
    // The slot table of 20,000 vertices takes 160 kB of it.
    let budget = 512 * 1024;
    let mut cache = ShadingCache::new(budget);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
    let vertices = 20_000u32;
    for now in 1..400u64 {
        let start = rng.random_range(0..vertices - 300);
        let visible: Vec<SampleKey> = (start..start + 300).map(key).collect();
        for &k in &visible {
            cache.insert(k, marked(k.vertex, now));
            cache.touch(k, now);
        }
        cache.evict(now, &|_| false);
        assert!(
            cache.bytes() <= budget,
            "{} bytes at step {now}",
            cache.bytes()
        );
        assert!(
            visible.iter().all(|&k| cache
                .get(k)
                .is_some_and(|s| s.rgb() == marked(k.vertex, now).rgb())),
            "a visible sample was evicted or moved to another key"
        );
    }
    assert!(cache.len() > 300);
}

/// A sample whose colour names its vertex (below 65,536), exactly: channels of 256 to 511 keep
/// every bit in the cache's shared-exponent encoding (`cache::quantised`).
#[test]
fn a_budget_that_shrinks_frees_the_samples_capacity_too() {
    let mut cache = ShadingCache::new(1 << 30);
    for v in 0..20_000 {
        cache.insert(key(v), marked(v, 1));
    }
    let before = cache.capacity_bytes();
    assert!(before >= cache.bytes());
    cache.set_budget_bytes(cache.bytes() / 4);
    assert!(cache.evict(2, &|_| false) > 0);
    assert!(cache.bytes() <= cache.budget_bytes());
    // The slot table (160 kB for 20,000 vertices) stays with the vertices; the samples go.
    assert!(
        cache.capacity_bytes() < before / 2,
        "{} of {before} bytes still allocated",
        cache.capacity_bytes()
    );
}

fn marked(vertex: u32, seen: u64) -> CachedSample {
    let channel = |byte: u32| 256.0 + (byte & 0xff) as f32;
    CachedSample {
        parts: SampleParts::direct_only([channel(vertex), channel(vertex >> 8), 256.0], 0.25),
        ..sample(0.0, Quality::DIRECT, seen)
    }
}

fn glossy(eye: Vec3, seen: u64) -> CachedSample {
    CachedSample {
        view_dependent: true,
        eye: Some(eye),
        ..sample(1.0, Quality::DIRECT, seen)
    }
}

/// Eyes are keyed by slot, so removals that move other samples leave them in place, and an
/// evicted or diffuse-replaced sample's eye is dropped (and no longer charged).
#[test]
fn eyes_follow_their_samples_through_eviction() {
    let mut cache = ShadingCache::new(1);
    cache.insert(key(0), glossy(Vec3::Y, 1));
    for v in 1..10 {
        cache.insert(key(v), sample(1.0, Quality::DIRECT, 1));
    }
    // Last in the array: each removal before it moves it to the freed index.
    cache.insert(key(10), glossy(Vec3::X, 6));
    cache.insert(key(11), glossy(Vec3::Z, 1));
    cache.insert(key(11), sample(1.0, Quality::INTERACTIVE, 1));
    assert_eq!(cache.get(key(11)).unwrap().eye, None);
    assert_eq!(cache.eyes.len(), 2);

    // Everything not seen at 6 goes: the budget of one byte is never met.
    assert_eq!(cache.evict(6, &|_| false), 11);
    assert_eq!(cache.len(), 1);
    let survivor = cache.get(key(10)).unwrap();
    assert_eq!((survivor.eye, survivor.last_seen), (Some(Vec3::X), 6));
    assert_eq!(cache.eyes.len(), 1);

    let before = cache.bytes();
    assert_eq!(cache.evict(7, &|_| false), 1);
    assert!(cache.get(key(10)).is_none() && cache.eyes.is_empty());
    assert_eq!(
        before - cache.bytes(),
        size_of::<PackedSample>() + size_of::<u32>() + EYE_ENTRY_BYTES + size_of::<EyeVariant>()
    );
}

/// Each eye keeps its own radiance; a reader gets the kept eye nearest to it; a fifth eye
/// replaces the kept one nearest to it; a kept eye merges further paths at its depth.
#[test]
fn view_dependent_samples_keep_one_radiance_per_eye() {
    let mut cache = ShadingCache::new(1 << 20);
    let at = |x: f32| Vec3::new(x, 0.0, 0.0);
    let shaded = |x: f32, quality| CachedSample {
        parts: SampleParts::direct_only([x; 3], 0.25),
        quality,
        ..glossy(at(x), 1)
    };
    for x in [0.0, 10.0, 20.0, 30.0] {
        assert_ne!(
            cache.insert(key(1), shaded(x, Quality::DIRECT)),
            CacheInsert::Ignored
        );
    }
    let seen = |cache: &ShadingCache, x| cache.get_seen_from(key(1), Some(at(x))).unwrap();
    assert_eq!(seen(&cache, 9.0).rgb(), [10.0; 3]);
    assert_eq!(seen(&cache, 9.0).eye, Some(at(10.0)));
    assert_eq!(cache.get(key(1)).unwrap().rgb(), [30.0; 3], "the latest");
    // A fifth eye at 12 replaces the one at 10; the others stay.
    cache.insert(key(1), shaded(12.0, Quality::DIRECT));
    assert_eq!(seen(&cache, 9.0).rgb(), [12.0; 3]);
    assert_eq!(seen(&cache, 1.0).rgb(), [0.0; 3]);
    assert_eq!(cache.eye_variants, MAX_EYES);
    // The same eye again: its paths add to that eye's estimate; a deeper one replaces it.
    let again = CachedSample {
        parts: SampleParts::direct_only([5.0; 3], 0.25),
        ..shaded(20.0, Quality::DIRECT)
    };
    assert_eq!(cache.insert(key(1), again), CacheInsert::Upgraded);
    assert_eq!(seen(&cache, 21.0).rgb(), [12.5; 3]);
    let better = CachedSample {
        quality: Quality::INTERACTIVE,
        ..again
    };
    assert_eq!(cache.insert(key(1), better), CacheInsert::Upgraded);
    assert_eq!(seen(&cache, 21.0).rgb(), [5.0; 3]);
    assert_eq!(cache.eye_variants, MAX_EYES);
    // A diffuse reading (no eye) and a diffuse sample: the latest, then no eyes at all.
    assert_eq!(cache.get_seen_from(key(1), None).unwrap().rgb(), [5.0; 3]);
    let best = Quality {
        paths: Quality::INTERACTIVE.paths,
        bounces: Some(3),
    };
    cache.insert(key(1), sample(7.0, best, 1));
    assert_eq!(seen(&cache, 9.0).rgb(), [7.0; 3]);
    assert!(cache.eyes.is_empty() && cache.eye_variants == 0);
}

/// Frame counts past `u32::MAX` saturate: no panic, and a sample seen "now" is still spared.
#[test]
fn last_seen_beyond_u32_saturates() {
    let mut cache = ShadingCache::new(1);
    cache.insert(key(0), sample(1.0, Quality::DIRECT, u64::MAX));
    assert_eq!(cache.get(key(0)).unwrap().last_seen, u64::from(u32::MAX));
    cache.insert(key(1), sample(1.0, Quality::DIRECT, 5));
    cache.touch(key(1), u64::from(u32::MAX) + 1);
    assert_eq!(cache.get(key(1)).unwrap().last_seen, u64::from(u32::MAX));
    assert_eq!(cache.evict(u64::MAX, &|_| false), 0);
    assert_eq!(cache.len(), 2);
}

/// A key given up on counts as known, and its leaves show the mean of their other vertices.
#[test]
fn a_failed_key_is_shown_with_the_mean_of_the_others() {
    let mesh = SubdivisionMesh::new(&crate::mesh::test_meshes::square(), Default::default());
    let mut cache = ShadingCache::new(1 << 20);
    let [a, b, c] = mesh.node(0).vertices;
    cache.insert(key(a), sample(1.0, Quality::INTERACTIVE, 0));
    cache.insert(key(b), sample(3.0, Quality::INTERACTIVE, 0));
    assert!(cache.leaf_radiance(&mesh, 0, Side::Front).is_none());
    assert_eq!(cache.missing_keys(&mesh, 0, Side::Front).count(), 1);
    cache.mark_failed(key(c));
    assert_eq!(cache.missing_keys(&mesh, 0, Side::Front).count(), 0);
    assert_eq!(
        cache.leaf_radiance(&mesh, 0, Side::Front),
        Some([[1.0; 3], [3.0; 3], [2.0; 3]])
    );
    cache.insert(key(c), sample(5.0, Quality::INTERACTIVE, 0));
    assert!(!cache.is_failed(key(c)), "a valid answer clears the mark");
}

/// A vertex the mesh freed for reuse loses its samples, both sides, and only its own.
#[test]
fn forgotten_vertices_lose_their_samples_and_only_theirs() {
    let mut cache = ShadingCache::new(1 << 20);
    for v in 0..6 {
        cache.insert(key(v), sample(1.0, Quality::DIRECT, 0));
    }
    let back = SampleKey {
        vertex: 2,
        side: Side::Back,
    };
    cache.insert(back, sample(1.0, Quality::DIRECT, 0));
    cache.forget_vertices(&[2, 4]);
    assert_eq!(cache.len(), 4);
    assert!(cache.get(key(2)).is_none() && cache.get(back).is_none());
    assert!(cache.get(key(4)).is_none());
    for v in [0, 1, 3, 5] {
        assert_eq!(cache.get(key(v)).unwrap().rgb(), [1.0; 3], "vertex {v}");
    }
}
