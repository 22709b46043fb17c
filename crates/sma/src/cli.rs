//! The SMA's command line (`sma …`, and `walkthrough sma …` through the launcher): every
//! refinement parameter is a flag. The defaults are set once, in `SmaConfig::default` and the
//! core's `CriterionSettings::default` / `MeshParams::default`; the measurements behind them are
//! on each flag here. The only module of the library that knows clap: it turns flags into an
//! [`SmaConfig`] and runs [`server::start`](crate::server::start).

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Parser;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use protocol::admission::PortLimits;
use protocol::liveness::Liveness;

use crate::cache_file::{CacheFileConfig, Location};
use crate::config::{DirectTileSettings, Profile, ScheduleConfig, SmaConfig};
use crate::criteria::{CriterionKind, CriterionSettings};
use crate::indirect_filter::IndirectFilterSettings;
use crate::mesh::{MeshParams, NeighbourRule};
use protocol::direct_tile::DirectLights;

fn defaults() -> SmaConfig {
    SmaConfig::default()
}

fn criterion_defaults() -> CriterionSettings {
    CriterionSettings::default()
}

fn mesh_defaults() -> MeshParams {
    MeshParams::default()
}

/// `--criterion`: one of the criteria's names, as a [`CriterionKind`].
fn criterion_parser() -> impl TypedValueParser<Value = CriterionKind> {
    let names: Vec<&str> = CriterionKind::ALL.iter().map(|k| k.name()).collect();
    PossibleValuesParser::new(names)
        .map(|name| CriterionKind::from_name(&name).expect("a possible value"))
}

/// `--neighbour-rule`: one of the rules' names, as a [`NeighbourRule`].
fn neighbour_rule_parser() -> impl TypedValueParser<Value = NeighbourRule> {
    let names: Vec<&str> = NeighbourRule::ALL.iter().map(|r| r.name()).collect();
    PossibleValuesParser::new(names)
        .map(|name| NeighbourRule::from_name(&name).expect("a possible value"))
}

/// `--profile`: one of the profiles' names, as a [`Profile`].
fn profile_parser() -> impl TypedValueParser<Value = Profile> {
    let names: Vec<&str> = Profile::ALL.iter().map(|p| p.name()).collect();
    PossibleValuesParser::new(names)
        .map(|name| Profile::from_name(&name).expect("a possible value"))
}

/// `on` or `off`, as a bool.
fn on_off(text: &str) -> Result<bool, String> {
    match text {
        "on" => Ok(true),
        "off" => Ok(false),
        _ => Err(format!("{text:?}: on or off")),
    }
}

/// A `DirectLights` by its name.
fn direct_lights(text: &str) -> Result<DirectLights, String> {
    let found = DirectLights::ALL.into_iter().find(|l| l.name() == text);
    found.ok_or_else(|| format!("{text:?}: sun, sun-sky or all"))
}

/// A fraction: at least 0, below 1.
fn fraction(text: &str) -> Result<f64, String> {
    let value: f64 = text.parse().map_err(|e| format!("{text:?}: {e}"))?;
    if (0.0..1.0).contains(&value) {
        Ok(value)
    } else {
        Err(format!("{value} is not a fraction (at least 0, below 1)"))
    }
}

/// A share of time: above 0, at most 1.
fn share(text: &str) -> Result<f64, String> {
    let value: f64 = text.parse().map_err(|e| format!("{text:?}: {e}"))?;
    if value > 0.0 && value <= 1.0 {
        Ok(value)
    } else {
        Err(format!(
            "{value} is not a share of time (above 0, at most 1)"
        ))
    }
}

/// Seconds of keeping, from 0 to an hour (`ShownSet` notes the syncs of that long).
fn keeping_seconds(text: &str) -> Result<Duration, String> {
    let value: f64 = text.parse().map_err(|e| format!("{text:?}: {e}"))?;
    if (0.0..=3600.0).contains(&value) {
        Ok(Duration::from_secs_f64(value))
    } else {
        Err(format!("{value} s is not from 0 to 3600"))
    }
}

