//! Headless mode: the window's drawing offscreen, with snapshots at set times, at set sample
//! counts or when the SMA goes idle (DESIGN.md §10: the convergence measurements read these).
//! Time 0 is when the first camera is sent.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::Context;
use protocol::viewer_link::{Camera, Epoch, ViewerToSma};

use crate::camera_path::CameraPath;
use crate::camera_sender::{CameraSender, DEFAULT_INTERVAL};
use crate::config::ViewerConfig;
use crate::draw::DrawSettings;
use crate::link::{Link, LinkEvent, event_queue};
use crate::live_frames::LiveFrames;
use crate::panel::Facts;
use crate::progress::ProgressPrinter;
use crate::session::{pick_viewpoint, preferences};
use crate::snapshot_files::{SnapshotRecord, SnapshotWriter};
use crate::snapshot_painter::{Canvas, Frame};
use crate::view_state::{Reaction, ViewState};
use crate::walk_camera::WalkCamera;

/// How often the loop wakes without news, to follow the camera path and the clock.
const TICK: Duration = Duration::from_millis(20);
/// Field of view of camera-path keyframes that give none, when the scene has no viewpoint.
const FALLBACK_FOV_DEG: f32 = 60.0;

/// When to take snapshots and when to stop.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotPlan {
    every_s: Option<f64>,
    next_periodic_s: f64,
    /// Sample counts not yet reached, ascending.
    thresholds: Vec<u64>,
    /// Times (seconds) not yet reached, ascending.
    times: Vec<f64>,
    when_idle: bool,
    seconds: Option<f64>,
    /// No trigger was asked for: one snapshot at the end.
    at_end_only: bool,
}

impl SnapshotPlan {
    pub fn new(
        every_s: Option<f64>,
        mut thresholds: Vec<u64>,
        mut times: Vec<f64>,
        when_idle: bool,
        seconds: Option<f64>,
    ) -> SnapshotPlan {
        thresholds.sort_unstable();
        thresholds.dedup();
        times.retain(|t| t.is_finite());
        times.sort_by(f64::total_cmp);
        times.dedup();
        let at_end_only =
            every_s.is_none() && thresholds.is_empty() && times.is_empty() && !when_idle;
        SnapshotPlan {
            every_s,
            next_periodic_s: 0.0,
            thresholds,
            times,
            when_idle,
            seconds,
            at_end_only,
        }
    }

    /// Whether to take a snapshot now, at `t` seconds, given the latest epoch and the sequence
    /// number of the camera in force; the triggers it answers are used up.
    pub fn due(&mut self, t: f64, epoch: Option<&Epoch>, camera_seq: u64) -> bool {
        let mut due = false;
        if let Some(every) = self.every_s
            && t >= self.next_periodic_s
            && self.seconds.is_none_or(|end| self.next_periodic_s <= end)
        {
            // Skipped slots (a slow snapshot) are not made up: one snapshot, then the next slot.
            while self.next_periodic_s <= t {
                self.next_periodic_s += every;
            }
            due = true;
        }
        // Times passed between two ticks give one snapshot, as skipped periodic slots do.
        let passed = self.times.partition_point(|&at| at <= t);
        if passed > 0 {
            self.times.drain(..passed);
            due = true;
        }
        if let Some(e) = epoch {
            let reached = self.thresholds.partition_point(|&n| n <= e.samples);
            if reached > 0 {
                self.thresholds.drain(..reached);
                due = true;
            }
            if self.when_idle && e.camera_seq == camera_seq && e.outstanding == 0 {
                self.when_idle = false;
                due = true;
            }
        }
        due || (self.at_end_only && self.out_of_time(t))
    }

    fn out_of_time(&self, t: f64) -> bool {
        self.seconds.is_some_and(|end| t >= end)
    }

