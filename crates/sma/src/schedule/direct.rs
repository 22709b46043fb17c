//! The schedule's side of per-pixel direct light (DESIGN.md §3 step 8, `direct_tiles`): each
//! resting viewer's next passes go to the pool's tile lane, each answer merged into its tile and
//! forwarded to the viewer's outbox, and the passes of a camera that moved are withdrawn.

use protocol::viewer_link::SmaToViewer;

use super::Schedule;
use super::viewers::Viewer;
use crate::direct_tiles::{DirectTiles, TileTarget};
use crate::pool::TileNews;

impl Schedule {
    /// Withdraws the passes of old cameras, then asks for the next pass of every tile of each
    /// resting viewer's camera (the pool sends them only while no batch waits). A camera whose
    /// tiles would not fit the memory budget gets none, and tiles are dropped once everything
    /// no longer fits: per-pixel direct light refines the picture, as a round of splits does,
    /// and the budget wins (DESIGN.md §5).
    pub(super) fn request_tiles(&mut self) {
        let settings = self.config.direct_tiles;
        let account = self.memory_account();
        for viewer in self.viewers.iter_mut() {
            let withdrawn = viewer.direct.take_withdrawn();
            if !withdrawn.is_empty() {
                self.pool.withdraw_tiles(&withdrawn);
            }
            let Some(camera) = &viewer.camera else {
                continue;
            };
            // A viewer's first camera rests at once (`turns::TurnView::camera_replaced`).
            let rests = !viewer.camera_replaced || viewer.camera_at.elapsed() >= self.config.rest;
            if !settings.enabled || self.renderers == 0 || viewer.paused || !rests {
                continue;
            }
            let growth = if viewer.direct.holds(camera) {
                0
            } else {
                DirectTiles::bytes_for(camera)
            };
            if !self.memory.fits(&account, growth) {
                if growth > 0 || viewer.direct.heap_bytes() > 0 {
                    tracing::debug!(
                        camera = camera.seq,
                        "no direct tiles: the memory budget is full"
                    );
                    viewer.direct.decline(camera);
                }
                continue;
            }
            let target = target(viewer, self.config.display_error);
            for request in viewer.direct.requests(camera, settings.lights, target) {
                self.pool.submit_tile(request);
            }
        }
    }

    /// The stated end (DESIGN.md §5) with per-pixel direct light on also waits for every tile
    /// of the viewer's camera to show a displayed standard error below the display error
    /// (`direct_tiles::Tile::done` states the statistic).
    pub(super) fn tiles_converged(&self, viewer: &Viewer) -> bool {
        let target = target(viewer, self.config.display_error);
        !self.config.direct_tiles.enabled || viewer.direct.converged(target)
    }

    pub(super) fn on_tile_news(&mut self, news: TileNews) {
        match news {
            TileNews::Answered(answer) => {
                let asker = (self.viewers.iter_mut()).find(|v| v.direct.asked(answer.tile_id));
                let Some(viewer) = asker else {
                    // Asked for a camera that has moved since, or by a viewer that left.
                    tracing::debug!(tile_id = answer.tile_id, "tile answer of no resting camera");
                    return;
                };
                match viewer.direct.answered(&answer) {
                    Ok(tile) => viewer.send(SmaToViewer::DirectTile(tile)),
                    Err(reason) => tracing::warn!(%reason, "tile answer refused"),
                }
            }
            TileNews::Dropped { tile_id, reason } => {
                tracing::debug!(tile_id, %reason, "tile pass not answered; asked again");
                for viewer in self.viewers.iter_mut() {
                    viewer.direct.dropped(tile_id);
                }
            }
        }
    }
}

/// A viewer's tiles are judged through its last tone map.
fn target(viewer: &Viewer, display_error: f32) -> TileTarget {
    TileTarget {
        l_white: viewer.last_l_white,
        display_error,
    }
}
