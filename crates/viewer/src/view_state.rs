//! What the viewer knows, window or headless: the scene, the triangle table, L_white and the SMA's
//! latest counters, kept in step with the link's events.

use protocol::viewer_link::{Epoch, SceneInfo, SkyInfo, Stats};

use std::sync::Arc;

use crate::direct_image::DirectImage;
use crate::link::LinkEvent;
use crate::looks::Looks;
use crate::table::TriangleTable;

/// What the system is doing for this viewer, as the panel and the progress line say it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activity {
    /// No SMA session.
    Connecting,
    /// The SMA has no renderer to compute samples.
    NoRenderer,
    Paused,
    /// The SMA has nothing more to do for this view.
    Converged,
    Refining,
}

impl std::fmt::Display for Activity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Activity::Connecting => "connecting",
            Activity::NoRenderer => "no renderer",
            Activity::Paused => "paused",
            Activity::Converged => "converged",
            Activity::Refining => "refining",
        })
    }
}

/// What the front end must do after an event.
#[derive(Debug, PartialEq)]
pub enum Reaction {
    Nothing,
    /// A new session began: send the camera, criterion and pause state again.
    Resend,
    /// An epoch closed an update; the table changed.
    Drawn(Epoch),
    /// A direct tile of the current camera, or a texture, arrived: the picture changed.
    Tile,
}

pub struct ViewState {
    pub scene: Option<SceneInfo>,
    pub table: TriangleTable,
    /// The per-pixel direct tiles of the camera last sent (the front end follows its cameras).
    pub direct: DirectImage,
    /// The scene's materials and textures (shared with snapshots copied meanwhile).
    pub looks: Arc<Looks>,
    /// The SMA's L_white (thesis §2.3); 1 until it sends one.
    pub l_white: f32,
    pub epoch: Option<Epoch>,
    /// Counters summed over the epochs since `take_interval` (Δins, Δrem of thesis table 5.2).
    pub interval_inserted: u64,
    pub interval_removed: u64,
    pub stats: Stats,
    /// Whether this session has had its first `Stats` yet.
    stats_seen: bool,
    /// Active criterion and whether refinement is paused, as the SMA last said.
    pub refinement: Option<(String, bool)>,
    pub connected: bool,
}

impl Default for ViewState {
    fn default() -> Self {
        ViewState {
            scene: None,
            table: TriangleTable::new(),
            direct: DirectImage::default(),
            looks: Arc::default(),
            l_white: 1.0,
            epoch: None,
            interval_inserted: 0,
            interval_removed: 0,
            stats: Stats::default(),
            stats_seen: false,
            refinement: None,
            connected: false,
        }
    }
}

impl ViewState {
    /// What the SMA's latest `Stats` and `Refinement` say; a paused view still shades what is
    /// visible, so "paused" yields to "converged" once that is done.
    pub fn activity(&self) -> Activity {
        let paused = self.refinement.as_ref().is_some_and(|(_, p)| *p);
        match () {
            _ if !self.connected => Activity::Connecting,
            _ if self.stats.converged => Activity::Converged,
            _ if self.stats.renderers == 0 => Activity::NoRenderer,
            _ if paused => Activity::Paused,
            _ => Activity::Refining,
        }
    }

    /// The scene's sky, black until the scene is known.
    pub fn sky(&self) -> SkyInfo {
        self.scene.as_ref().map(|s| s.sky).unwrap_or_default()
    }