#[derive(Parser, Debug, Clone)]
#[command(
    name = "sma",
    about = "Shading Management Agent: visibility, shading cache, refinement",
    long_about = "Shading Management Agent (SMA): loads the scene, asks the renderers for samples \
                  of what the viewers see, caches them and refines where shading varies. It \
                  connects to renderers (--renderer), lets renderers join \
                  (--renderer-listen) and accepts viewers (--listen).",
    after_help = "Renderer, SMA and viewers on several machines: see \"Running on three machines \
                  of a LAN\" in the README."
)]
pub struct Cli {
    /// Scene: a TOML scene file or a built-in name (bracara, bracara-textured, cornell).
    #[arg(long, default_value = "bracara")]
    pub scene: String,
    /// Address to accept viewers on.
    #[arg(long, default_value_t = defaults().listen)]
    pub listen: String,
    /// A renderer `host:port` to connect to; repeat for several.
    #[arg(long = "renderer", required_unless_present = "renderer_listen")]
    pub renderers: Vec<String>,
    /// Address of a port on which renderers join (`renderer serve --join ADDR`); the bound
    /// address is printed as "sma renderers listening on ADDR".
    #[arg(long)]
    pub renderer_listen: Option<String>,
    /// Renderers served at once on the renderer port; one past this is refused.
    #[arg(long, default_value_t = defaults().renderer_port.max_connections)]
    pub max_renderers: usize,
    /// Milliseconds between heartbeats to each renderer.
    #[arg(long, default_value_t = defaults().liveness.heartbeat.as_millis() as u64)]
    pub heartbeat_ms: u64,
    /// A renderer that sends nothing, heartbeat answers included, for this many milliseconds
    /// is lost: its batches go to the others and its link reconnects.
    #[arg(long, default_value_t = defaults().liveness.silence.as_millis() as u64)]
    pub silence_ms: u64,
    /// A frame begun on any link must be complete within this many milliseconds.
    #[arg(long, default_value_t = defaults().liveness.frame_timeout.as_millis() as u64)]
    pub frame_timeout_ms: u64,
    /// A batch is lost once this many times its expected time at its renderer's measured rate
    /// has passed.
    #[arg(long, default_value_t = defaults().deadline_factor)]
    pub deadline_factor: f64,
    /// A batch sent to a renderer whose rate is not measured yet (before its first answer) is
    /// lost after this many milliseconds.
    #[arg(long, default_value_t = defaults().first_deadline.as_millis() as u64)]
    pub first_deadline_ms: u64,
    /// KiB of changes that may wait for one viewer that reads slowly or not at all; past them it
    /// is disconnected. What waits is the latest state of each triangle, not every step, so a
    /// slow viewer needs at most about 90 bytes per triangle it could be shown.
    #[arg(long, default_value_t = defaults().viewer_backlog_bytes >> 10)]
    pub viewer_backlog_kib: usize,
    /// A viewer that answers no heartbeat (sent every --heartbeat-ms) for this many
    /// milliseconds is lost and its connection closed.
    #[arg(long, default_value_t = defaults().viewer_silence.as_millis() as u64)]
    pub viewer_silence_ms: u64,
    /// Which system runs: today's, or the thesis's as published (2006): fixed-quality samples at
    /// the scene's preset (no quality ladder), L_white the maximum, NLD_IS leaves of 6 pixels at
    /// least, nld-os and nld-is as their -thesis forms (nld-px refused), one pass of RND and
    /// NLD_IS per camera, the thesis's neighbour rule, no coarsening (`SmaConfig::with_profile`).
    /// --neighbour-rule, --l-white-outliers and --coarsen-after-passes, given, still win; the
    /// quality ladder's flags do nothing under it.
    #[arg(long, default_value_t = Profile::Today, value_parser = profile_parser())]
    pub profile: Profile,
    /// Refinement criterion (each viewer may change its own with SetCriterion) [default:
    /// nld-px, the best measured; nld-os-thesis under --profile thesis].
    #[arg(long, value_parser = criterion_parser())]
    pub criterion: Option<CriterionKind>,
    /// No refinement at all: only the base mesh is shaded (the control run).
    #[arg(long)]
    pub no_refine: bool,
    /// Seed of the criteria's and the renderers' random streams.
    #[arg(long, default_value_t = defaults().schedule.seed)]
    pub seed: u64,

