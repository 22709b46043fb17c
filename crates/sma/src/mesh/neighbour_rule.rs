//! How closure splits a neighbour left with one midpoint on its edges (thesis §4.2, fig. 4.7;
//! DESIGN.md §4).
//!
//! Red–green (the default) bisects it (green). The thesis's rule splits it 1:4 (Loop) when the
//! split edge is shorter than the neighbour's height on that edge, and bisects it otherwise: a
//! bisection across a short edge would make a needle of a tall triangle. Here the thesis's rule
//! only changes that one choice inside red–green's closure: a green leaf is still never split
//! (its parent is split red instead) and a leaf with two or three midpoints is still split red.
//! So what red–green guarantees still holds (module documentation of [`super`]): reds are
//! similar to their base triangle and greens are one median bisection of a red or base node, so
//! the angle bound stands; every split is of a leaf with a finer neighbour, so closure stops at
//! the finest level present; the leaves stay conforming.
//!
//! What the thesis's rule adds is propagation: a neighbour split 1:4 leaves midpoints on its two
//! other edges, whose neighbours may in turn be tall on them, and a run of needles (a thin
//! column) or of fins on one non-manifold edge could be split whole by one selection, in one
//! step, sent to the viewer as one update (DESIGN.md §4). The thesis met this "exaggerated
//! propagation" and bounded it with bisection itself, but its rule alone does not bound it, so
//! one step makes at most `MAX_THESIS_SPLITS_PER_STEP` such 1:4 splits; past it, closure
//! bisects, as red–green does, and the mesh counts the step in [`NeighbourStats::bound_hits`].

use super::{NodeId, SubdivisionMesh};

/// Which split closes a neighbour with one split edge.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum NeighbourRule {
    /// Bisect it (green), Bank–Sherman–Weiser.
    #[default]
    RedGreen,
    /// Thesis §4.2: 1:4 when the split edge is shorter than the neighbour's height on it,
    /// bisect otherwise; at most `MAX_THESIS_SPLITS_PER_STEP` 1:4 splits per step.
    Thesis,
}

impl NeighbourRule {
    pub const ALL: [NeighbourRule; 2] = [NeighbourRule::RedGreen, NeighbourRule::Thesis];

    /// The rule's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            NeighbourRule::RedGreen => "red-green",
            NeighbourRule::Thesis => "thesis",
        }
    }

    pub fn from_name(name: &str) -> Option<NeighbourRule> {
        NeighbourRule::ALL.into_iter().find(|r| r.name() == name)
    }
}

impl std::fmt::Display for NeighbourRule {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The most neighbours one refinement step splits 1:4 by the thesis's rule rather than
/// bisecting them. Nine is two rings around the selected triangle of a manifold mesh: its three
/// neighbours (fig. 4.7 stops there) and, for each, the two across its other edges, which a
/// 1:4 split leaves with a midpoint. Past it the step closes as red–green's would.
pub(crate) const MAX_THESIS_SPLITS_PER_STEP: u32 = 9;

/// What the thesis's rule did since the mesh was made (zero under red–green).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NeighbourStats {
    /// Neighbours split 1:4 where red–green would have bisected them.
    pub thesis_splits: u64,
    /// Refinement steps that reached `MAX_THESIS_SPLITS_PER_STEP` and bisected a neighbour
    /// the rule would have split 1:4.
    pub bound_hits: u64,
}

/// One step's use of the thesis's rule, against its bound.
#[derive(Default)]
pub(super) struct Cascade {
    splits: u32,
    hit: bool,
}

impl Cascade {
    /// Adds the step to the mesh's counters.
    pub(super) fn finish(self, stats: &mut NeighbourStats) {
        stats.thesis_splits += u64::from(self.splits);
        stats.bound_hits += u64::from(self.hit);
    }
}

impl SubdivisionMesh {
    /// What the thesis's rule has done so far (see [`NeighbourStats`]).
    pub fn neighbour_stats(&self) -> NeighbourStats {
        self.neighbour_stats
    }