    /// Whether the run is over: out of time, or every finite trigger used up and none periodic.
    pub fn finished(&self, t: f64) -> bool {
        let triggers_done = self.every_s.is_none()
            && self.thresholds.is_empty()
            && self.times.is_empty()
            && !self.when_idle
            && !self.at_end_only;
        self.out_of_time(t) || triggers_done
    }
}

pub fn run(config: &ViewerConfig) -> anyhow::Result<()> {
    anyhow::ensure!(
        config.seconds.is_some()
            || !config.snapshot_at_samples.is_empty()
            || !config.snapshot_at.is_empty()
            || config.snapshot_when_idle,
        "headless needs an end: --seconds, --snapshot-at, --snapshot-at-samples or \
         --snapshot-when-idle"
    );
    let path_text = config
        .camera_path
        .as_ref()
        .map(|p| std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display())))
        .transpose()?;
    let canvas = Canvas {
        width: config.width,
        height: config.height,
        overlay: config.overlay,
    };
    let (writer, adapter) = SnapshotWriter::create(&config.out, canvas, config.hold_snapshots)?;
    tracing::debug!(%adapter, "headless viewer");
    tracing::info!("snapshots go to {}", config.out.display());
    let frames = config
        .draw_frames
        .then(|| LiveFrames::new(config.width, config.height, &config.out))
        .transpose()?;
    // The loop looks every tick, so it needs no wake-up.
    let (notify, events) = event_queue(|| {});
    let link = Link::spawn(config.connect.clone(), notify)?;
    let mut headless = Headless {
        writer,
        plan: SnapshotPlan::new(
            config.snapshot_every,
            config.snapshot_at_samples.clone(),
            config.snapshot_at.clone(),
            config.snapshot_when_idle,
            config.seconds,
        ),
        config,
        path_text,
        link,
        state: ViewState::default(),
        sender: CameraSender::new(DEFAULT_INTERVAL),
        walk: None,
        snapshots: 0,
        progress: ProgressPrinter::new(config.progress),
        frames,
    };
    let result = headless.run(&events.receiver);
    // Nothing takes the link's events any more: a link waiting for room stops waiting.
    drop(events);
    headless.link.close();
    let frames = headless.frames.as_ref().map_or(Ok(()), LiveFrames::finish);
    result.and(frames).and(headless.writer.finish())
}

/// The camera in force and the scripted walk, if any, that moves it.
struct Walk {
    camera: Camera,
    path: Option<CameraPath>,
    /// t = 0: when the first camera was sent.
    started: Instant,
}

struct Headless<'a> {
    config: &'a ViewerConfig,
    writer: SnapshotWriter,
    plan: SnapshotPlan,
    path_text: Option<String>,
    link: Link,
    state: ViewState,
    sender: CameraSender,
    /// None until the SMA's scene is known.
    walk: Option<Walk>,
    snapshots: u32,
    progress: ProgressPrinter,
    /// `--draw-frames`: the window's frames, drawn and timed as it would.
    frames: Option<LiveFrames>,
}

