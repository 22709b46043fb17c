//! The SMA's configuration as plain values (no argument parsing here: `cli` fills it from flags).
//! Every default is set once, in the `Default` impls, with the measurement behind it on the flag
//! in `cli` (DESIGN.md §6: each unstated thesis parameter is a flag with a measured default).

use std::time::Duration;

use protocol::admission::PortLimits;
use protocol::direct_tile::DirectLights;
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::liveness::Liveness;

use crate::cache::L_WHITE_OUTLIERS;
use crate::cache_file::CacheFileConfig;
use crate::criteria::{CriterionKind, CriterionSettings, Passes};
use crate::indirect_filter::IndirectFilterSettings;
use crate::mesh::{MeshParams, NeighbourRule};

/// A whole SMA: where it listens, which renderers it uses, and how it refines.
#[derive(Clone, Debug)]
pub struct SmaConfig {
    /// Address to accept viewers on; port 0 lets the OS pick (the bound address is reported).
    pub listen: String,
    /// Renderer `host:port`s the SMA dials.
    pub renderers: Vec<String>,
    /// Address of the port renderers join on (`renderer serve --join`); none: no such port.
    pub renderer_listen: Option<String>,
    /// Renderers served at once on `renderer_listen`, and their handshake deadline.
    pub renderer_port: PortLimits,
    /// The farm's liveness rule (DESIGN.md §2): heartbeats, silence, frame timeout; the viewer
    /// links use its frame timeout.
    pub liveness: Liveness,
    /// A batch is lost once this many times its expected time at its renderer's measured rate
    /// has passed (plus the silence limit).
    pub deadline_factor: f64,
    /// A batch's deadline before its renderer's rate is measured.
    pub first_deadline: Duration,
    /// Bytes of changes that may wait for one viewer; past them it is disconnected.
    pub viewer_backlog_bytes: usize,
    /// A viewer that answers no heartbeat for this long is lost (pinged every
    /// `liveness.heartbeat`).
    pub viewer_silence: Duration,
    /// Largest frame accepted or sent.
    pub max_frame: usize,
    /// Viewers served at once on `listen`, and their handshake deadline.
    pub viewer_port: PortLimits,
    /// The subdivision mesh: minimum edge, weld tolerance, neighbour rule (DESIGN.md §4).
    pub mesh: MeshParams,
    pub schedule: ScheduleConfig,
    /// The cache file the mesh and the samples are kept in between runs (DESIGN.md §5); none:
    /// everything learnt is lost at the stop.
    pub cache_file: Option<CacheFileConfig>,
}

impl Default for SmaConfig {
    fn default() -> Self {
        SmaConfig {
            listen: "127.0.0.1:7200".into(),
            renderers: Vec::new(),
            renderer_listen: None,
            renderer_port: PortLimits::default(),
            liveness: Liveness::default(),
            // A renderer slowed to a quarter by another job on its host is slow, not lost.
            deadline_factor: 4.0,
            // Until a renderer has answered once its heartbeats alone tell a hung one.
            first_deadline: Duration::from_secs(30),
            // Two maximum frames: the largest single update always fits.
            viewer_backlog_bytes: 2 * DEFAULT_MAX_FRAME,
            // A viewer's link answers from its own thread, but its machine may be a laptop
            // under load; ten seconds tells a partitioned one from a busy one.
            viewer_silence: Duration::from_secs(10),
            max_frame: DEFAULT_MAX_FRAME,
            viewer_port: PortLimits::default(),
            mesh: MeshParams::default(),
            schedule: ScheduleConfig::default(),
            cache_file: None,
        }
    }
}

