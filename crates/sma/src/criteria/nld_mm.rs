//! NLD_MM (thesis §4.3.2, eq. 4.4): the Shading Cache's priority metric (Tole et al. 2002), the
//! difference between the largest and the smallest luminance of a triangle's vertices, which
//! the thesis defines as the NLD metric (eq. 4.3) "applied to two values, the maximum and the
//! minimum of the N samples, which amounts to putting N = 2 in eq. 4.3":
//!
//! ```text
//!     S = sqrt( [max L(x_i) - min L(x_i)]^2 / L_max^2 )  =  (max - min) / L_max      (eq. 4.4)
//! ```
//!
//! How it relates to eq. 4.3 (both tested below):
//! - **N = 2** they are one S: N*N div 4 = 1 and the one pair is (max, min), so eq. 4.3 over two
//!   samples is |L_1 - L_2| / L_max, eq. 4.4 over them.
//! - **N = 3** (a leaf's vertices, eq. 4.6 against eq. 4.4, fig. 4.9): with d = max - min and the
//!   middle sample cutting d into a + b, eq. 4.6's pair sum is d² + a² + b², between 3d²/2 (middle
//!   halfway) and 2d² (middle at an end), over 2 L_max²; so √3/2 × eq. 4.4 <= eq. 4.6 <= eq. 4.4.
//!   Eq. 4.6 is never above eq. 4.4 and never below √3/2 (0.87) of it, so the two curves are close for
//!   few samples, as the thesis finds; a lone outlier scores the full d in both.
//!
//! The criterion is NLD_OS's (§4.3.4–§4.3.5: S_ref stepping from `s_ref_start` down to `s_min`,
//! the large-triangle rule) with eq. 4.4 in place of eq. 4.6, in object space over a leaf's three
//! vertex samples (N = 3) on radiance luminance, as the thesis's `*-thesis` criteria: `NldOs`
//! with `Metric::MaxMin`, named `nld-mm` (`CriterionKind::NldMm`). The thesis kept it as the
//! yardstick against which eq. 4.3 was judged; here it is measured beside them.

