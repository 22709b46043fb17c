//! Refinement rounds and the luminance image (DESIGN.md §3 step 6, §4, §6): a criterion's
//! selections split into pending groups, groups committed once their visible leaves are shaded,
//! coarsening of what no viewer has seen lately, and the Gouraud luminance image that image-space
//! criteria read.

use std::collections::{HashMap, HashSet};

use anyhow::Context;

use super::Schedule;
use crate::criteria::{CriterionInput, LuminanceImage};
use crate::mesh::NodeId;
use crate::viewer_link::ViewerId;

impl Schedule {
    /// Collapses subdivision out of every view for long (DESIGN.md §4, thesis §6) before the
    /// passes, so they see the coarser mesh; steps wait in the pending groups like refinement
    /// steps until what they expose is shaded. Not while refinement steps wait, whose leaves
    /// they could remove.
    pub(super) fn coarsen_stale(&mut self) {
        if !self.pending.is_empty() {
            return;
        }
        let steps = self.coarsening.collapse_stale(&mut self.mesh, self.frame);
        if steps.is_empty() {
            return;
        }
        tracing::debug!(
            steps = steps.len(),
            leaves = self.mesh.leaf_count(),
            refined_bases = self.coarsening.refined_bases(),
            "coarsened what no viewer has seen lately"
        );
        self.pending.add(steps);
        for viewer in self.viewers.values_mut() {
            viewer.wait.leaves_changed();
        }
    }

    /// Commits every pending group none of whose visible new leaves lacks a sample.
    pub(super) fn commit_ready_groups(&mut self) {
        if self.pending.is_empty() {
            return;
        }
        let mut waiting = HashSet::new();
        for view in self.viewers.values().filter_map(|v| v.view.as_ref()) {
            for v in &view.visible.leaves {
                if let Some(g) = self.pending.group_of(v.leaf)
                    && self
                        .cache
                        .missing_keys(&self.mesh, v.leaf, v.side)
                        .next()
                        .is_some()
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
            return;
        }
        for g in ready {
            self.pending.commit(g);
        }
        for viewer in self.viewers.values_mut() {
            viewer.wait.new_input();
        }
        self.owed.groups_committed();
    }

    /// Empty criterion calls in a row after which a viewer's refinement counts as exhausted (enough
    /// for `nld-os` to step S_ref from its start down to S_min with the default settings).
    const EMPTY_CALLS_BEFORE_EXHAUSTED: usize = 32;

    /// One refinement round for one viewer (DESIGN.md §3 step 6, §6).
    pub(super) fn refine_round(&mut self, id: ViewerId) -> anyhow::Result<()> {
        self.refine_turn += 1;
        let image = self.luminance_image(id)?;
        let viewer = self.viewers.get_mut(&id).expect("candidate exists");
        let view = viewer.view.as_ref().expect("candidate has a view");
        let input = CriterionInput {
            mesh: &self.mesh,
            cache: &self.cache,
            visible: &view.visible,
            l_white: viewer
                .last_l_white
                .unwrap_or_else(|| self.cache.l_white(&self.mesh, &view.visible)),
            image: image.as_ref(),
        };
        // A criterion may answer an empty call and still have more to give: `nld-os` lowers
        // S_ref one step after a pass that selects nothing (§4.3.4). Only a run of empty calls
        // means it has nothing left for this view.
        let selected = (0..Self::EMPTY_CALLS_BEFORE_EXHAUSTED)
            .map(|_| viewer.criterion.select(&input, self.config.max_selections))
            .find(|s| !s.is_empty())
            .unwrap_or_default();
        if selected.is_empty() {
            viewer.wait.exhausted();
            if !viewer.criterion_dry {
                viewer.criterion_dry = true;
                // Its samples may now get more paths.
                self.owed.queue_changed();
            }
            tracing::debug!(viewer = id, "criterion found nothing more to refine");
            return Ok(());
        }
        viewer.criterion_dry = false;
        let pixels: HashMap<NodeId, u32> = view
            .visible
            .leaves
            .iter()
            .map(|v| (v.leaf, v.pixels))
            .collect();
        let min_pixels = self.config.min_split_pixels;
        let too_small = |leaf: NodeId| pixels.get(&leaf).is_none_or(|&p| p < min_pixels);
        // A resumable criterion may still hold a leaf that coarsening has removed since.
        let selected: Vec<NodeId> = selected
            .into_iter()
            .filter(|&l| self.mesh.is_leaf(l))
            .collect();
        let steps = self.mesh.refine(&selected, &too_small);
        if steps.is_empty() {
            // Every selected leaf was too small; criteria offer a leaf once per view, so the
            // next round moves on to others.
            tracing::debug!(
                viewer = id,
                selected = selected.len(),
                "selected leaves too small"
            );
            return Ok(());
        }
        tracing::debug!(
            viewer = id,
            selected = selected.len(),
            steps = steps.len(),
            "refinement round"
        );
        self.coarsening.refined(&self.mesh, &steps);
        self.pending.add(steps);
        for viewer in self.viewers.values_mut() {
            viewer.wait.leaves_changed();
        }
        Ok(())
    }

    /// The Gouraud luminance image of what `id` shows, when its criterion needs one.
    fn luminance_image(&mut self, id: ViewerId) -> anyhow::Result<Option<LuminanceImage>> {
        let viewer = &self.viewers[&id];
        let (Some(view), Some(camera)) = (&viewer.view, &viewer.camera) else {
            return Ok(None);
        };
        if !viewer.criterion.needs_image() {
            return Ok(None);
        }
        let triangles: Vec<_> = viewer
            .display
            .shown_triangles()
            .map(|(node, rgb)| {
                (
                    self.mesh.leaf_positions(node),
                    rgb.map(conventions::luminance),
                )
            })
            .collect();
        let pass_view = self.visibility.view(camera);
        let lum = self
            .luminance
            .render(self.visibility.gpu(), &triangles, &pass_view)
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
}