impl Headless<'_> {
    fn run(&mut self, events: &mpsc::Receiver<LinkEvent>) -> anyhow::Result<()> {
        let launched = Instant::now();
        loop {
            let wait = self.frames.as_ref().map_or(TICK, |f| f.due_in().min(TICK));
            for event in first_and_pending(events, wait) {
                if self.state.handle(event) == Reaction::Resend {
                    self.restate()?;
                }
            }
            if self.frames.is_none() {
                // No GPU copy follows this table (a snapshot copies it whole), so the slots it
                // changed need no keeping.
                self.state.table.clear_dirty();
            }
            self.progress.tick(&self.state);
            let Some(walk) = &self.walk else {
                let waited = launched.elapsed().as_secs_f64();
                if self.config.seconds.is_some_and(|s| waited >= s) {
                    anyhow::bail!(
                        "no SMA answered at {} within {waited:.1} s",
                        self.config.connect
                    );
                }
                continue;
            };
            let t = walk.started.elapsed().as_secs_f64();
            self.follow_path(t);
            self.draw_frame(t)?;
            if self
                .plan
                .due(t, self.state.epoch.as_ref(), self.sender.seq())
            {
                self.snapshot(t)?;
            }
            if self.plan.finished(t) {
                tracing::info!(
                    t = format!("{t:.1}"),
                    snapshots = self.snapshots,
                    "{}",
                    conventions::logging::HEADLESS_RUN_OVER
                );
                return Ok(());
            }
        }
    }

    /// A new session: send the camera and the refinement preferences again.
    fn restate(&mut self) -> anyhow::Result<()> {
        let Some(scene) = &self.state.scene else {
            return Ok(());
        };
        if self.walk.is_none() {
            let (camera, path) = start_camera(self.config, scene, self.path_text.as_deref())?;
            self.walk = Some(Walk {
                camera,
                path,
                started: Instant::now(),
            });
        }
        let camera = &self.walk.as_ref().expect("set above").camera;
        let sent = self.sender.force(camera, Instant::now());
        self.state.direct.follow(&sent);
        self.link.send(ViewerToSma::Camera(sent));
        for msg in preferences(self.config.criterion.as_deref(), self.config.no_refine) {
            self.link.send(msg);
        }
        Ok(())
    }

    fn follow_path(&mut self, t: f64) {
        let Some(Walk {
            camera,
            path: Some(path),
            ..
        }) = &mut self.walk
        else {
            return;
        };
        *camera =
            Camera::from_viewpoint(&path.at(t as f32), 0, self.config.width, self.config.height);
        if let Some(sent) = self.sender.offer(camera, Instant::now()) {
            self.state.direct.follow(&sent);
            self.link.send(ViewerToSma::Camera(sent));
        }
    }

    fn draw_settings(&self) -> DrawSettings {
        DrawSettings {
            tone_map: self.config.tone_map,
            l_white: self.state.l_white,
            wireframe: self.config.wireframe,
            sky: self.state.sky(),
        }
    }

    /// `--draw-frames`: the window's frame at the current camera, when one is due.
    fn draw_frame(&mut self, t: f64) -> anyhow::Result<()> {
        let settings = self.draw_settings();
        let (Some(frames), Some(walk)) = (&mut self.frames, &self.walk) else {
            return Ok(());
        };
        frames.draw_if_due(&mut self.state, &walk.camera, &settings, t)
    }

    fn snapshot(&mut self, t: f64) -> anyhow::Result<()> {
        let settings = self.draw_settings();
        let Some(walk) = &self.walk else {
            return Ok(());
        };
        // `--overlay`: the window's panel over the PNG snapshots.
        let facts = self.config.overlay.then(|| Facts {
            tone_map: settings.tone_map,
            wireframe: settings.wireframe,
            paused: self.config.no_refine,
            ..Facts::of(&self.state, &self.config.connect)
        });
        let frame = Frame::capture(
            (&self.state.table, &self.state.direct, &self.state.looks),
            &walk.camera,
            settings,
            facts,
        );
        let (inserted, removed) = self.state.take_interval();
        let epoch = self.state.epoch.unwrap_or_default();
        let record = SnapshotRecord {
            index: self.snapshots,
            time_s: t,
            camera_seq: epoch.camera_seq,
            shown: self.state.table.len() as u64,
            inserted,
            removed,
            samples: epoch.samples,
            paths: epoch.paths,
            outstanding: epoch.outstanding,
            stats: self.state.stats,
        };
        tracing::debug!(
            index = record.index,
            t,
            shown = record.shown,
            samples = record.samples,
            "snapshot"
        );
        self.writer.write(record, frame)?;
        self.snapshots += 1;
        Ok(())
    }
}

