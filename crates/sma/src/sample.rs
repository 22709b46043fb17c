//! What one cached sample is (DESIGN.md §5, "a sample is an estimate with its uncertainty"): in
//! parts (direct and indirect illumination, view-dependent radiance: `protocol::SampleParts`),
//! per part the running mean RGB of its paths and the variance of their luminance; how many
//! paths (one count: the parts of a sample always come from the same paths), and the bounce
//! depth they were traced at. Everything that reads or merges samples goes through here.
//!
//! - [`display_radiance`]: where the illumination parts meet the mean albedo around the sample's
//!   vertex,
//!   turning a stored estimate into the radiance the SMA judges (the cache's readers get it so).
//!   A viewer is sent the illumination itself and multiplies each pixel's albedo in
//!   (`cache::leaf_shading`).
//! - [`Estimate::rgb`]: the displayed radiance, the sum of the parts of such an estimate; every
//!   reader of a sample's radiance (criteria, L_white, the stopping rule) goes through it.
//! - [`Estimate::accumulate`]: further paths at the same depth are added to the estimate, part by
//!   part (the pairwise update of Chan et al. for the variance); paths at another depth never mix
//!   with it.
//! - [`Estimate::display_standard_error`]: the uncertainty of the mean in the units the person
//!   sees (Drago tone map with L_white, then sRGB encoding, 0..1), which the noise-aware criteria
//!   and the schedule's stopping rule compare against.

use conventions::luminance;
use protocol::renderer_link::Quality;
use protocol::{PartEstimate, SampleParts};

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

/// One sample's estimate. Plain data: the cache file stores it as it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Per part, the mean radiance of the paths and the sample variance of their luminance.
    pub parts: SampleParts,
    /// Paths averaged (the same for every part).
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
        self.parts.is_valid() && self.paths > 0
    }

    /// The sum of the parts: of an estimate the cache reads back ([`display_radiance`]), the
    /// radiance the person sees.
    pub fn rgb(&self) -> [f32; 3] {
        self.parts.radiance([1.0; 3])
    }

    /// The luminance variance of [`Self::rgb`], taking the parts as uncorrelated. Within a path
    /// they are drawn from independent numbers but for the sky, where a first continuation ray
    /// that escapes gives direct light and one that hits gives indirect light: that covariance
    /// is negative, so the sum of the variances errs on the safe side.
    pub fn luminance_variance(&self) -> f32 {
        self.parts.each().iter().map(|p| p.luminance_variance).sum()
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
        (self.luminance_variance() / self.paths as f32).sqrt()
    }

    /// Luminance as the person sees it: Drago with `l_white`, sRGB-encoded, in 0..1.
    pub fn display_luminance(&self, l_white: f32) -> f32 {
        DisplayMap::new(l_white).display(luminance(self.rgb()))
    }

    /// [`Self::standard_error`] carried through the display mapping (its slope at the mean):
    /// the same radiance error counts for more in the dark, where the sRGB curve is steep.
    pub fn display_standard_error(&self, l_white: f32) -> f32 {
        self.displayed(&DisplayMap::new(l_white)).standard_error
    }

    /// The displayed luminance and standard error together, for one mapping: the noise-aware
    /// criteria read both for every vertex of every visible leaf, several times a second.
    pub fn displayed(&self, map: &DisplayMap) -> Displayed {
        let (luminance, slope) = map.display_and_slope(luminance(self.rgb()));
        Displayed {
            luminance,
            standard_error: slope * self.standard_error(),
        }
    }
}

/// A sample as the person sees it (DESIGN.md §6: the noise-aware criteria's units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Displayed {
    pub luminance: f32,
    pub standard_error: f32,
}

/// Drago (DESIGN.md §9) then sRGB encoding, for one L_white: 1 / ln(1 + L_white) is taken once.
#[derive(Clone, Copy, Debug)]
pub struct DisplayMap {
    /// 0 when L_white is not a positive finite number: nothing is displayed.
    inv_log_white: f32,
}

/// Below this linear value sRGB encoding is its linear toe, 12.92 x.
const SRGB_TOE: f32 = 0.003_130_8;

impl DisplayMap {
    pub fn new(l_white: f32) -> DisplayMap {
        let valid = l_white > 0.0 && l_white.is_finite();
        DisplayMap {
            inv_log_white: if valid { 1.0 / l_white.ln_1p() } else { 0.0 },
        }
    }

    /// Display value of luminance `l`, in 0..1.
    pub fn display(&self, l: f32) -> f32 {
        self.display_and_slope(l).0
    }

