//! NLD_PX, a criterion the thesis did not build: every candidate leaf ranked by
//! (ε + (1 - ε) S) × pixels, the top R taken.
//!
//! Why: NLD_OS takes, in visible-set order, any leaf above the current S_ref, so a leaf of
//! S = 0.31 covering 2,000 pixels waits behind every leaf of S = 0.32 covering 6; and its
//! large-triangle rule (§4.3.5) takes every large leaf at once, however flat, before any
//! shading edge. The error a Gouraud leaf adds to the image is at most its vertex spread times
//! the pixels it covers, so the greedy way to lower the image error per sample is to refine the
//! largest S × pixels first. This is the Shading Cache's priority (thesis §3.1.4: colour
//! difference of the vertices, weighted by projected area through hit-and-test) made
//! deterministic: instead of drawing pixels and accepting with the priority, it takes the top R
//! priorities `(ε + (1 - ε) S) × pixels` (eq. 3.4's mix) each call. ε is the chance given to a
//! feature between the vertices (fig. 4.10): it ranks large flat leaves among themselves and
//! against shading edges, instead of the large-triangle rule's "always first". Which leaves are
//! candidates is NLD_OS's rule: S above its floor, or large (§4.3.5); a flat small leaf is never
//! taken, so the floor and `large_triangle_fraction` still end the refinement. No S_ref schedule:
//! the ranking is the schedule. S is the noise-aware metric, so once a leaf's samples have
//! settled its floor is one display step (`display_error`, `criteria::leaf_floor`): it stays a
//! candidate while its vertices differ by more than their noise explains plus one step, which
//! the picture can still show (DESIGN.md §5–§6); `s_min`, five steps, the floor before, left
//! such leaves Gouraud-interpolated in a view that had reached its stated end.
//!
//! Measured (synthetic runs of `bench::criteria_experiment`, defaults, mean absolute error over
//! the shadow line, the disc and the ripple): 0.0062 after 300 samples against NLD_OS's 0.0150,
//! 0.0044 after 600 against 0.0091, 0.0031 after 1,200 for both (the shadow line and the disc
//! have converged by then: no leaf of 6 pixels or more is left to split). NLD_OS with a larger
//! large-triangle fraction (0.005) closes part of the gap early (0.0087, 0.0044) but ends worse
//! (0.0034: the disc is found later); NLD_PX needs no such trade.

use super::{
    Criterion, CriterionInput, CriterionKind, CriterionSettings, Metric, Offered, is_large,
    leaf_nld_and_floor,
};
use crate::mesh::NodeId;

pub struct NldPx {
    settings: CriterionSettings,
    /// Leaves already returned; one still a leaf was declined by the caller.
    offered: Offered,
}

impl NldPx {
    pub fn new(settings: &CriterionSettings) -> Self {
        NldPx {
            settings: *settings,
            offered: Offered::default(),
        }
    }
}

