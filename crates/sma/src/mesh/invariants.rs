//! Property tests of the subdivision mesh on random meshes (seams, mixed winding, needles,
//! non-manifold fins) under random refinement and coarsening (DESIGN.md §4), each case under both
//! neighbour rules (`neighbour_rule`): the thesis's keeps red–green's guarantees.

use std::collections::{BTreeSet, HashMap};

use glam::Vec3;
use proptest::prelude::*;
use scene::{Mesh, Triangle};

use super::test_meshes::grid;
use super::{MeshParams, NeighbourRule, NodeId, RefinementStep, Split, SubdivisionMesh, min_angle};

/// A grid with uneven columns (needles where a column is thin), some triangles flipped, some
/// given their own vertex copies (a seam), and fins standing on some interior edges (three faces
/// on one edge).
fn random_mesh(n: u32, widths: &[f32], flips: &[bool], seams: &[bool], fins: &[bool]) -> Mesh {
    let mut mesh = grid(n);
    let xs: Vec<f32> = std::iter::once(0.0)
        .chain(widths.iter().scan(0.0, |x, w| {
            *x += w;
            Some(*x)
        }))
        .collect();
    for p in &mut mesh.positions {
        p.x = xs[p.x as usize];
    }
    let count = mesh.triangles.len();
    let mut finned = std::collections::HashSet::new();
    for t in 0..count {
        if flips[t % flips.len()] {
            mesh.triangles[t].vertices.swap(1, 2);
        }
        if seams[t % seams.len()] {
            let copies = mesh.triangles[t].vertices.map(|v| {
                mesh.positions.push(mesh.positions[v as usize]);
                mesh.normals.push(Vec3::Z);
                mesh.positions.len() as u32 - 1
            });
            mesh.triangles[t].vertices = copies;
        }
        let [a, b, _] = mesh.triangles[t].vertices;
        // One fin per edge: two coincident fins would be one face twice.
        if fins[t % fins.len()]
            && finned.insert(edge_key(
                mesh.positions[a as usize],
                mesh.positions[b as usize],
            ))
        {
            let apex = 0.5 * (mesh.positions[a as usize] + mesh.positions[b as usize]) + Vec3::Z;
            mesh.positions.push(apex);
            mesh.normals.push(Vec3::Y);
            let top = mesh.positions.len() as u32 - 1;
            mesh.triangles.push(Triangle {
                vertices: [a, b, top],
                material: 1,
            });
        }
    }
    mesh
}