    /// Display value of `l` and its derivative d display / d L there, in closed form: Drago's
    /// slope 1 / ((1 + L) ln(1 + L_white)) times sRGB's, 1.055 / 2.4 · t^(1/2.4 − 1) (12.92 on
    /// the toe), 0 once clamped at white. One logarithm and one power per sample: these run for
    /// every vertex of every visible leaf at each refinement round and re-plan (a central
    /// difference took three of each and was a fifth of the SMA's thread on Sponza).
    pub fn display_and_slope(&self, l: f32) -> (f32, f32) {
        if self.inv_log_white == 0.0 {
            return (0.0, 0.0);
        }
        let l = l.max(0.0);
        let t = l.ln_1p() * self.inv_log_white;
        if t >= 1.0 {
            return (1.0, 0.0);
        }
        let drago_slope = self.inv_log_white / (1.0 + l);
        if t <= SRGB_TOE {
            return (12.92 * t, 12.92 * drago_slope);
        }
        let root = t.powf(1.0 / 2.4);
        (1.055 * root - 0.055, 1.055 / 2.4 * root / t * drago_slope)
    }
}

/// Drago (DESIGN.md §9) then sRGB encoding.
pub fn display(l: f32, l_white: f32) -> f32 {
    DisplayMap::new(l_white).display(l)
}

/// The estimate as the SMA judges it (DESIGN.md §5, "Parts, and textures"; §6): `albedo`, the
/// mean diffuse albedo over the leaves around the sample's vertex (`cache::albedo`: the mean of
/// the texels a viewer shows there, or `Kd`), multiplies the illumination parts,
/// and their luminance variances scale by the square of the luminance ratio it makes (exact for
/// a grey albedo); the view-dependent part stays as it is. The criteria, L_white and the
/// stopping rule read this, so they judge what the person sees: a dark texture does not draw
/// paths that no one could see.
pub fn display_radiance(e: &Estimate, albedo: [f32; 3]) -> Estimate {
    let shade = |p: &PartEstimate| {
        let rgb: [f32; 3] = std::array::from_fn(|i| albedo[i] * p.rgb[i]);
        let before = luminance(p.rgb);
        let scale = if before > 0.0 {
            luminance(rgb) / before
        } else {
            luminance(albedo)
        };
        PartEstimate {
            rgb,
            luminance_variance: p.luminance_variance * scale * scale,
        }
    };
    Estimate {
        parts: SampleParts {
            direct: shade(&e.parts.direct),
            indirect: shade(&e.parts.indirect),
            view_dependent: e.parts.view_dependent,
        },
        ..*e
    }
}

/// `b`'s paths added to `a`'s, part by part.
fn combine(a: &Estimate, b: &Estimate) -> Estimate {
    let (na, nb) = (f64::from(a.paths), f64::from(b.paths));
    let part = |pa: &PartEstimate, pb: &PartEstimate| combine_part(pa, na, pb, nb);
    Estimate {
        parts: SampleParts {
            direct: part(&a.parts.direct, &b.parts.direct),
            indirect: part(&a.parts.indirect, &b.parts.indirect),
            view_dependent: part(&a.parts.view_dependent, &b.parts.view_dependent),
        },
        paths: a.paths.saturating_add(b.paths),
        depth: a.depth,
    }
}

/// Chan, Golub and LeVeque's pairwise update of mean and variance: `b`'s `nb` paths added to
/// `a`'s `na`.
pub(crate) fn combine_part(a: &PartEstimate, na: f64, b: &PartEstimate, nb: f64) -> PartEstimate {
    let n = na + nb;
    let rgb =
        std::array::from_fn(|i| ((na * f64::from(a.rgb[i]) + nb * f64::from(b.rgb[i])) / n) as f32);
    let delta = f64::from(luminance(b.rgb)) - f64::from(luminance(a.rgb));
    let m2 = f64::from(a.luminance_variance) * (na - 1.0).max(0.0)
        + f64::from(b.luminance_variance) * (nb - 1.0).max(0.0)
        + delta * delta * na * nb / n;
    PartEstimate {
        rgb,
        luminance_variance: if n > 1.0 {
            (m2 / (n - 1.0)) as f32
        } else {
            0.0
        },
    }
}

