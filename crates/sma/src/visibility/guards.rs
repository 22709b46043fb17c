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
//! leaf around the corner; and on from those, across their own edges that close to the centre,
//! since a stack of needles thinner together than the rounding may give it to any of them (a
//! fan of needles on Sponza S1 did). They carry no pixels (criteria and priorities weigh them as
//! nothing, and they do not set the tone map's white), but they are shaded and shown like
//! visible leaves, and refinement swaps them in with their group. Only edges that pass that close
//! to a centre count: guarding every edge of the visible leaves sent 40–60 % more leaves than
//! were visible and 15–25 % more samples (bracara VT, Sponza S2 and S3 at 1024×768); this way
//! 14–18 % and 6–8 %. Finding them takes about half a microsecond per visible leaf (45 ms for
//! 95 000 on a loaded two-core machine), less than half of a level-2 pass.

use glam::{DMat3, DVec2, DVec3, Vec2Swizzles, Vec3};
use protocol::viewer_link::Camera;

use super::levels::{LeafView, side_facing};
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::VisibleLeaf;

/// How far, in pixels, two drawings of one edge may lie apart: each rasteriser snaps vertices
/// to its sub-pixel grid (1/256 of a pixel on llvmpipe and most GPUs, 1/16 at the least Vulkan
/// allows) after rounding camera-relative positions to f32 (well below 1/100 of a pixel unless
/// a vertex is a few centimetres from the eye).
pub const ROUNDING_PX: f64 = 1.0 / 32.0;

