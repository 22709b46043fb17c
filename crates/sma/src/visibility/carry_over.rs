//! A view carried over to a changed mesh without a pass (DESIGN.md §3 step 3, §4).
//!
//! Refinement and coarsening only re-tile base triangles: every leaf lies in the plane of its
//! base triangle, and the leaves of a base cover exactly that triangle. With the camera
//! unchanged, a pixel therefore keeps its base triangle and its depth; only which leaf of that
//! base holds the pixel's centre can change. [`carry_over`] finds it on the CPU, for the pixels
//! whose leaf is gone, by walking the hierarchy from the nearest live node down the children the
//! pixel's ray passes through. A round splits a few hundred leaves, so this touches thousands of
//! pixels where a level-2 pass drew every leaf of every visible base (on Sponza, 100–200 ms
//! a pass at 1024×768 on llvmpipe, several times a second, on the cores the renderers use).
//!
//! The answer is a fresh pass's up to pixels whose centre lies on a shared edge, which the GPU's
//! rasterisation rule and this walk may give to either neighbour.

use std::collections::HashMap;

use conventions::camera::{Pinhole, relative_to};
use glam::{DVec3, Vec3};
use protocol::viewer_link::Camera;

use super::guards::add_guards;
use super::id_pass::Coverage;
use super::levels::{LeafView, side_facing};
use super::pixel_leaves::PixelLeaves;
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::{VisibleLeaf, VisibleSet};

/// At most this share of the image's pixels may have lost their leaf for a carry-over to
/// be worth it: re-assigning one costs about a tenth of a microsecond, and a pass that follows
/// the first rounds over a coarse mesh (leaves of thousands of pixels) is cheaper drawn.
const MOST_PIXELS_CARRIED: f64 = 0.125;

/// `view`, seen from `camera` through `mesh` before it changed, brought to the mesh's current
/// leaves; `None` when so many pixels lost their leaf that a pass is cheaper. Leaves still live
/// keep their entries; the pixels of the others go to the leaves that now hold them, which get
/// entries after the kept ones, in pixel order; the guards (`guards`) are found afresh.
pub fn carry_over(view: LeafView, mesh: &SubdivisionMesh, camera: &Camera) -> Option<LeafView> {
    let stale_pixels: u32 = view
        .pixel_leaves
        .runs()
        .filter(|(_, p)| p.is_some_and(|leaf| !mesh.is_leaf(leaf)))
        .map(|(pixels, _)| pixels.len() as u32)
        .sum();
    if f64::from(stale_pixels) > MOST_PIXELS_CARRIED * view.pixel_leaves.len() as f64 {
        return None;
    }
    let LeafView {
        visible,
        centroids: old_centroids,
        pixel_leaves: old_pixel_leaves,
        camera: view_camera,
        visible_bases,
        submitted_leaves,
    } = view;
    let width = camera.width.max(1);
    let rays = Rays::new(&camera.pinhole());
    let mut walk = Walk::new(mesh, camera.eye_vec().as_dvec3());
    let mut gained: HashMap<NodeId, Coverage, FastHash> = HashMap::default();
    let mut gained_order = Vec::new();
    let mut pixel_leaves = PixelLeaves::default();
    for (pixels, old) in old_pixel_leaves.runs() {
        let Some(old) = old.filter(|&leaf| !mesh.is_leaf(leaf)) else {
            pixel_leaves.push(old, pixels.len() as u32);
            continue;
        };
        for i in pixels {
            let (x, y) = (i % width, i / width);
            let leaf = walk.locate(old, rays.through(x, y));
            pixel_leaves.push(Some(leaf), 1);
            let c = gained.entry(leaf).or_insert_with(|| {
                gained_order.push(leaf);
                Coverage::default()
            });
            c.pixels += 1;
            c.sum_x += u64::from(x);
            c.sum_y += u64::from(y);
        }
    }
    pixel_leaves.shrink_to_fit();
    let (mut leaves, mut centroids) = (Vec::new(), Vec::new());
    for (v, &centroid) in visible.leaves.iter().zip(&old_centroids) {
        if !mesh.is_leaf(v.leaf) {
            continue;
        }
        // A kept leaf gains pixels only on an edge its new neighbour shares.
        let extra = gained.remove(&v.leaf).unwrap_or_default();
        let pixels = v.pixels + extra.pixels;
        let weight =
            |c: f32, sum: u64| ((c - 0.5) * v.pixels as f32 + sum as f32) / pixels as f32 + 0.5;
        leaves.push(VisibleLeaf { pixels, ..*v });
        centroids.push((
            weight(centroid.0, extra.sum_x),
            weight(centroid.1, extra.sum_y),
        ));
    }
    let eye = camera.eye_vec();
    for leaf in gained_order {
        let Some(c) = gained.get(&leaf) else { continue };
        leaves.push(VisibleLeaf {
            leaf,
            side: side_facing(mesh, leaf, eye),
            pixels: c.pixels,
        });
        centroids.push(c.centroid());
    }
    let mut view = LeafView {
        visible: VisibleSet { leaves, ..visible },
        centroids,
        pixel_leaves,
        camera: view_camera,
        visible_bases,
        // Nothing was drawn: the figure stays that of the pass the view comes from.
        submitted_leaves,
    };
    add_guards(&mut view, mesh, camera);
    Some(view)
}