    /// R: leaves a criterion may select per refinement round (§4.3.5).
    // Why the default: a round waits for its samples and a visibility pass, so small rounds leave
    // the renderers idle: in 10-s runs (`bench convergence --sma-flags=--max-selections,…`)
    // NLD_OS on bracara VT reached mean FLIP 0.095 / 0.082 / 0.067 at 1 s with R = 64 / 256 /
    // 1024, and RND on Sponza S1 0.132 / 0.119 / 0.117 at 10 s; but with 1024 RND ran out of
    // leaves to offer on VT after 5 s (0.072 against 0.057 with 256). A camera change is not held
    // up: it re-plans the queue at once.
    #[arg(long, default_value_t = defaults().schedule.max_selections)]
    pub max_selections: usize,
    /// No leaf covering fewer pixels is split (one sample per few pixels is the useful limit).
    #[arg(long, default_value_t = defaults().schedule.min_split_pixels)]
    pub min_split_pixels: u32,
    /// K: the views are revisited after this many new samples (a camera at rest without a pass)
    #[arg(long, default_value_t = defaults().schedule.revisit_samples)]
    pub revisit_samples: u64,
    /// Points per shade batch sent to a renderer.
    #[arg(long, default_value_t = defaults().schedule.batch_points)]
    pub batch_points: usize,
    /// Paths per shade batch, at most: a batch at a high rung of the quality ladder carries
    /// fewer points, so that a sample a picture waits for never queues behind a long batch.
    // Why the default: twice a full batch at the scenes' 64 paths, so only the ladder's rungs
    // past the scene's quality are cut. On bracara VT (`nld-px`, five 4-s runs each) the median
    // time to mean FLIP 0.1 was 0.84 / 0.75 / 0.57 s without a bound / at 16384 / at 8192; on
    // Sponza S3 (three 20-s runs each) 6.0 / 6.0 / 7.0 s, FLIP at 19 s 0.066 / 0.069 / 0.074:
    // every extra batch costs the SMA a turn, and there its passes share the renderer's cores.
    #[arg(long, default_value_t = defaults().schedule.batch_paths)]
    pub batch_paths: u64,
    /// Batches in flight per renderer.
    #[arg(long, default_value_t = defaults().schedule.batches_per_renderer)]
    pub batches_per_renderer: usize,
    /// Work kept waiting in the pool beyond the renderers' batches, in milliseconds at their
    /// measured rate: it keeps them busy while the SMA runs a pass or a refinement round (0: only
    /// the batches per renderer).
    #[arg(long, default_value_t = defaults().schedule.renderer_backlog.as_millis() as u64)]
    pub renderer_backlog_ms: u64,
    /// Refinement waits until fewer samples than this, of those a picture or a refinement step
    /// waits for, are queued or in flight.
    // Why the default: the next round is chosen while the last round's upgrades are still being
    // shaded, so rounds overlap with the renderers' work instead of taking turns with it. On
    // bracara VT (`nld-px`, 6-s runs, six runs each, quiet machine) the median time to mean FLIP
    // 0.1 was 1.29 / 1.06 / 1.08 / 1.19 s at 256 / 1024 / 4096 / 16384; on Sponza S3 (three
    // 10-s runs each) 7.0 s at 256 and 6.0 s at 4096, FLIP at 8 s 0.089 and 0.088.
    #[arg(long, default_value_t = defaults().schedule.queue_low)]
    pub queue_low: usize,
    /// A camera that replaced another rests once unchanged this many milliseconds (refinement
    /// waits for it without --work-while-walking; with it, a stop lifts the rounds' spacing); a
    /// viewer's first camera rests at once.
    // Why a first camera does not wait: nothing says it moves, and the wait was the largest
    // delay before a view's first refinement. On bracara VT (`nld-px`, six 4-s runs each,
    // interleaved) the median time to mean FLIP 0.1 was 0.50 s when the first camera waited
    // 100 ms and 0.34 s when it rested at once.
    #[arg(long, default_value_t = defaults().schedule.rest.as_millis() as u64)]
    pub rest_ms: u64,
    /// While work is queued for the renderers, refinement rounds are spaced so that each takes
    /// at most this share of the time until the next (0..1; 1: a round whenever its samples are
    /// in).
    // Why the default: a round, and the carry-over, re-plan and viewer sync it sets off, each
    // walk every visible leaf; unspaced, Sponza S3 had six rounds a second at 130-200 k leaves
    // and the renderer traced 0.73 M paths/s against 1.1 M without refinement. Three 12-s runs
    // each (`nld-px`, medians), time to mean FLIP 0.1 on S3 / bracara VT: 5.0 / 0.55 s unspaced
    // (share 1), 4.0 / 0.52 s at 0.1, 3.3 / 0.43 s at 0.05, 4.0 / 0.64 s at 0.02 (too little
    // refinement); a fixed 300 ms between rounds gave 3.9 / 2.0 s (early rounds, cheap and
    // decisive, held back). At 0.05 VT's FLIP at 8 s is 0.036 against 0.035 unspaced.
    #[arg(long, default_value_t = defaults().schedule.round_share, value_parser = share)]
    pub round_share: f64,
    /// Work while walking (on|off): while the camera keeps moving, refinement rounds and better
    /// samples go on for what stays in view, ahead of the motion first, after a new view's
    /// missing samples, and the moving camera's visibility passes are paced by their cost; off,
    /// refinement waits for the camera to rest [default: on; off under --profile thesis].
    #[arg(long, value_parser = on_off)]
    pub work_while_walking: Option<bool>,
    /// With work while walking, a walking camera's visibility passes are drawn a little ahead
    /// of it, its last step's motion continued, and again from the camera once it rests
    /// (on|off) [default: on; off under --profile thesis].
    #[arg(long, value_parser = on_off)]
    pub lead_while_walking: Option<bool>,
    /// Seconds a walking viewer keeps showing what left its view, while still a leaf: its view
    /// is the last visibility pass, a few steps behind its camera (0: only what that pass saw)
    /// [default: 2; 0 under --profile thesis].
    #[arg(long, value_parser = keeping_seconds)]
    pub kept_while_walking_s: Option<Duration>,
    /// A view-dependent sample is retaken once the eye has moved by this angle, seen from it.
    #[arg(long, default_value_t = defaults().schedule.view_angle_deg)]
    pub view_angle_deg: f32,
    /// Seconds between the statistics sent to viewers (and logged at debug level).
    #[arg(long, default_value_t = defaults().schedule.stats_every.as_secs_f32())]
    pub stats_secs: f32,
    /// Collapse the subdivision of a base triangle no viewer has seen for this many visibility
    /// passes (0: never) [default: 300; 0 under --profile thesis].
    // Passes come with each camera change and every K samples, so this is some seconds of walking
    // away, or minutes of standing elsewhere.
    #[arg(long)]
    pub coarsen_after_passes: Option<u64>,
    /// The fraction of the brightest visible samples that L_white, the tone map's white and the
    /// NLD metric's L_max, leaves above it (0: their maximum) [default: 0.001; 0 under --profile
    /// thesis].
    #[arg(long, value_parser = fraction)]
    pub l_white_outliers: Option<f64>,
    /// Merge back a visible red split whose midpoint samples the parent's corners predict
    /// (linear interpolation), within their noise or one display step, once all are settled
    /// (on|off) [default: off].
    // Off until measured: `walkthrough-bench convergence --sma-flags=--merge-uniform,on` against
    // three runs without it, the six default views at 60 s (leaves and bytes saved, FLIP).
    #[arg(long, value_parser = on_off)]
    pub merge_uniform: Option<bool>,
    /// Filter each sample's indirect part over its mesh neighbours in object space (on|off)
    /// [default: on, off under `--profile thesis`].
    // Measured by `walkthrough-bench convergence --sma-flags=--indirect-filter,off` against
    // runs with it: FLIP at 5 s on Sponza S1–S3 (`IndirectFilterSettings::default`).
    #[arg(long, value_parser = on_off)]
    pub indirect_filter: Option<bool>,
    /// The indirect filter's radius at 64 paths, as a fraction of the scene's bounding-box
    /// diagonal; it shrinks as paths^(-1/4).
    #[arg(long, value_parser = fraction, default_value_t = f64::from(defaults().schedule.indirect_filter.radius))]
    pub indirect_filter_radius: f64,
    /// When above 0, the indirect filter's radius at 64 paths is also at most this many times
    /// the longest edge of the finest visible leaf at the vertex.
    #[arg(long, default_value_t = f64::from(defaults().schedule.indirect_filter.leaf_radius))]
    pub indirect_filter_leaf_radius: f64,
    /// The quality ladder's last rung: samples get paths by fours past the scene's quality
    /// while the viewer rests, up to this many paths each.
    #[arg(long, default_value_t = defaults().schedule.max_paths)]
    pub max_paths: u32,
    /// No early rung on the quality ladder: upgrades from direct light and the samples of
    /// refinement steps get the scene's quality at once instead of a quarter of its paths first.
    #[arg(long)]
    pub no_early_rung: bool,
    /// While refinement's samples wait, this share of the paths traced still goes to bringing
    /// early-rung samples up to the scene's quality (0..1; 0: only when refinement waits for
    /// nothing).
    #[arg(long, default_value_t = defaults().schedule.top_up_share)]
    pub top_up_share: f64,
    /// Bounces of every path, in place of the scene's quality preset's (fewer: faster and
    /// less accurate).
    #[arg(long)]
    pub bounces: Option<u32>,
    /// A sample stops getting paths once its standard error is below this many displayed
    /// units (0..1 after tone map and sRGB; default one 8-bit step); the noise-aware criteria
    /// stop subdividing a leaf once its vertices differ by no more, beyond their noise.
    #[arg(long, default_value_t = defaults().schedule.display_error)]
    pub display_error: f32,
    /// While a viewer's camera rests, ask the renderers for its direct light per pixel and
    /// forward it in tiles (on|off) [default: off, and under `--profile thesis`].
    #[arg(long, value_parser = on_off)]
    pub per_pixel_direct: Option<bool>,
    /// The lights the per-pixel tiles trace (sun|sun-sky|all): only `all` replaces the
    /// vertices' whole direct part; the others measure a light's cost and noise per pixel.
    #[arg(long, value_parser = direct_lights, default_value = "all")]
    pub per_pixel_lights: DirectLights,
    /// Keep the mesh and the samples in this file between runs, and start from what it holds
    /// (DESIGN.md §5); a file of another scene, version or settings is renamed to
    /// `PATH.rejected` [default: none; none under --profile thesis].
    #[arg(long, value_name = "PATH")]
    pub cache_file: Option<PathBuf>,
    /// Keep the cache file in this directory, one per scene: `DIR/<scene>-<fingerprint>.redb`
    /// (the launcher's default, in the user's cache directory).
    #[arg(long, value_name = "DIR", conflicts_with = "cache_file")]
    pub cache_dir: Option<PathBuf>,
    /// Seconds between saves of the cache file (a crash loses at most this much).
    #[arg(long, default_value_t = CacheFileConfig::SAVE_EVERY.as_secs_f64())]
    pub cache_file_save_s: f64,
    /// Memory budget of the SMA's own structures, MiB: the subdivision mesh, the shading cache
    /// and the viewers' state, counted by capacity. Near it, what was seen least recently is
    /// coarsened and evicted first; when the current views alone need more, refinement stops
    /// and the SMA reports itself memory-bound. The default, 2 GiB, the cache's earlier budget
    /// and as much again for the mesh and viewers, is some twenty million leaves at about 100
    /// bytes a leaf: it binds only on long walks, and leaves most of an 8-GiB machine to
    /// renderers on the same host. A fraction is allowed (small scenes, tests).
    #[arg(long, default_value_t = (defaults().schedule.memory_budget_bytes >> 20) as f64)]
    pub memory_mib: f64,
    /// Largest protocol frame accepted or sent, bytes.
    #[arg(long, default_value_t = defaults().max_frame)]
    pub max_frame: usize,
    /// Viewers served at once; one past this is refused (DESIGN.md §8).
    #[arg(long, default_value_t = defaults().viewer_port.max_connections)]
    pub max_viewers: usize,
    /// A viewer that has not completed its handshake within this many milliseconds is closed.
    #[arg(long, default_value_t = defaults().viewer_port.handshake_deadline.as_millis() as u64)]
    pub handshake_deadline_ms: u64,

