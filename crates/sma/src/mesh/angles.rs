//! The minimum-angle bound of red–green refinement (module documentation of [`super`]).

use glam::Vec3;

/// The three interior angles (radians) at vertices 0, 1, 2. By `atan2` of the sides' cross and
/// dot products rather than `acos` of their cosine, which rounds angles below about 0.03° (the
/// scenes' slivers) to zero.
pub fn angles(p: [Vec3; 3]) -> [f32; 3] {
    let angle_at = |i: usize| {
        let (a, b, c) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
        let (u, v) = (b - a, c - a);
        u.cross(v).length().atan2(u.dot(v))
    };
    [angle_at(0), angle_at(1), angle_at(2)]
}

/// Smallest interior angle, radians.
pub fn min_angle(p: [Vec3; 3]) -> f32 {
    let [a, b, c] = angles(p);
    a.min(b).min(c)
}

/// Smallest angle any red–green descendant of a triangle can have: reds are similar to it and a
/// green is one median bisection of a red, so this is the least of its own smallest angle and
/// those of the two halves of each of its three median bisections.
pub fn angle_bound(p: [Vec3; 3]) -> f32 {
    (0..3).fold(min_angle(p), |bound, k| {
        let (a, b, o) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
        let m = 0.5 * (a + b);
        bound.min(min_angle([a, m, o])).min(min_angle([m, b, o]))
    })
}

/// The worst shape among the leaves that splits made (thesis §4.2, fig. 4.7; DESIGN.md §4): their
/// smallest interior angle, and its smallest ratio to that of the leaf's base triangle, which
/// tells the slivers a neighbour rule makes apart from those the scene's own triangles have.
/// Kept as leaves are made; one that coarsening or merging removed still counts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitShapes {
    smallest_angle: f32,
    smallest_ratio_to_base: f32,
}

impl Default for SplitShapes {
    fn default() -> Self {
        SplitShapes {
            smallest_angle: f32::INFINITY,
            smallest_ratio_to_base: f32::INFINITY,
        }
    }
}

impl SplitShapes {
    /// Counts a leaf a split made, at `leaf`, under a base triangle whose smallest angle is
    /// `base_angle` (a degenerate base, angle 0, counts in the absolute figure only).
    pub(super) fn observe(&mut self, leaf: [Vec3; 3], base_angle: f32) {
        let angle = min_angle(leaf);
        if angle.is_nan() {
            return;
        }
        self.smallest_angle = self.smallest_angle.min(angle);
        if base_angle > 0.0 {
            self.smallest_ratio_to_base = self.smallest_ratio_to_base.min(angle / base_angle);
        }
    }

    /// The smallest angle of a leaf a split made, radians; `None` before any split.
    pub fn smallest_angle(&self) -> Option<f32> {
        self.smallest_angle
            .is_finite()
            .then_some(self.smallest_angle)
    }

    /// The smallest ratio of such a leaf's smallest angle to its base triangle's.
    pub fn smallest_ratio_to_base(&self) -> Option<f32> {
        self.smallest_ratio_to_base
            .is_finite()
            .then_some(self.smallest_ratio_to_base)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_bound_is_that_of_its_median_halves() {
        let p = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 3f32.sqrt() / 2.0, 0.0)];
        assert!((min_angle(p).to_degrees() - 60.0).abs() < 1e-3);
        // A median of an equilateral triangle makes 30-60-90 halves.
        assert!((angle_bound(p).to_degrees() - 30.0).abs() < 1e-3);
    }

    #[test]
    fn split_shapes_keep_the_worst_leaf_and_its_ratio_to_its_base() {
        let mut shapes = SplitShapes::default();
        assert_eq!(shapes.smallest_angle(), None);
        let equilateral = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 3f32.sqrt() / 2.0, 0.0)];
        let right = [Vec3::ZERO, Vec3::X, Vec3::Y];
        shapes.observe(equilateral, 60f32.to_radians());
        shapes.observe(right, 90f32.to_radians());
        let deg = shapes.smallest_angle().unwrap().to_degrees();
        assert!((deg - 45.0).abs() < 1e-3, "{deg}");
        assert!((shapes.smallest_ratio_to_base().unwrap() - 0.5).abs() < 1e-4);
        // A degenerate base counts in the absolute figure only.
        shapes.observe(right, 0.0);
        assert!((shapes.smallest_ratio_to_base().unwrap() - 0.5).abs() < 1e-4);
    }

    #[test]
    fn a_sliver_has_its_small_angle_not_zero() {
        let sliver = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-5, 0.0)];
        let expected = 2e-5f32.atan();
        let angle = min_angle(sliver);
        assert!(
            (angle / expected - 1.0).abs() < 1e-2,
            "{angle} against {expected}"
        );
    }
}
