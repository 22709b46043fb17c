//! What the viewer knows, window or headless: the scene, the triangle table, L_white and the SMA's
//! latest counters, kept in step with the link's events.

use protocol::viewer_link::{Epoch, SceneInfo, Stats};

use crate::link::LinkEvent;
use crate::table::TriangleTable;

/// What the front end must do after an event.
#[derive(Debug, PartialEq)]
pub enum Reaction {
    Nothing,
    /// A new session began: send the camera, criterion and pause state again.
    Resend,
    /// An epoch closed an update; the table changed.
    Drawn(Epoch),
}

pub struct ViewState {
    pub scene: Option<SceneInfo>,
    pub table: TriangleTable,
    /// The SMA's L_white (thesis §2.3); 1 until it sends one.
    pub l_white: f32,
    pub epoch: Option<Epoch>,
    /// Counters summed over the epochs since `take_interval` (Δins, Δrem of thesis table 5.2).
    pub interval_inserted: u64,
    pub interval_removed: u64,
    pub stats: Stats,
    /// Active criterion and whether refinement is paused, as the SMA last said.
    pub refinement: Option<(String, bool)>,
    pub connected: bool,
}

impl Default for ViewState {
    fn default() -> Self {
        ViewState {
            scene: None,
            table: TriangleTable::new(),
            l_white: 1.0,
            epoch: None,
            interval_inserted: 0,
            interval_removed: 0,
            stats: Stats::default(),
            refinement: None,
            connected: false,
        }
    }
}

impl ViewState {
    pub fn handle(&mut self, event: LinkEvent) -> Reaction {
        match event {
            LinkEvent::Connected(info) => {
                self.table.clear();
                self.epoch = None;
                self.refinement = info.criteria.first().map(|c| (c.clone(), false));
                self.scene = Some(info);
                self.connected = true;
                return Reaction::Resend;
            }
            LinkEvent::Scene(info) => self.scene = Some(info),
            LinkEvent::Update(update) => {
                let counts = self.table.apply(&update.ops);
                if counts.ignored > 0 {
                    // Removes or recolours of triangles never inserted: the SMA and the viewer
                    // disagree, which the next session (or the SMA's log) must explain.
                    tracing::debug!(?counts, epoch = ?update.epoch, "update touched unknown triangles");
                }
                if let Some(l_white) = update.l_white {
                    self.l_white = l_white;
                }
                self.interval_inserted += update.epoch.inserted;
                self.interval_removed += update.epoch.removed;
                self.epoch = Some(update.epoch);
                return Reaction::Drawn(update.epoch);
            }
            LinkEvent::Refinement { criterion, paused } => {
                self.refinement = Some((criterion, paused))
            }
            LinkEvent::Stats(stats) => self.stats = stats,
            LinkEvent::RemoteError(message) => tracing::warn!(%message, "the SMA reports an error"),
            LinkEvent::Disconnected(_) => self.connected = false,
        }
        Reaction::Nothing
    }

    /// Δins and Δrem since the previous call.
    pub fn take_interval(&mut self) -> (u64, u64) {
        let counts = (self.interval_inserted, self.interval_removed);
        (self.interval_inserted, self.interval_removed) = (0, 0);
        counts
    }
}
