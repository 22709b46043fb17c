//! Guard leaves: leaves that hold no pixel centre in the SMA's pass but may hold one in a
//! viewer's drawing, sent with the visible ones so that no viewer shows the background through a
//! crack between shown triangles (DESIGN.md §3 step 3, §4).
//!
//! A leaf is visible when it holds a pixel centre in the ID pass. A viewer draws the same leaves
//! through its own arithmetic (another origin and matrix, its own rasteriser's sub-pixel grid,
//! maybe another machine's GPU), so a pixel centre within a rounding of a leaf's edge may fall
//! on the other side of it there. When the leaf across held no centre here (a sliver, or a leaf
//! smaller than a pixel) it was not sent, and the viewer showed the background through it: 1 to
//! 18 single pixels in each 1024×768 frame of bracara's and Sponza's default views.
//!
//! So wherever a pixel centre lies within [`ROUNDING_PX`] of an edge of a visible leaf, the
//! leaves across that edge are sent too, and wherever one lies that close to a corner, every
//! leaf around the corner. They carry no pixels (criteria and priorities weigh them as nothing,
//! and they do not set the tone map's white), but they are shaded and shown like visible leaves,
//! and refinement swaps them in with their group. Only edges that pass that close to a centre
//! count: guarding every edge of the visible leaves sent 40–60 % more leaves than were visible
//! and 15–25 % more samples (bracara VT, Sponza S2 and S3 at 1024×768); this way 10–15 % and
//! 5–9 %.

use std::collections::HashSet;

use glam::{DMat3, DVec2, DVec3, Vec2Swizzles, Vec3};
use protocol::viewer_link::Camera;

use super::levels::{LeafView, side_facing};
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::VisibleLeaf;

/// How far, in pixels, two drawings of one edge may lie apart: each rasteriser snaps vertices
/// to its sub-pixel grid (1/256 of a pixel on llvmpipe and most GPUs, 1/16 at the least Vulkan
/// allows) after rounding camera-relative positions to f32 (well below 1/100 of a pixel unless
/// a vertex is a few centimetres from the eye).
pub const ROUNDING_PX: f64 = 1.0 / 32.0;

/// At most this many leaves around one corner are guarded.
const MOST_AROUND: usize = 64;

/// Drops the guards `view` holds (entries with no pixels: those of an earlier mesh, when a view
/// is carried over) and appends those of its visible leaves as seen by `camera`, each with no
/// pixels and the centroid of the visible leaf that brought it.
pub fn add_guards(view: &mut LeafView, mesh: &SubdivisionMesh, camera: &Camera) {
    let mut kept = 0;
    for i in 0..view.visible.leaves.len() {
        if view.visible.leaves[i].pixels > 0 {
            view.visible.leaves[kept] = view.visible.leaves[i];
            view.centroids[kept] = view.centroids[i];
            kept += 1;
        }
    }
    view.visible.leaves.truncate(kept);
    view.centroids.truncate(kept);
    let mut listed: HashSet<NodeId, FastHash> =
        view.visible.leaves.iter().map(|v| v.leaf).collect();
    let image = Image::new(camera);
    let eye = camera.eye_vec();
    let mut found = Vec::new();
    for i in 0..kept {
        let leaf = view.visible.leaves[i].leaf;
        let corners = mesh.leaf_positions(leaf).map(|p| image.camera_space(p));
        for (c, &corner) in corners.iter().enumerate() {
            if image.near_point(corner) {
                mesh.leaves_around(leaf, c, MOST_AROUND, &mut found);
            }
        }
        for k in 0..3 {
            if image.near_segment(corners[k], corners[(k + 1) % 3]) {
                mesh.leaves_across(leaf, k, &mut found);
            }
        }
        for guard in found.drain(..) {
            if listed.insert(guard) {
                view.visible.leaves.push(VisibleLeaf {
                    leaf: guard,
                    side: side_facing(mesh, guard, eye),
                    pixels: 0,
                });
                view.centroids.push(view.centroids[i]);
            }
        }
    }
}

