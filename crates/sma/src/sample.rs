//! What one cached sample is (DESIGN.md §5, "a sample is an estimate with its uncertainty"): the
//! running mean RGB of its paths, the variance of their luminance, how many paths, and the bounce
//! depth they were traced at. Everything that reads or merges samples goes through here, so a
//! later extension of the sample (texture coordinates, a cache file on disk) changes one module.
//!
//! - [`Estimate::accumulate`]: further paths at the same depth are added to the estimate (the
//!   pairwise update of Chan et al. for the variance); paths at another depth never mix with it.
//! - [`Estimate::display_standard_error`]: the uncertainty of the mean in the units the person
//!   sees (Drago tone map with L_white, then sRGB encoding, 0..1), which the noise-aware criteria
//!   and the schedule's stopping rule compare against.

use conventions::tone_map::srgb_encode;
use conventions::{ToneMap, luminance};
use protocol::renderer_link::Quality;

/// A bounce depth as stored: `Some(b)` up to 254 bounces, `None` (unbounded, ended by Russian
/// roulette) as 255, the deepest.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Depth(u8);

impl Depth {
    pub fn of(bounces: Option<u32>) -> Depth {
        Depth(bounces.map_or(u8::MAX, |b| b.min(254) as u8))
    }

    pub fn bounces(self) -> Option<u32> {
        (self.0 != u8::MAX).then_some(u32::from(self.0))
    }
}

/// One sample's estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Mean radiance of the paths.
    pub rgb: [f32; 3],
    /// Sample variance of the paths' luminance.
    pub luminance_variance: f32,
    /// Paths averaged.
    pub paths: u32,
    pub depth: Depth,
}

/// What merging a new estimate into a kept one did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Merge {
    /// Same depth: the paths were added.
    Accumulated,
    /// A deeper estimate took the place of a shallower one (a direct-light-only sample is not
    /// averaged with a 2-bounce one).
    Replaced,
    /// Shallower than what is kept: dropped.
    Kept,
}

impl Estimate {
    /// Whether a renderer's answer may be cached: finite, non-negative radiance and variance, and
    /// at least one path. Anything else is rejected per point (DESIGN.md §8: bad input loses
    /// nothing else).
    pub fn is_valid(&self) -> bool {
        self.rgb.iter().all(|c| c.is_finite() && *c >= 0.0)
            && self.luminance_variance.is_finite()
            && self.luminance_variance >= 0.0
            && self.paths > 0
    }

    pub fn quality(&self) -> Quality {
        Quality {
            paths: self.paths,
            bounces: self.depth.bounces(),
        }
    }

    /// Merges `new` into `self` by the rules of the module documentation.
    pub fn accumulate(&mut self, new: &Estimate) -> Merge {
        match new.depth.cmp(&self.depth) {
            std::cmp::Ordering::Greater => {
                *self = *new;
                Merge::Replaced
            }
            std::cmp::Ordering::Less => Merge::Kept,
            std::cmp::Ordering::Equal => {
                *self = combine(self, new);
                Merge::Accumulated
            }
        }
    }

    /// The standard error of the mean luminance, in radiance units.
    pub fn standard_error(&self) -> f32 {
        if self.paths == 0 {
            return f32::INFINITY;
        }
        (self.luminance_variance / self.paths as f32).sqrt()
    }

    /// Luminance as the person sees it: Drago with `l_white`, sRGB-encoded, in 0..1.
    pub fn display_luminance(&self, l_white: f32) -> f32 {
        display(luminance(self.rgb), l_white)
    }

    /// [`Self::standard_error`] carried through the display mapping (its slope at the mean):
    /// the same radiance error counts for more in the dark, where the sRGB curve is steep.
    pub fn display_standard_error(&self, l_white: f32) -> f32 {
        display_slope(luminance(self.rgb), l_white) * self.standard_error()
    }
}

/// Drago (DESIGN.md §9) then sRGB encoding.
pub fn display(l: f32, l_white: f32) -> f32 {
    if !(l_white > 0.0 && l_white.is_finite()) {
        return 0.0;
    }
    srgb_encode(
        ToneMap::Drago
            .display_luminance(l.max(0.0), l_white)
            .clamp(0.0, 1.0),
    )
}

/// d display / d L at `l`, by a central difference an eighth of a stop wide: the tone map and
/// the sRGB curve have closed forms, but the clamp at white and the linear toe of sRGB make a
/// difference the simpler honest answer.
fn display_slope(l: f32, l_white: f32) -> f32 {
    let l = l.max(1e-6 * l_white.max(1e-6));
    let h = l * 0.045;
    ((display(l + h, l_white) - display(l - h, l_white)) / (2.0 * h)).max(0.0)
}

