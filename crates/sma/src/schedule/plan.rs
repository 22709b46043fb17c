//! From one viewer's visible set to what it should be shown and what must be shaded
//! (DESIGN.md §3 steps 4–6, §5, §7).

use std::collections::HashSet;

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey, ShadePoint};

use super::pending::PendingRefinement;
use super::requests::{Need, Urgency};
use crate::cache::ShadingCache;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visibility::{LeafView, side_facing};

/// The nodes to show for a visible set: each visible leaf, except that a new leaf of a pending
/// refinement group stands for the leaves the group replaced (seen from the eye's side), so the
/// closure swaps in only when complete.
pub fn targets(
    view: &LeafView,
    pending: &PendingRefinement,
    mesh: &SubdivisionMesh,
    eye: Vec3,
) -> Vec<(NodeId, Side)> {
    let mut seen_groups = HashSet::new();
    let mut out = Vec::with_capacity(view.visible.leaves.len());
    for v in &view.visible.leaves {
        match pending.group_of(v.leaf) {
            None => out.push((v.leaf, v.side)),
            Some(g) if seen_groups.insert(g) => {
                let group = pending.group(g).expect("a leaf's group is pending");
                out.extend(
                    group
                        .replaced_leaves
                        .iter()
                        .map(|&r| (r, side_facing(mesh, r, eye))),
                );
            }
            Some(_) => {}
        }
    }
    out
}

/// Sample qualities of progressive shading: a cheap direct-light one first where it is cheaper
/// than the scene's, then the scene's (DESIGN.md §7).
#[derive(Clone, Copy, Debug)]
pub struct Qualities {
    pub first: Quality,
    pub full: Quality,
}

impl Qualities {
    pub fn new(full: Quality) -> Self {
        let first = if Quality::DIRECT.rank() < full.rank() {
            Quality::DIRECT
        } else {
            full
        };
        Qualities { first, full }
    }
}

/// How far a view-dependent sample's eye may move, as the angle seen from the vertex, before
/// the sample is retaken (DESIGN.md §5).
#[derive(Clone, Copy, Debug)]
pub struct Aging {
    pub max_angle_rad: f32,
}

impl Aging {
    pub fn is_stale(&self, vertex: Vec3, sample_eye: Option<Vec3>, eye: Vec3) -> bool {
        sample_eye.is_none_or(|old| (old - vertex).angle_between(eye - vertex) > self.max_angle_rad)
    }
}

/// Everything a viewer's visible leaves still need.
pub struct NeedsInput<'a> {
    pub view: &'a LeafView,
    pub eye: Vec3,
    pub pending: &'a PendingRefinement,
    pub mesh: &'a SubdivisionMesh,
    pub cache: &'a ShadingCache,
    /// Whether a base triangle's material is view-dependent.
    pub view_dependent: &'a [bool],
    pub qualities: Qualities,
    pub aging: Aging,
}

pub fn needs(input: &NeedsInput) -> Vec<Need> {
    let visible = &input.view.visible;
    let (w, h) = (visible.width as f32, visible.height as f32);
    let mut out = Vec::new();
    for (v, &(cx, cy)) in visible.leaves.iter().zip(&input.view.centroids) {
        // On-screen size, weighted toward the centre (1 at the centre, 1/3 in a corner).
        let (dx, dy) = ((cx - 0.5 * w) / (0.5 * w), (cy - 0.5 * h) / (0.5 * h));
        let priority = v.pixels as f32 / (1.0 + dx * dx + dy * dy);
        let refining = input.pending.group_of(v.leaf).is_some();
        for vertex in input.mesh.node(v.leaf).vertices {
            let key = SampleKey {
                vertex,
                side: v.side,
            };
            need_key(input, key, refining, priority, &mut out);
        }
    }
    out
}

fn need_key(
    input: &NeedsInput,
    key: SampleKey,
    refining: bool,
    priority: f32,
    out: &mut Vec<Need>,
) {
    let mv = input.mesh.vertex(key.vertex);
    let view_dependent = input
        .view_dependent
        .get(mv.base_triangle as usize)
        .copied()
        .unwrap_or(false);
    let point = ShadePoint {
        key,
        base_triangle: mv.base_triangle,
        bary: mv.bary,
        side: key.side,
        eye: view_dependent.then(|| input.eye.to_array()),
    };
    let full = input.qualities.full;
    let mut push = |quality, urgency, new_eye| {
        out.push(Need {
            point,
            quality,
            urgency,
            priority,
            new_eye,
        });
    };
    match input.cache.get_seen_from(key, Some(input.eye)) {
        None if refining => push(full, Urgency::Refinement, false),
        None => {
            push(input.qualities.first, Urgency::Missing, false);
            push(full, Urgency::Better, false);
        }
        Some(s) if s.quality.rank() < full.rank() => push(full, Urgency::Better, false),
        Some(s) if s.view_dependent && input.aging.is_stale(mv.position, s.eye, input.eye) => {
            push(full, Urgency::Better, true);
        }
        Some(_) => {}
    }
}