    /// NLD_OS: first S_ref (§4.3.4).
    #[arg(long, default_value_t = criterion_defaults().s_ref_start)]
    pub s_ref_start: f32,
    /// NLD_OS: S_ref decrease once a pass finds nothing above it.
    #[arg(long, default_value_t = criterion_defaults().s_ref_step)]
    pub s_ref_step: f32,
    /// NLD_OS, NLD_PX as the thesis has them (`*-thesis`): S at or below which a leaf is never
    /// selected (the noise-aware ones stop at --display-error).
    #[arg(long, default_value_t = criterion_defaults().s_min)]
    pub s_min: f32,
    /// A leaf covering more than this fraction of the image is always selected (§4.3.5).
    #[arg(long, default_value_t = criterion_defaults().large_triangle_fraction)]
    pub large_triangle_fraction: f32,
    /// RND: a pass ends after picks of this fraction of the pixels (§4.3.1).
    #[arg(long, default_value_t = criterion_defaults().rnd_fraction)]
    pub rnd_fraction: f32,
    /// NLD_IS: at most this fraction of the pixels is selected per camera (§4.3.3).
    #[arg(long, default_value_t = criterion_defaults().nld_is_fraction)]
    pub nld_is_fraction: f32,
    /// No criterion selects a leaf covering fewer pixels (§4.3.3 has 6 for NLD_IS, which
    /// --profile thesis sets for NLD_IS alone; measured: see `CriterionSettings::default`).
    #[arg(long, default_value_t = criterion_defaults().min_leaf_pixels)]
    pub min_leaf_pixels: u32,
    /// NLD_PX: weight of size alone in a leaf's priority (eq. 3.4's ε).
    #[arg(long, default_value_t = criterion_defaults().nld_px_epsilon)]
    pub nld_px_epsilon: f32,
    /// No split below this edge length, scene units.
    #[arg(long, default_value_t = mesh_defaults().min_edge_length)]
    pub min_edge_length: f32,
    /// Weld tolerance for adjacency, fraction of the scene diagonal.
    #[arg(long, default_value_t = mesh_defaults().weld_tolerance_rel)]
    pub weld_tolerance: f32,
    /// How a neighbour across a split edge is closed (§4.2, DESIGN.md §4): red-green bisects it;
    /// thesis splits it 1:4 when the edge is shorter than its height on it (fig. 4.7), up to a
    /// bound per refinement step (`mesh::NeighbourRule`), bisecting past it [default:
    /// red-green; thesis under --profile thesis].
    #[arg(long, value_parser = neighbour_rule_parser())]
    pub neighbour_rule: Option<NeighbourRule>,
}

