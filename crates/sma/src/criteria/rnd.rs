//! RND (thesis §4.3.1): random pixels of the ID buffer, the leaf seen there is refined; a pass
//! ends after `rnd_fraction` × width × height picks. A uniform pixel is drawn from the visible
//! set's pixel counts (a pixel beyond their sum is background and still counts as a pick), which
//! is the same distribution as reading a random pixel of the ID buffer, without the image.

use std::collections::HashSet;

use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64Mcg;

use super::{Criterion, CriterionInput, CriterionSettings};
use crate::mesh::NodeId;
use crate::mesh::fast_hash::FastHash;

pub struct Rnd {
    seed: u64,
    rng: Pcg64Mcg,
    fraction: f32,
    picks: u64,
}

impl Rnd {
    pub fn new(settings: &CriterionSettings, seed: u64) -> Self {
        Rnd {
            seed,
            rng: Pcg64Mcg::seed_from_u64(seed),
            fraction: settings.rnd_fraction,
            picks: 0,
        }
    }
}

impl Criterion for Rnd {
    fn name(&self) -> &'static str {
        "rnd"
    }

    fn needs_image(&self) -> bool {
        false
    }

    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId> {
        let visible = input.visible;
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
        let mut chosen = HashSet::<NodeId, FastHash>::default();
        let mut out = Vec::new();
        while out.len() < max && self.picks < budget && image > 0 {
            self.picks += 1;
            let pixel = self.rng.random_range(0..image);
            let i = cumulative.partition_point(|&c| c <= pixel);
            if let Some(v) = visible.leaves.get(i)
                && input.mesh.is_leaf(v.leaf)
                && chosen.insert(v.leaf)
            {
                out.push(v.leaf);
            }
        }
        out
    }

    fn reset(&mut self) {
        self.rng = Pcg64Mcg::seed_from_u64(self.seed);
        self.picks = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::synthetic::{Shading, Synthetic};

    #[test]
    fn picks_follow_pixels_stop_after_the_fraction_and_repeat_after_reset() {
        let scene = Synthetic::new(4, 64, Shading::Flat);
        let settings = CriterionSettings {
            rnd_fraction: 0.01,
            ..Default::default()
        };
        let mut rnd = Rnd::new(&settings, 3);
        let first = rnd.select(&scene.input(), 1000);
        assert!(
            !first.is_empty() && first.len() <= 41,
            "{} picks of at most 40 + 1",
            first.len()
        );
        assert!(
            rnd.select(&scene.input(), 1000).is_empty(),
            "the pass is over"
        );
        rnd.reset();
        assert_eq!(rnd.select(&scene.input(), 1000), first);
    }
}