/// Chan, Golub and LeVeque's pairwise update of mean and variance: `b`'s paths added to `a`'s.
fn combine(a: &Estimate, b: &Estimate) -> Estimate {
    let (na, nb) = (f64::from(a.paths), f64::from(b.paths));
    let n = na + nb;
    let rgb =
        std::array::from_fn(|i| ((na * f64::from(a.rgb[i]) + nb * f64::from(b.rgb[i])) / n) as f32);
    let delta = f64::from(luminance(b.rgb)) - f64::from(luminance(a.rgb));
    let m2 = f64::from(a.luminance_variance) * (na - 1.0).max(0.0)
        + f64::from(b.luminance_variance) * (nb - 1.0).max(0.0)
        + delta * delta * na * nb / n;
    Estimate {
        rgb,
        luminance_variance: if n > 1.0 {
            (m2 / (n - 1.0)) as f32
        } else {
            0.0
        },
        paths: a.paths.saturating_add(b.paths),
        depth: a.depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn estimate(values: &[f32], depth: Option<u32>) -> Estimate {
        let n = values.len() as f64;
        let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|&v| (f64::from(v) - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        Estimate {
            rgb: [mean as f32; 3],
            luminance_variance: var as f32,
            paths: values.len() as u32,
            depth: Depth::of(depth),
        }
    }

    #[test]
    fn accumulating_batches_equals_one_big_batch_and_the_error_falls() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let values: Vec<f32> = (0..1024).map(|_| rng.random::<f32>() * 2.0).collect();
        let mut kept = estimate(&values[..64], Some(2));
        let mut errors = vec![kept.standard_error()];
        for chunk in values[64..].chunks(192) {
            assert_eq!(
                kept.accumulate(&estimate(chunk, Some(2))),
                Merge::Accumulated
            );
            errors.push(kept.standard_error());
        }
        let whole = estimate(&values, Some(2));
        assert_eq!(kept.paths, 1024);
        assert!((kept.rgb[0] - whole.rgb[0]).abs() < 1e-5);
        assert!((kept.luminance_variance - whole.luminance_variance).abs() < 1e-4);
        assert!(
            errors.windows(2).all(|w| w[1] < w[0]),
            "the standard error falls with every batch: {errors:?}"
        );
        assert!(
            errors.last().unwrap() * 3.0 < errors[0],
            "1024 paths: a quarter of 64's error"
        );
    }

    #[test]
    fn another_depth_replaces_or_is_dropped_never_averaged() {
        let direct = estimate(&[1.0, 1.2, 0.8, 1.0], Some(0));
        let mut kept = direct;
        let deeper = estimate(&[2.0, 2.5, 1.5], Some(2));
        assert_eq!(kept.accumulate(&deeper), Merge::Replaced);
        assert_eq!(kept, deeper);
        assert_eq!(kept.accumulate(&direct), Merge::Kept);
        assert_eq!(kept, deeper);
        let unbounded = estimate(&[3.0, 3.0], None);
        assert_eq!(kept.accumulate(&unbounded), Merge::Replaced);
        assert_eq!(kept.depth.bounces(), None);
    }

    #[test]
    fn bad_answers_are_not_valid() {
        let good = estimate(&[1.0, 2.0], Some(1));
        assert!(good.is_valid());
        for bad in [
            Estimate {
                rgb: [f32::NAN, 0.0, 0.0],
                ..good
            },
            Estimate {
                rgb: [f32::INFINITY, 0.0, 0.0],
                ..good
            },
            Estimate {
                rgb: [-0.1, 0.0, 0.0],
                ..good
            },
            Estimate {
                luminance_variance: f32::NAN,
                ..good
            },
            Estimate {
                luminance_variance: -1.0,
                ..good
            },
            Estimate { paths: 0, ..good },
        ] {
            assert!(!bad.is_valid(), "{bad:?}");
        }
    }

    #[test]
    fn display_error_is_larger_in_the_dark() {
        let at = |l: f32| Estimate {
            rgb: [l; 3],
            luminance_variance: 0.01f32.powi(2) * 64.0,
            paths: 64,
            depth: Depth::of(Some(2)),
        };
        // The same radiance error, 0.01.
        let (dark, bright) = (at(0.05), at(5.0));
        assert!(dark.display_standard_error(10.0) > bright.display_standard_error(10.0));
        assert!(bright.display_standard_error(10.0) > 0.0);
        assert_eq!(
            at(1.0).display_standard_error(0.0),
            0.0,
            "no L_white, nothing displayed"
        );
    }
}