impl Cli {
    /// The configuration these flags ask for: today's from the flags, then the profile
    /// (`SmaConfig::with_profile`), then the flags of what it sets, where given. Refused: a
    /// criterion the profile does not offer.
    pub fn config(&self) -> anyhow::Result<SmaConfig> {
        let mut config = self.today().with_profile(self.profile)?;
        if let Some(rule) = self.neighbour_rule {
            config.mesh.neighbour_rule = rule;
        }
        if let Some(fraction) = self.l_white_outliers {
            config.schedule.l_white_outliers = fraction;
        }
        if let Some(passes) = self.coarsen_after_passes {
            config.schedule.coarsen_after_passes = passes;
        }
        if let Some(on) = self.work_while_walking {
            config.schedule.work_while_walking = on;
        }
        if let Some(on) = self.lead_while_walking {
            config.schedule.lead_while_walking = on;
        }
        if let Some(keeping) = self.kept_while_walking_s {
            config.schedule.kept_while_walking = keeping;
        }
        if let Some(on) = self.merge_uniform {
            config.schedule.merge_uniform = on;
        }
        if let Some(on) = self.indirect_filter {
            config.schedule.indirect_filter.enabled = on;
        }
        if let Some(on) = self.per_pixel_direct {
            config.schedule.direct_tiles.enabled = on;
        }
        Ok(config)
    }

