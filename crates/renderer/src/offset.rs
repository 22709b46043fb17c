//! Robust ray origins (DESIGN.md §7): no self-intersection, no light leaking through a wall at a
//! concave corner, also far from the origin (coordinates around 1e5).
//!
//! A point computed in f32 carries an error of a few ulps of its largest coordinate, so the origin
//! is pushed off its surface by a margin that grows with the coordinates (a few ulps) plus a small
//! part of the scene's size. Shading points on a triangle are also pulled a little toward the
//! triangle's centroid: a point on a shared edge or at a corner vertex (as every mesh vertex is)
//! otherwise lies exactly on the neighbouring wall, and rays from it slip through that wall.

use glam::Vec3;

/// Relative margin in units of the point's largest coordinate: 4 ulps of 1.
const RELATIVE: f32 = 4.0 * f32::EPSILON;
/// Absolute margin as a fraction of the scene's extent (its bounding-box diagonal).
const ABSOLUTE_OF_EXTENT: f32 = 1e-5;
/// Part of the way to the centroid a shading point is pulled. Triangle tests are not watertight
/// (DEPENDENCY-NOTES.md): a crack of a few ulps along a neighbour's edge, seen from a point a
/// hair away from it, covers a wide angle and lets light through; a thousandth of the triangle's
/// size away it covers almost none.
const INSET_FRACTION: f32 = 1e-3;

/// How far to move points off surfaces in a scene of the given extent.
#[derive(Clone, Copy, Debug)]
pub struct Offsetter {
    absolute: f32,
}

impl Offsetter {
    pub fn new(scene_extent: f32) -> Offsetter {
        let extent = if scene_extent.is_finite() {
            scene_extent
        } else {
            1.0
        };
        Offsetter {
            absolute: (ABSOLUTE_OF_EXTENT * extent).max(f32::MIN_POSITIVE),
        }
    }

    /// The margin at point `p`.
    pub fn margin(&self, p: Vec3) -> f32 {
        self.absolute + RELATIVE * p.abs().max_element()
    }

    /// Origin for rays leaving the surface at `p` into the side of unit normal `n`.
    pub fn origin(&self, p: Vec3, n: Vec3) -> Vec3 {
        p + n * self.margin(p)
    }

    /// `p` on triangle `tri` pulled toward its centroid by a few margins plus a thousandth of the
    /// way (never past half of it), so a point on an edge or vertex lies inside its own face and
    /// off its neighbours.
    pub fn inset(&self, p: Vec3, tri: [Vec3; 3]) -> Vec3 {
        let centroid = (tri[0] + tri[1] + tri[2]) / 3.0;
        let to_centre = centroid - p;
        let len = to_centre.length();
        if len <= 0.0 {
            return p;
        }
        let step = (4.0 * self.margin(p) + INSET_FRACTION * len).min(0.5 * len);
        p + to_centre * (step / len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn margin_exceeds_float_spacing_far_from_the_origin() {
        let off = Offsetter::new(10.0);
        let p = Vec3::new(1.0e5, 3.0, -1.0e5);
        let ulp = f32::from_bits(1.0e5f32.to_bits() + 1) - 1.0e5;
        assert!(off.margin(p) >= 3.0 * ulp);
        let q = off.origin(p, Vec3::Y);
        assert!(q.y > p.y && q.x == p.x);
    }

    #[test]
    fn inset_moves_a_vertex_inside_its_triangle_but_not_past_the_centroid() {
        let off = Offsetter::new(1.0);
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Z];
        let p = off.inset(Vec3::ZERO, tri);
        assert!(p.x > 0.0 && p.z > 0.0 && p.x < 1.0 / 3.0);
        let tiny = [Vec3::ZERO, Vec3::X * 1e-9, Vec3::Z * 1e-9];
        let q = off.inset(Vec3::ZERO, tiny);
        assert!(q.x <= 1e-9 / 3.0 * 0.5 + 1e-15);
    }
}
