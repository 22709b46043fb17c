//! NLD_OS (thesis §4.3.4–§4.3.5): object space. A visible leaf is selected when S over its three
//! vertex samples (eq. 4.6) exceeds S_ref; S_ref starts at `s_ref_start` and drops by
//! `s_ref_step` each time a whole pass over the visible set selects nothing, down to S_min:
//! `s_min` for eq. 4.6 as the thesis has it, one display step (`display_error`) for the
//! noise-aware metric, which then refines until no leaf's vertices differ visibly beyond their
//! noise (`CriterionSettings::significance_floor`, DESIGN.md §5–§6); a leaf whose samples have
//! not settled on the quality ladder is held to `s_min` meanwhile (`criteria::leaf_floor`).
//! Large-triangle rule (§4.3.5, fig. 4.10): a leaf covering more than `large_triangle_fraction`
//! of the image is selected whatever its S, since a shadow may cross it without touching its
//! vertices. A leaf is offered once until `reset` (one the caller declined to split, being too
//! small, would be declined again), and the level does not drop while the visible set still lists split
//! leaves or leaves without all samples: their children or samples may be above S_ref.
//! With eq. 4.4 in place of eq. 4.6 (`Metric::MaxMin`, floor `s_min` as eq. 4.6's) it is NLD_MM
//! (`super::nld_mm`).

use super::{
    Criterion, CriterionInput, CriterionKind, CriterionSettings, Metric, Offered, is_large,
    leaf_nld_and_floor,
};
use crate::mesh::NodeId;

pub struct NldOs {
    settings: CriterionSettings,
    metric: Metric,
    s_ref: f32,
    cursor: usize,
    found_in_pass: bool,
    waiting_in_pass: bool,
    /// Leaves returned since `reset`.
    offered: Offered,
}

/// What the end of a pass over the visible set leads to.
#[derive(PartialEq)]
enum PassEnd {
    Again,
    Wait,
    Done,
}

impl NldOs {
    pub fn new(settings: &CriterionSettings, metric: Metric) -> Self {
        NldOs {
            settings: *settings,
            metric,
            s_ref: settings.s_ref_start,
            cursor: 0,
            found_in_pass: false,
            waiting_in_pass: false,
            offered: Offered::default(),
        }
    }

    /// The current S_ref.
    pub fn s_ref(&self) -> f32 {
        self.s_ref
    }

    /// S_min (§4.3.4) for this criterion's metric.
    fn s_min(&self) -> f32 {
        self.settings
            .significance_floor(self.metric, self.settings.s_min)
    }

    fn end_pass(&mut self) -> PassEnd {
        let s_min = self.s_min();
        let end = if self.found_in_pass {
            PassEnd::Again
        } else if self.waiting_in_pass {
            PassEnd::Wait
        } else if self.s_ref > s_min {
            self.s_ref = (self.s_ref - self.settings.s_ref_step).max(s_min);
            PassEnd::Again
        } else {
            // Not final: samples and leaves that arrive later (children of a refinement, a
            // better sample) are looked at by the next call.
            PassEnd::Done
        };
        self.cursor = 0;
        self.found_in_pass = false;
        self.waiting_in_pass = false;
        end
    }
}

