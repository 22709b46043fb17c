use std::collections::BTreeSet;

use glam::Vec3;
use proptest::prelude::*;

use super::*;
use crate::cache::CachedSample;
use crate::mesh::invariants::{apply, check};
use crate::mesh::test_meshes::grid;
use crate::visible_set::VisibleLeaf;
use protocol::SampleParts;

/// The scene's depth, and the paths from which the ladder believes a variance (a scene of 64
/// paths: its first rung above).
const DEPTH: Option<u32> = Some(2);
const TRUSTED_PATHS: u32 = 256;
/// The ladder's cap.
const CAP: u32 = 1024;
const STEP: f32 = 1.0 / 255.0;
const L_WHITE: f32 = 1.0;

fn trusted(q: Quality) -> bool {
    q.bounces == DEPTH && q.paths >= TRUSTED_PATHS
}

fn config() -> ScheduleConfig {
    ScheduleConfig {
        merge_uniform: true,
        display_error: STEP,
        max_paths: CAP,
        ..ScheduleConfig::default()
    }
}

fn sample(l: f32, luminance_variance: f32, paths: u32) -> CachedSample {
    CachedSample {
        parts: SampleParts::direct_only([l; 3], luminance_variance),
        quality: Quality {
            paths,
            bounces: DEPTH,
        },
        view_dependent: false,
        eye: None,
        last_seen: 0,
    }
}

/// Every vertex of `mesh` shaded by `f` of its position, noiseless, settled.
fn shade_all(mesh: &SubdivisionMesh, cache: &mut ShadingCache, f: impl Fn(Vec3) -> f32) {
    for vertex in 0..mesh.vertex_count() as u32 {
        let l = f(mesh.vertex(vertex).position);
        let key = SampleKey {
            vertex,
            side: Side::Front,
        };
        if cache.get(key).is_none() {
            cache.insert(key, sample(l, 0.0, TRUSTED_PATHS));
        }
    }
}

/// Every leaf, seen from the front on `pixels` pixels of a 1000 × 1000 image (a leaf is large
/// above 2,000 with the default fraction).
fn all_visible(mesh: &SubdivisionMesh, pixels: u32) -> VisibleSet {
    VisibleSet {
        leaves: mesh
            .leaves()
            .map(|leaf| VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels,
            })
            .collect(),
        width: 1000,
        height: 1000,
    }
}

fn pass(
    merge: &mut UniformMerge,
    mesh: &mut SubdivisionMesh,
    cache: &ShadingCache,
) -> Vec<RefinementStep> {
    let visible = all_visible(mesh, 10);
    let views = [JudgedView {
        visible: &visible,
        l_white: L_WHITE,
    }];
    merge.pass(&views, mesh, cache, &trusted)
}

fn verdict(mesh: &SubdivisionMesh, cache: &ShadingCache, parent: NodeId) -> Verdict {
    let settling = Settling {
        display_error: STEP,
        max_paths: CAP,
        trusted: &trusted,
    };
    judge(mesh, cache, parent, Side::Front, L_WHITE, &settling)
}

/// A 2 × 2 grid with its triangle 0, (0,0) (1,0) (1,1), split red (and its closure), every
/// vertex shaded by `f`.
fn split_corner(f: impl Fn(Vec3) -> f32) -> (SubdivisionMesh, ShadingCache) {
    let mut mesh = SubdivisionMesh::new(&grid(2), Default::default());
    mesh.refine(&[0], &|_| false);
    assert!(matches!(mesh.node(0).split(), Split::Red { .. }));
    let mut cache = ShadingCache::new(1 << 20);
    shade_all(&mesh, &mut cache, f);
    (mesh, cache)
}

/// The sample keys of parent 0's corners and of its midpoints.
fn corners_and_midpoints(mesh: &SubdivisionMesh) -> ([SampleKey; 3], [SampleKey; 3]) {
    let Split::Red { first_child } = mesh.node(0).split() else {
        panic!("node 0 is split red");
    };
    let key = |vertex| SampleKey {
        vertex,
        side: Side::Front,
    };
    (
        mesh.node(0).vertices.map(key),
        mesh.node(first_child + 3).vertices.map(key),
    )
}