    /// Whether closure splits leaf `id`, whose only split edge is `k`, 1:4 rather than bisecting
    /// it: under the thesis's rule, when edge `k` is shorter than the height on it (|e|² < 2 ×
    /// area, i.e. |e|² < |e × (o - a)|), the leaf's red children keep `min_edge_length`
    /// (the split is the rule's choice, not conformity's) and the step's bound allows.
    pub(super) fn splits_neighbour_whole(
        &self,
        id: NodeId,
        k: usize,
        cascade: &mut Cascade,
    ) -> bool {
        if self.neighbour_rule != NeighbourRule::Thesis {
            return false;
        }
        let p = self.leaf_positions(id);
        let (a, b, o) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
        let edge = b - a;
        let short = edge.length_squared() < edge.cross(o - a).length();
        if !short || self.longest_edge(id) < self.min_split_edge {
            return false;
        }
        if cascade.splits >= MAX_THESIS_SPLITS_PER_STEP {
            cascade.hit = true;
            return false;
        }
        cascade.splits += 1;
        true
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use scene::{Mesh, Triangle};

    use super::*;
    use crate::mesh::invariants::{check, coarsen_all};
    use crate::mesh::{MeshParams, Split};

    fn mesh_of(positions: Vec<Vec3>, triangles: &[[u32; 3]]) -> Mesh {
        Mesh {
            normals: vec![Vec3::Z; positions.len()],
            positions,
            triangles: triangles
                .iter()
                .map(|&vertices| Triangle {
                    vertices,
                    material: 0,
                })
                .collect(),
        }
    }

    fn refined(scene: &Mesh, rule: NeighbourRule) -> SubdivisionMesh {
        let params = MeshParams {
            neighbour_rule: rule,
            ..MeshParams::default()
        };
        let mut mesh = SubdivisionMesh::new(scene, params);
        assert_eq!(mesh.refine(&[0], &|_| false).len(), 1);
        check(&mesh, scene).unwrap();
        mesh
    }

    /// Triangle 0, (0,0)-(0.5,-0.5)-(1,0), is selected; triangle 1 stands on its edge (0,0)-(1,0)
    /// with its apex at `apex`; triangle 2, when there, stands on triangle 1's edge from (1,0) to
    /// the apex, rising 4 out of the plane from that edge's midpoint.
    fn neighbours(apex: Vec3, third: bool) -> Mesh {
        let mut positions = vec![Vec3::ZERO, Vec3::X, apex, Vec3::new(0.5, -0.5, 0.0)];
        let mut triangles = vec![[0, 3, 1], [0, 1, 2]];
        if third {
            positions.push(0.5 * (Vec3::X + apex) + 4.0 * Vec3::Z);
            triangles.push([1, 2, 4]);
        }
        mesh_of(positions, &triangles)
    }

    /// Fig. 4.7: a neighbour tall on the split edge (edge 1, height 3) is split 1:4 by the thesis's
    /// rule where red–green bisects it, and one tall on its own long edge beyond it follows; a
    /// neighbour wide on the edge (height 0.8) is bisected by both rules.
    #[test]
    fn a_neighbour_tall_on_the_split_edge_is_split_whole_by_the_thesis_rule() {
        let tall = Vec3::new(0.5, 3.0, 0.0);
        let wide = Vec3::new(0.5, 0.8, 0.0);
        // (apex, third triangle, rule) -> leaves, how triangle 1 is split, thesis splits
        let cases = [
            (tall, false, NeighbourRule::RedGreen, 6, false, 0),
            (tall, false, NeighbourRule::Thesis, 8, true, 1),
            (tall, true, NeighbourRule::RedGreen, 7, false, 0),
            (tall, true, NeighbourRule::Thesis, 12, true, 2),
            (wide, false, NeighbourRule::RedGreen, 6, false, 0),
            (wide, false, NeighbourRule::Thesis, 6, false, 0),
        ];
        for (apex, third, rule, leaves, whole, splits) in cases {
            let scene = neighbours(apex, third);
            let mut mesh = refined(&scene, rule);
            let case = format!("{rule}, apex {apex}, third {third}");
            assert_eq!(mesh.leaf_count(), leaves, "{case}");
            let split = mesh.node(1).split();
            assert_eq!(
                matches!(split, Split::Red { .. }),
                whole,
                "{case}: {split:?}"
            );
            assert_eq!(
                mesh.neighbour_stats(),
                NeighbourStats {
                    thesis_splits: splits,
                    bound_hits: 0
                },
                "{case}"
            );
            coarsen_all(&mut mesh, &scene).unwrap();
            assert_eq!(mesh.leaf_count(), scene.triangles.len(), "{case}");
        }
    }

    /// The shapes the rules make on fig. 4.7's tall neighbour: red–green's bisection halves its
    /// apex angle, the thesis's 1:4 split keeps the neighbour's shape (the rule's purpose).
    #[test]
    fn split_shapes_show_the_sliver_red_green_makes_of_a_tall_neighbour() {
        let scene = neighbours(Vec3::new(0.5, 3.0, 0.0), false);
        let apex = 2.0 * (0.5f32 / 3.0).atan();
        let shapes = |rule| refined(&scene, rule).split_shapes();
        let red_green = shapes(NeighbourRule::RedGreen);
        assert!((red_green.smallest_angle().unwrap() - apex / 2.0).abs() < 1e-4);
        assert!((red_green.smallest_ratio_to_base().unwrap() - 0.5).abs() < 1e-3);
        let thesis = shapes(NeighbourRule::Thesis);
        assert!((thesis.smallest_angle().unwrap() - apex).abs() < 1e-4);
        assert!((thesis.smallest_ratio_to_base().unwrap() - 1.0).abs() < 1e-3);
    }

    /// Twelve fins tall on one non-manifold edge: one step splits `MAX_THESIS_SPLITS_PER_STEP`
    /// of them 1:4, bisects the rest and counts the bound as hit; the mesh stays conforming.
    #[test]
    fn the_thesis_rule_stops_at_its_bound_and_counts_it() {
        let fins = 12u32;
        let mut positions = vec![Vec3::ZERO, Vec3::X, Vec3::new(0.5, -0.5, 0.0)];
        let mut triangles = vec![[0, 2, 1]];
        for i in 0..fins {
            let angle = i as f32 * std::f32::consts::PI / fins as f32;
            positions.push(Vec3::new(0.5, 3.0 * angle.cos(), 3.0 * angle.sin()));
            triangles.push([0, 1, 3 + i]);
        }
        let scene = mesh_of(positions, &triangles);

        let red_green = refined(&scene, NeighbourRule::RedGreen);
        assert_eq!(red_green.leaf_count(), 4 + 2 * fins as usize);

        let mut thesis = refined(&scene, NeighbourRule::Thesis);
        let whole = MAX_THESIS_SPLITS_PER_STEP as usize;
        assert!(whole < fins as usize);
        assert_eq!(
            thesis.leaf_count(),
            4 + 4 * whole + 2 * (fins as usize - whole)
        );
        assert_eq!(
            thesis.neighbour_stats(),
            NeighbourStats {
                thesis_splits: whole as u64,
                bound_hits: 1
            }
        );
        coarsen_all(&mut thesis, &scene).unwrap();
        assert_eq!(thesis.leaf_count(), scene.triangles.len());
    }

    #[test]
    fn rules_are_found_by_their_names() {
        for rule in NeighbourRule::ALL {
            assert_eq!(NeighbourRule::from_name(rule.name()), Some(rule));
        }
        assert_eq!(NeighbourRule::default(), NeighbourRule::RedGreen);
        assert_eq!(NeighbourRule::from_name("loop"), None);
    }
}
