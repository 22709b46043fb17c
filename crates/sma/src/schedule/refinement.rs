//! Refinement rounds and the luminance image (DESIGN.md §3 step 6, §4, §6): a criterion's
//! selections split into pending groups, groups committed once their visible leaves are shaded,
//! coarsening of what no viewer has seen lately and of what a split showed to be uniform
//! (`uniformity`), and the Gouraud luminance image that image-space criteria read. Each step
//! says what it changed; the schedule tells the viewers and the queue.

use std::collections::{HashMap, HashSet};

use anyhow::Context;

use super::coarsening::Coarsening;
use super::pending::PendingRefinement;
use super::uniformity::{JudgedView, UniformMerge};
use super::viewers::Viewer;
use crate::cache::ShadingCache;
use crate::config::ScheduleConfig;
use crate::criteria::{CriterionInput, LuminanceImage};
use crate::mesh::{NodeId, RefinementStep, SubdivisionMesh};
use crate::viewer_link::ViewerId;
use crate::visibility::{LeafView, LuminancePass, Visibility};
use protocol::renderer_link::Quality;

/// Empty criterion calls in a row after which a viewer's refinement counts as exhausted (enough
/// for `nld-os` to step S_ref from its start down to S_min with the default settings).
const EMPTY_CALLS_BEFORE_EXHAUSTED: usize = 32;

/// Refinement's state: the steps waiting for their samples, what coarsening watches, and the
/// rounds so far.
#[derive(Debug)]
pub struct Refinement {
    /// Refinement and coarsening steps waiting for their samples.
    pub pending: PendingRefinement,
    coarsening: Coarsening,
    /// Coarsening by uniformity (thesis §6), when on.
    uniform: UniformMerge,
    /// Rounds so far: the ready viewers take turns (`turns::refinement_candidate`).
    pub rounds: usize,
    /// R: selections per round (§4.3.5).
    max_selections: usize,
    /// No leaf covering fewer pixels is split.
    min_split_pixels: u32,
}

/// What one round did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Round {
    /// The criterion found nothing more for the view; `newly_dry` when it had found something
    /// before (its samples may now get more paths: the queue is stale).
    Exhausted { newly_dry: bool },
    /// Every selected leaf was too small to split.
    TooSmall,
    /// Leaves were split: every view's leaves changed.
    Refined,
}

impl Refinement {
    pub fn new(base_count: usize, config: &ScheduleConfig) -> Refinement {
        Refinement {
            pending: PendingRefinement::default(),
            coarsening: Coarsening::new(base_count, config.coarsen_after_passes),
            uniform: UniformMerge::new(config),
            rounds: 0,
            max_selections: config.max_selections,
            min_split_pixels: config.min_split_pixels,
        }
    }

    /// Marks what a view shows as seen at `frame` (coarsening spares it).
    pub fn seen(&mut self, mesh: &SubdivisionMesh, view: &LeafView, frame: u64) {
        self.coarsening.seen(mesh, &view.visible, frame);
    }

    /// Collapses subdivision out of every view for long (DESIGN.md §4, thesis §6) before the
    /// passes, so they see the coarser mesh; steps wait in the pending groups like refinement
    /// steps until what they expose is shaded. Not while refinement steps wait, whose leaves
    /// they could remove. Returns whether the leaves changed.
    pub fn coarsen_stale(&mut self, mesh: &mut SubdivisionMesh, frame: u64) -> bool {
        if !self.pending.is_empty() {
            return false;
        }
        let steps = self.coarsening.collapse_stale(mesh, frame);
        if steps.is_empty() {
            return false;
        }
        tracing::debug!(
            steps = steps.len(),
            leaves = mesh.leaf_count(),
            refined_bases = self.coarsening.refined_bases(),
            "coarsened what no viewer has seen lately"
        );
        self.pending.add(steps);
        true
    }

    /// Under the memory budget's pressure (`memory`): collapses the `share` of the refined base
    /// triangles in no view that were seen least recently, as [`Self::coarsen_stale`] does (and
    /// not while refinement steps wait). Returns whether the leaves changed.
    pub fn coarsen_pressed(&mut self, mesh: &mut SubdivisionMesh, frame: u64, share: f64) -> bool {
        if !self.pending.is_empty() {
            return false;
        }
        let steps = self.coarsening.collapse_least_recent(mesh, frame, share);
        if steps.is_empty() {
            return false;
        }
        tracing::debug!(
            steps = steps.len(),
            leaves = mesh.leaf_count(),
            "coarsened what was seen least recently, for the memory budget"
        );
        self.pending.add(steps);
        true
    }

    /// Under the memory budget's pressure with a cache file (`persistence`): the `share` of the
    /// refined base triangles in no view, among those `eligible`, that were seen least recently.
    pub fn least_recent_unseen(
        &mut self,
        frame: u64,
        share: f64,
        eligible: impl Fn(u32) -> bool,
    ) -> Vec<u32> {
        self.coarsening.least_recent(frame, share, eligible)
    }

