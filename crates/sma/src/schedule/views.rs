//! Each viewer's view for a pass (DESIGN.md §3): carried over onto the changed leaves while its
//! camera stays, drawn afresh otherwise; a walking viewer's a little ahead of its camera
//! (`Viewer::pass_camera`), and drawn again from its camera once that rests. While the cache
//! file holds records not loaded yet, those of the base triangles the views show are loaded and
//! the views carried over onto their leaves, until no view shows another (`persistence`, the
//! file's lazy loading).

use std::time::Instant;

use anyhow::Context;

use super::Schedule;
use crate::visibility::carry_over;

impl Schedule {
    /// The views of the viewers owed a pass (`redraw`: drawn afresh even where they could be
    /// carried over); returns whether any was drawn.
    pub(super) fn pass_views(&mut self, redraw: bool) -> anyhow::Result<bool> {
        let mut drew = false;
        let lead = self.config.work_while_walking && self.config.lead_while_walking;
        loop {
            let now = Instant::now();
            for viewer in self.viewers.iter_mut().filter(|v| v.wait.needs_pass()) {
                viewer.wait.pass_done();
                let Some(camera) = viewer.pass_camera(lead, self.config.rest, now) else {
                    continue;
                };
                // The camera unchanged, only the leaves did (a round, coarsening): the view is
                // carried over, exact but for slivers, without drawing (`visibility::carry_over`).
                let carried = viewer
                    .view
                    .take()
                    .filter(|view| !redraw && view.camera.as_ref() == Some(&camera))
                    .and_then(|view| carry_over(view, &self.mesh, &camera));
                let view = match carried {
                    Some(view) => view,
                    None => {
                        drew = true;
                        viewer.drawn_at = Some(now);
                        self.visibility
                            .leaf_view(&self.mesh, &camera)
                            .context("visibility pass")?
                    }
                };
                viewer.view = Some(view);
            }
            if !self.load_visible_records() {
                return Ok(drew);
            }
        }
    }
}