impl SmaConfig {
    /// This configuration under `profile`: the one place a profile is applied, so whatever
    /// differs between the system of today and the thesis's is read here. `Profile::Today`
    /// changes nothing. `Profile::Thesis` runs the system as the thesis published it:
    ///
    /// - fixed-quality samples: every vertex is shaded once at the scene's quality preset, with
    ///   no quality ladder (no direct-light first sample, no early rung, no rungs above the
    ///   preset, no more paths where noise shows): the thesis's renderer returned one value per
    ///   vertex (§2.1, §2.2; DESIGN.md §5), so `ScheduleConfig::ladder` is off;
    /// - L_white the maximum luminance of the visible samples (§2.3 "the maximum luminance",
    ///   §4.3.2's L_max, appendix A's x_max), not a percentile: `l_white_outliers` 0;
    /// - NLD_IS leaves at least 6 pixels (§4.3.3): `nld_is_min_leaf_pixels`;
    /// - no noise discounting: `nld-os` and `nld-is` run as `nld-os-thesis` and
    ///   `nld-is-thesis` (eq. 4.6, 4.5), and `nld-px`, this project's criterion, is not offered
    ///   ([`Profile::criterion`]);
    /// - one pass of RND and of NLD_IS per camera, as §4.3.1 and §4.3.3 end them
    ///   (`Passes::One`); NLD_OS's passes, S_ref stepping down to S_min, are §4.3.4's own;
    /// - the thesis's neighbour rule (§4.2, fig. 4.7) in place of red–green's bisection;
    /// - no coarsening, by passes unseen or by uniformity (`merge_uniform`): removing
    ///   subdivision is future work in §6;
    /// - no object-space filter of the indirect part (`indirect_filter`) and no per-pixel direct
    ///   light (`direct_tiles`): the thesis shows each vertex's sample as the renderer answered
    ///   it, interpolated;
    /// - refinement only while the camera rests (DESIGN.md §3 step 6): no work while walking
    ///   (step 9), and every camera's pass at once;
    /// - no cache file: every run starts from an empty cache, as the thesis's SMA did.
    ///
    /// What the thesis never gave a value for keeps today's measured default: S_ref's start and
    /// step, S_min, R, K, the large-triangle fraction, RND's and NLD_IS's fractions, the other
    /// criteria's leaf minimum, and the bound on the neighbour rule's propagation
    /// (`mesh::neighbour_rule`'s 9 splits per step).
    ///
    /// Every addition beyond the thesis (merging by uniformity, the cache file, per-pixel direct
    /// light, the object-space filter) has a setting of its own, turned off here under
    /// `Profile::Thesis`.
    pub fn with_profile(mut self, profile: Profile) -> Result<SmaConfig, CriterionRefused> {
        let schedule = &mut self.schedule;
        schedule.criterion = profile.criterion(schedule.criterion)?;
        schedule.profile = profile;
        match profile {
            Profile::Today => {}
            Profile::Thesis => {
                schedule.ladder = false;
                schedule.l_white_outliers = 0.0;
                schedule.criterion_settings.nld_is_min_leaf_pixels = Some(THESIS_NLD_IS_MIN_PIXELS);
                schedule.criterion_settings.passes = Passes::One;
                schedule.coarsen_after_passes = 0;
                schedule.merge_uniform = false;
                schedule.indirect_filter.enabled = false;
                schedule.direct_tiles.enabled = false;
                schedule.work_while_walking = false;
                schedule.lead_while_walking = false;
                schedule.kept_while_walking = Duration::ZERO;
                self.mesh.neighbour_rule = NeighbourRule::Thesis;
                self.cache_file = None;
            }
        }
        Ok(self)
    }
}

impl SmaConfig {
    /// The defaults under `profile`, with the profile's own default criterion.
    pub fn of_profile(profile: Profile) -> SmaConfig {
        let mut config = SmaConfig::default();
        config.schedule.criterion = profile.default_criterion();
        config
            .with_profile(profile)
            .expect("a profile runs its own default criterion")
    }
}

/// §4.3.3: NLD_IS subdivides a leaf only if it covers at least 6 pixels.
pub const THESIS_NLD_IS_MIN_PIXELS: u32 = 6;

/// Which system the SMA runs: today's, or the thesis's as published (DESIGN.md §10), applied by
/// [`SmaConfig::with_profile`], which lists what differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Profile {
    #[default]
    Today,
    Thesis,
}

impl Profile {
    pub const ALL: [Profile; 2] = [Profile::Today, Profile::Thesis];