#[test]
fn a_split_of_flat_or_linear_shading_is_merged_back_and_one_across_a_shadow_edge_is_not() {
    let flat = |_: Vec3| 0.4f32;
    let linear = |p: Vec3| 0.2 + 0.3 * p.x + 0.1 * p.y;
    for f in [&flat as &dyn Fn(Vec3) -> f32, &linear] {
        let (mut mesh, cache) = split_corner(f);
        assert_eq!(verdict(&mesh, &cache, 0), Verdict::Uniform);
        let mut merge = UniformMerge::new(&config());
        let steps = pass(&mut merge, &mut mesh, &cache);
        assert!(!steps.is_empty());
        assert!(mesh.is_leaf(0), "merged back");
        assert_eq!(mesh.leaf_count(), mesh.base_count(), "closure undone too");
        assert_eq!(merge.merges(), 1);
    }
    // A shadow edge at x = 0.75: the midpoint (0.5, 0) is in shadow, its corners' mean is not.
    let (mut mesh, cache) = split_corner(|p| if p.x > 0.75 { 1.0 } else { 0.1 });
    assert_eq!(verdict(&mesh, &cache, 0), Verdict::Varies);
    let mut merge = UniformMerge::new(&config());
    let leaves = mesh.leaf_count();
    assert!(pass(&mut merge, &mut mesh, &cache).is_empty());
    assert_eq!(mesh.leaf_count(), leaves);
    assert_eq!(merge.merges(), 0);
}

#[test]
fn only_settled_samples_decide_and_their_noise_explains_what_it_can() {
    // Corners at 0.5, midpoints off by `offset`, every sample with `variance` over `paths`.
    let with = |offset: f32, variance: f32, paths: u32| {
        let (mesh, _) = split_corner(|_| 0.5);
        let (corners, midpoints) = corners_and_midpoints(&mesh);
        let mut cache = ShadingCache::new(1 << 20);
        for key in corners {
            cache.insert(key, sample(0.5, variance, paths));
        }
        for key in midpoints {
            cache.insert(key, sample(0.5 + offset, variance, paths));
        }
        verdict(&mesh, &cache, 0)
    };
    // Noiseless and settled: a tenth of a display step passes, five steps do not.
    assert_eq!(with(0.0002, 0.0, TRUSTED_PATHS), Verdict::Uniform);
    assert_eq!(with(0.02, 0.0, TRUSTED_PATHS), Verdict::Varies);
    // Below the rung whose variance the ladder believes: undecided, even flat.
    assert_eq!(with(0.0, 0.0, 64), Verdict::Unsettled);
    // Believed, but noisier than one display step and below the cap: undecided, even flat.
    let noisy = 1.2;
    assert_eq!(with(0.0, noisy, TRUSTED_PATHS), Verdict::Unsettled);
    // At the cap it has settled however noisy: its noise explains a small offset (about one
    // combined standard error), not a shadow's (many).
    assert_eq!(with(0.04, noisy, CAP), Verdict::Uniform);
    assert_eq!(with(0.3, noisy, CAP), Verdict::Varies);
    // The same small offset without noise is five display steps: not uniform.
    assert_eq!(with(0.04, 0.0, CAP), Verdict::Varies);
}

#[test]
fn noisy_unsettled_samples_are_never_merged() {
    // Flat, but every sample at the scene's 64 paths with a visible noise: merging waits.
    let mut mesh = SubdivisionMesh::new(&grid(2), Default::default());
    mesh.refine(&[0], &|_| false);
    let mut cache = ShadingCache::new(1 << 20);
    for vertex in 0..mesh.vertex_count() as u32 {
        let key = SampleKey {
            vertex,
            side: Side::Front,
        };
        cache.insert(key, sample(0.5, 1.2, 64));
    }
    let mut merge = UniformMerge::new(&config());
    let leaves = mesh.leaf_count();
    assert!(pass(&mut merge, &mut mesh, &cache).is_empty());
    assert_eq!(mesh.leaf_count(), leaves);
    assert_eq!(verdict(&mesh, &cache, 0), Verdict::Unsettled);
}

#[test]
fn large_children_view_dependent_samples_and_a_switched_off_merge_are_left_alone() {
    let (mut mesh, mut cache) = split_corner(|_| 0.4);
    let mut merge = UniformMerge::new(&config());
    // Children above the large-triangle fraction: §4.3.5's rule is still searching them.
    let large = all_visible(&mesh, 5_000);
    let views = [JudgedView {
        visible: &large,
        l_white: L_WHITE,
    }];
    assert!(merge.pass(&views, &mut mesh, &cache, &trusted).is_empty());
    // A view-dependent midpoint.
    let (_, midpoints) = corners_and_midpoints(&mesh);
    cache.insert(
        midpoints[0],
        CachedSample {
            view_dependent: true,
            eye: Some(Vec3::Z),
            ..sample(0.4, 0.0, TRUSTED_PATHS)
        },
    );
    assert_eq!(verdict(&mesh, &cache, 0), Verdict::NotCandidate);
    // Off: never due, whatever comes.
    let mut off = UniformMerge::new(&ScheduleConfig::default());
    off.new_input();
    assert!(!off.is_due());
    let mut on = UniformMerge::new(&config());
    assert!(!on.is_due(), "nothing new yet");
    on.new_input();
    assert!(on.is_due());
}

