//! Coarsening by uniformity (thesis §6, future work, in translation: "a flat, non-specular
//! surface without discontinuities need not be subdivided, but that is only known after
//! subdividing it", so neighbours whose vertices carry the same shading need not all be kept;
//! DESIGN.md §4): a visible red parent whose split showed nothing its own vertices do not is
//! merged back. Switched by `ScheduleConfig::merge_uniform` (`--merge-uniform`).
//!
//! **The test.** A red split adds three vertices, the midpoints of the parent's edges. Drawn
//! unsplit, the parent shows at the midpoint of edge (a, b) the Gouraud interpolation of its
//! corners, (L_a + L_b) / 2; split, the midpoint's own sample L_m. Where, for all three
//! midpoints, the two differ by no more than their noise explains (`nld::NOISE_Z` times the
//! combined standard error, sqrt(σ_m² + (σ_a² + σ_b²) / 4), each σ carried through the
//! display mapping at its own mean) or by no more than one display step (`display_error`), in
//! the displayed units the noise-aware criteria judge in (Drago with the view's L_white, then
//! sRGB; `sample::DisplayMap`), the children show what the parent shows: the split brought
//! nothing (`judge`). The luminance is judged as the criteria judge it, and each colour
//! channel as the viewer shows it (tone-mapped on its luminance, its colour kept), against the
//! same allowance, since a sample keeps the variance of its luminance only.
//!
//! The test is stricter than the criteria's own (they count a difference once it exceeds the
//! noise *plus* one step): a merge removes detail on evidence that must be final, so it takes
//! the cautious side, and the gap between the two is a hysteresis against a merge and a split
//! that undo each other. For the same reason only **settled** samples count, all six of them:
//! at a rung whose variance the ladder believes (`ladder::Qualities::trusts`, at the scene's
//! depth), and at the ladder's cap or with a displayed standard error within one step (as
//! `criteria::leaf_floor` settles a leaf). A merge is never decided on early, noisy samples.
//! View-dependent samples hold for one eye, so a parent with one is never merged.
//!
//! **What is not merged.** A parent with a visible child above the large-triangle fraction
//! (§4.3.5): the large-triangle rule splits such a leaf whatever its vertices say, because a
//! shadow may cross it between them, and merging it back would undo that search.
//!
//! **When.** With a refinement round, paced as rounds are (`--round-share`), only while the
//! view rests, no pass is owed and no refinement step waits (`turns::refinement_candidate`); a
//! pass is due once samples or views came since the last, and a viewer whose criterion found
//! nothing more still takes its turn for it (samples settle after the splits that asked them).
//!
//! **How.** Through the mesh's conforming coarsening (`SubdivisionMesh::coarsen_many`): the
//! steps wait in the pending groups like any refinement or coarsening step, and the viewers
//! get ordinary `Remove`/`Insert` updates, whole closures at once (DESIGN.md §4).
//!
//! **No oscillation.** The criterion sees a merged parent's own corners; if it split the parent
//! for them (a gradient, which a Gouraud parent shows exactly, or the large-triangle rule), it
//! would split it again on the same samples. A merged parent is therefore recorded with the
//! paths of its corner samples, and not split again by a criterion's selection until one of
//! them has gained paths (`UniformMerge::allows`). The records hold one entry per leaf (or green
//! split) of the mesh at most: an entry goes once its node is split red again.

use std::collections::HashMap;

use conventions::ToneMap;
use conventions::luminance;
use conventions::tone_map::srgb_encode;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey};

use crate::cache::ShadingCache;
use crate::config::ScheduleConfig;
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, NodeKind, RefinementStep, Split, SubdivisionMesh};
use crate::nld::NOISE_Z;
use crate::sample::{DisplayMap, Estimate};
use crate::visible_set::VisibleSet;

/// When a sample has settled (DESIGN.md §5), as the criteria and the quality ladder say.
pub struct Settling<'a> {
    /// One display step: a displayed standard error within it has settled.
    pub display_error: f32,
    /// The ladder's cap: a sample there has settled however noisy.
    pub max_paths: u32,
    /// Whether the ladder believes the variance of a sample of this quality.
    pub trusted: &'a dyn Fn(Quality) -> bool,
}

impl Settling<'_> {
    fn settled(&self, e: &Estimate, map: &DisplayMap) -> bool {
        (self.trusted)(e.quality())
            && (e.paths >= self.max_paths || e.displayed(map).standard_error <= self.display_error)
    }
}

/// What [`judge`] finds of one parent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Not a red parent of four leaves, or a view-dependent one.
    NotCandidate,
    /// A sample is missing or has not settled: nothing is decided yet.
    Unsettled,
    /// A midpoint differs from its corners' prediction beyond the allowance.
    Varies,
    /// Every midpoint is what the corners predict: the split shows nothing the parent does not.
    Uniform,
}