    /// The profile's name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Profile::Today => "today",
            Profile::Thesis => "thesis",
        }
    }

    pub fn from_name(name: &str) -> Option<Profile> {
        Profile::ALL.into_iter().find(|p| p.name() == name)
    }

    /// How tables, plots and logs name it.
    pub fn label(self) -> &'static str {
        match self {
            Profile::Today => "today",
            Profile::Thesis => "thesis (2006)",
        }
    }

    /// The criterion that runs when none is asked for: today's best measured one, `nld-px`
    /// (BENCHMARKS.md, "accuracy": ahead of the others at equal paths on every view), and under
    /// the thesis's profile the criterion it chose, NLD_OS of eq. 4.3 (§4.3.4, §5.2).
    pub fn default_criterion(self) -> CriterionKind {
        match self {
            Profile::Today => CriterionKind::NldPx,
            Profile::Thesis => CriterionKind::NldOsThesis,
        }
    }

    /// The criterion that runs under this profile when `kind` is asked for. The thesis's
    /// criteria read eq. 4.3 as it stands, with no noise discounting: the noise-aware `nld-os`
    /// and `nld-is` run as their `-thesis` forms, and `nld-px`, which has no thesis form, is
    /// refused.
    pub fn criterion(self, kind: CriterionKind) -> Result<CriterionKind, CriterionRefused> {
        match (self, kind) {
            (Profile::Today, kind) => Ok(kind),
            (Profile::Thesis, CriterionKind::NldOs) => Ok(CriterionKind::NldOsThesis),
            (Profile::Thesis, CriterionKind::NldIs) => Ok(CriterionKind::NldIsThesis),
            (Profile::Thesis, CriterionKind::NldPx) => Err(CriterionRefused::NotOffered {
                criterion: kind,
                profile: self,
            }),
            (Profile::Thesis, kind) => Ok(kind),
        }
    }

    /// [`Profile::criterion`] for a criterion's name.
    pub fn criterion_named(self, name: &str) -> Result<CriterionKind, CriterionRefused> {
        let kind = CriterionKind::from_name(name)
            .ok_or_else(|| CriterionRefused::Unknown(name.to_string()))?;
        self.criterion(kind)
    }

    /// The criteria this profile offers: those that run as themselves (a viewer's panel lists
    /// these; the names mapped to them are still accepted).
    pub fn criteria(self) -> Vec<CriterionKind> {
        CriterionKind::ALL
            .into_iter()
            .filter(|&k| self.criterion(k) == Ok(k))
            .collect()
    }

    /// The offered criteria's names, comma-separated (for messages).
    pub fn criteria_names(self) -> String {
        let names: Vec<&str> = self.criteria().iter().map(|k| k.name()).collect();
        names.join(", ")
    }
}

impl std::fmt::Display for Profile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A criterion asked for that the profile does not run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CriterionRefused {
    /// No criterion has this name.
    Unknown(String),
    /// The profile does not offer it.
    NotOffered {
        criterion: CriterionKind,
        profile: Profile,
    },
}

impl std::fmt::Display for CriterionRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CriterionRefused::Unknown(name) => write!(
                f,
                "unknown criterion {name:?}; known: {}",
                CriterionKind::names()
            ),
            CriterionRefused::NotOffered { criterion, profile } => write!(
                f,
                "criterion {criterion} is not part of the {} profile (the thesis's criteria \
                 have no noise discounting); it offers {}",
                profile.label(),
                profile.criteria_names()
            ),
        }
    }
}

impl std::error::Error for CriterionRefused {}

