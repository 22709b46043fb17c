//! The minimum-angle bound of red–green refinement (module documentation of [`super`]).

use glam::Vec3;

/// The three interior angles (radians) at vertices 0, 1, 2.
pub fn angles(p: [Vec3; 3]) -> [f32; 3] {
    let angle_at = |i: usize| {
        let (a, b, c) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
        (b - a).angle_between(c - a)
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
}