fn bits(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

fn edge_key(a: Vec3, b: Vec3) -> ([u32; 3], [u32; 3]) {
    let (a, b) = (bits(a), bits(b));
    if a < b { (a, b) } else { (b, a) }
}

fn area(p: [Vec3; 3]) -> f32 {
    0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
}

/// Whether segment a-b lies on segment p-q (collinear, within it).
fn on_segment(a: Vec3, b: Vec3, p: Vec3, q: Vec3) -> bool {
    let d = q - p;
    let len2 = d.length_squared();
    [a, b].iter().all(|&x| {
        let t = (x - p).dot(d) / len2;
        (-1e-5..=1.0 + 1e-5).contains(&t) && (p + t * d).distance(x) <= 1e-5 * len2.sqrt()
    })
}

/// Conforming triangulation, area per base, angle bound, leaf count.
pub(crate) fn check(mesh: &SubdivisionMesh, scene: &Mesh) -> Result<(), TestCaseError> {
    let leaves: Vec<NodeId> = mesh.leaves().collect();
    prop_assert_eq!(leaves.len(), mesh.leaf_count());
    let mut edges: HashMap<_, (u32, Vec3, Vec3)> = HashMap::new();
    let mut corners = std::collections::HashSet::new();
    let mut base_area = vec![0.0f64; mesh.base_count()];
    for &leaf in &leaves {
        let p = mesh.leaf_positions(leaf);
        let base = mesh.base_of(leaf);
        base_area[base as usize] += f64::from(area(p));
        let bound = mesh.base_angle_bound(base);
        prop_assert!(
            min_angle(p) >= bound - 1e-3,
            "leaf {} angle {} < bound {}",
            leaf,
            min_angle(p),
            bound
        );
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            edges.entry(edge_key(a, b)).or_insert((0, a, b)).0 += 1;
            corners.insert(bits(a));
        }
    }
    for (t, &got) in base_area.iter().enumerate() {
        let want = f64::from(scene.triangle_area(t));
        prop_assert!(
            (got - want).abs() <= 1e-4 * want.max(1e-6),
            "base {} area {} != {}",
            t,
            got,
            want
        );
    }
    for &(count, a, b) in edges.values() {
        // No vertex at a dyadic point inside a leaf edge: no T-junction.
        let m = 0.5 * (a + b);
        for x in [m, 0.5 * (a + m), 0.5 * (m + b)] {
            prop_assert!(
                !corners.contains(&bits(x)),
                "hanging vertex at {} on {}-{}",
                x,
                a,
                b
            );
        }
        // As many leaves on the edge as base faces hold it on their boundary, or two inside one.
        let faces = (0..scene.triangles.len())
            .filter(|&t| {
                let q = scene.triangle_positions(t);
                (0..3).any(|k| on_segment(a, b, q[k], q[(k + 1) % 3]))
            })
            .count() as u32;
        let expected = if faces == 0 { 2 } else { faces };
        prop_assert_eq!(count, expected, "edge {}-{}", a, b);
    }
    Ok(())
}

/// Coarsens everything, one level per call, checking that each step is a conforming unit that
/// takes the leaves from before it to after it.
pub(super) fn coarsen_all(mesh: &mut SubdivisionMesh, scene: &Mesh) -> Result<(), TestCaseError> {
    loop {
        let parents: Vec<NodeId> = (0..mesh.node_count() as NodeId)
            .filter(|&id| {
                mesh.node(id).is_alive() && matches!(mesh.node(id).split(), Split::Red { .. })
            })
            .collect();
        let mut shown: BTreeSet<NodeId> = mesh.leaves().collect();
        let steps = mesh.coarsen_many(&parents);
        if steps.is_empty() {
            return Ok(());
        }
        for step in steps {
            apply(&mut shown, &step, mesh)?;
        }
        prop_assert_eq!(&shown, &mesh.leaves().collect::<BTreeSet<_>>());
        check(mesh, scene)?;
    }
}

/// Applies a step to the leaves a viewer shows: it replaces only leaves shown, adds only new
/// ones, and covers exactly the area it replaces.
pub(crate) fn apply(
    shown: &mut BTreeSet<NodeId>,
    step: &RefinementStep,
    mesh: &SubdivisionMesh,
) -> Result<(), TestCaseError> {
    for l in &step.replaced_leaves {
        prop_assert!(shown.remove(l), "step replaces leaf {} it did not have", l);
    }
    for &l in &step.new_leaves {
        prop_assert!(shown.insert(l), "step adds leaf {} twice", l);
    }
    let sum = |ids: &[NodeId]| {
        ids.iter()
            .map(|&l| f64::from(area(mesh.leaf_positions(l))))
            .sum::<f64>()
    };
    let (new, old) = (sum(&step.new_leaves), sum(&step.replaced_leaves));
    prop_assert!(
        (new - old).abs() <= 1e-4 * old,
        "a step covers what it replaces"
    );
    Ok(())
}

