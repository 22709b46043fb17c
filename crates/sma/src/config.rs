//! The SMA's configuration as plain values (no argument parsing here: `cli` fills it from flags).
//! Every default is set once, in the `Default` impls, with the measurement behind it on the flag
//! in `cli` (DESIGN.md §6: each unstated thesis parameter is a flag with a measured default).

use std::time::Duration;

use protocol::admission::PortLimits;
use protocol::frame::DEFAULT_MAX_FRAME;
use protocol::liveness::Liveness;

use crate::criteria::{CriterionKind, CriterionSettings};
use crate::mesh::MeshParams;

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
        }
    }
}

/// Every knob of the schedule's loop.
#[derive(Clone, Debug)]
pub struct ScheduleConfig {
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
    /// rests at once: `schedule::turns::TurnView::camera_replaced`).
    pub rest: Duration,
    /// Refinement rounds are spaced so that each takes at most this share of the time until
    /// the next (0..1]: a round walks every visible leaf, and so do the carry-over, re-plan and
    /// viewer sync it sets off, so on a large view the rounds' cycle, not the renderers, took
    /// the cores. Only while work is queued for the renderers; a camera move lifts the spacing
    /// (`schedule::pace::Pace`).
    pub round_share: f64,
    /// A view-dependent sample is retaken once the eye has moved by this angle, seen from it.
    pub view_angle_deg: f32,
    /// Time between stats lines.
    pub stats_every: Duration,
    pub cache_budget_bytes: usize,
    /// Visibility passes a base triangle must be out of every view before its subdivision is
    /// collapsed; 0: never.
    pub coarsen_after_passes: u64,
    /// Coarsening by uniformity (thesis §6, DESIGN.md §4): a visible red parent whose midpoint
    /// samples its own corners predict, within their noise or one display step, is merged back
    /// (`schedule::uniformity`). Off until measured.
    pub merge_uniform: bool,
    /// Seed of the criteria's random streams.
    pub seed: u64,
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
}

impl Default for ScheduleConfig {
    fn default() -> Self {
        ScheduleConfig {
            criterion: CriterionKind::NldOs,
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
            view_angle_deg: 2.0,
            stats_every: Duration::from_secs(2),
            cache_budget_bytes: 1024 << 20,
            coarsen_after_passes: 300,
            merge_uniform: false,
            seed: 1,
            // 64 × 4 × 4: two rungs past the interactive preset, a quarter of its noise.
            max_paths: 1024,
            early_rung: true,
            top_up_share: 0.5,
            bounces: None,
            // One step of an 8-bit display.
            display_error: 1.0 / 255.0,
        }
    }
}