impl Criterion for NldPx {
    fn kind(&self) -> CriterionKind {
        CriterionKind::NldPx
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId> {
        let s = &self.settings;
        self.offered.follow(input.mesh);
        let mut ranked: Vec<(f32, NodeId)> = input
            .visible
            .leaves
            .iter()
            .filter(|v| {
                v.pixels >= s.min_leaf_pixels
                    && input.mesh.is_leaf(v.leaf)
                    && !self.offered.contains(v.leaf)
            })
            .filter_map(|v| {
                let (nld, floor) =
                    leaf_nld_and_floor(input, s, v.leaf, v.side, Metric::NoiseAware)?;
                let weight = s.nld_px_epsilon + (1.0 - s.nld_px_epsilon) * nld;
                let large = is_large(v.pixels, input.visible, s.large_triangle_fraction);
                (nld > floor || large).then_some((weight * v.pixels as f32, v.leaf))
            })
            .collect();
        if ranked.len() > max && max > 0 {
            ranked.select_nth_unstable_by(max - 1, |a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
            ranked.truncate(max);
        }
        ranked.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let out: Vec<NodeId> = ranked.into_iter().take(max).map(|(_, leaf)| leaf).collect();
        for &leaf in &out {
            self.offered.insert(leaf);
        }
        out
    }

    fn reset(&mut self) {
        self.offered.reset();
    }

    fn heap_bytes(&self) -> usize {
        self.offered.heap_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::criteria::leaf_nld;
    use crate::criteria::synthetic::{Shading, Synthetic};

    #[test]
    fn ranks_by_spread_times_pixels_and_leaves_flat_regions_alone() {
        let flat = Synthetic::new(6, 96, Shading::Flat);
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        assert!(NldPx::new(&settings).select(&flat.input(), 10).is_empty());

        let edge = Synthetic::new(6, 96, Shading::ShadowEdge);
        let picked = NldPx::new(&settings).select(&edge.input(), 4);
        assert_eq!(picked.len(), 4);
        assert!(picked.iter().all(|&l| edge.straddles_shadow(l)));
    }

    #[test]
    fn a_shadow_edge_goes_before_large_flat_leaves_which_still_come() {
        let edge = Synthetic::new(8, 128, Shading::ShadowEdge);
        let settings = CriterionSettings::default();
        let everything = edge.visible.leaves.len();
        assert!(
            edge.visible.leaves.iter().all(|v| is_large(
                v.pixels,
                &edge.visible,
                settings.large_triangle_fraction
            )),
            "every base leaf is large"
        );
        let ranked = NldPx::new(&settings).select(&edge.input(), everything);
        assert_eq!(
            ranked.len(),
            everything,
            "the large-triangle rule takes all"
        );
        let straddling = ranked.iter().filter(|&&l| edge.straddles_shadow(l)).count();
        assert!(straddling > 0);
        assert!(
            ranked[..straddling]
                .iter()
                .all(|&l| edge.straddles_shadow(l)),
            "the leaves across the shadow line come first"
        );
    }

    /// The noise-aware floor is one display step (DESIGN.md §5–§6): a faint ripple whose
    /// vertices differ by more than a step but less than S_min, the Gouraud error a view stopped
    /// at S_min kept, is refined where it is steepest; a flat patch whose samples differ by their
    /// noise alone mostly is not.
    #[test]
    fn a_ripple_above_one_display_step_is_refined_and_noise_mostly_is_not() {
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        let faint = Synthetic::new(24, 192, Shading::Faint);
        let input = faint.input();
        let s_of = |leaf| {
            let v = faint
                .visible
                .leaves
                .iter()
                .find(|v| v.leaf == leaf)
                .unwrap();
            leaf_nld(&input, leaf, v.side, Metric::NoiseAware).unwrap()
        };
        let steepest = faint
            .visible
            .leaves
            .iter()
            .map(|v| s_of(v.leaf))
            .fold(0.0, f32::max);
        assert!(
            steepest > 2.0 * settings.display_error && steepest < settings.s_min,
            "the ripple's largest S {steepest} lies between one display step and S_min"
        );
        let picked = NldPx::new(&settings).select(&input, usize::MAX);
        let leaves = faint.visible.leaves.len();
        assert!(
            picked.len() * 4 > leaves,
            "{} of {leaves} leaves refined",
            picked.len()
        );
        assert!(picked.iter().all(|&l| s_of(l) > settings.display_error));

        let noisy = Synthetic::noisy(24, 192, Shading::Flat, 0.5, 11);
        let picked = NldPx::new(&settings).select(&noisy.input(), usize::MAX);
        assert!(
            picked.len() * 10 < leaves,
            "noise alone: {} of {leaves} leaves refined",
            picked.len()
        );
    }

    #[test]
    fn declined_leaves_are_not_offered_again() {
        let edge = Synthetic::new(6, 96, Shading::ShadowEdge);
        let mut px = NldPx::new(&CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        });
        let first = px.select(&edge.input(), 4);
        let second = px.select(&edge.input(), 4);
        assert!(first.iter().all(|l| !second.contains(l)));
        px.reset();
        assert_eq!(px.select(&edge.input(), 4), first);
    }

    /// A recycle renames the mesh's nodes (`SubdivisionMesh::recycle_removed`): the leaves
    /// offered before it are judged again after it, every candidate once more, none skipped
    /// because its new id is one offered before (`criteria::Offered`).
    #[test]
    fn a_recycle_of_the_mesh_s_nodes_has_every_candidate_judged_again() {
        let mut edge = Synthetic::new(6, 96, Shading::ShadowEdge);
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        // Greens made, then removed by the red split of their parent: retired nodes.
        let first = NldPx::new(&settings).select(&edge.input(), 1);
        edge.refine_and_shade(&first);
        let green = edge
            .mesh
            .leaves()
            .find(|&l| edge.mesh.node(l).kind() == crate::mesh::NodeKind::Green)
            .expect("the split greened a neighbour");
        edge.refine_and_shade(&[green]);
        // Every candidate offered and declined (not split).
        let mut px = NldPx::new(&settings);
        let candidates = px.select(&edge.input(), usize::MAX);
        assert!(candidates.len() > 4);
        assert!(px.select(&edge.input(), usize::MAX).is_empty());
        assert!(edge.mesh.recycle_removed(), "removed nodes to recycle");
        edge.refine_and_shade(&[]);
        let again = px.select(&edge.input(), usize::MAX);
        assert_eq!(
            again.len(),
            candidates.len(),
            "every candidate judged again"
        );
    }
}