/// The test of the module documentation for `parent`, with the samples of `side`, for a view
/// whose tone map has white point `l_white`.
pub fn judge(
    mesh: &SubdivisionMesh,
    cache: &ShadingCache,
    parent: NodeId,
    side: Side,
    l_white: f32,
    settling: &Settling,
) -> Verdict {
    let node = mesh.node(parent);
    let Split::Red { first_child } = node.split() else {
        return Verdict::NotCandidate;
    };
    if !node.is_alive() || !(first_child..first_child + 4).all(|c| mesh.is_leaf(c)) {
        return Verdict::NotCandidate;
    }
    if !(l_white > 0.0 && l_white.is_finite()) {
        return Verdict::Unsettled;
    }
    let map = DisplayMap::new(l_white);
    // The middle child's vertices are the midpoints of edges 0, 1, 2 (`refine::red_children`).
    let midpoints = mesh.node(first_child + 3).vertices;
    let mut samples = [None; 6];
    for (slot, vertex) in samples
        .iter_mut()
        .zip(node.vertices.into_iter().chain(midpoints))
    {
        let Some(sample) = cache.get(SampleKey { vertex, side }) else {
            return Verdict::Unsettled;
        };
        if sample.view_dependent {
            return Verdict::NotCandidate;
        }
        let estimate = sample.estimate();
        if !settling.settled(&estimate, &map) {
            return Verdict::Unsettled;
        }
        *slot = Some(estimate);
    }
    let [a, b, c, m0, m1, m2] = samples.map(|s| s.expect("every sample read"));
    let edges = [(a, b, m0), (b, c, m1), (c, a, m2)];
    let predicted = edges
        .iter()
        .all(|(a, b, m)| predicts(a, b, m, &map, l_white, settling.display_error));
    if predicted {
        Verdict::Uniform
    } else {
        Verdict::Varies
    }
}

/// Whether corners `a` and `b` predict their midpoint's sample `m` (see the module
/// documentation): in displayed luminance and in each displayed channel, the difference is
/// within `NOISE_Z` combined standard errors or within one display step.
fn predicts(
    a: &Estimate,
    b: &Estimate,
    m: &Estimate,
    map: &DisplayMap,
    l_white: f32,
    display_error: f32,
) -> bool {
    let rgb: [f32; 3] = std::array::from_fn(|i| 0.5 * (a.rgb()[i] + b.rgb()[i]));
    let (shown, slope) = map.display_and_slope(luminance(rgb));
    let predicted_error = slope * 0.5 * a.standard_error().hypot(b.standard_error());
    let at_m = m.displayed(map);
    let allowance = (NOISE_Z * at_m.standard_error.hypot(predicted_error)).max(display_error);
    if (at_m.luminance - shown).abs() > allowance {
        return false;
    }
    let channels = |rgb: [f32; 3]| ToneMap::Drago.display_rgb(rgb, l_white).map(srgb_encode);
    let (at_m, shown) = (channels(m.rgb()), channels(rgb));
    at_m.iter()
        .zip(&shown)
        .all(|(x, y)| (x - y).abs() <= allowance)
}

/// A view as the merge pass reads it: what is visible, and the white point it is shown with.
pub struct JudgedView<'a> {
    pub visible: &'a VisibleSet,
    pub l_white: f32,
}

/// A merged parent: the side it was judged on and its corner samples' paths then.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Merged {
    side: Side,
    paths: [u32; 3],
}

/// The state of coarsening by uniformity.
#[derive(Debug)]
pub struct UniformMerge {
    on: bool,
    /// New samples or a new view since the last pass.
    due: bool,
    display_error: f32,
    max_paths: u32,
    /// §4.3.5's fraction of the image above which a leaf is large.
    large_triangle_fraction: f32,
    /// Merged parents not to be split again on the same samples (module documentation).
    merged: HashMap<NodeId, Merged, FastHash>,
    /// Parents merged back since the start.
    merges: u64,
}

impl UniformMerge {
    pub fn new(config: &ScheduleConfig) -> UniformMerge {
        UniformMerge {
            on: config.merge_uniform,
            due: false,
            display_error: config.display_error,
            max_paths: config.max_paths,
            large_triangle_fraction: config.criterion_settings.large_triangle_fraction,
            merged: HashMap::default(),
            merges: 0,
        }
    }

    /// Whether a pass is due: merging is on and something changed since the last one.
    pub fn is_due(&self) -> bool {
        self.on && self.due
    }

    /// New samples arrived or the views changed: what was undecided may be decided now.
    pub fn new_input(&mut self) {
        self.due = true;
    }

    /// Parents merged back since the start.
    pub fn merges(&self) -> u64 {
        self.merges
    }

