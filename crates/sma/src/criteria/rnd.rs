//! RND (thesis §4.3.1): random pixels of the ID buffer, the leaf seen there is refined; a pass
//! ends after `rnd_fraction` × width × height picks. A uniform pixel is drawn from the visible
//! set's pixel counts (a pixel beyond their sum is background and still counts as a pick), which
//! is the same distribution as reading a random pixel of the ID buffer, without the image.
//!
//! A leaf is offered once per camera, and only if it covers `min_leaf_pixels`; a pass that
//! offered something is followed by another (at most one new pass per call, so it sees the mesh
//! refined meanwhile), one that offered nothing ends the criterion's work for the camera. With
//! `Passes::One` (the thesis profile) the first pass ends it, as §4.3.1 does.

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::{Criterion, CriterionInput, CriterionKind, CriterionSettings, Offered, Passes};
use crate::mesh::NodeId;

pub struct Rnd {
    seed: u64,
    rng: Pcg64Mcg,
    fraction: f32,
    min_leaf_pixels: u32,
    passes: Passes,
    /// Picks of the pass under way.
    picks: u64,
    /// The pass under way offered a leaf.
    found: bool,
    offered: Offered,
}

impl Rnd {
    pub fn new(settings: &CriterionSettings, seed: u64) -> Self {
        Rnd {
            seed,
            rng: Pcg64Mcg::seed_from_u64(seed),
            fraction: settings.rnd_fraction,
            min_leaf_pixels: settings.min_leaf_pixels,
            passes: settings.passes,
            picks: 0,
            found: false,
            offered: Offered::default(),
        }
    }
}

impl Criterion for Rnd {
    fn kind(&self) -> CriterionKind {
        CriterionKind::Rnd
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId> {
        let visible = input.visible;
        self.offered.follow(input.mesh);
        let cumulative: Vec<u64> = visible
            .leaves
            .iter()
            .scan(0u64, |sum, v| {
                *sum += u64::from(v.pixels);
                Some(*sum)
            })
            .collect();
        let image = visible
            .image_pixels()
            .max(cumulative.last().copied().unwrap_or(0));
        let budget = (f64::from(self.fraction) * visible.image_pixels() as f64) as u64;
        let mut may_start = true;
        let mut out = Vec::new();
        while out.len() < max && image > 0 {
            if self.picks >= budget {
                let again = self.found && self.passes == Passes::UntilDry;
                if !(may_start && again) {
                    break;
                }
                (self.picks, self.found, may_start) = (0, false, false);
            }
            self.picks += 1;
            let pixel = self.rng.random_range(0..image);
            let i = cumulative.partition_point(|&c| c <= pixel);
            if let Some(v) = visible.leaves.get(i)
                && v.pixels >= self.min_leaf_pixels
                && input.mesh.is_leaf(v.leaf)
                && self.offered.insert(v.leaf)
            {
                self.found = true;
                out.push(v.leaf);
            }
        }
        out
    }

    fn reset(&mut self) {
        self.rng = Pcg64Mcg::seed_from_u64(self.seed);
        self.picks = 0;
        self.found = false;
        self.offered.reset();
    }

    fn heap_bytes(&self) -> usize {
        self.offered.heap_bytes()
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashSet;

    use super::*;
    use crate::criteria::synthetic::{Shading, Synthetic};

    #[test]
    fn passes_go_on_while_they_offer_new_leaves_and_repeat_after_reset() {
        let mut scene = Synthetic::new(4, 64, Shading::Flat);
        let settings = CriterionSettings {
            rnd_fraction: 0.01,
            ..Default::default()
        };
        let mut rnd = Rnd::new(&settings, 3);
        let first = rnd.select(&scene.input(), 1000);
        assert!(
            !first.is_empty() && first.len() <= 40,
            "{} leaves from one pass of 40 picks",
            first.len()
        );
        // Further passes on the same mesh offer each leaf at most once, then run dry.
        let mut offered = first.clone();
        loop {
            let more = rnd.select(&scene.input(), 1000);
            if more.is_empty() {
                break;
            }
            offered.extend(more);
        }
        let distinct: HashSet<NodeId> = offered.iter().copied().collect();
        assert_eq!(distinct.len(), offered.len(), "a leaf offered twice");
        assert!(offered.len() <= scene.mesh.leaf_count());
        assert!(rnd.select(&scene.input(), 1000).is_empty());
        rnd.reset();
        assert_eq!(rnd.select(&scene.input(), 1000), first);
        // The refined mesh has new leaves to offer.
        scene.refine_and_shade(&first);
        assert!(!rnd.select(&scene.input(), 1000).is_empty());
    }

    /// §4.3.1: one pass of picks per camera, however much it found.
    #[test]
    fn one_pass_ends_the_work_for_the_camera() {
        let mut scene = Synthetic::new(4, 64, Shading::Flat);
        let settings = CriterionSettings {
            rnd_fraction: 0.01,
            passes: Passes::One,
            ..Default::default()
        };
        let mut rnd = Rnd::new(&settings, 3);
        let first = rnd.select(&scene.input(), 1000);
        assert!(!first.is_empty());
        scene.refine_and_shade(&first);
        assert!(
            rnd.select(&scene.input(), 1000).is_empty(),
            "no second pass"
        );
        rnd.reset();
        assert!(!rnd.select(&scene.input(), 1000).is_empty(), "a new camera");
    }
}