    pub fn handle(&mut self, event: LinkEvent) -> Reaction {
        match event {
            LinkEvent::Connected(info) => {
                self.table.clear();
                self.direct.clear();
                self.epoch = None;
                self.stats_seen = false;
                self.refinement = info.criteria.first().map(|c| (c.clone(), false));
                self.looks = Arc::new(Looks::of(&info));
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
                if update.epoch.shown > 0 && self.epoch.is_none_or(|e| e.shown == 0) {
                    tracing::info!(
                        triangles = update.epoch.shown,
                        samples = update.epoch.samples,
                        "first picture"
                    );
                }
                self.interval_inserted += update.epoch.inserted;
                self.interval_removed += update.epoch.removed;
                self.epoch = Some(update.epoch);
                return Reaction::Drawn(update.epoch);
            }
            LinkEvent::Texture(image) => {
                if Arc::make_mut(&mut self.looks).accept(&image) {
                    return Reaction::Tile;
                }
            }
            LinkEvent::DirectTile(tile) => {
                if self.direct.accept(&tile) {
                    return Reaction::Tile;
                }
            }
            LinkEvent::Refinement { criterion, paused } => {
                self.refinement = Some((criterion, paused))
            }
            LinkEvent::Stats(stats) => {
                log_changes(self.stats_seen.then_some(&self.stats), &stats);
                (self.stats, self.stats_seen) = (stats, true);
            }
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

/// What a person wants to hear of a new `Stats` (`old`: the session's previous one); the rest
/// is at debug level.
fn log_changes(old: Option<&Stats>, new: &Stats) {
    let was = old.copied().unwrap_or_default();
    if new.converged && !was.converged {
        // The SMA says so at info level itself; the panel shows it to the person at the viewer.
        tracing::debug!("converged: nothing more to refine or shade for this view");
    }
    match old {
        None if new.renderers == 0 => {
            tracing::warn!("the SMA has no renderer: nothing is shaded until one joins")
        }
        Some(old) if new.renderers > old.renderers => {
            tracing::info!(renderers = new.renderers, "a renderer joined")
        }
        Some(old) if new.renderers < old.renderers => {
            tracing::warn!(renderers = new.renderers, "a renderer was lost")
        }
        _ => {}
    }
    tracing::debug!(?new, "stats");
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene() -> SceneInfo {
        SceneInfo {
            name: "s".into(),
            fingerprint: [0; 32],
            bounds: protocol::types::Bounds {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            viewpoints: vec![],
            criteria: vec!["rnd".into()],
            sky: SkyInfo::default(),
            quality: protocol::renderer_link::Quality {
                paths: 1,
                bounces: None,
            },
            textures: false,
            materials: vec![],
            texture_table: vec![],
        }
    }

    fn stats(renderers: u32, converged: bool) -> LinkEvent {
        LinkEvent::Stats(Stats {
            renderers,
            converged,
            ..Stats::default()
        })
    }

    #[test]
    fn the_activity_follows_the_session_the_stats_and_the_pause() {
        let mut state = ViewState::default();
        assert_eq!(state.activity(), Activity::Connecting);
        state.handle(LinkEvent::Connected(scene()));
        state.handle(stats(0, false));
        assert_eq!(state.activity(), Activity::NoRenderer);
        state.handle(stats(2, false));
        assert_eq!(state.activity(), Activity::Refining);
        state.handle(LinkEvent::Refinement {
            criterion: "rnd".into(),
            paused: true,
        });
        assert_eq!(state.activity(), Activity::Paused);
        state.handle(stats(2, true));
        assert_eq!(state.activity(), Activity::Converged);
        state.handle(LinkEvent::Disconnected("gone".into()));
        assert_eq!(state.activity(), Activity::Connecting);
    }

    /// A session's textures reach its looks; a new session starts from its own scene's.
    #[test]
    fn textures_reach_the_looks_and_a_new_session_forgets_them() {
        let textured = SceneInfo {
            materials: vec![protocol::texture::MaterialLook {
                kd: [0.5; 3],
                texture: Some(protocol::texture::MaterialTexture {
                    index: 0,
                    times_kd: true,
                    clamp: false,
                }),
            }],
            texture_table: vec![protocol::texture::TextureInfo {
                name: "t.png".into(),
                width: 1,
                height: 1,
                bytes: 0,
            }],
            ..scene()
        };
        let mut png = Vec::new();
        image::RgbImage::from_pixel(1, 1, image::Rgb([9, 8, 7]))
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let texture =
            |png: Vec<u8>| LinkEvent::Texture(protocol::texture::TextureImage { index: 0, png });
        let mut state = ViewState::default();
        state.handle(LinkEvent::Connected(textured.clone()));
        assert_eq!(state.handle(texture(b"junk".to_vec())), Reaction::Nothing);
        assert_eq!(state.looks.drawn(8).0.len(), 0);
        assert_eq!(state.handle(texture(png)), Reaction::Tile);
        assert_eq!(state.looks.drawn(8).0.len(), 1);
        state.handle(LinkEvent::Connected(textured));
        assert_eq!(state.looks.drawn(8).0.len(), 0);
    }
}
