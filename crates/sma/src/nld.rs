//! The NLD metric (thesis eq. 4.3, appendix A), with luminance from RGB by Rec. 709 weights
//! (DESIGN.md §6, `conventions::luminance`).

/// `S` of eq. 4.3 for any N: sqrt(sum_{i<j} (L_i - L_j)^2 / ((N*N div 4) L_white^2)). The pair
/// sum is computed as N * sum (L_i - mean)^2, the same quantity, in O(N) and never negative.
/// Clamped to [0, 1] (a vertex may be brighter than L_white); 0 when N < 2, when L_white is not
/// positive and finite, or when a luminance is NaN.
pub fn nld_metric(lum: &[f32], l_white: f32) -> f32 {
    let n = lum.len();
    if n < 2 || !(l_white > 0.0 && l_white.is_finite()) {
        return 0.0;
    }
    let mean = lum.iter().map(|&l| f64::from(l)).sum::<f64>() / n as f64;
    let spread: f64 = lum.iter().map(|&l| (f64::from(l) - mean).powi(2)).sum();
    let pairs = n as f64 * spread;
    let norm = ((n * n) / 4) as f64 * f64::from(l_white).powi(2);
    clamp_unit((pairs / norm).sqrt() as f32)
}

/// Eq. 4.6 (N = 3) without allocation, for the per-leaf loop of NLD_OS.
pub fn nld3(l: [f32; 3], l_white: f32) -> f32 {
    if !(l_white > 0.0 && l_white.is_finite()) {
        return 0.0;
    }
    let pairs = (l[0] - l[1]).powi(2) + (l[1] - l[2]).powi(2) + (l[2] - l[0]).powi(2);
    clamp_unit((pairs / (2.0 * l_white * l_white)).sqrt())
}

/// How many combined standard errors a difference between two samples must exceed before the
/// noise-aware metric counts it as shading variation: two, so that about 95 % of the differences
/// pure noise makes are discounted entirely.
pub const NOISE_Z: f32 = 2.0;

/// The noise-aware S (DESIGN.md §6, beyond the thesis): eq. 4.3 over values in displayed units
/// (tone-mapped and sRGB-encoded, 0..1, so L_max is 1), each with its standard error in those
/// units, where a pair's difference counts only by what exceeds [`NOISE_Z`] of their combined
/// standard error. Equal to eq. 4.3 on displayed values when the errors are 0.
pub fn noise_aware_nld(values: &[(f32, f32)]) -> f32 {
    let n = values.len();
    if n < 2 {
        return 0.0;
    }
    let mut pairs = 0.0f64;
    for (i, &(a, ea)) in values.iter().enumerate() {
        for &(b, eb) in &values[i + 1..] {
            let explained = NOISE_Z * (ea * ea + eb * eb).sqrt();
            let excess = ((a - b).abs() - explained).max(0.0);
            pairs += f64::from(excess).powi(2);
        }
    }
    let norm = ((n * n) / 4) as f64;
    clamp_unit((pairs / norm).sqrt() as f32)
}

/// [0, 1], NaN to 0.
fn clamp_unit(s: f32) -> f32 {
    if s >= 0.0 { s.min(1.0) } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn extreme_split_gives_one_and_equal_values_zero() {
        assert_eq!(nld_metric(&[0.0, 0.0, 2.0, 2.0], 2.0), 1.0);
        assert!(
            (nld_metric(&[0.0, 2.0, 2.0], 2.0) - 1.0).abs() < 1e-6,
            "N=3: N*N div 4 = 2"
        );
        assert_eq!(nld_metric(&[1.0; 5], 3.0), 0.0);
        assert_eq!(nld_metric(&[0.0, 1.0], 0.0), 0.0);
        assert_eq!(nld_metric(&[f32::NAN, 1.0], 1.0), 0.0);
    }

    #[test]
    fn eq_4_3_by_pairs_matches_the_variance_form() {
        let l = [0.1f32, 0.7, 0.3, 0.9, 0.2];
        let pairs: f32 = (0..5)
            .flat_map(|i| (i + 1..5).map(move |j| (i, j)))
            .map(|(i, j)| (l[i] - l[j]).powi(2))
            .sum();
        let expected = (pairs / (6.0 * 1.0f32)).sqrt();
        assert!((nld_metric(&l, 1.0) - expected).abs() < 1e-6);
    }

    #[test]
    fn noise_explains_small_differences_but_not_large_ones() {
        assert_eq!(
            noise_aware_nld(&[(0.4, 0.05), (0.5, 0.05)]),
            0.0,
            "0.1 < 2 × 0.07"
        );
        let s = noise_aware_nld(&[(0.2, 0.01), (0.8, 0.01)]);
        assert!(
            (s - (0.6 - 2.0 * 0.02f32.sqrt() * 0.1)).abs() < 1e-3,
            "S = {s}"
        );
        let exact = noise_aware_nld(&[(0.1, 0.0), (0.7, 0.0), (0.3, 0.0)]);
        assert!((exact - nld3([0.1, 0.7, 0.3], 1.0)).abs() < 1e-6);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]
        #[test]
        fn s_is_in_unit_range_and_finite(
            lum in prop::collection::vec(prop_oneof![0.0f32..10.0, Just(f32::INFINITY), Just(1e30f32)], 0..9),
            l_white in prop_oneof![0.0f32..5.0, Just(0.0f32), Just(f32::INFINITY)],
        ) {
            let s = nld_metric(&lum, l_white);
            prop_assert!(s.is_finite() && (0.0..=1.0).contains(&s), "S = {s}");
            if lum.len() == 3 {
                let s = nld3([lum[0], lum[1], lum[2]], l_white);
                prop_assert!(s.is_finite() && (0.0..=1.0).contains(&s));
                if lum.iter().all(|l| l.is_finite() && *l < 1e3) {
                    prop_assert!((s - nld_metric(&lum, l_white)).abs() < 1e-4);
                }
            }
        }
    }
}