/// The direction through each pixel centre, unnormalised (only signs are read): linear in the
/// pixel's coordinates, as `Pinhole::ray_direction` without its normalisation.
struct Rays {
    corner: Vec3,
    per_x: Vec3,
    per_y: Vec3,
}

impl Rays {
    fn new(camera: &Pinhole) -> Rays {
        let t = camera.half_height();
        let (w, h) = (camera.width.max(1) as f32, camera.height.max(1) as f32);
        let r = camera.rotation;
        Rays {
            corner: r * Vec3::new(-t * camera.aspect(), t, -1.0),
            per_x: r * Vec3::new(2.0 * t * camera.aspect() / w, 0.0, 0.0),
            per_y: r * Vec3::new(0.0, -2.0 * t / h, 0.0),
        }
    }

    fn through(&self, x: u32, y: u32) -> Vec3 {
        self.corner + (x as f32 + 0.5) * self.per_x + (y as f32 + 0.5) * self.per_y
    }
}

/// The walk down the hierarchy, with each split node's children's edge planes (through the
/// eye) kept: the pixels of one split leaf all walk the same few nodes.
struct Walk<'a> {
    mesh: &'a SubdivisionMesh,
    eye: DVec3,
    planes: HashMap<NodeId, Vec<(NodeId, [Vec3; 3])>, FastHash>,
}

impl<'a> Walk<'a> {
    fn new(mesh: &'a SubdivisionMesh, eye: DVec3) -> Self {
        Walk {
            mesh,
            eye,
            planes: HashMap::default(),
        }
    }

    /// The current leaf whose triangle `ray` passes through, below the nearest live ancestor of
    /// `node` (base triangles are never removed).
    fn locate(&mut self, mut node: NodeId, ray: Vec3) -> NodeId {
        let mesh = self.mesh;
        while !mesh.node(node).is_alive() {
            node = mesh
                .node(node)
                .parent()
                .expect("a removed node has a parent: base triangles are never removed");
        }
        while !mesh.node(node).children().is_empty() {
            let eye = self.eye;
            let children = self.planes.entry(node).or_insert_with(|| {
                mesh.node(node)
                    .children()
                    .map(|c| (c, edge_planes(mesh, c, eye)))
                    .collect()
            });
            node = children
                .iter()
                .map(|&(c, planes)| {
                    (
                        c,
                        planes
                            .map(|n| n.dot(ray))
                            .into_iter()
                            .fold(f32::INFINITY, f32::min),
                    )
                })
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .expect("a split node has children")
                .0;
        }
        node
    }
}

/// The planes through the eye and each edge of triangle `node`, oriented so that a ray from the
/// eye through the triangle's inside is on the positive side of all three: the one child a ray
/// crosses has no negative dot product, each sibling has one.
fn edge_planes(mesh: &SubdivisionMesh, node: NodeId, eye: DVec3) -> [Vec3; 3] {
    let [a, b, c] = mesh.leaf_positions(node).map(|p| relative_to(p, eye));
    let planes = [a.cross(b), b.cross(c), c.cross(a)];
    // The triangle's orientation as seen from the eye: the sign of the volume it spans with it.
    let orientation = if a.dot(planes[1]) >= 0.0 { 1.0 } else { -1.0 };
    planes.map(|n| n * orientation)
}
