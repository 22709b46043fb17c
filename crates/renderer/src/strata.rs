//! The first bounce's directions stratified across the paths of one start (DESIGN.md §7; the
//! thesis sampled every path independently). Path `k` of a start takes point `k` of a
//! (0,2)-sequence (the first two Sobol dimensions), Owen-scrambled with the start's own seeds, for
//! the 2D sample of its first continuation ray. Every point is uniform on the unit square, so each
//! path stays an unbiased estimate; together the paths of a start cover the hemisphere evenly, so
//! their mean varies less than the mean of independent paths: the first bounce's direction is the
//! largest source of noise in a vertex's indirect light. Every later dimension (lobe choice, light
//! samples, later bounces) still comes from the start's random stream.
//!
//! The paths are then no longer independent: the sample variance of their luminance, which the
//! reply carries, over-states the variance of their mean. Criteria and the schedule that read it
//! (DESIGN.md §5, §6) therefore err toward more paths, never toward fewer.
//!
//! Scrambling follows Burley, "Practical Hash-based Owen Scrambling" (JCGT 2020): a hash whose
//! every output bit depends only on the same and lower bits of its input, applied to the reversed
//! bits, permutes each elementary interval's halves as Owen's nested scrambling does.

use rand::RngExt;

use crate::sampling::Rng;

/// How the first bounce of a start's paths is sampled: a field of the [`World`](crate::World), so
/// a benchmark can set today's renderer beside the one before stratification, in one run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FirstBounce {
    /// Every path draws its first direction from the start's random stream, independently.
    Independent,
    /// Path `k` takes point `k` of the start's [`Strata`].
    #[default]
    Stratified,
}

impl FirstBounce {
    /// The start's strata, drawn from its stream, or `None` where paths are independent (the
    /// stream is then left exactly as the unstratified estimator used it).
    pub(crate) fn strata(self, rng: &mut Rng) -> Option<Strata> {
        match self {
            FirstBounce::Independent => None,
            FirstBounce::Stratified => Some(Strata::new(rng)),
        }
    }
}

/// One start's scrambled (0,2)-sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Strata {
    seeds: [u32; 2],
}

impl Strata {
    /// Fresh scrambling seeds from the start's stream: two batches of the same point are two
    /// independent stratified sets, so their paths may be averaged (DESIGN.md §5).
    pub(crate) fn new(rng: &mut Rng) -> Strata {
        Strata {
            seeds: [rng.random(), rng.random()],
        }
    }

    /// Point `index` of the sequence, in [0, 1)².
    pub(crate) fn point(self, index: u32) -> [f32; 2] {
        [
            unit(owen_scramble(index.reverse_bits(), self.seeds[0])),
            unit(owen_scramble(sobol_second(index), self.seeds[1])),
        ]
    }
}

/// The second Sobol dimension (primitive polynomial x + 1): direction numbers v_{k+1} = v_k ^
/// (v_k >> 1) from v_0 = 1/2; with the first dimension (the bit-reversed index) every 2^m
/// consecutive points from a multiple of 2^m form a (0, m, 2)-net.
fn sobol_second(mut index: u32) -> u32 {
    let mut direction = 1u32 << 31;
    let mut x = 0;
    while index != 0 {
        if index & 1 == 1 {
            x ^= direction;
        }
        index >>= 1;
        direction ^= direction >> 1;
    }
    x
}

/// Nested uniform scrambling of a 32-bit fraction by `seed` (Burley 2020, after Laine and
/// Karras): multiplications by even constants and the addition make each bit of the reversed
/// value depend on it and the bits below only.
fn owen_scramble(x: u32, seed: u32) -> u32 {
    let mut v = x.reverse_bits().wrapping_add(seed);
    v ^= v.wrapping_mul(0x6c50_b47c);
    v ^= v.wrapping_mul(0xb82f_1e52);
    v ^= v.wrapping_mul(0xc7af_e638);
    v ^= v.wrapping_mul(0x8d22_f6e6);
    v.reverse_bits()
}

/// A 32-bit fraction as an f32 below 1 (its top 24 bits: f32's precision).
fn unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::stream;

    /// Every elementary interval of area 1/64 (8×8 cells, 64×1 strips, 1×64 strips, …) holds
    /// exactly one of the first 64 points, whatever the scrambling.
    #[test]
    fn the_first_64_points_form_a_net_for_any_seed() {
        let mut rng = stream(7, 0);
        for _ in 0..20 {
            let strata = Strata::new(&mut rng);
            let points: Vec<[f32; 2]> = (0..64).map(|k| strata.point(k)).collect();
            for bits_x in 0..=6 {
                let (cells_x, cells_y) = (1usize << bits_x, 1usize << (6 - bits_x));
                let mut count = vec![0; 64];
                for p in &points {
                    let cx = (p[0] * cells_x as f32) as usize;
                    let cy = (p[1] * cells_y as f32) as usize;
                    count[cy * cells_x + cx] += 1;
                }
                assert!(
                    count.iter().all(|&c| c == 1),
                    "{cells_x}×{cells_y} cells: {count:?}"
                );
            }
        }
    }

    /// Over many scramblings, one point is uniform: the mean and the second moment of each
    /// coordinate are those of U(0, 1).
    #[test]
    fn a_scrambled_point_is_uniform() {
        let mut rng = stream(11, 3);
        let k = 20_000;
        let mut moments = [[0.0f64; 2]; 2];
        for _ in 0..k {
            let p = Strata::new(&mut rng).point(5);
            for d in 0..2 {
                moments[d][0] += p[d] as f64;
                moments[d][1] += (p[d] as f64).powi(2);
            }
        }
        for m in moments {
            // Standard deviations of the estimates: sqrt(1/12 / k) and sqrt(4/45 / k).
            assert!((m[0] / k as f64 - 0.5).abs() < 4.0 * (1.0 / 12.0 / k as f64).sqrt());
            assert!((m[1] / k as f64 - 1.0 / 3.0).abs() < 4.0 * (4.0 / 45.0 / k as f64).sqrt());
        }
    }

    #[test]
    fn points_stay_below_one() {
        let strata = Strata {
            seeds: [u32::MAX, u32::MAX],
        };
        for k in 0..4096 {
            let p = strata.point(k);
            assert!(p.iter().all(|&c| (0.0..1.0).contains(&c)), "{p:?}");
        }
    }
}