/// Every knob of the schedule's loop.
#[derive(Clone, Debug)]
pub struct ScheduleConfig {
    /// Which system runs; set by [`SmaConfig::with_profile`] together with every setting it
    /// changes, never alone. The schedule reads it where a viewer names a criterion.
    pub profile: Profile,
    /// The criterion a viewer starts with (each may change its own with `SetCriterion`).
    pub criterion: CriterionKind,
    pub criterion_settings: CriterionSettings,
    /// Refinement at all (off: the end-to-end control run).
    pub refine: bool,
    /// R: selections per refinement round (§4.3.5).
    pub max_selections: usize,
    /// No leaf covering fewer pixels is split.
    pub min_split_pixels: u32,
    /// K: the views are revisited after this many new samples (thesis §4.1; a camera at rest is
    /// carried over to the current leaves, `visibility::carry_over`, without a pass).
    pub revisit_samples: u64,
    /// Points per shade batch.
    pub batch_points: usize,
    /// Paths per shade batch, at most (at least one point): a batch at a high rung of the
    /// quality ladder carries fewer points (`schedule::requests::BatchLimit`).
    pub batch_paths: u64,
    /// Batches in flight per connected renderer.
    pub batches_per_renderer: usize,
    /// Work the pool keeps waiting beyond the renderers' batches, in time at their measured
    /// rate: it covers the schedule's longest turns (a pass, a refinement round), so the
    /// renderers never wait for them.
    pub renderer_backlog: Duration,
    /// Refinement waits until fewer samples than this, of those a picture or a refinement step
    /// waits for (`Requests::outstanding_before_paths`), are queued or in flight.
    pub queue_low: usize,
    /// A camera that replaced another rests once unchanged this long (a viewer's first camera
    /// rests at once: `schedule::turns::TurnView::camera_replaced`). Without
    /// `work_while_walking` refinement waits for it; with it, a camera coming to rest lifts the
    /// rounds' spacing and the plan stops looking ahead of the motion.
    pub rest: Duration,
    /// Refinement rounds are spaced so that each takes at most this share of the time until
    /// the next (0..1]: a round walks every visible leaf, and so do the carry-over, re-plan and
    /// viewer sync it sets off, so on a large view the rounds' cycle, not the renderers, took
    /// the cores. Only while work is queued for the renderers; a camera coming to rest lifts
    /// the spacing (`schedule::pace::Pace`, `schedule::turns::TurnView::ready_at`).
    pub round_share: f64,
    /// Work while walking (DESIGN.md §3 step 9): while a camera keeps moving, what stays in
    /// view keeps getting refinement rounds (at their pace, for the current camera), and the
    /// samples of the visible leaves are ordered by what the next steps will see; the
    /// visibility passes of a moving camera are paced by their own cost. A new view's missing
    /// samples still come first. Off: refinement waits for the camera to rest, as in the
    /// thesis, and every camera gets its pass at once.
    pub work_while_walking: bool,
    /// With work while walking, a walking viewer's visibility passes are drawn a little ahead
    /// of its camera, its last step's motion continued (`schedule::ahead::lead`): the view
    /// reaches the viewer a pass later and is shown until the next. Off: from its camera, as
    /// in the thesis.
    pub lead_while_walking: bool,
    /// While its camera moves, a viewer keeps what left its view for this long, if still a
    /// leaf (`schedule::shown`): its view lags its camera by a pass. Zero: it is shown only what
    /// the last pass saw, as in the thesis.
    pub kept_while_walking: Duration,
    /// A view-dependent sample is retaken once the eye has moved by this angle, seen from it.
    pub view_angle_deg: f32,
    /// Time between stats lines.
    pub stats_every: Duration,
    /// The fraction of the brightest visible samples that L_white leaves above it (DESIGN.md
    /// §6, `ShadingCache::l_white`); 0: their maximum, as the thesis has it.
    pub l_white_outliers: f64,
    /// What the SMA's own structures may hold together, by capacity: the mesh, the shading
    /// cache and the viewers' state (`schedule::memory`).
    pub memory_budget_bytes: usize,
    /// Visibility passes a base triangle must be out of every view before its subdivision is
    /// collapsed; 0: never.
    pub coarsen_after_passes: u64,
    /// Coarsening by uniformity (thesis §6, DESIGN.md §4): a visible red parent whose midpoint
    /// samples its own corners predict, within their noise or one display step, is merged back
    /// (`schedule::uniformity`). Off until measured.
    pub merge_uniform: bool,
    /// The object-space filter of the samples' indirect part (DESIGN.md §5,
    /// `indirect_filter`): off until measured to help (it did not on Sponza), and under the
    /// thesis profile.
    pub indirect_filter: IndirectFilterSettings,
    /// Seed of the criteria's random streams.
    pub seed: u64,
    /// Whether samples climb the quality ladder (DESIGN.md §5, `schedule::ladder`); off, every
    /// visible sample is traced once at the scene's quality preset (or `bounces`) and gets no
    /// more paths, as in the thesis, and the stated end comes once every visible sample is at
    /// that quality and the criterion finds nothing more.
    pub ladder: bool,
    /// The quality ladder's last rung: paths per sample (DESIGN.md §5).
    pub max_paths: u32,
    /// Whether the ladder has its early rung, a quarter of the scene's paths, for direct-light
    /// upgrades and refinement samples (`schedule::ladder::Qualities`); off, both get the scene's
    /// quality at once, so that the two can be measured side by side.
    pub early_rung: bool,
    /// While refinement's samples are queued, the share of the paths traced that goes to
    /// bringing early-rung samples up to the scene's quality (`schedule::need::Urgency::
    /// TopUp`); 0: only when refinement waits for nothing.
    pub top_up_share: f64,
    /// Bounces of every path, in place of the scene's quality preset's (None: the preset's):
    /// what accuracy costs in time is measured by trading it (DESIGN.md §10).
    pub bounces: Option<u32>,
    /// A visible sample whose standard error, in displayed units (Drago, sRGB, 0..1), is below
    /// this gets no more paths: the view has converged when every one is (or is at the cap)
    /// and the criterion finds nothing to subdivide.
    pub display_error: f32,
    /// Direct light per pixel while a viewer's camera rests (`direct_tiles`).
    pub direct_tiles: DirectTileSettings,
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        ScheduleConfig {
            profile: Profile::Today,
            criterion: Profile::Today.default_criterion(),
            criterion_settings: CriterionSettings::default(),
            refine: true,
            max_selections: 256,
            // As `CriterionSettings::min_leaf_pixels`, with the figures that chose it.
            min_split_pixels: 2,
            revisit_samples: 20_000,
            batch_points: 128,
            // As `Cli::batch_paths`, with the figures that chose it.
            batch_paths: 16_384,
            batches_per_renderer: 4,
            renderer_backlog: Duration::from_millis(500),
            // Overlaps a round with the shading of the last one's upgrades (see `cli.rs`).
            queue_low: 4096,
            rest: Duration::from_millis(100),
            // As `Cli::round_share`, with the figures that chose it.
            round_share: 0.05,
            work_while_walking: true,
            lead_while_walking: true,
            kept_while_walking: Duration::from_secs(2),
            view_angle_deg: 2.0,
            stats_every: Duration::from_secs(2),
            // One glint otherwise sets it for the whole view (see `ShadingCache::l_white`).
            l_white_outliers: L_WHITE_OUTLIERS,
            // The cache's earlier budget alone (1 GiB) and as much again for the mesh and the
            // viewers: at about 100 bytes a leaf for mesh and cache (BENCHMARKS.md), some twenty
            // million leaves, many 1080p views' worth, so it binds only on long walks, and it
            // leaves most of an 8-GiB machine to renderers on the same host.
            memory_budget_bytes: 2048 << 20,
            coarsen_after_passes: 300,
            merge_uniform: false,
            indirect_filter: IndirectFilterSettings::default(),
            seed: 1,
            // 64 × 4 × 4: two rungs past the interactive preset, a quarter of its noise.
            ladder: true,
            max_paths: 1024,
            early_rung: true,
            top_up_share: 0.5,
            bounces: None,
            // One step of an 8-bit display.
            display_error: 1.0 / 255.0,
            direct_tiles: DirectTileSettings::default(),
        }
    }
}

