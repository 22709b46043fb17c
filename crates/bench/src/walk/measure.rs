//! What `bench walk` judges and how: the instants asked of both systems (set delays after each
//! stop begins, and the moments along the walk), each instant's picture against its camera's
//! ground truth, and the rows of the walk's CSV.

use std::collections::HashMap;
use std::sync::Arc;

use rayon::prelude::*;

use super::route::{WalkCamera, WalkPlan};
use super::truths::Truths;
use super::viewport::ViewportRun;
use super::{SystemRun, WalkConfig};
use crate::metrics::{ImageError, LinearImage, Reference};

/// Snapshots at a stop, in seconds after it began (those within the stop), and one just before
/// it ends: fine early on, where the time to FLIP 0.1 is read.
const STOP_DELAYS: [f64; 15] = [
    0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.3, 1.6, 2.0, 3.0, 4.5, 6.5,
];
/// The last snapshot of a stop is this long before it ends.
const BEFORE_END_S: f64 = 0.05;
/// A moment's snapshot taken later than this after it shows another camera than the moment's
/// (1.4 m/s: 7 cm): it is left out, as is a stop's snapshot taken after the stop ended.
const MOMENT_LATENESS_S: f64 = 0.05;

/// The two systems, as the CSV and the section name them.
pub(crate) const SYSTEM: &str = "system";
pub(crate) const PER_PIXEL: &str = "per-pixel";

/// An instant judged on both systems.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Ask {
    /// Whether it is at a stop (with the seconds since the stop began) or a moment of the walk.
    pub stop_since_s: Option<f64>,
    pub pass: u32,
    /// The stop's or moment's number within its pass.
    pub number: usize,
    /// The camera the picture is judged against (the stop's, or the moment's).
    pub camera: WalkCamera,
    time_s: f64,
    /// A snapshot taken after this shows another camera.
    until_s: f64,
}

impl Ask {
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    pub fn kind(&self) -> &'static str {
        if self.stop_since_s.is_some() {
            "stop"
        } else {
            "moment"
        }
    }
}

/// Every instant asked of the walk, in time order.
pub(crate) fn asks(plan: &WalkPlan) -> Vec<Ask> {
    let mut asks: Vec<Ask> = Vec::new();
    for stop in &plan.stops {
        let last = stop.seconds() - BEFORE_END_S;
        let delays = STOP_DELAYS.iter().copied().filter(|&d| d < last);
        for since in delays.chain(std::iter::once(last)) {
            asks.push(Ask {
                stop_since_s: Some(since),
                pass: stop.pass,
                number: stop.number,
                camera: stop.camera,
                time_s: stop.start_s() + since,
                until_s: stop.start_s() + stop.seconds(),
            });
        }
    }
    asks.extend(plan.moments.iter().map(|m| Ask {
        stop_since_s: None,
        pass: m.pass,
        number: m.number,
        camera: m.camera,
        time_s: m.camera.time_s(),
        until_s: m.camera.time_s() + MOMENT_LATENESS_S,
    }));
    asks.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
    asks
}

/// The ground truths of a walk's cameras, by step within a pass (both passes share them), and
/// what they cost.
pub(crate) struct References {
    by_step: HashMap<usize, Arc<Reference>>,
    steps_per_pass: usize,
    pub stops: GroundTruthCost,
    pub moments: GroundTruthCost,
}

/// How many ground truths of one kind, at how many paths per pixel, and the seconds they took
/// to render (this run's, or those kept beside the cached ones).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct GroundTruthCost {
    pub count: usize,
    pub spp: u32,
    pub seconds: f64,
}

impl References {
    fn of(&self, camera: &WalkCamera) -> &Reference {
        &self.by_step[&(camera.step % self.steps_per_pass)]
    }
}

/// Renders (or reads from the cache) the first pass's stop and moment ground truths.
pub(crate) fn ground_truths(
    truths: &Truths,
    plan: &WalkPlan,
    config: &WalkConfig,
) -> anyhow::Result<References> {
    let mut refs = References {
        by_step: HashMap::new(),
        steps_per_pass: plan.steps_per_pass,
        stops: GroundTruthCost {
            spp: config.stop_spp,
            ..Default::default()
        },
        moments: GroundTruthCost {
            spp: config.moment_spp,
            ..Default::default()
        },
    };
    let stops = plan.stops.iter().filter(|s| s.pass == 1).map(|s| s.camera);
    let moments = plan
        .moments
        .iter()
        .filter(|m| m.pass == 1)
        .map(|m| m.camera);
    for (cameras, stop) in [
        (stops.collect::<Vec<_>>(), true),
        (moments.collect(), false),
    ] {
        for camera in cameras {
            let cost = if stop {
                &mut refs.stops
            } else {
                &mut refs.moments
            };
            let truth = truths.ensure(&camera, cost.spp)?;
            cost.count += 1;
            cost.seconds += truth.render_s;
            let reference = Reference::read_exr(&truth.exr)?;
            refs.by_step.insert(camera.step, Arc::new(reference));
        }
    }
    Ok(refs)
}