/// S of eq. 4.4 over `lum`, clamped to [0, 1] (a sample may be brighter than L_max) like
/// [`crate::nld::nld_metric`]; 0 when N < 2, when L_white is not positive and finite, or when a
/// luminance is NaN.
pub fn nld_mm(lum: &[f32], l_white: f32) -> f32 {
    if lum.len() < 2 || !(l_white > 0.0 && l_white.is_finite()) || lum.iter().any(|l| l.is_nan()) {
        return 0.0;
    }
    let (lo, hi) = lum
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &l| {
            (lo.min(l), hi.max(l))
        });
    let s = (hi - lo) / l_white;
    // NaN (two infinities) counts as no difference, as in `nld_metric`.
    if s >= 0.0 { s.min(1.0) } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::criteria::synthetic::{Shading, Synthetic};
    use crate::criteria::{CriterionKind, CriterionSettings, make_criterion};
    use crate::nld::{nld_metric, nld3};
    use proptest::prelude::*;

    #[test]
    fn eq_4_4_is_the_range_over_l_max() {
        assert_eq!(nld_mm(&[0.2, 0.9, 0.5], 1.4), 0.5);
        assert_eq!(nld_mm(&[3.0, 3.0, 3.0], 1.0), 0.0);
        assert_eq!(nld_mm(&[0.0, 5.0], 1.0), 1.0, "clamped");
        assert_eq!(nld_mm(&[1.0], 1.0), 0.0);
        assert_eq!(nld_mm(&[0.0, 1.0], 0.0), 0.0);
        assert_eq!(nld_mm(&[f32::NAN, 1.0], 1.0), 0.0);
        // One outlier among four: eq. 4.4 scores the whole range, eq. 4.5 √(3/4) of it (three
        // pairs of d² over 4 L_max²): the cases §4.3.2 says eq. 4.4 cannot tell apart.
        assert_eq!(nld_mm(&[0.0, 0.0, 0.0, 1.0], 1.0), 1.0);
        assert!((nld_metric(&[0.0, 0.0, 0.0, 1.0], 1.0) - 0.75f32.sqrt()).abs() < 1e-6);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        /// The thesis's definition: eq. 4.4 is eq. 4.3 with N = 2, over the largest and the
        /// smallest sample; for two samples the two metrics are the same S.
        #[test]
        fn eq_4_4_is_eq_4_3_with_n_2(
            lum in prop::collection::vec(0.0f32..100.0, 2..9),
            l_white in 0.01f32..200.0,
        ) {
            let (lo, hi) = lum.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &l| (lo.min(l), hi.max(l)));
            let mm = nld_mm(&lum, l_white);
            prop_assert!((mm - nld_metric(&[hi, lo], l_white)).abs() <= 1e-5, "{mm}");
            let pair = [lum[0], lum[1]];
            prop_assert!(
                (nld_mm(&pair, l_white) - nld_metric(&pair, l_white)).abs() <= 1e-5,
                "N = 2: {} against {}", nld_mm(&pair, l_white), nld_metric(&pair, l_white)
            );
        }

        /// N = 3: √3/2 × eq. 4.4 <= eq. 4.6 <= eq. 4.4 (module documentation), the bounds
        /// reached with the middle sample halfway and at an end.
        #[test]
        fn eq_4_6_lies_within_sqrt3_over_2_of_eq_4_4(
            l in prop::array::uniform3(0.0f32..100.0),
            l_white in 0.01f32..200.0,
            middle in prop_oneof![Just(None), Just(Some(0.0f32)), Just(Some(0.5f32)), (0.0f32..1.0).prop_map(Some)],
        ) {
            let mut l = l;
            if let Some(t) = middle {
                // Put the middle sample at a chosen fraction of the range.
                l[2] = l[0] + t * (l[1] - l[0]);
            }
            let (mm, os) = (nld_mm(&l, l_white), nld3(l, l_white));
            let tol = 1e-5;
            prop_assert!(os <= mm + tol, "eq. 4.6 {os} > eq. 4.4 {mm}");
            prop_assert!(os >= 3f32.sqrt() / 2.0 * mm - tol, "eq. 4.6 {os} < √3/2 × {mm}");
            match middle {
                Some(0.0) => prop_assert!((os - mm).abs() <= tol),
                Some(0.5) if mm < 1.0 => {
                    prop_assert!((os - 3f32.sqrt() / 2.0 * mm).abs() <= 1e-4)
                }
                _ => {}
            }
        }
    }

    /// The criterion: made by its name, and NLD_OS's passes with eq. 4.4 follow a shadow edge
    /// and leave a flat region alone.
    #[test]
    fn nld_mm_follows_a_shadow_edge_and_leaves_flat_light_alone() {
        let settings = CriterionSettings {
            large_triangle_fraction: 1.0,
            ..Default::default()
        };
        let mut mm = make_criterion(CriterionKind::NldMm, &settings, 1);
        assert_eq!(mm.kind(), CriterionKind::NldMm);
        assert!(!mm.needs_image());
        assert_eq!(
            CriterionKind::from_name("nld-mm"),
            Some(CriterionKind::NldMm)
        );

        let flat = Synthetic::new(6, 96, Shading::Flat);
        assert!((0..10).all(|_| mm.select(&flat.input(), 100).is_empty()));

        mm.reset();
        let mut edge = Synthetic::new(6, 96, Shading::ShadowEdge);
        let mut picked_any = false;
        for _ in 0..4 {
            let picked = mm.select(&edge.input(), 16);
            assert!(picked.iter().all(|&l| edge.straddles_shadow(l)));
            picked_any |= !picked.is_empty();
            edge.refine_and_shade(&picked);
        }
        assert!(picked_any && edge.mesh.leaf_count() > 72);
    }
}