/// The mean of `values` and their sample variance: what an estimate of those paths should
/// say, for tests here and of the filters that read estimates.
#[cfg(test)]
pub(crate) fn mean_and_variance(values: &[f32]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = values
        .iter()
        .map(|&v| (f64::from(v) - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, var)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn estimate(values: &[f32], depth: Option<u32>) -> Estimate {
        let (mean, var) = mean_and_variance(values);
        // A quarter of every path is direct light, half indirect, a quarter view-dependent: the
        // parts' variances are then a sixteenth, a quarter and a sixteenth of the paths'.
        let part = |share: f64| PartEstimate {
            rgb: [(share * mean) as f32; 3],
            luminance_variance: (share * share * var) as f32,
        };
        Estimate {
            parts: SampleParts {
                direct: part(0.25),
                indirect: part(0.5),
                view_dependent: part(0.25),
            },
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
        for (k, w) in kept.parts.each().iter().zip(whole.parts.each()) {
            assert!((k.rgb[0] - w.rgb[0]).abs() < 1e-5, "{k:?} vs {w:?}");
            assert!((k.luminance_variance - w.luminance_variance).abs() < 1e-4);
        }
        assert!(
            (kept.rgb()[0] - whole.rgb()[0]).abs() < 1e-5,
            "the sum of the parts"
        );
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
        let bad_parts = [
            PartEstimate {
                rgb: [f32::NAN, 0.0, 0.0],
                ..good.parts.direct
            },
            PartEstimate {
                rgb: [f32::INFINITY, 0.0, 0.0],
                ..good.parts.direct
            },
            PartEstimate {
                rgb: [-0.1, 0.0, 0.0],
                ..good.parts.direct
            },
            PartEstimate {
                luminance_variance: f32::NAN,
                ..good.parts.direct
            },
            PartEstimate {
                luminance_variance: -1.0,
                ..good.parts.direct
            },
        ];
        for part in bad_parts {
            // Any part bad makes the answer bad, though the others are good.
            for parts in [
                SampleParts {
                    direct: part,
                    ..good.parts
                },
                SampleParts {
                    indirect: part,
                    ..good.parts
                },
                SampleParts {
                    view_dependent: part,
                    ..good.parts
                },
            ] {
                let bad = Estimate { parts, ..good };
                assert!(!bad.is_valid(), "{bad:?}");
            }
        }
        assert!(!Estimate { paths: 0, ..good }.is_valid());
    }

    #[test]
    fn the_display_map_is_drago_then_srgb_and_its_slope_a_derivative() {
        use conventions::ToneMap;
        use conventions::tone_map::srgb_encode;
        for l_white in [0.5f32, 3.0, 40.0] {
            let map = DisplayMap::new(l_white);
            // From the sRGB toe, through the curve, to past white.
            for l in [
                0.0f32,
                1e-4,
                0.003,
                0.02,
                0.3,
                1.0,
                0.9 * l_white,
                2.0 * l_white,
            ] {
                let want = srgb_encode(ToneMap::Drago.display_luminance(l, l_white).min(1.0));
                let (shown, slope) = map.display_and_slope(l);
                assert!(
                    (shown - want).abs() < 2e-6,
                    "{l} at {l_white}: {shown} vs {want}"
                );
                // A central difference a thousandth of L wide, away from the toe's kink.
                let h = (l * 1e-3).max(1e-7);
                let t = l.ln_1p() / l_white.ln_1p();
                if (t - SRGB_TOE).abs() > 1e-3 && (t - 1.0).abs() > 1e-2 && l > 0.0 {
                    let diff = (map.display(l + h) - map.display(l - h)) / (2.0 * h);
                    assert!(
                        (slope - diff).abs() <= 2e-3 * diff.abs().max(1e-3),
                        "{l} at {l_white}: slope {slope} vs difference {diff}"
                    );
                }
            }
        }
        assert_eq!(DisplayMap::new(f32::NAN).display_and_slope(1.0), (0.0, 0.0));
        assert_eq!(
            DisplayMap::new(2.0).display_and_slope(5.0),
            (1.0, 0.0),
            "clamped at white"
        );
    }

    /// The albedo multiplies the illumination parts and their standard errors, never the
    /// view-dependent part; a black albedo leaves only the view-dependent part, with its own
    /// uncertainty, and nothing is divided.
    #[test]
    fn display_radiance_multiplies_the_illumination_by_the_albedo() {
        let e = estimate(&[1.0, 2.0, 3.0, 2.0], Some(2));
        let grey = display_radiance(&e, [0.5; 3]);
        let want: [f32; 3] = std::array::from_fn(|i| {
            0.5 * (e.parts.direct.rgb[i] + e.parts.indirect.rgb[i]) + e.parts.view_dependent.rgb[i]
        });
        for (got, want) in grey.rgb().iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        }
        let quarter = |p: &PartEstimate| p.luminance_variance * 0.25;
        assert!((grey.parts.direct.luminance_variance - quarter(&e.parts.direct)).abs() < 1e-6);
        assert!((grey.parts.indirect.luminance_variance - quarter(&e.parts.indirect)).abs() < 1e-6);
        assert_eq!(grey.parts.view_dependent, e.parts.view_dependent);
        assert_eq!((grey.paths, grey.depth), (e.paths, e.depth));
        let black = display_radiance(&e, [0.0; 3]);
        assert_eq!(black.rgb(), e.parts.view_dependent.rgb);
        assert_eq!(
            black.luminance_variance(),
            e.parts.view_dependent.luminance_variance
        );
        let white = display_radiance(&e, [1.0; 3]);
        assert_eq!(white, e, "an albedo of one changes nothing");
        // A coloured albedo: the mean per channel, the error by the luminance it keeps.
        let red = display_radiance(&e, [1.0, 0.0, 0.0]);
        assert_eq!(red.parts.direct.rgb[1], 0.0);
        assert!(red.parts.direct.luminance_variance < e.parts.direct.luminance_variance);
    }

    #[test]
    fn display_error_is_larger_in_the_dark() {
        let at = |l: f32| Estimate {
            parts: SampleParts::direct_only([l; 3], 0.01f32.powi(2) * 64.0),
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