/// At most this many leaves are gathered around one pixel centre (a fan of hundreds of faces
/// at one point is a modelling accident, not a surface).
const MOST_NEAR: usize = 64;

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
    // Bit sets, by node id and by pixel: a pass walks every visible leaf, and these are met
    // several times each.
    let mut listed = BitSet::new(mesh.node_count());
    for v in &view.visible.leaves {
        listed.insert(v.leaf as usize);
    }
    let image = Image::new(camera);
    let eye = camera.eye_vec();
    // Each centre near an edge is gathered around once, from the first visible leaf near it.
    let mut gathered = BitSet::new(image.size.x as usize * image.size.y as usize);
    let (mut centres, mut near) = (Vec::new(), Vec::new());
    for i in 0..kept {
        let leaf = view.visible.leaves[i].leaf;
        let outline = image.outline(mesh, leaf);
        centres.clear();
        for k in 0..3 {
            if let Some((a, b)) = image.edge(&outline, k) {
                image.centres_near_segment(a, b, &mut centres);
            }
        }
        for &centre in &centres {
            if !gathered.insert(image.index(centre)) {
                continue;
            }
            image.leaves_near(mesh, leaf, centre, &mut near);
            for &guard in &near {
                if listed.insert(guard as usize) {
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
}

/// A leaf's corners in camera space, and projected when all are in front of the eye.
struct Outline {
    corners: [DVec3; 3],
    flat: Option<[DVec2; 3]>,
}

/// A set of small whole numbers.
struct BitSet(Vec<u64>);

impl BitSet {
    fn new(size: usize) -> BitSet {
        BitSet(vec![0; size.div_ceil(64)])
    }

    /// Whether `i` was not in the set yet.
    fn insert(&mut self, i: usize) -> bool {
        let (word, bit) = (&mut self.0[i / 64], 1u64 << (i % 64));
        let new = *word & bit == 0;
        *word |= bit;
        new
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

    /// A leaf as the image sees it, each corner projected once.
    fn outline(&self, mesh: &SubdivisionMesh, leaf: NodeId) -> Outline {
        let corners = mesh.leaf_positions(leaf).map(|p| self.camera_space(p));
        let flat = corners
            .iter()
            .all(|q| q.z <= -CLIP_Z)
            .then(|| corners.map(|q| self.project(q)));
        Outline { corners, flat }
    }

    /// Edge `k` of a leaf, its part in front of the eye projected; `None` if it is all behind.
    fn edge(&self, outline: &Outline, k: usize) -> Option<(DVec2, DVec2)> {
        match outline.flat {
            Some(flat) => Some((flat[k], flat[(k + 1) % 3])),
            None => self.project_segment(outline.corners[k], outline.corners[(k + 1) % 3]),
        }
    }

    /// Corner `k` of a leaf, projected, if it is in front of the eye.
    fn corner(&self, outline: &Outline, k: usize) -> Option<DVec2> {
        let q = outline.corners[k];
        outline
            .flat
            .map(|flat| flat[k])
            .or_else(|| (q.z <= -CLIP_Z).then(|| self.project(q)))
    }

    /// A pixel centre's index, row-major.
    fn index(&self, centre: DVec2) -> usize {
        centre.y as usize * self.size.x as usize + centre.x as usize
    }

    /// The segment's part in front of the eye, projected; `None` if it is all behind.
    fn project_segment(&self, a: DVec3, b: DVec3) -> Option<(DVec2, DVec2)> {
        let clip =
            |from: DVec3, to: DVec3| from + (to - from) * ((-CLIP_Z - from.z) / (to.z - from.z));
        let (a, b) = match (a.z <= -CLIP_Z, b.z <= -CLIP_Z) {
            (true, true) => (a, b),
            (true, false) => (a, clip(a, b)),
            (false, true) => (clip(b, a), b),
            (false, false) => return None,
        };
        Some((self.project(a), self.project(b)))
    }

    /// The leaves but `from` that a drawing may give `centre` to, as a rounding moves their
    /// edges: from `from`, across every edge passing within [`ROUNDING_PX`] of it and around
    /// every corner that close, and on from each leaf reached, so that a stack of needles
    /// thinner together than the rounding is crossed whole.
    fn leaves_near(
        &self,
        mesh: &SubdivisionMesh,
        from: NodeId,
        centre: DVec2,
        near: &mut Vec<NodeId>,
    ) {
        near.clear();
        near.push(from);
        let (mut next, mut found) = (0, Vec::new());
        while next < near.len() && near.len() < MOST_NEAR {
            let leaf = near[next];
            next += 1;
            let outline = self.outline(mesh, leaf);
            found.clear();
            for k in 0..3 {
                if self
                    .corner(&outline, k)
                    .is_some_and(|p| p.distance(centre) <= ROUNDING_PX)
                {
                    mesh.leaves_around(leaf, k, MOST_NEAR, &mut found);
                }
                if self
                    .edge(&outline, k)
                    .is_some_and(|(a, b)| distance_to_segment(centre, a, b) <= ROUNDING_PX)
                {
                    mesh.leaves_across(leaf, k, &mut found);
                }
            }
            for &leaf in &found {
                if !near.contains(&leaf) {
                    near.push(leaf);
                }
            }
        }
        near.remove(0);
    }

    /// Pushes the pixel centres within [`ROUNDING_PX`] of the projected segment.
    fn centres_near_segment(&self, a: DVec2, b: DVec2, out: &mut Vec<DVec2>) {
        // Walk the columns (or rows, for a steep segment) it spans: a centre within the
        // tolerance of it is within `band` of the line along the column, less than half a
        // pixel, so the centre nearest the line in each column is the only candidate, and most
        // are passed over without the exact distance.
        let steep = (b.y - a.y).abs() > (b.x - a.x).abs();
        let (a, b, size) = if steep {
            (a.yx(), b.yx(), self.size.yx())
        } else {
            (a, b, self.size)
        };
        let (run, rise) = (b.x - a.x, b.y - a.y);
        let (slope, band) = if run != 0.0 {
            (
                rise / run,
                ROUNDING_PX * (run * run + rise * rise).sqrt() / run.abs(),
            )
        } else {
            (0.0, ROUNDING_PX)
        };
        let from = (a.x.min(b.x) - ROUNDING_PX).max(0.0);
        let to = (a.x.max(b.x) + ROUNDING_PX).min(size.x - 1.0);
        // Columns are whole numbers: the first at or after `from` (truncation is a floor here).
        let mut x = from as i64 as f64;
        if x < from {
            x += 1.0;
        }
        while x <= to {
            let line = a.y + (x - a.x) * slope;
            if let Some(y) = centre_at(line, size.y)
                && (y - line).abs() <= band
            {
                let c = DVec2::new(x, y);
                if distance_to_segment(c, a, b) <= ROUNDING_PX {
                    out.push(if steep { c.yx() } else { c });
                }
            }
            x += 1.0;
        }
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

    /// The camera over the square [0, 1]² of z = 0, which fills its 4 × 4 image, moved `shift`
    /// pixels along x: pixel centre (x, y) sees (x + 0.5 + shift, 3.5 - y) / 4.
    fn over_the_unit_square(shift: f32) -> Camera {
        Camera {
            seq: 1,
            eye: [0.5 + shift / 4.0, 0.5, 1.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 2.0 * 0.5f32.atan().to_degrees(),
            width: 4,
            height: 4,
        }
    }

    /// The guards of `mesh` seen by `camera` when leaf 0 alone is visible.
    fn guards_of_leaf_0(mesh: &scene::Mesh, camera: &Camera) -> Vec<(NodeId, u32)> {
        use crate::mesh::{MeshParams, SubdivisionMesh};
        use crate::visible_set::VisibleSet;

        let mesh = SubdivisionMesh::new(mesh, MeshParams::default());
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
        add_guards(&mut view, &mesh, camera);
        view.visible.leaves[1..]
            .iter()
            .map(|v| (v.leaf, v.pixels))
            .collect()
    }

    #[test]
    fn the_leaf_across_an_edge_through_a_pixel_centre_is_a_guard() {
        let square = crate::mesh::test_meshes::square();
        // The diagonal runs through pixel centres.
        assert_eq!(
            guards_of_leaf_0(&square, &over_the_unit_square(0.0)),
            [(1, 0)]
        );
        // Half a pixel over, it runs between them: nothing is near enough to change hands.
        assert_eq!(guards_of_leaf_0(&square, &over_the_unit_square(0.5)), []);
    }

    /// A fan of needles from (0, 0.625), each a thousandth high at x = 1: where pixel centre
    /// (3, 1) sees them, at x = 0.875, all five are thinner together than the rounding, and a
    /// drawing may give the centre to any of them.
    #[test]
    fn a_stack_of_needles_near_a_pixel_centre_is_guarded_whole() {
        let mut positions = vec![Vec3::new(0.0, 0.625, 0.0)];
        positions.extend((0..6).map(|i| Vec3::new(1.0, 0.625 + (i as f32 - 2.0) * 1e-3, 0.0)));
        let fan = scene::Mesh {
            normals: vec![Vec3::Z; positions.len()],
            positions,
            triangles: (1..6)
                .map(|i| scene::Triangle {
                    vertices: [0, i, i + 1],
                    material: 0,
                })
                .collect(),
        };
        let mut guards = guards_of_leaf_0(&fan, &over_the_unit_square(0.0));
        guards.sort_unstable();
        assert_eq!(guards, [(1, 0), (2, 0), (3, 0), (4, 0)]);
    }

    #[test]
    fn projection_puts_pixel_centres_at_integers() {
        let p = image().project(at(3.0, 7.0));
        assert!(p.distance(DVec2::new(3.0, 7.0)) < 1e-9, "{p:?}");
    }

    #[test]
    fn the_centres_near_a_segment_are_those_within_the_rounding() {
        let image = image();
        let near = |a: DVec3, b: DVec3| {
            let mut centres = Vec::new();
            if let Some((a, b)) = image.project_segment(a, b) {
                image.centres_near_segment(a, b, &mut centres);
            }
            centres
        };
        let off = 0.5 * ROUNDING_PX;
        let centre = [DVec2::new(10.0, 20.0)];
        // Shallow and steep, each way, passing just beside centre (10, 20) and 0.08 or more
        // from every other.
        let (left, right) = (at(5.0, 18.5 + off), at(15.0, 21.5 + off));
        assert_eq!(near(left, right), centre);
        assert_eq!(near(right, left), centre);
        assert_eq!(near(at(8.5 + off, 15.0), at(11.5 + off, 25.0)), centre);
        // Between centres all along.
        assert!(near(at(5.0, 20.5), at(15.0, 20.5)).is_empty());
        assert!(near(at(5.3, 20.5), at(5.7, 30.5)).is_empty());
        // Ending short of the centre, then reaching it.
        let short = 2.0 * ROUNDING_PX;
        assert!(near(at(9.5, 19.5), at(10.0 - short, 20.0 - short)).is_empty());
        assert_eq!(near(at(9.5, 19.5), at(10.0 - off, 20.0 - off)), centre);
        // Along a row of centres: each of them.
        assert_eq!(near(at(2.0, 3.0), at(4.0, 3.0)).len(), 3);
        // Off the image.
        assert!(near(at(-5.0, 20.0), at(-1.0, 20.0)).is_empty());
        // Behind the eye: clipped, so only its part in front counts.
        assert!(near(DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, 2.0)).is_empty());
        assert!(near(at(10.0, 20.0), DVec3::new(0.0, 0.0, 1.0)).contains(&centre[0]));
    }

    #[test]
    fn a_corner_is_projected_only_in_front_of_the_eye() {
        let image = image();
        let outline = |corners: [DVec3; 3]| Outline {
            corners,
            flat: None,
        };
        let behind = DVec3::new(0.0, 0.0, 1.0);
        let seen = outline([at(10.0, 20.0), behind, behind]);
        let corner = image.corner(&seen, 0).expect("in front");
        assert!(corner.distance(DVec2::new(10.0, 20.0)) < 1e-9);
        assert_eq!(image.corner(&seen, 1), None);
        assert_eq!(image.edge(&seen, 1), None, "all behind");
        assert!(image.edge(&seen, 0).is_some(), "clipped");
    }
}