/// The camera's image in f64, with pixel centres at integer coordinates: `(x, y)` is the
/// centre of pixel column `x`, row `y` from the top left (`conventions::camera`).
struct Image {
    eye: DVec3,
    to_camera: DMat3,
    /// Pixels per unit of `x / -z` (and of `y / -z`: pixels are square).
    focal: f64,
    size: DVec2,
}

/// Camera-space points nearer the eye plane than this are clipped off (no pass draws them).
const CLIP_Z: f64 = 1e-6;

impl Image {
    fn new(camera: &Camera) -> Image {
        let tan_half = (0.5 * f64::from(camera.fov_y_deg).to_radians()).tan();
        let size = DVec2::new(
            f64::from(camera.width.max(1)),
            f64::from(camera.height.max(1)),
        );
        Image {
            eye: camera.eye_vec().as_dvec3(),
            to_camera: DMat3::from_quat(camera.rotation().as_dquat().inverse()),
            focal: 0.5 * size.y / tan_half,
            size,
        }
    }

    /// Looking down -z, +y up.
    fn camera_space(&self, p: Vec3) -> DVec3 {
        self.to_camera * (p.as_dvec3() - self.eye)
    }

    /// Where a camera-space point in front of the eye lands.
    fn project(&self, q: DVec3) -> DVec2 {
        let s = self.focal / -q.z;
        DVec2::new(
            0.5 * self.size.x + q.x * s - 0.5,
            0.5 * self.size.y - q.y * s - 0.5,
        )
    }

    /// Whether a pixel centre lies within [`ROUNDING_PX`] of the point.
    fn near_point(&self, q: DVec3) -> bool {
        if q.z > -CLIP_Z {
            return false;
        }
        let p = self.project(q);
        match (centre_at(p.x, self.size.x), centre_at(p.y, self.size.y)) {
            (Some(x), Some(y)) => p.distance(DVec2::new(x, y)) <= ROUNDING_PX,
            _ => false,
        }
    }

    /// Whether a pixel centre lies within [`ROUNDING_PX`] of the segment's part in front of
    /// the eye.
    fn near_segment(&self, a: DVec3, b: DVec3) -> bool {
        let clip =
            |from: DVec3, to: DVec3| from + (to - from) * ((-CLIP_Z - from.z) / (to.z - from.z));
        let (a, b) = match (a.z <= -CLIP_Z, b.z <= -CLIP_Z) {
            (true, true) => (a, b),
            (true, false) => (a, clip(a, b)),
            (false, true) => (clip(b, a), b),
            (false, false) => return false,
        };
        let (a, b) = (self.project(a), self.project(b));
        // Walk the columns (or rows, for a steep segment) it spans: a centre within the
        // tolerance of it is within 0.05 of the line vertically, so the centre nearest the line
        // in each column is the only candidate.
        let steep = (b.y - a.y).abs() > (b.x - a.x).abs();
        let (a, b, size) = if steep {
            (a.yx(), b.yx(), self.size.yx())
        } else {
            (a, b, self.size)
        };
        let from = (a.x.min(b.x) - ROUNDING_PX).ceil().max(0.0);
        let to = (a.x.max(b.x) + ROUNDING_PX).floor().min(size.x - 1.0);
        let slope = if b.x != a.x {
            (b.y - a.y) / (b.x - a.x)
        } else {
            0.0
        };
        let mut x = from;
        while x <= to {
            if let Some(y) = centre_at(a.y + (x - a.x) * slope, size.y)
                && distance_to_segment(DVec2::new(x, y), a, b) <= ROUNDING_PX
            {
                return true;
            }
            x += 1.0;
        }
        false
    }
}

/// The pixel centre coordinate nearest `x` on an axis `size` pixels long, if on the image
/// (rounded by truncation: `f64::round` is a library call on baseline x86-64).
fn centre_at(x: f64, size: f64) -> Option<f64> {
    let c = ((x + 0.5).max(-1.0) as i64) as f64;
    (x + 0.5 >= 0.0 && c < size).then_some(c)
}