    /// The configuration of today's profile, from the flags and the defaults.
    fn today(&self) -> SmaConfig {
        SmaConfig {
            listen: self.listen.clone(),
            renderers: self.renderers.clone(),
            renderer_listen: self.renderer_listen.clone(),
            renderer_port: PortLimits {
                max_connections: self.max_renderers,
                handshake_deadline: Duration::from_millis(self.handshake_deadline_ms),
            },
            liveness: Liveness {
                heartbeat: Duration::from_millis(self.heartbeat_ms.max(1)),
                silence: Duration::from_millis(self.silence_ms.max(1)),
                frame_timeout: Duration::from_millis(self.frame_timeout_ms.max(1)),
            },
            deadline_factor: self.deadline_factor,
            first_deadline: Duration::from_millis(self.first_deadline_ms.max(1)),
            viewer_backlog_bytes: self.viewer_backlog_kib << 10,
            viewer_silence: Duration::from_millis(self.viewer_silence_ms.max(1)),
            max_frame: self.max_frame,
            viewer_port: PortLimits {
                max_connections: self.max_viewers,
                handshake_deadline: Duration::from_millis(self.handshake_deadline_ms),
            },
            mesh: MeshParams {
                min_edge_length: self.min_edge_length,
                weld_tolerance_rel: self.weld_tolerance,
                neighbour_rule: mesh_defaults().neighbour_rule,
            },
            schedule: self.schedule_config(),
            cache_file: self.cache_file_config(),
        }
    }