/// One judged picture: a CSV row.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Row {
    /// [`SYSTEM`] or [`PER_PIXEL`].
    pub system: &'static str,
    /// "stop" or "moment".
    pub kind: &'static str,
    pub pass: u32,
    pub number: usize,
    /// The step of the judged camera (of the whole walk).
    pub step: usize,
    /// When the picture was taken (the system: its snapshot's time; the viewport: the time
    /// asked) and, at a stop, how long after it began.
    pub time_s: f64,
    pub since_stop_s: Option<f64>,
    /// The system: samples computed so far; the viewport: frames averaged in the picture.
    pub samples: u64,
    /// The system: paths traced so far; the viewport: the picture's paths per pixel.
    pub paths: u64,
    /// The SMA's latest stats: renderers' busy share, leaves and cached samples; its resident
    /// memory then, MB (none for the viewport).
    pub busy: f64,
    pub leaves: u64,
    pub cached_samples: u64,
    pub rss_mb: f64,
    /// The SMA's accounted memory (`Stats`, every part its budget bounds), MB, and whether it
    /// was memory-bound (none for the viewport).
    pub accounted_mb: f64,
    pub memory_bound: bool,
    pub error: ImageError,
}

/// A scene's walk measured on both systems.
pub(crate) struct SceneResult {
    pub plan: WalkPlan,
    pub rows: Vec<Row>,
    pub references: GroundTruthCosts,
    /// The SMA's resident memory along the walk: (seconds, MB).
    pub sma_rss_mb: Vec<(f64, f64)>,
    pub cpu: testkit::loopback::CpuShares,
    pub viewport_fps: f64,
    pub viewport_walking_fps: f64,
    /// The system's snapshots taken too late to show the camera asked for, left out.
    pub late: usize,
    /// The viewer's frame rate with work while walking on and off (`frames`; empty: not
    /// measured).
    pub frame_rates: super::frames::FrameRates,
}

/// The stops' and moments' ground truths' costs.
#[derive(Clone, Copy, Debug)]
pub(crate) struct GroundTruthCosts {
    pub stops: GroundTruthCost,
    pub moments: GroundTruthCost,
}

const MB: f64 = 1e6;

/// Judges both systems' pictures at every ask.
pub(crate) fn judge(
    plan: WalkPlan,
    asks: Vec<Ask>,
    refs: &References,
    system: SystemRun,
    viewport: ViewportRun,
) -> anyhow::Result<SceneResult> {
    let rss_mb: Vec<(f64, f64)> = system
        .sma_rss
        .iter()
        .map(|&(t, b)| (t, b as f64 / MB))
        .collect();
    let taken = matched_snapshots(&asks, &system.snapshots)?;
    let in_time: Vec<(&Ask, &Snapshot)> = asks
        .iter()
        .zip(taken)
        .filter(|(ask, s)| s.time_s < ask.until_s)
        .collect();
    let late = asks.len() - in_time.len();
    let mut rows: Vec<Row> = in_time
        .into_par_iter()
        .map(|(ask, s)| {
            let error = refs
                .of(&ask.camera)
                .error_of(&LinearImage::read_exr(&s.exr)?)?;
            Ok(Row {
                system: SYSTEM,
                kind: ask.kind(),
                pass: ask.pass,
                number: ask.number,
                step: ask.camera.step,
                time_s: s.time_s,
                since_stop_s: ask.stop_since_s.map(|d| d + s.time_s - ask.time_s),
                samples: s.samples,
                paths: s.paths,
                busy: s.renderer_busy,
                leaves: s.mesh.as_ref().map_or(0, |m| m.leaves),
                cached_samples: s.mesh.as_ref().map_or(0, |m| m.cached_samples),
                rss_mb: memory_at(&rss_mb, s.time_s),
                accounted_mb: s.budget.map_or(0.0, |b| b.accounted_bytes as f64 / MB),
                memory_bound: s.budget.is_some_and(|b| b.memory_bound),
                error,
            })
        })
        .collect::<anyhow::Result<_>>()?;
    let viewport_rows: Vec<Row> = asks
        .par_iter()
        .zip(&viewport.shown)
        .map(|(ask, (image, frames))| {
            Ok(Row {
                system: PER_PIXEL,
                kind: ask.kind(),
                pass: ask.pass,
                number: ask.number,
                step: ask.camera.step,
                time_s: ask.time_s,
                since_stop_s: ask.stop_since_s,
                samples: u64::from(*frames),
                paths: u64::from(*frames),
                busy: 1.0,
                leaves: 0,
                cached_samples: 0,
                rss_mb: 0.0,
                accounted_mb: 0.0,
                memory_bound: false,
                error: refs.of(&ask.camera).error_of(image)?,
            })
        })
        .collect::<anyhow::Result<_>>()?;
    rows.extend(viewport_rows);
    Ok(SceneResult {
        rows,
        references: GroundTruthCosts {
            stops: refs.stops,
            moments: refs.moments,
        },
        sma_rss_mb: rss_mb,
        cpu: system.cpu,
        viewport_fps: viewport.frames_per_second(),
        viewport_walking_fps: viewport.walking_frames_per_second(),
        late,
        plan,
        frame_rates: Default::default(),
    })
}