fn distance_to_segment(p: DVec2, a: DVec2, b: DVec2) -> f64 {
    let d = b - a;
    let len2 = d.length_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(d) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + t * d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image() -> Image {
        Image {
            eye: DVec3::ZERO,
            to_camera: DMat3::IDENTITY,
            focal: 100.0,
            size: DVec2::new(200.0, 100.0),
        }
    }

    /// The camera-space point that lands on pixel coordinates `(x, y)` at depth 1.
    fn at(x: f64, y: f64) -> DVec3 {
        DVec3::new((x + 0.5 - 100.0) / 100.0, (50.0 - y - 0.5) / 100.0, -1.0)
    }

    /// The unit square's two triangles seen from above through a 4 × 4 image that the square
    /// fills, with the eye moved `shift` pixels along x, and triangle 0 alone visible.
    fn guards_of_the_square(shift: f32) -> Vec<VisibleLeaf> {
        use crate::mesh::test_meshes::square;
        use crate::mesh::{MeshParams, SubdivisionMesh};
        use crate::visible_set::VisibleSet;

        let mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        let camera = Camera {
            seq: 1,
            eye: [0.5 + shift / 4.0, 0.5, 1.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 2.0 * 0.5f32.atan().to_degrees(),
            width: 4,
            height: 4,
        };
        let mut view = LeafView {
            visible: VisibleSet {
                leaves: vec![VisibleLeaf {
                    leaf: 0,
                    side: protocol::Side::Front,
                    pixels: 6,
                }],
                width: 4,
                height: 4,
            },
            centroids: vec![(2.5, 1.5)],
            ..LeafView::default()
        };
        add_guards(&mut view, &mesh, &camera);
        view.visible.leaves
    }

    #[test]
    fn the_leaf_across_an_edge_through_a_pixel_centre_is_a_guard() {
        // The diagonal runs through pixel centres.
        let leaves = guards_of_the_square(0.0);
        assert_eq!(leaves.len(), 2, "{leaves:?}");
        assert_eq!((leaves[1].leaf, leaves[1].pixels), (1, 0));
        // Half a pixel over, it runs between them: nothing is near enough to change hands.
        assert_eq!(guards_of_the_square(0.5).len(), 1);
    }

    #[test]
    fn projection_puts_pixel_centres_at_integers() {
        let p = image().project(at(3.0, 7.0));
        assert!(p.distance(DVec2::new(3.0, 7.0)) < 1e-9, "{p:?}");
    }

    #[test]
    fn a_segment_is_near_only_centres_within_the_rounding() {
        let image = image();
        let off = 0.5 * ROUNDING_PX;
        // Shallow and steep, each way, passing just beside centre (10, 20).
        assert!(image.near_segment(at(5.0, 20.0 + off), at(15.0, 21.0 + off)));
        assert!(image.near_segment(at(15.0, 21.0 + off), at(5.0, 20.0 + off)));
        assert!(image.near_segment(at(10.0 + off, 15.0), at(11.0 + off, 25.0)));
        // Between centres all along.
        assert!(!image.near_segment(at(5.0, 20.5), at(15.0, 20.5)));
        assert!(!image.near_segment(at(5.3, 20.5), at(5.7, 30.5)));
        // Ending short of the centre, then reaching it.
        let short = 2.0 * ROUNDING_PX;
        assert!(!image.near_segment(at(9.5, 19.5), at(10.0 - short, 20.0 - short)));
        assert!(image.near_segment(at(9.5, 19.5), at(10.0 - off, 20.0 - off)));
        // Off the image.
        assert!(!image.near_segment(at(-5.0, 20.0), at(-1.0, 20.0)));
        // Behind the eye: clipped, so only its part in front counts.
        assert!(!image.near_segment(DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, 2.0)));
        assert!(image.near_segment(at(10.0, 20.0), DVec3::new(0.0, 0.0, 1.0)));
    }

    #[test]
    fn a_point_is_near_a_centre_within_the_rounding() {
        let image = image();
        assert!(image.near_point(at(10.0 + 0.5 * ROUNDING_PX, 20.0)));
        assert!(!image.near_point(at(10.0 + 2.0 * ROUNDING_PX, 20.0)));
        assert!(!image.near_point(at(-1.0, 20.0)));
    }
}