    fn cache_file_config(&self) -> Option<CacheFileConfig> {
        let location = match (&self.cache_file, &self.cache_dir) {
            (Some(path), _) => Location::File(path.clone()),
            (None, Some(dir)) => Location::PerScene(dir.clone()),
            (None, None) => return None,
        };
        Some(CacheFileConfig {
            location,
            save_every: Duration::from_secs_f64(self.cache_file_save_s.clamp(0.1, 86_400.0)),
        })
    }

    fn criterion_settings(&self) -> CriterionSettings {
        CriterionSettings {
            s_ref_start: self.s_ref_start,
            s_ref_step: self.s_ref_step,
            s_min: self.s_min,
            display_error: self.display_error,
            max_paths: self.max_paths,
            large_triangle_fraction: self.large_triangle_fraction,
            rnd_fraction: self.rnd_fraction,
            nld_is_fraction: self.nld_is_fraction,
            min_leaf_pixels: self.min_leaf_pixels,
            nld_px_epsilon: self.nld_px_epsilon,
            ..criterion_defaults()
        }
    }

    fn schedule_config(&self) -> ScheduleConfig {
        ScheduleConfig {
            profile: defaults().schedule.profile,
            criterion: self.criterion.unwrap_or(self.profile.default_criterion()),
            criterion_settings: self.criterion_settings(),
            refine: !self.no_refine,
            max_selections: self.max_selections,
            min_split_pixels: self.min_split_pixels,
            revisit_samples: self.revisit_samples,
            batch_points: self.batch_points.max(1),
            batch_paths: self.batch_paths.max(1),
            batches_per_renderer: self.batches_per_renderer.max(1),
            renderer_backlog: Duration::from_millis(self.renderer_backlog_ms),
            queue_low: self.queue_low,
            rest: Duration::from_millis(self.rest_ms),
            round_share: self.round_share,
            work_while_walking: defaults().schedule.work_while_walking,
            lead_while_walking: defaults().schedule.lead_while_walking,
            kept_while_walking: defaults().schedule.kept_while_walking,
            view_angle_deg: self.view_angle_deg,
            stats_every: Duration::from_secs_f32(self.stats_secs.max(0.1)),
            l_white_outliers: defaults().schedule.l_white_outliers,
            memory_budget_bytes: (self.memory_mib.max(0.0) * f64::from(1 << 20)) as usize,
            coarsen_after_passes: defaults().schedule.coarsen_after_passes,
            merge_uniform: defaults().schedule.merge_uniform,
            indirect_filter: IndirectFilterSettings {
                radius: self.indirect_filter_radius as f32,
                leaf_radius: self.indirect_filter_leaf_radius.max(0.0) as f32,
                ..defaults().schedule.indirect_filter
            },
            seed: self.seed,
            ladder: defaults().schedule.ladder,
            max_paths: self.max_paths,
            early_rung: !self.no_early_rung,
            top_up_share: self.top_up_share,
            bounces: self.bounces,
            display_error: self.display_error,
            direct_tiles: DirectTileSettings {
                lights: self.per_pixel_lights,
                ..defaults().schedule.direct_tiles
            },
        }
    }
}

/// Runs the SMA until Ctrl-C (graceful: links closed, threads joined).
pub fn run(cli: Cli) -> anyhow::Result<()> {
    conventions::logging::init();
    let runtime = tokio::runtime::Runtime::new().context("starting the async runtime")?;
    runtime.block_on(serve(cli))
}

async fn serve(cli: Cli) -> anyhow::Result<()> {
    let config = cli.config()?;
    let scene =
        scene::load(&cli.scene).with_context(|| format!("loading scene {:?}", cli.scene))?;
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
        tracing::info!("shutting down");
    };
    let running = crate::server::start(config, scene, ctrl_c).await?;
    // The launcher and tests read this line to learn the port when `--listen` asks for port 0.
    conventions::listening::announce("sma", running.addr)?;
    // After the viewers' line, which a reader of the first `listening on` line takes.
    if let Some(addr) = running.renderer_addr {
        conventions::listening::announce("sma renderers", addr)?;
    }
    running.stopped().await
}

#[cfg(test)]
mod tests;
