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

use super::id_pass::Coverage;
use super::levels::{LeafView, side_facing};
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::{VisibleLeaf, VisibleSet};

/// `view`, seen from `camera` through `mesh` before it changed, brought to the mesh's current
/// leaves. Leaves still live keep their entries; the pixels of the others go to the leaves that
/// now hold them, which get entries after the kept ones, in pixel order.
pub fn carry_over(view: &LeafView, mesh: &SubdivisionMesh, camera: &Camera) -> LeafView {
    let pinhole = camera.pinhole();
    let width = camera.width.max(1) as usize;
    let mut pixel_leaves = view.pixel_leaves.clone();
    let mut gained: HashMap<NodeId, Coverage, FastHash> = HashMap::default();
    let mut gained_order = Vec::new();
    for (i, slot) in pixel_leaves.iter_mut().enumerate() {
        let Some(old) = *slot else { continue };
        if mesh.is_leaf(old) {
            continue;
        }
        let (x, y) = (i % width, i / width);
        let leaf = locate(mesh, old, &pinhole, (x as f32 + 0.5, y as f32 + 0.5));
        *slot = Some(leaf);
        let c = gained.entry(leaf).or_insert_with(|| {
            gained_order.push(leaf);
            Coverage::default()
        });
        c.pixels += 1;
        c.sum_x += x as u64;
        c.sum_y += y as u64;
    }
    let (mut leaves, mut centroids) = (Vec::new(), Vec::new());
    for (v, &centroid) in view.visible.leaves.iter().zip(&view.centroids) {
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
    LeafView {
        visible: VisibleSet {
            leaves,
            width: view.visible.width,
            height: view.visible.height,
        },
        centroids,
        pixel_leaves,
        camera: view.camera.clone(),
        visible_bases: view.visible_bases,
        // Nothing was drawn: the figure stays that of the pass the view comes from.
        submitted_leaves: view.submitted_leaves,
    }
}

/// The current leaf whose triangle the ray through image point `(x, y)` passes through, below
/// the nearest live ancestor of `node` (base triangles never die).
fn locate(
    mesh: &SubdivisionMesh,
    mut node: NodeId,
    camera: &Pinhole,
    (x, y): (f32, f32),
) -> NodeId {
    while !mesh.node(node).is_alive() {
        node = mesh
            .node(node)
            .parent()
            .expect("a removed node has a parent: base triangles are never removed");
    }
    let eye = camera.eye.as_dvec3();
    let ray = camera.ray_direction(x, y);
    loop {
        let children = mesh.node(node).children();
        if children.is_empty() {
            return node;
        }
        node = children
            .max_by(|&a, &b| {
                let (sa, sb) = (inside(mesh, a, eye, ray), inside(mesh, b, eye, ray));
                sa.total_cmp(&sb)
            })
            .expect("a split node has children");
    }
}

/// How far inside triangle `node` the ray from `eye` along `ray` passes: the smallest of the
/// three signed volumes its edges make with the ray, oriented so that all three are positive
/// inside. Non-negative for the one child the ray crosses, negative for its siblings.
fn inside(mesh: &SubdivisionMesh, node: NodeId, eye: DVec3, ray: Vec3) -> f32 {
    let [a, b, c] = mesh.leaf_positions(node).map(|p| relative_to(p, eye));
    let s = [
        ray.dot(a.cross(b)),
        ray.dot(b.cross(c)),
        ray.dot(c.cross(a)),
    ];
    let orientation = if s.iter().sum::<f32>() >= 0.0 {
        1.0
    } else {
        -1.0
    };
    s.into_iter()
        .map(|v| v * orientation)
        .fold(f32::INFINITY, f32::min)
}