type Snapshot = crate::convergence::snapshots::Snapshot;

/// For each ask, the first snapshot taken at or after it (the viewer takes one on the first
/// tick at or past each asked time; two asks within one tick share it).
fn matched_snapshots<'a>(
    asks: &[Ask],
    snapshots: &'a [Snapshot],
) -> anyhow::Result<Vec<&'a Snapshot>> {
    asks.iter()
        .map(|ask| {
            snapshots
                .iter()
                .find(|s| s.time_s >= ask.time_s - 5e-4)
                .ok_or_else(|| {
                    anyhow::anyhow!(
                        "the viewer took no snapshot at or after {:.3} s ({} snapshots)",
                        ask.time_s,
                        snapshots.len()
                    )
                })
        })
        .collect()
}

/// The latest memory sample at or before `t` (the first one before any).
fn memory_at(samples: &[(f64, f64)], t: f64) -> f64 {
    samples
        .iter()
        .take_while(|(at, _)| *at <= t)
        .last()
        .or(samples.first())
        .map_or(0.0, |s| s.1)
}

/// The first time after a stop began at which `rows` (one system's, one stop's, in time order)
/// show mean FLIP at or below `level`.
pub(crate) fn time_to(rows: &[&Row], level: f64) -> Option<f64> {
    rows.iter()
        .find(|r| r.error.flip <= level)
        .and_then(|r| r.since_stop_s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::walk::{route, sites};

    #[test]
    fn every_stop_and_moment_is_asked_in_time_order_and_within_its_stop() {
        let plan = route::generate(&sites::bracara().quick(2.5, 1.5), 2);
        let asks = asks(&plan);
        assert!(asks.windows(2).all(|w| w[0].time_s <= w[1].time_s));
        assert_eq!(asks.iter().filter(|a| a.kind() == "moment").count(), 4);
        for stop in &plan.stops {
            let at: Vec<&Ask> = asks
                .iter()
                .filter(|a| (a.pass, a.number, a.kind()) == (stop.pass, stop.number, "stop"))
                .collect();
            assert!(at.len() >= 8, "{}", at.len());
            assert_eq!(at[0].time_s, stop.start_s());
            let end = stop.start_s() + stop.seconds();
            assert!(at.iter().all(|a| a.time_s < end && a.camera == stop.camera));
        }
    }

    #[test]
    fn snapshots_are_matched_to_the_first_at_or_after_each_ask() {
        let snap = |t: f64| Snapshot {
            time_s: t,
            shown: 0,
            inserted: 0,
            removed: 0,
            samples: 0,
            paths: 0,
            outstanding: 0,
            renderer_busy: 0.0,
            converged: false,
            exr: format!("{t}.exr").into(),
            mesh: None,
            budget: None,
        };
        let plan = route::generate(&sites::bracara().quick(2.5, 1.5), 1);
        let asks: Vec<Ask> = asks(&plan).into_iter().take(3).collect();
        let snaps: Vec<Snapshot> = asks.iter().map(|a| snap(a.time_s + 0.015)).collect();
        let matched = matched_snapshots(&asks, &snaps).unwrap();
        assert!(
            matched
                .iter()
                .zip(&snaps)
                .all(|(m, s)| m.time_s == s.time_s)
        );
        assert!(matched_snapshots(&asks, &snaps[..1]).is_err());
    }

    #[test]
    fn memory_is_the_latest_sample_before_the_instant() {
        let samples = [(0.5, 10.0), (1.0, 20.0), (1.5, 30.0)];
        assert_eq!(memory_at(&samples, 1.2), 20.0);
        assert_eq!(memory_at(&samples, 0.1), 10.0);
        assert_eq!(memory_at(&[], 1.0), 0.0);
    }
}