/// The first camera and the walk to follow, once the scene is known.
fn start_camera(
    config: &ViewerConfig,
    scene: &protocol::viewer_link::SceneInfo,
    path_text: Option<&str>,
) -> anyhow::Result<(Camera, Option<CameraPath>)> {
    let start = pick_viewpoint(scene, config.view.as_deref())?;
    let fov = start.as_ref().map_or(FALLBACK_FOV_DEG, |vp| vp.fov_y_deg);
    let path = path_text
        .map(|text| CameraPath::parse(text, fov))
        .transpose()?;
    let camera = match (&path, &start) {
        (Some(path), _) => Camera::from_viewpoint(&path.at(0.0), 0, config.width, config.height),
        (None, Some(vp)) => Camera::from_viewpoint(vp, 0, config.width, config.height),
        (None, None) => {
            WalkCamera::overlooking(&scene.bounds, 1.0).camera(config.width, config.height)
        }
    };
    Ok((camera, path))
}

/// Waits up to `timeout` for one event, then takes whatever else is already queued.
fn first_and_pending<T>(rx: &mpsc::Receiver<T>, timeout: Duration) -> Vec<T> {
    let mut events: Vec<T> = rx.recv_timeout(timeout).into_iter().collect();
    events.extend(rx.try_iter());
    events
}

#[cfg(test)]
mod tests {
    use super::*;

    fn epoch(samples: u64, outstanding: u64, camera_seq: u64) -> Epoch {
        Epoch {
            samples,
            outstanding,
            camera_seq,
            ..Epoch::default()
        }
    }

    #[test]
    fn periodic_snapshots_start_at_zero_and_stop_at_the_end() {
        let mut plan = SnapshotPlan::new(Some(1.0), vec![], vec![], false, Some(2.0));
        let taken: Vec<f64> = [0.0, 0.5, 1.02, 1.5, 2.3, 3.5]
            .into_iter()
            .filter(|&t| plan.due(t, None, 1))
            .collect();
        assert_eq!(taken, vec![0.0, 1.02, 2.3]);
        assert!(!plan.finished(1.9) && plan.finished(2.0));
    }

    #[test]
    fn sample_thresholds_fire_once_and_end_the_run() {
        let mut plan = SnapshotPlan::new(None, vec![200, 100], vec![], false, None);
        assert!(!plan.due(0.1, Some(&epoch(50, 9, 1)), 1));
        assert!(plan.due(0.2, Some(&epoch(150, 9, 1)), 1));
        assert!(!plan.due(0.3, Some(&epoch(150, 9, 1)), 1));
        assert!(!plan.finished(0.3));
        assert!(plan.due(0.4, Some(&epoch(500, 9, 1)), 1));
        assert!(plan.finished(0.4));
    }

    #[test]
    fn idle_means_nothing_outstanding_for_the_current_camera() {
        let mut plan = SnapshotPlan::new(None, vec![], vec![], true, Some(60.0));
        assert!(
            !plan.due(0.1, Some(&epoch(10, 0, 1)), 2),
            "an epoch of an older camera"
        );
        assert!(!plan.due(0.2, Some(&epoch(10, 3, 2)), 2));
        assert!(plan.due(0.3, Some(&epoch(13, 0, 2)), 2));
        assert!(plan.finished(0.3));
    }

    #[test]
    fn without_triggers_one_snapshot_at_the_end() {
        let mut plan = SnapshotPlan::new(None, vec![], vec![], false, Some(1.0));
        assert!(!plan.due(0.5, Some(&epoch(1, 0, 1)), 1) && !plan.finished(0.5));
        assert!(plan.due(1.0, None, 1) && plan.finished(1.0));
    }

    #[test]
    fn set_times_fire_once_each_and_end_the_run() {
        let mut plan = SnapshotPlan::new(None, vec![], vec![2.0, 0.5, 0.6], false, None);
        assert!(!plan.due(0.4, None, 1));
        assert!(plan.due(0.7, None, 1), "0.5 and 0.6 passed: one snapshot");
        assert!(!plan.due(1.0, None, 1) && !plan.finished(1.0));
        assert!(plan.due(2.0, None, 1) && plan.finished(2.0));
    }
}
