//! The viewer's frame rate while the system works, against the same walk with work while walking
//! off (DESIGN.md §3 step 9: the renderers keep working while a person walks, and the viewer's
//! frame rate must not drop for it). A fresh system follows the first pass of the route's first
//! stops with a headless viewer that draws every frame as its window would (`--draw-frames`: at
//! the current camera, at most 60 a second, timed); the runs alternate between work while
//! walking on and off, and each side's figure is the median of its runs. On this machine all
//! three processes share the cores, so the frames compete with the renderers for them; with the
//! renderers elsewhere (a farm) only the updates the viewer receives would.

use std::path::Path;
use std::time::Duration;

use anyhow::Context;

use super::route::{STEPS_PER_SECOND, WalkPlan};
use super::{WalkConfig, Walkable};
use crate::convergence::START_ALLOWANCE;
use crate::stats::median;
use testkit::loopback::{System, ViewerConfig};
use viewer::live_frames::FRAMES_CSV;

/// The stretch drawn: the route's first stops (walked once).
pub(crate) const FRAME_STOPS: usize = 2;

/// The viewer's frames a second while walking, per run, with work while walking on and off.
#[derive(Clone, Debug, Default)]
pub(crate) struct FrameRates {
    pub on: Vec<f64>,
    pub off: Vec<f64>,
    /// Seconds walked in each run (the moving stretches of its first pass).
    pub walking_s: f64,
}

impl FrameRates {
    /// Writes one line per run, `work_while_walking,run,frames_per_s` (nothing if none ran).
    pub fn write_csv(&self, path: &Path) -> anyhow::Result<()> {
        if self.on.is_empty() && self.off.is_empty() {
            return Ok(());
        }
        let mut text = String::from("work_while_walking,run,frames_per_s\n");
        for (side, fps) in [("on", &self.on), ("off", &self.off)] {
            for (run, f) in fps.iter().enumerate() {
                text.push_str(&format!("{side},{},{f:.2}\n", run + 1));
            }
        }
        std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
    }

    /// The medians, on and off, if both sides ran.
    pub fn medians(&self) -> Option<(f64, f64)> {
        (!self.on.is_empty() && !self.off.is_empty())
            .then(|| (median(self.on.clone()), median(self.off.clone())))
    }
}

/// `runs` runs of each side, alternating, on the first pass of `plan` (the route's first
/// [`FRAME_STOPS`] stops).
pub(crate) fn measure(
    config: &WalkConfig,
    exe: &Path,
    walkable: &Walkable,
    plan: &WalkPlan,
    runs: usize,
    dir: &Path,
) -> anyhow::Result<FrameRates> {
    let path_file = dir.join("frames.path");
    std::fs::write(&path_file, plan.path_text())?;
    let first_pass_s = plan.seconds() / 2.0;
    let mut rates = FrameRates {
        walking_s: walking_seconds(plan),
        ..FrameRates::default()
    };
    for run in 0..runs {
        for on in [true, false] {
            let run_dir = dir.join(format!("frames-{}-{run}", if on { "on" } else { "off" }));
            let fps = frames_while_walking(
                config,
                exe,
                walkable,
                (plan, first_pass_s),
                on,
                &path_file,
                &run_dir,
            )?;
            eprintln!(
                "  frames, work while walking {}: {fps:.1} a second",
                if on { "on" } else { "off" }
            );
            if on {
                rates.on.push(fps);
            } else {
                rates.off.push(fps);
            }
        }
    }
    Ok(rates)
}

/// One run: the frames a second drawn while the camera moved in the first `seconds`.
fn frames_while_walking(
    config: &WalkConfig,
    exe: &Path,
    walkable: &Walkable,
    (plan, seconds): (&WalkPlan, f64),
    on: bool,
    path_file: &Path,
    dir: &Path,
) -> anyhow::Result<f64> {
    if dir.exists() {
        std::fs::remove_dir_all(dir)?;
    }
    std::fs::create_dir_all(dir)?;
    let off = ["--work-while-walking", "off"].map(String::from);
    let system = config.system(exe, walkable, if on { &[] } else { &off });
    let viewer = ViewerConfig {
        view: walkable.first_view()?,
        width: config.width,
        height: config.height,
        seconds: Some(seconds),
        time_limit: Duration::from_secs_f64(seconds) + START_ALLOWANCE,
        every_seconds: None,
        at_samples: vec![],
        when_idle: false,
    };
    let flags = [
        "--camera-path",
        &path_file.to_string_lossy(),
        "--draw-frames",
    ]
    .map(String::from);
    let out = dir.join("snapshots");
    let mut running = System::start(&system, dir)?;
    running.run_viewer_with(&viewer, &flags, &out)?;
    drop(running);
    let csv = out.join(FRAMES_CSV);
    let text =
        std::fs::read_to_string(&csv).with_context(|| format!("reading {}", csv.display()))?;
    let times = frame_times(&text).with_context(|| format!("in {}", csv.display()))?;
    let walking_frames = times
        .iter()
        .filter(|&&t| t < seconds && plan.walking_at((t * STEPS_PER_SECOND) as usize))
        .count();
    Ok(walking_frames as f64 / walking_seconds(plan).max(1e-9))
}

/// The seconds of the first pass of `plan` in which the camera moves.
fn walking_seconds(plan: &WalkPlan) -> f64 {
    let steps = (0..plan.steps() / 2).filter(|&s| plan.walking_at(s));
    steps.count() as f64 / STEPS_PER_SECOND
}

/// The frames' start times in a viewer's frames.csv (`time_s,frame_ms`).
fn frame_times(text: &str) -> anyhow::Result<Vec<f64>> {
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some("time_s,frame_ms"),
        "not a frames.csv header"
    );
    lines
        .map(|line| {
            let t = line.split(',').next().unwrap_or_default();
            t.parse::<f64>()
                .with_context(|| format!("a frame's time: {line:?}"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_times_are_read_and_a_bad_line_is_refused() {
        let times = frame_times("time_s,frame_ms\n0.0100,12.5\n0.0300,11.0\n").unwrap();
        assert_eq!(times, vec![0.01, 0.03]);
        assert!(frame_times("t,ms\n").is_err());
        assert!(frame_times("time_s,frame_ms\nx,1\n").is_err());
    }

    #[test]
    fn medians_need_both_sides() {
        let mut rates = FrameRates {
            on: vec![20.0, 30.0, 25.0],
            ..FrameRates::default()
        };
        assert_eq!(rates.medians(), None);
        rates.off = vec![40.0];
        assert_eq!(rates.medians(), Some((25.0, 40.0)));
    }
}
