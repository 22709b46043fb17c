//! The compact encodings of a stored sample's parts (DESIGN.md §5): a part's mean RGB as three
//! 9-bit mantissas with a shared 5-bit exponent (the RGB9E5 layout of
//! `EXT_texture_shared_exponent`), its luminance variance in 10 bits (an `f32` cut to a 6-bit
//! exponent and 4 mantissa bits).
//!
//! Why the error is harmless: every channel of a mean comes back within 1/511 (about 2^-9) of
//! the part's largest channel (within 2^-18 where that channel is below 2^-9), a variance within
//! 2^-5 of itself. A displayed value is tone-mapped against
//! L_white, at least the brightest luminance, and shown in 1/255 steps, so 2^-9 of the brightest
//! channel is below one display step wherever the tone map's slope is at most 2 (it is below 1
//! for the global Reinhard operator of DESIGN.md §6). A stored mean is re-encoded after each merge
//! of a batch of paths: the rounding errors of k merges add up to about sqrt(k) × 2^-9 / 3 of the
//! largest channel, which stays below the Monte Carlo error of the batches for the few dozen
//! merges a vertex sees. A variance is only an uncertainty: 2^-5 of it is 2^-6 of a standard
//! error, below the variance's own sampling error up to several thousand paths (sqrt(2/n)).

/// Mantissa bits per channel of [`SharedExponentRgb`].
const MANTISSA_BITS: i32 = 9;
/// Exponent bias of [`SharedExponentRgb`]: the smallest step is 2^-(BIAS + MANTISSA_BITS).
/// 8 rather than RGB9E5's 15: a vertex that mirrors the sun (radiance 5·10^4 in the scenes)
/// must fit; what is lost below is under 2^-17 in absolute terms, far below a display step.
const EXPONENT_BIAS: i32 = 8;
const MAX_EXPONENT: i32 = 31;
/// The largest encodable channel, (511/512) × 2^23; brighter channels are clamped to it, over a
/// hundred times the sun's radiance in the scenes.
pub(super) const MAX_CHANNEL: f32 = 8_372_224.0;

/// A non-negative RGB in 32 bits: three 9-bit mantissas sharing one 5-bit exponent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct SharedExponentRgb(u32);

impl SharedExponentRgb {
    /// Rounds to nearest; negative or NaN channels (refused before they reach the cache) become
    /// 0, channels above [`MAX_CHANNEL`] clamp to it.
    pub(super) fn encode(rgb: [f32; 3]) -> Self {
        let c = rgb.map(|v| if v > 0.0 { v.min(MAX_CHANNEL) } else { 0.0 });
        let largest = c[0].max(c[1]).max(c[2]);
        if largest == 0.0 {
            return SharedExponentRgb(0);
        }
        // floor(log2(largest)) exactly, from the bits (subnormals are below the range anyway).
        let floor_log2 = ((largest.to_bits() >> 23) & 0xff) as i32 - 127;
        let mut exponent = floor_log2.max(-EXPONENT_BIAS - 1) + 1 + EXPONENT_BIAS;
        if (largest / step(exponent)).round() >= (1 << MANTISSA_BITS) as f32 {
            exponent += 1;
        }
        let exponent = exponent.min(MAX_EXPONENT);
        let s = step(exponent);
        let mantissa = |v: f32| ((v / s).round() as u32).min((1 << MANTISSA_BITS) - 1);
        SharedExponentRgb(
            mantissa(c[0])
                | mantissa(c[1]) << MANTISSA_BITS
                | mantissa(c[2]) << (2 * MANTISSA_BITS)
                | (exponent as u32) << (3 * MANTISSA_BITS),
        )
    }

    pub(super) fn decode(self) -> [f32; 3] {
        let s = step((self.0 >> (3 * MANTISSA_BITS)) as i32);
        let mask = (1 << MANTISSA_BITS) - 1;
        [0, 1, 2].map(|i| ((self.0 >> (i * MANTISSA_BITS as u32)) & mask) as f32 * s)
    }
}

/// The value of one mantissa unit at a stored exponent.
fn step(exponent: i32) -> f32 {
    2f32.powi(exponent - EXPONENT_BIAS - MANTISSA_BITS)
}

/// Four non-negative `f32`s (a sample's luminance variances) in 10 bits each: a 6-bit exponent
/// covering 2^-26 to 2^38 and the top 4 bits of the mantissa, rounded to nearest. Below the range
/// a variance reads back as 0 (a standard error under 10^-4, far below a display step); above it,
/// it clamps to about 2.6·10^11 (a vertex that mirrors the sun has a few 10^9).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct ShortVariances(u64);