impl Criterion for NldOs {
    fn kind(&self) -> CriterionKind {
        match self.metric {
            Metric::NoiseAware => CriterionKind::NldOs,
            Metric::Thesis => CriterionKind::NldOsThesis,
            Metric::MaxMin => CriterionKind::NldMm,
        }
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId> {
        let leaves = &input.visible.leaves;
        self.offered.follow(input.mesh);
        let mut out = Vec::new();
        // Two pass ends per call at most: one pass over everything, whatever the levels.
        let mut pass_ends = 0;
        while out.len() < max {
            let Some(v) = leaves.get(self.cursor) else {
                pass_ends += 1;
                if self.end_pass() != PassEnd::Again || pass_ends > 2 {
                    break;
                }
                continue;
            };
            self.cursor += 1;
            if !input.mesh.is_leaf(v.leaf) {
                self.waiting_in_pass = true;
                continue;
            }
            if v.pixels < self.settings.min_leaf_pixels || self.offered.contains(v.leaf) {
                continue;
            }
            let wanted = if is_large(
                v.pixels,
                input.visible,
                self.settings.large_triangle_fraction,
            ) {
                true
            } else if let Some((s, floor)) =
                leaf_nld_and_floor(input, &self.settings, v.leaf, v.side, self.metric)
            {
                // The floor is below S_ref for eq. 4.6; for the noise-aware metric it holds a
                // leaf of unsettled samples to S_min (`leaf_floor`).
                s > self.s_ref && s > floor
            } else {
                self.waiting_in_pass = true;
                false
            };
            if wanted {
                self.offered.insert(v.leaf);
                self.found_in_pass = true;
                out.push(v.leaf);
            }
        }
        out
    }

    fn reset(&mut self) {
        *self = NldOs::new(&self.settings, self.metric);
    }

    fn heap_bytes(&self) -> usize {
        self.offered.heap_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::criteria::synthetic::{Shading, Synthetic};

    #[test]
    fn a_flat_lit_region_is_left_alone() {
        let flat = Synthetic::new(6, 96, Shading::Flat);
        let mut os = NldOs::new(
            &CriterionSettings {
                large_triangle_fraction: 1.0,
                ..Default::default()
            },
            Metric::Thesis,
        );
        for _ in 0..10 {
            assert!(os.select(&flat.input(), 100).is_empty());
        }
        assert_eq!(os.s_ref(), CriterionSettings::default().s_min);
    }

    #[test]
    fn a_shadow_edge_across_a_strip_is_followed() {
        let mut edge = Synthetic::new(6, 96, Shading::ShadowEdge);
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        let mut os = NldOs::new(&settings, Metric::Thesis);
        for _ in 0..6 {
            let picked = os.select(&edge.input(), 16);
            assert!(
                picked.iter().all(|&l| edge.straddles_shadow(l)),
                "only leaves across the edge"
            );
            edge.refine_and_shade(&picked);
        }
        // Refinement concentrates along the edge: the finest leaves straddle it.
        assert!(
            edge.mesh.leaf_count() > 3 * 72,
            "refined: {}",
            edge.mesh.leaf_count()
        );
        let deepest = edge
            .mesh
            .leaves()
            .max_by_key(|&l| edge.mesh.depth(l))
            .unwrap();
        assert!(
            edge.distance_to_shadow(deepest) < 0.5,
            "deepest leaf {deepest} is near the shadow line"
        );
    }

    #[test]
    fn the_large_triangle_rule_fires_on_a_flat_big_leaf() {
        let blob = Synthetic::new(1, 64, Shading::Flat);
        let mut os = NldOs::new(&CriterionSettings::default(), Metric::Thesis);
        let picked = os.select(&blob.input(), 10);
        assert_eq!(
            picked.len(),
            2,
            "both halves of the one square cover half the image"
        );
        let mut none = NldOs::new(
            &CriterionSettings {
                large_triangle_fraction: 1.0,
                ..Default::default()
            },
            Metric::Thesis,
        );
        assert!(none.select(&blob.input(), 10).is_empty());
    }

    /// The noise-aware S_ref steps down to one display step, not to S_min (DESIGN.md §5–§6):
    /// a faint ripple whose vertices differ by a few display steps, all under S_min, is refined.
    #[test]
    fn the_noise_aware_s_ref_ends_at_one_display_step() {
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        let faint = Synthetic::new(24, 192, Shading::Faint);
        let leaves = faint.visible.leaves.len();
        let mut os = NldOs::new(&settings, Metric::NoiseAware);
        let picked: usize = (0..40).map(|_| os.select(&faint.input(), 1000).len()).sum();
        assert!(picked * 4 > leaves, "{picked} of {leaves} leaves refined");
        assert_eq!(os.s_ref(), settings.display_error);
    }

    /// Noise is not shading: a flat patch whose samples scatter by their own standard error is
    /// subdivided by eq. 4.6 as the thesis has it, and left alone by the noise-aware metric;
    /// a real shadow edge is found by both.
    #[test]
    fn a_flat_noisy_patch_is_refined_by_the_thesis_metric_only() {
        use crate::criteria::synthetic::{Shading, Synthetic};
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        let noisy = Synthetic::noisy(12, 192, Shading::Flat, 0.5, 11);
        let leaves = noisy.visible.leaves.len();
        let select_all = |metric| {
            let mut os = NldOs::new(&settings, metric);
            (0..40)
                .flat_map(|_| os.select(&noisy.input(), 1000))
                .count()
        };
        let thesis = select_all(Metric::Thesis);
        let aware = select_all(Metric::NoiseAware);
        assert!(
            thesis * 2 > leaves,
            "eq. 4.6 reads the noise as shading: {thesis} of {leaves}"
        );
        assert!(
            aware * 50 <= leaves,
            "noise-aware: {aware} of {leaves} selected"
        );

        let edge = Synthetic::noisy(12, 192, Shading::ShadowEdge, 0.5, 11);
        let picked = NldOs::new(&settings, Metric::NoiseAware).select(&edge.input(), 8);
        assert!(!picked.is_empty() && picked.iter().all(|&l| edge.straddles_shadow(l)));
    }
}