#[test]
fn a_merged_parent_is_not_split_again_until_its_corners_gain_paths() {
    // A gradient: the criterion split the parent for its corners' spread, which the merged
    // parent still shows.
    let gradient = |p: Vec3| 0.1 + 0.6 * p.x;
    let (mut mesh, mut cache) = split_corner(gradient);
    let mut merge = UniformMerge::new(&config());
    assert!(!pass(&mut merge, &mut mesh, &cache).is_empty());
    assert!(mesh.is_leaf(0));
    assert!(!merge.allows(0, &mesh, &cache), "same samples: not again");
    assert!(merge.allows(1, &mesh, &cache), "another leaf");
    // A corner gains paths: the samples changed, the criterion may split it again.
    let corner = SampleKey {
        vertex: mesh.node(0).vertices[0],
        side: Side::Front,
    };
    let more = cache.get(corner).unwrap();
    cache.insert(corner, more);
    assert!(merge.allows(0, &mesh, &cache));
    assert!(merge.allows(0, &mesh, &cache), "the record is gone");

    // A neighbour's split bisects a merged parent green: its halves stand for it.
    let (mut mesh, cache) = split_corner(gradient);
    let mut merge = UniformMerge::new(&config());
    assert!(!pass(&mut merge, &mut mesh, &cache).is_empty());
    // Triangle 3, (1,0) (2,1) (1,1), shares the edge x = 1 with triangle 0.
    mesh.refine(&[3], &|_| false);
    let Split::Green { first_child, .. } = mesh.node(0).split() else {
        panic!("triangle 0 is bisected by the closure");
    };
    assert!(!merge.allows(first_child, &mesh, &cache));
    assert!(!merge.allows(first_child + 1, &mesh, &cache));
}

/// Random refinement of a grid shaded with a gradient and a shadow edge, then merge passes
/// until none merges: after each, the mesh is a conforming triangulation within its angle bound
/// (`mesh::invariants`), and the steps take the leaves a viewer shows to the mesh's leaves.
/// With the gradient alone everything merges back to the base mesh.
fn refine_and_merge(
    picks: &[Vec<prop::sample::Index>],
    shadow: bool,
) -> Result<SubdivisionMesh, TestCaseError> {
    let scene = grid(4);
    let mut mesh = SubdivisionMesh::new(&scene, Default::default());
    let shade = |p: Vec3| {
        let lit = if shadow && p.x + 0.3 * p.y > 2.1 {
            0.1
        } else {
            1.0
        };
        lit * (0.2 + 0.1 * p.x + 0.05 * p.y)
    };
    for round in picks {
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        let selected: Vec<NodeId> = round
            .iter()
            .map(|i| leaves[i.index(leaves.len())])
            .collect();
        mesh.refine(&selected, &|_| false);
    }
    check(&mesh, &scene)?;
    let mut cache = ShadingCache::new(1 << 24);
    shade_all(&mesh, &mut cache, shade);
    let mut merge = UniformMerge::new(&config());
    loop {
        let mut shown: BTreeSet<NodeId> = mesh.leaves().collect();
        let steps = pass(&mut merge, &mut mesh, &cache);
        if steps.is_empty() {
            break;
        }
        for step in &steps {
            apply(&mut shown, step, &mesh)?;
        }
        prop_assert_eq!(&shown, &mesh.leaves().collect::<BTreeSet<_>>());
        check(&mesh, &scene)?;
    }
    Ok(mesh)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn merges_keep_the_mesh_conforming(
        picks in prop::collection::vec(prop::collection::vec(any::<prop::sample::Index>(), 1..6), 1..6),
    ) {
        let mesh = refine_and_merge(&picks, false)?;
        prop_assert_eq!(mesh.leaf_count(), mesh.base_count(), "a gradient merges back whole");
        refine_and_merge(&picks, true)?;
    }
}