/// Variances per [`ShortVariances`].
pub(super) const VARIANCES: usize = 4;

/// Mantissa bits an `f32` loses in a [`ShortVariances`] code.
const DROPPED_BITS: u32 = 23 - 4;
/// The biased `f32` exponent of code 1 (code 0 is zero).
const SMALLEST_EXPONENT: u32 = 127 - 26;
const CODE_BITS: u32 = 10;
const LARGEST_CODE: u32 = (1 << CODE_BITS) - 1;

impl ShortVariances {
    pub(super) fn encode(variances: [f32; VARIANCES]) -> Self {
        let code = |v: f32| {
            if v.is_nan() || v <= 0.0 {
                return 0;
            }
            let rounded = (v.min(f32::MAX).to_bits() + (1 << (DROPPED_BITS - 1))) >> DROPPED_BITS;
            // The biased exponent and 4 mantissa bits, counted from the range's start; code 0
            // is zero.
            (rounded + 1)
                .saturating_sub(SMALLEST_EXPONENT << 4)
                .min(LARGEST_CODE)
        };
        ShortVariances(variances.iter().enumerate().fold(0, |word, (i, &v)| {
            word | u64::from(code(v)) << (i as u32 * CODE_BITS)
        }))
    }

    pub(super) fn decode(self) -> [f32; VARIANCES] {
        std::array::from_fn(|i| {
            let code = (self.0 >> (i as u32 * CODE_BITS)) as u32 & LARGEST_CODE;
            if code == 0 {
                0.0
            } else {
                f32::from_bits((code - 1 + (SMALLEST_EXPONENT << 4)) << DROPPED_BITS)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// Half a mantissa step of 9 bits, relative to the smallest mantissa that keeps the exponent.
    const MEAN_BOUND: f32 = 1.0 / 511.0;

    /// Every channel within 1/511 of the largest channel (2^-18, half the smallest step, where
    /// that is more), over twelve decades and mixed hues.
    #[test]
    fn a_mean_comes_back_within_1_511th_of_its_largest_channel() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        for _ in 0..100_000 {
            let scale = 10f32.powf(rng.random_range(-6.0..6.5));
            let rgb = [0; 3].map(|_| scale * rng.random_range(0.0..1.0f32));
            let back = SharedExponentRgb::encode(rgb).decode();
            let largest = rgb[0].max(rgb[1]).max(rgb[2]);
            let bound = (MEAN_BOUND * largest).max(2f32.powi(-18));
            for (a, b) in rgb.iter().zip(back) {
                assert!((a - b).abs() <= bound, "{rgb:?} came back as {back:?}");
            }
        }
        assert_eq!(SharedExponentRgb::encode([0.0; 3]).decode(), [0.0; 3]);
        assert_eq!(
            SharedExponentRgb::encode([1.0, 0.5, 0.25]).decode(),
            [1.0, 0.5, 0.25]
        );
    }

    /// Out of range: clamped, never wrapped or infinite.
    #[test]
    fn a_mean_out_of_range_is_clamped() {
        let back = SharedExponentRgb::encode([1e12, f32::INFINITY, -1.0]).decode();
        assert_eq!(back, [MAX_CHANNEL, MAX_CHANNEL, 0.0]);
        let tiny = SharedExponentRgb::encode([1e-12, 0.0, 0.0]).decode();
        assert!(tiny[0] < 1e-7);
    }

    /// Relative error within 2^-5 over the range, 0 below it, clamped above it.
    #[test]
    fn a_variance_comes_back_within_2_pow_minus_5_of_itself() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(8);
        for _ in 0..100_000 {
            let v = [0; VARIANCES].map(|_| 10f32.powf(rng.random_range(-7.5..11.0)));
            let back = ShortVariances::encode(v).decode();
            for (a, b) in v.iter().zip(back) {
                assert!((a - b).abs() <= a / 32.0, "{v:?} came back as {back:?}");
            }
        }
        let edges = ShortVariances::encode([0.0, 1e-9, -1.0, f32::NAN]).decode();
        assert_eq!(edges, [0.0; VARIANCES]);
        let huge = ShortVariances::encode([f32::MAX, f32::INFINITY, 1e12, 1e15]).decode();
        assert!(huge.iter().all(|v| v.is_finite() && *v > 2e11), "{huge:?}");
        assert_eq!(
            ShortVariances::encode([0.25, 1.0, 4.0, 16.0]).decode(),
            [0.25, 1.0, 4.0, 16.0]
        );
    }
}