    /// The refined base triangles no view has seen for the set number of passes, with a cache
    /// file (`persistence`); not while refinement steps wait, as [`Self::coarsen_stale`].
    pub fn stale(&self, frame: u64) -> Vec<u32> {
        if !self.pending.is_empty() {
            return Vec::new();
        }
        self.coarsening.stale(frame)
    }

    /// Whether no view saw base triangle `base` at `frame`.
    pub fn unseen(&self, base: u32, frame: u64) -> bool {
        self.coarsening.unseen(base, frame)
    }

    /// Subtrees the cache file brought back or took away: their steps wait in the pending
    /// groups like a round's, and coarsening follows the base triangles they refined.
    pub fn cache_file_steps(
        &mut self,
        mesh: &SubdivisionMesh,
        steps: Vec<RefinementStep>,
        left: &[u32],
    ) {
        self.coarsening.refined(mesh, &steps);
        self.coarsening.collapsed(mesh, left);
        self.pending.add_from_file(steps);
    }

    /// Whether the last coarsening under the memory budget's pressure found nothing out of view
    /// to collapse.
    pub fn pressed_in_vain(&self) -> bool {
        self.coarsening.pressed_in_vain()
    }

    /// Whether a pass of coarsening by uniformity is due (it is on, and samples or views came
    /// since the last one).
    pub fn merge_due(&self) -> bool {
        self.uniform.is_due()
    }

    /// New samples or views: a parent undecided before may be decided now.
    pub fn merge_input(&mut self) {
        self.uniform.new_input();
    }

    /// Parents merged back by uniformity since the start.
    pub fn uniform_merges(&self) -> u64 {
        self.uniform.merges()
    }

    /// Merges back what the views show to be uniform (thesis §6, `uniformity`); the steps wait
    /// in the pending groups like coarsening's. Not while refinement steps wait, whose leaves
    /// they could remove. Returns whether the leaves changed.
    pub fn merge_uniform(
        &mut self,
        views: &[JudgedView],
        mesh: &mut SubdivisionMesh,
        cache: &ShadingCache,
        trusted: &dyn Fn(Quality) -> bool,
    ) -> bool {
        if !self.pending.is_empty() {
            return false;
        }
        let steps = self.uniform.pass(views, mesh, cache, trusted);
        if steps.is_empty() {
            return false;
        }
        tracing::debug!(
            steps = steps.len(),
            leaves = mesh.leaf_count(),
            merged_uniform = self.uniform.merges(),
            "merged uniform subdivision back"
        );
        self.pending.add(steps);
        true
    }

    /// Commits every pending group none of whose visible new leaves lacks a sample (its guards
    /// counted only where it waits for them, `Group::waits_for_guards`); returns whether any
    /// was.
    pub fn commit_ready<'a>(
        &mut self,
        views: impl Iterator<Item = &'a LeafView>,
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
    ) -> bool {
        if self.pending.is_empty() {
            return false;
        }
        let mut waiting = HashSet::new();
        for view in views {
            for v in &view.visible.leaves {
                if let Some(g) = self.pending.group_of(v.leaf)
                    && (v.pixels > 0 || self.pending.waits_for_guards(g))
                    && cache.missing_keys(mesh, v.leaf, v.side).next().is_some()
                {
                    waiting.insert(g);
                }
            }
        }
        let ready: Vec<usize> = self
            .pending
            .ids()
            .into_iter()
            .filter(|g| !waiting.contains(g))
            .collect();
        if ready.is_empty() {
            return false;
        }
        for g in ready {
            self.pending.commit(g);
        }
        true
    }

    /// One refinement round for one viewer, which has a view (DESIGN.md §3 step 6, §6), with
    /// the luminance image of what it shows when its criterion needs one.
    pub fn round(
        &mut self,
        id: ViewerId,
        viewer: &mut Viewer,
        image: Option<LuminanceImage>,
        mesh: &mut SubdivisionMesh,
        cache: &ShadingCache,
    ) -> Round {
        self.rounds += 1;
        let view = viewer.view.as_ref().expect("candidate has a view");
        let input = CriterionInput {
            mesh,
            cache,
            visible: &view.visible,
            l_white: viewer
                .last_l_white
                .unwrap_or_else(|| cache.l_white(mesh, &view.visible)),
            image: image.as_ref(),
        };
        // A criterion may answer an empty call and still have more to give: `nld-os` lowers
        // S_ref one step after a pass that selects nothing (§4.3.4). Only a run of empty calls
        // means it has nothing left for this view.
        let selected = (0..EMPTY_CALLS_BEFORE_EXHAUSTED)
            .map(|_| viewer.criterion.select(&input, self.max_selections))
            .find(|s| !s.is_empty())
            .unwrap_or_default();
        if selected.is_empty() {
            viewer.wait.exhausted();
            let newly_dry = !viewer.criterion_dry;
            viewer.criterion_dry = true;
            tracing::debug!(viewer = id, "criterion found nothing more to refine");
            return Round::Exhausted { newly_dry };
        }
        viewer.criterion_dry = false;
        let pixels: HashMap<NodeId, u32> = view
            .visible
            .leaves
            .iter()
            .map(|v| (v.leaf, v.pixels))
            .collect();
        let min_pixels = self.min_split_pixels;
        let too_small = |leaf: NodeId| pixels.get(&leaf).is_none_or(|&p| p < min_pixels);
        // A resumable criterion may still hold a leaf that coarsening has removed since; a
        // parent merged by uniformity is not split again on the samples that merged it.
        let selected: Vec<NodeId> = selected
            .into_iter()
            .filter(|&l| mesh.is_leaf(l) && self.uniform.allows(l, mesh, cache))
            .collect();
        let steps = mesh.refine(&selected, &too_small);
        if steps.is_empty() {
            // Every selected leaf was too small; criteria offer a leaf once per view, so the
            // next round moves on to others.
            tracing::debug!(
                viewer = id,
                selected = selected.len(),
                "selected leaves too small"
            );
            return Round::TooSmall;
        }
        tracing::debug!(
            viewer = id,
            selected = selected.len(),
            steps = steps.len(),
            "refinement round"
        );
        self.coarsening.refined(mesh, &steps);
        self.pending.add(steps);
        Round::Refined
    }
}