/// What per-pixel direct light a viewer gets (DESIGN.md §3 step 8, `direct_tiles`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DirectTileSettings {
    /// Off: the viewer shows the vertices' direct part alone, to measure against.
    pub enabled: bool,
    pub lights: DirectLights,
}

impl Default for DirectTileSettings {
    fn default() -> Self {
        DirectTileSettings {
            // Off until a tile's pixel shows no noise where it stands in: at 512×384 it was
            // neutral (60 s, nld-px: bracara VT 0.044 with against 0.046 without, Sponza S1
            // 0.051 both), but at 1024×768 (BENCHMARKS.md's headline, measured with it on)
            // bracara VT's mean FLIP rose from 30 s to 60 s in all three runs (0.040 → 0.044),
            // as more tile pixels passed the quiet test (standard error under 1.5–3 % of the
            // pixel) and their grain replaced the smooth vertex picture. A stricter quiet test
            // is the next thing to measure.
            enabled: false,
            lights: DirectLights::All,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn thesis() -> SmaConfig {
        SmaConfig::of_profile(Profile::Thesis)
    }

    #[test]
    fn today_changes_nothing() {
        let today = SmaConfig::default().with_profile(Profile::Today).unwrap();
        let default = SmaConfig::default();
        assert_eq!(format!("{today:?}"), format!("{default:?}"));
    }

    #[test]
    fn the_thesis_profile_sets_what_the_thesis_published() {
        let (thesis, today) = (thesis(), SmaConfig::default());
        let s = &thesis.schedule;
        assert_eq!(s.profile, Profile::Thesis);
        assert!(!s.ladder && today.schedule.ladder, "fixed-quality samples");
        assert_eq!(s.l_white_outliers, 0.0, "L_white the maximum");
        assert_eq!(s.criterion_settings.nld_is_min_leaf_pixels, Some(6));
        assert_eq!(s.criterion_settings.passes, Passes::One);
        assert_eq!(s.coarsen_after_passes, 0, "no coarsening");
        assert!(
            !s.work_while_walking && today.schedule.work_while_walking,
            "refinement only at rest"
        );
        assert!(
            !s.lead_while_walking && today.schedule.lead_while_walking,
            "passes from the camera"
        );
        assert_eq!(thesis.mesh.neighbour_rule, NeighbourRule::Thesis);
        assert_eq!(s.criterion, CriterionKind::NldOsThesis);
        // What the thesis never gave a value for stays as today.
        let mut unchanged = today.schedule.criterion_settings;
        unchanged.nld_is_min_leaf_pixels = Some(6);
        unchanged.passes = Passes::One;
        assert_eq!(s.criterion_settings, unchanged);
        assert_eq!(
            (s.max_selections, s.revisit_samples, s.min_split_pixels),
            (
                today.schedule.max_selections,
                today.schedule.revisit_samples,
                today.schedule.min_split_pixels
            )
        );
    }

    #[test]
    fn the_thesis_offers_its_own_criteria_and_maps_the_noise_aware_ones() {
        use CriterionKind::*;
        assert_eq!(Profile::Today.criteria(), CriterionKind::ALL);
        assert_eq!(
            Profile::Thesis.criteria(),
            [Rnd, NldIsThesis, NldOsThesis, NldMm]
        );
        let thesis = Profile::Thesis;
        assert_eq!(thesis.criterion(NldOs), Ok(NldOsThesis));
        assert_eq!(thesis.criterion(NldIs), Ok(NldIsThesis));
        assert_eq!(thesis.criterion_named("rnd"), Ok(Rnd));
        assert_eq!(thesis.criterion_named("nld-mm"), Ok(NldMm));
        assert_eq!(
            thesis.criterion_named("nld-px"),
            Err(CriterionRefused::NotOffered {
                criterion: NldPx,
                profile: thesis
            })
        );
        assert!(matches!(
            thesis.criterion_named("nope"),
            Err(CriterionRefused::Unknown(_))
        ));
        let mut config = SmaConfig::default();
        config.schedule.criterion = NldPx;
        let refused = config.with_profile(thesis).unwrap_err().to_string();
        assert!(
            refused.contains("nld-px is not part of the thesis (2006) profile"),
            "{refused}"
        );
        assert!(Profile::Today.criterion_named("nld-px").is_ok());
    }

    #[test]
    fn profiles_are_named_and_labelled() {
        for p in Profile::ALL {
            assert_eq!(Profile::from_name(p.name()), Some(p));
        }
        assert_eq!(Profile::Thesis.label(), "thesis (2006)");
        assert_eq!(Profile::Today.label(), "today");
        assert_eq!(Profile::default(), Profile::Today);
    }
}