    /// Merges back every red parent a view sees whose four children are leaves and which is
    /// uniform ([`judge`]) in every view that sees it, as far as conforming coarsening lets it
    /// go; returns the steps, for the pending groups.
    pub fn pass(
        &mut self,
        views: &[JudgedView],
        mesh: &mut SubdivisionMesh,
        cache: &ShadingCache,
        trusted: &dyn Fn(Quality) -> bool,
    ) -> Vec<RefinementStep> {
        self.due = false;
        self.merged.retain(|&p, _| {
            let node = mesh.node(p);
            node.is_alive() && !matches!(node.split(), Split::Red { .. })
        });
        let settling = Settling {
            display_error: self.display_error,
            max_paths: self.max_paths,
            trusted,
        };
        // Per parent: the side it is uniform on in every view seen so far, or `None`.
        let mut uniform: HashMap<NodeId, Option<Side>, FastHash> = HashMap::default();
        for view in views {
            let visible = view.visible;
            let large_above =
                f64::from(self.large_triangle_fraction) * visible.image_pixels() as f64;
            let mut in_view: HashMap<NodeId, Option<Side>, FastHash> = HashMap::default();
            for v in &visible.leaves {
                let node = mesh.node(v.leaf);
                if node.kind() != NodeKind::Red || !mesh.is_leaf(v.leaf) {
                    continue;
                }
                let parent = node.parent().expect("a red child has a parent");
                let known = in_view.get(&parent).copied();
                let ok = known != Some(None)
                    && f64::from(v.pixels) <= large_above
                    && (known.is_some()
                        || judge(mesh, cache, parent, v.side, view.l_white, &settling)
                            == Verdict::Uniform);
                in_view.insert(parent, ok.then_some(known.flatten().unwrap_or(v.side)));
            }
            for (parent, side) in in_view {
                uniform
                    .entry(parent)
                    .and_modify(|s| *s = s.and(side))
                    .or_insert(side);
            }
        }
        let mut parents: Vec<(NodeId, Side)> = uniform
            .into_iter()
            .filter_map(|(p, side)| Some((p, side?)))
            .collect();
        if parents.is_empty() {
            return Vec::new();
        }
        parents.sort_unstable_by_key(|&(p, _)| p);
        let ids: Vec<NodeId> = parents.iter().map(|&(p, _)| p).collect();
        let steps = mesh.coarsen_many(&ids);
        for (parent, side) in parents {
            if !matches!(mesh.node(parent).split(), Split::Red { .. }) {
                let paths = corner_paths(mesh, cache, parent, side);
                self.merged.insert(parent, Merged { side, paths });
                self.merges += 1;
            }
        }
        steps
    }

    /// Whether a criterion's selection of `leaf` may be split: not a merged parent (nor a green
    /// half of one, which coarsening bisected along an edge a neighbour still splits) whose
    /// corner samples have gained no paths since it was merged.
    pub fn allows(&mut self, leaf: NodeId, mesh: &SubdivisionMesh, cache: &ShadingCache) -> bool {
        if self.merged.is_empty() {
            return true;
        }
        let node = mesh.node(leaf);
        let holder = if self.merged.contains_key(&leaf) {
            leaf
        } else {
            match node.parent() {
                Some(p) if node.kind() == NodeKind::Green && self.merged.contains_key(&p) => p,
                _ => return true,
            }
        };
        let record = self.merged[&holder];
        if corner_paths(mesh, cache, holder, record.side) == record.paths {
            return false;
        }
        self.merged.remove(&holder);
        true
    }
}

/// The paths of a node's corner samples on `side` (0 where none is cached).
fn corner_paths(
    mesh: &SubdivisionMesh,
    cache: &ShadingCache,
    node: NodeId,
    side: Side,
) -> [u32; 3] {
    mesh.node(node).vertices.map(|vertex| {
        cache
            .get(SampleKey { vertex, side })
            .map_or(0, |s| s.quality.paths)
    })
}

impl super::Schedule {
    /// Coarsening by uniformity over every view shown with a tone map (thesis §6, DESIGN.md
    /// §4): a sample has settled from the rung whose variance the ladder believes, at the
    /// scene's depth. Returns whether the leaves changed.
    pub(super) fn merge_uniform(&mut self) -> bool {
        let views: Vec<JudgedView> = self
            .viewers
            .iter()
            .filter_map(|v| {
                Some(JudgedView {
                    visible: &v.view.as_ref()?.visible,
                    l_white: v.last_l_white?,
                })
            })
            .collect();
        let qualities = self.rules.qualities;
        let trusted = |q: Quality| q.bounces == qualities.full.bounces && qualities.trusts(q);
        self.refinement
            .merge_uniform(&views, &mut self.mesh, &self.cache, &trusted)
    }
}

#[cfg(test)]
mod tests;