/// The Gouraud luminance image of what `viewer` shows, when its criterion needs one.
pub fn luminance_image(
    viewer: &Viewer,
    mesh: &SubdivisionMesh,
    visibility: &Visibility,
    luminance: &mut LuminancePass,
) -> anyhow::Result<Option<LuminanceImage>> {
    // The view's own camera: a walking viewer's view is drawn ahead of its camera
    // (`Viewer::pass_camera`), and the image must match its leaf per pixel.
    let Some((view, camera)) = viewer
        .view
        .as_ref()
        .and_then(|v| Some((v, v.camera.as_ref()?)))
    else {
        return Ok(None);
    };
    if !viewer.criterion.needs_image() {
        return Ok(None);
    }
    let triangles: Vec<_> = viewer
        .shown
        .shown_triangles()
        .map(|(corners, luminance)| (corners.map(|v| mesh.vertex(v).position), luminance))
        .collect();
    let pass_view = visibility.view(camera);
    let lum = luminance
        .render(visibility.gpu(), &triangles, &pass_view)
        .context("luminance pass")?;
    let ids = view
        .pixel_leaves
        .iter()
        .map(|l| l.unwrap_or(LuminanceImage::NONE))
        .collect();
    Ok(Some(LuminanceImage {
        width: camera.width,
        height: camera.height,
        luminance: lum,
        ids,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::CachedSample;
    use crate::mesh::grid_mesh;
    use crate::visible_set::{VisibleLeaf, VisibleSet};
    use protocol::SampleParts;
    use protocol::Side;
    use protocol::renderer_link::SampleKey;

    /// A refined grid whose new leaves are all visible, one of them as a guard (no pixels),
    /// every vertex shaded but one corner of the guard's.
    fn refined_with_an_unshaded_guard()
    -> (SubdivisionMesh, Vec<RefinementStep>, LeafView, ShadingCache) {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let steps = mesh.refine(&[0], &|_| false);
        let leaves: Vec<NodeId> = mesh.leaves().collect();
        let guard = *steps[0].new_leaves.last().expect("a split makes leaves");
        let unshaded = mesh.node(guard).vertices[2];
        let mut cache = ShadingCache::new(1 << 20);
        for vertex in (0..mesh.vertex_count() as u32).filter(|&v| v != unshaded) {
            let sample = CachedSample::diffuse(SampleParts::direct_only([0.5; 3], 0.0));
            cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                sample,
            );
        }
        let mut visible = VisibleSet::of_front_leaves(&leaves);
        let others_of_unshaded =
            |v: &VisibleLeaf| v.leaf != guard && mesh.node(v.leaf).vertices.contains(&unshaded);
        visible.leaves.retain(|v| !others_of_unshaded(v));
        for v in visible.leaves.iter_mut().filter(|v| v.leaf == guard) {
            v.pixels = 0;
        }
        let view = LeafView {
            visible,
            ..Default::default()
        };
        (mesh, steps, view, cache)
    }

    #[test]
    fn a_refinement_step_waits_for_its_guards_and_a_restored_subtree_does_not() {
        let config = ScheduleConfig::default();
        let (mesh, steps, view, cache) = refined_with_an_unshaded_guard();
        let mut refinement = Refinement::new(mesh.base_count(), &config);
        refinement.pending.add(steps.clone());
        let views = || std::iter::once(&view);
        assert!(
            !refinement.commit_ready(views(), &mesh, &cache),
            "waits for its guard"
        );
        assert!(!refinement.pending.is_empty());

        let mut restored = Refinement::new(mesh.base_count(), &config);
        restored.cache_file_steps(&mesh, steps, &[]);
        assert!(
            restored.commit_ready(views(), &mesh, &cache),
            "shown at once"
        );
        assert!(restored.pending.is_empty());
    }
}