/// The base triangles, which full coarsening must give back.
fn base_leaves(mesh: &SubdivisionMesh) -> BTreeSet<NodeId> {
    (0..mesh.base_count() as NodeId).collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn refinement_and_coarsening_keep_the_mesh_conforming(
        n in 1u32..4,
        widths in prop::collection::vec(prop_oneof![Just(0.02f32), 0.5f32..2.0], 4),
        flips in prop::collection::vec(any::<bool>(), 1..5),
        seams in prop::collection::vec(prop::bool::weighted(0.3), 1..5),
        fins in prop::collection::vec(prop::bool::weighted(0.2), 1..5),
        rounds in prop::collection::vec((prop::collection::vec(any::<prop::sample::Index>(), 1..6), any::<prop::sample::Index>(), any::<bool>()), 1..8),
    ) {
        let scene = random_mesh(n, &widths, &flips, &seams, &fins);
        for rule in NeighbourRule::ALL {
            refine_and_coarsen(&scene, rule, &rounds)
                .map_err(|e| TestCaseError::fail(format!("{rule}: {e}")))?;
        }
    }

    /// One refinement step, closure included, is undone by coarsening.
    #[test]
    fn coarsening_undoes_a_single_refinement(
        n in 1u32..4,
        widths in prop::collection::vec(prop_oneof![Just(0.02f32), 0.5f32..2.0], 4),
        flips in prop::collection::vec(any::<bool>(), 1..5),
        fins in prop::collection::vec(prop::bool::weighted(0.2), 1..5),
        pick in any::<prop::sample::Index>(),
    ) {
        let scene = random_mesh(n, &widths, &flips, &[false], &fins);
        for rule in NeighbourRule::ALL {
            let mut mesh = SubdivisionMesh::new(&scene, params(rule));
            let leaf = pick.index(mesh.base_count()) as NodeId;
            mesh.refine(&[leaf], &|_| false);
            check(&mesh, &scene)?;
            coarsen_all(&mut mesh, &scene)?;
            prop_assert_eq!(mesh.leaves().collect::<BTreeSet<_>>(), base_leaves(&mesh));
        }
    }
}

fn params(neighbour_rule: NeighbourRule) -> MeshParams {
    MeshParams {
        min_edge_length: 1e-3,
        weld_tolerance_rel: 1e-6,
        neighbour_rule,
    }
}

/// Rounds of refinement (leaves picked by index) and coarsening (one red parent, picked by index),
/// checking the mesh after each, then coarsening everything back to the base mesh.
fn refine_and_coarsen(
    scene: &Mesh,
    rule: NeighbourRule,
    rounds: &[(Vec<prop::sample::Index>, prop::sample::Index, bool)],
) -> Result<(), TestCaseError> {
    let mut mesh = SubdivisionMesh::new(scene, params(rule));
    for (picks, coarse_pick, coarsen) in rounds {
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        let selected: Vec<NodeId> = picks
            .iter()
            .map(|i| leaves[i.index(leaves.len())])
            .collect();
        // Applied in order, the steps take the leaves from before the call to after it.
        let mut shown: BTreeSet<NodeId> = leaves.iter().copied().collect();
        for step in mesh.refine(&selected, &|_| false) {
            apply(&mut shown, &step, &mesh)?;
        }
        prop_assert_eq!(shown, mesh.leaves().collect::<BTreeSet<_>>());
        check(&mesh, scene)?;
        if *coarsen {
            let inner: Vec<NodeId> = (0..mesh.node_count() as NodeId)
                .filter(|&id| {
                    mesh.node(id).is_alive() && matches!(mesh.node(id).split(), Split::Red { .. })
                })
                .collect();
            if !inner.is_empty() {
                let parent = inner[coarse_pick.index(inner.len())];
                let vertices = mesh.node(parent).vertices;
                if mesh.coarsen(parent).is_some() {
                    prop_assert_eq!(mesh.node(parent).vertices, vertices);
                    let green = matches!(mesh.node(parent).split(), Split::Green { .. });
                    prop_assert!(mesh.is_leaf(parent) || green);
                }
                check(&mesh, scene)?;
            }
        }
    }
    coarsen_all(&mut mesh, scene)?;
    prop_assert_eq!(mesh.leaves().collect::<BTreeSet<_>>(), base_leaves(&mesh));
    Ok(())
}
