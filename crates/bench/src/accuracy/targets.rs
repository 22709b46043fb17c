//! The end-to-end targets of convergence (DESIGN.md §10), each stated as met or missed with its
//! figures: the renderer never idles under a resting viewer, the error never plateaus, the system
//! is as good as the direct render at 60 s, the speed-up to mean FLIP 0.1, and the best
//! noise-aware criterion against the thesis's at equal paths traced.

use std::fmt::Write as _;

use super::{ViewResult, speedup};
use crate::convergence::record::{
    Measurement, NO_REFINE, at_paths, by_time, repetitions, run_labels, run_rows, time_to_reach,
};
use crate::convergence::tables::{PATH_LEVELS, millions};
use crate::convergence::{BEST_NOISE_AWARE, RIVALS};

/// The speed-up to this mean FLIP…
pub(super) const TARGET_FLIP: f64 = 0.1;
/// …at least this on every view…
const SPEEDUP_EVERY_VIEW: f64 = 10.0;
/// …and at least this on [`VIEWS_AT_TWENTY`] of them.
const SPEEDUP_MOST_VIEWS: f64 = 20.0;
const VIEWS_AT_TWENTY: usize = 4;
/// The renderer's busy share in every window from the first picture to the stated end.
const BUSY_SHARE: f64 = 0.8;
const BUSY_WINDOW_S: f64 = 5.0;
/// The instants at which the error must keep falling.
const PLATEAU_TIMES: [f64; 3] = [5.0, 20.0, 60.0];
/// At 60 s: at or below the direct render's FLIP on this many views, at most twice it on all.
const COMPETITOR_TIME: f64 = 60.0;
const VIEWS_AT_COMPETITOR: usize = 3;
/// At equal paths the best noise-aware criterion beats every rival on this many views.
const VIEWS_AT_EQUAL_PATHS: usize = 5;
const DEFAULT_VIEWS: usize = 6;

pub(crate) fn section(results: &[&ViewResult]) -> String {
    let mut md = String::from("### End-to-end targets\n\n");
    let _ = writeln!(
        md,
        "Judged on `{BEST_NOISE_AWARE}`, the best noise-aware criterion (the speed-up on the best criterion of \
         each view); its figures are medians over its runs (`runs`: `bench convergence --repetitions`), the \
         other criteria's from one run. Busy: the lowest renderer busy share over {BUSY_WINDOW_S:.0}-s windows from the first \
         picture (the first snapshot showing a triangle with the SMA's first statistics, about a second in) \
         to the stated end (`converged`) or the run's end, as \
         the SMA measured it; and the renderer's CPU time as a share of the machine's cores over the run's \
         time (t = 0 to the stated end, or to the last snapshot), which says whether the renderer computed while it held work (the SMA and \
         the viewer share the same cores). The target is the busy share (the renderer workers' time with a batch in hand over wall \
         time); the CPU share is a stricter check, stated on its own line.\n"
    );
    md.push_str(
        "| view | runs | busy (min over windows) | renderer CPU share | FLIP at 5 / 20 / 60 s | direct render's FLIP | best speed-up to FLIP 0.1 | at equal paths |\n\
         |---|---:|---:|---:|---:|---:|---:|---|\n",
    );
    let mut verdicts = Verdicts::default();
    for v in results {
        let runs: Vec<RunFigures> = repetitions(&v.rows, BEST_NOISE_AWARE)
            .iter()
            .map(|(label, rows)| RunFigures::of(v, label, rows))
            .collect();
        let busy = median_of(runs.iter().map(|r| r.busy));
        let cpu_share = median_of(runs.iter().map(|r| r.cpu_share));
        let flips = [0, 1, 2].map(|i| median_of(runs.iter().map(|r| r.flips[i])));
        let settled = runs.iter().filter(|r| r.converged).count() * 2 > runs.len();
        let speedup = best_speedup(v, &runs);
        let (wins, paths_text) = equal_paths(&v.rows);
        verdicts.add(v, [busy, cpu_share], settled, flips, speedup, wins);
        let flip_text: Vec<String> = flips
            .iter()
            .map(|f| f.map_or("—".into(), |f| format!("{f:.3}")))
            .collect();
        let _ = writeln!(
            md,
            "| {} {} | {} | {} | {} | {} | {:.3} | {} | {paths_text} |",
            v.record.label,
            v.record.view,
            runs.len(),
            busy.map_or("—".into(), |b| format!("{b:.2}")),
            cpu_share.map_or("—".into(), |c| format!("{c:.2}")),
            flip_text.join(" / "),
            v.direct.flip,
            speedup.map_or("not reached".into(), |s| format!("{s:.1}×")),
        );
    }
    md.push('\n');
    md.push_str(&verdicts.text(results.len()));
    md
}

/// Each target's count over the views.
#[derive(Default)]
struct Verdicts {
    never_idle: usize,
    computing: usize,
    no_plateau: usize,
    at_competitor: usize,
    within_twice: usize,
    speedup_ten: usize,
    speedup_twenty: usize,
    equal_paths: usize,
}

impl Verdicts {
    /// One view's figures; the busy share and the renderer CPU share; `converged`:
    /// most of its runs reached the stated end.
    fn add(
        &mut self,
        v: &ViewResult,
        [busy, cpu_share]: [Option<f64>; 2],
        converged: bool,
        flips: [Option<f64>; 3],
        speedup: Option<f64>,
        wins_at_equal_paths: bool,
    ) {
        self.never_idle += usize::from(busy.is_some_and(|b| b >= BUSY_SHARE));
        self.computing += usize::from(cpu_share.is_some_and(|c| c >= BUSY_SHARE));
        let falling = match flips {
            [Some(a), Some(b), Some(c)] => c < b && b < a,
            _ => false,
        };
        self.no_plateau += usize::from(falling || converged);
        let at_60 = flips[2];
        self.at_competitor += usize::from(at_60.is_some_and(|f| f <= v.direct.flip));
        self.within_twice += usize::from(at_60.is_some_and(|f| f <= 2.0 * v.direct.flip));
        self.speedup_ten += usize::from(speedup.is_some_and(|s| s >= SPEEDUP_EVERY_VIEW));
        self.speedup_twenty += usize::from(speedup.is_some_and(|s| s >= SPEEDUP_MOST_VIEWS));
        self.equal_paths += usize::from(wins_at_equal_paths);
    }

    fn text(&self, n: usize) -> String {
        let verdict = |met: bool| if met { "**met**" } else { "**missed**" };
        let all = |k: usize| n > 0 && k == n;
        let of = |k: usize, want: usize| k >= want;
        let mut md = String::new();
        let mut line = |text: String| {
            let _ = writeln!(md, "- {text}");
        };
        line(format!(
            "Never idle (busy ≥ {BUSY_SHARE} in every {BUSY_WINDOW_S:.0}-s window, every view): {} ({} of {n}).",
            verdict(all(self.never_idle)),
            self.never_idle
        ));
        line(format!(
            "Stricter: renderer CPU share ≥ {BUSY_SHARE} (it computed while it held work), every view: {} ({} of {n}).",
            verdict(all(self.computing)),
            self.computing
        ));
        line(format!(
            "No plateau (FLIP at 60 s < at 20 s < at 5 s unless converged, every view): {} ({} of {n}).",
            verdict(all(self.no_plateau)),
            self.no_plateau
        ));
        line(format!(
            "At {COMPETITOR_TIME:.0} s, FLIP ≤ the direct render's on at least {VIEWS_AT_COMPETITOR} views: {} \
             ({} of {n}); ≤ 2× it on all: {} ({} of {n}).",
            verdict(of(self.at_competitor, VIEWS_AT_COMPETITOR)),
            self.at_competitor,
            verdict(all(self.within_twice)),
            self.within_twice
        ));
        line(format!(
            "Speed-up to mean FLIP {TARGET_FLIP} ≥ {SPEEDUP_EVERY_VIEW}× on every view: {} ({} of {n}); \
             ≥ {SPEEDUP_MOST_VIEWS}× on at least {VIEWS_AT_TWENTY}: {} ({} of {n}).",
            verdict(all(self.speedup_ten)),
            self.speedup_ten,
            verdict(of(self.speedup_twenty, VIEWS_AT_TWENTY)),
            self.speedup_twenty
        ));
        line(format!(
            "At equal paths traced, {BEST_NOISE_AWARE}'s FLIP ≤ that of {} on at least {VIEWS_AT_EQUAL_PATHS} \
             views: {} ({} of {n}).",
            RIVALS.join(", "),
            verdict(of(self.equal_paths, VIEWS_AT_EQUAL_PATHS)),
            self.equal_paths
        ));
        if n < DEFAULT_VIEWS {
            line(format!(
                "Only {n} of the {DEFAULT_VIEWS} default views were measured: a target stated as a number of \
                 views cannot be met by fewer."
            ));
        }
        md
    }
}

/// The lowest busy share over consecutive windows from the first picture to the stated end;
/// `None` when no full window fits. A snapshot's share is the SMA's second before it; the
/// snapshots taken before the viewer had any statistics carry none (a zero that is no reading),
/// so the windows start at the first picture that comes with a reading.
fn min_window_busy(run: &[&Measurement]) -> Option<f64> {
    let first = run
        .iter()
        .find(|m| m.shown > 0 && m.renderer_busy > 0.0)?
        .time_s;
    let end = run
        .iter()
        .find(|m| m.converged)
        .or(run.last())
        .map(|m| m.time_s)?;
    let mut lowest: Option<f64> = None;
    let mut start = first;
    while start + BUSY_WINDOW_S <= end + 1e-9 {
        let stop = start + BUSY_WINDOW_S;
        let inside: Vec<f64> = run
            .iter()
            .filter(|m| m.time_s > start && m.time_s <= stop + 1e-9)
            .map(|m| m.renderer_busy)
            .collect();
        if !inside.is_empty() {
            let mean = inside.iter().sum::<f64>() / inside.len() as f64;
            lowest = Some(lowest.map_or(mean, |l: f64| l.min(mean)));
        }
        start = stop;
    }
    lowest
}

/// The renderers' CPU seconds over `run` as a share of the machine's cores and the run's time up
/// to the stated end (its snapshot's time, or the last snapshot's): the rest after it is idle by
/// design (nothing is left to shade), and so are the viewer's start before t = 0 and the writing
/// of its queued snapshot files after its last one.
fn renderer_cpu_share(v: &ViewResult, run: &str, rows: &[&Measurement]) -> Option<f64> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let (_, c) = v.cpu.iter().find(|(r, _)| r == run)?;
    let end = rows.iter().find(|m| m.converged).or(rows.last())?.time_s;
    Some(c.renderers_s / (end.max(1e-9) * cores))
}

/// The best speed-up to [`TARGET_FLIP`] over the view's criteria (for the judged one, from the
/// median time over its runs), `None` when none reaches it.
fn best_speedup(v: &ViewResult, judged: &[RunFigures]) -> Option<f64> {
    let judged_time = median_time_to_target(judged);
    run_labels(&v.rows)
        .iter()
        .filter(|l| l.as_str() != NO_REFINE && l.as_str() != BEST_NOISE_AWARE)
        .filter_map(|c| time_to_reach(&run_rows(&v.rows, c), TARGET_FLIP))
        .chain(judged_time)
        .map(|t| speedup(v.direct.seconds, t))
        .max_by(f64::total_cmp)
}

/// What one run of the judged criterion shows.
pub(super) struct RunFigures {
    busy: Option<f64>,
    cpu_share: Option<f64>,
    /// FLIP at [`PLATEAU_TIMES`]: 5, 20 and 60 s.
    pub flips: [Option<f64>; 3],
    converged: bool,
    /// Time to [`TARGET_FLIP`].
    pub time_to_target: Option<f64>,
}

impl RunFigures {
    pub(super) fn of(v: &ViewResult, label: &str, rows: &[&Measurement]) -> RunFigures {
        RunFigures {
            busy: min_window_busy(rows),
            cpu_share: renderer_cpu_share(v, label, rows),
            flips: PLATEAU_TIMES.map(|t| by_time(rows, t).map(|m| m.error.flip)),
            converged: rows.iter().any(|m| m.converged),
            time_to_target: time_to_reach(rows, TARGET_FLIP),
        }
    }
}

/// The median time to [`TARGET_FLIP`] over `runs`: a run that never reaches it counts as the
/// slowest, not as missing (`None` when most never do).
pub(super) fn median_time_to_target(runs: &[RunFigures]) -> Option<f64> {
    let slowest_if_never = runs
        .iter()
        .map(|r| Some(r.time_to_target.unwrap_or(f64::INFINITY)));
    median_of(slowest_if_never).filter(|t| t.is_finite())
}

/// The median of the values present (`None` when there is none).
pub(super) fn median_of(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let present: Vec<f64> = values.flatten().collect();
    (!present.is_empty()).then(|| crate::stats::median(present))
}

/// Whether [`BEST_NOISE_AWARE`]'s FLIP is at most every rival's at the largest path count that it
/// and every rival reached, with the figures.
fn equal_paths(rows: &[Measurement]) -> (bool, String) {
    let mut compared: Vec<&str> = RIVALS.to_vec();
    compared.push(BEST_NOISE_AWARE);
    let reached_by_all = |n: u64| {
        compared
            .iter()
            .all(|c| at_paths(&run_rows(rows, c), n).is_some())
    };
    let Some(n) = PATH_LEVELS.into_iter().rev().find(|n| reached_by_all(*n)) else {
        return (false, "no common path count".into());
    };
    let flip = |c: &str| {
        at_paths(&run_rows(rows, c), n)
            .map(|m| m.error.flip)
            .unwrap_or(f64::NAN)
    };
    let best = flip(BEST_NOISE_AWARE);
    let holds = RIVALS.iter().all(|c| best <= flip(c));
    let figures: Vec<String> = compared
        .iter()
        .map(|c| format!("{c} {:.3}", flip(c)))
        .collect();
    (
        holds,
        format!(
            "{} at {} paths: {}",
            if holds { "yes" } else { "no" },
            millions(n),
            figures.join(", ")
        ),
    )
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::Direct;
    use super::*;
    use crate::convergence::manifest::ViewRecord;
    use crate::convergence::record::test_measurement;
    use testkit::loopback::CpuShares;

    /// A run of `criterion` with one snapshot a second: FLIP from `flip(t)`, busy `busy(t)`.
    pub(in crate::accuracy) fn run(
        criterion: &str,
        seconds: u32,
        flip: impl Fn(f64) -> f64,
        busy: impl Fn(f64) -> f64,
    ) -> Vec<Measurement> {
        (0..=seconds)
            .map(|s| {
                let t = f64::from(s);
                Measurement {
                    shown: u64::from(s > 0),
                    renderer_busy: busy(t),
                    ..test_measurement(criterion, t, u64::from(s) * 100_000, flip(t))
                }
            })
            .collect()
    }

    /// The renderer computed for `share` of the cores over a 60-s run.
    pub(in crate::accuracy) fn view(
        name: &str,
        direct_seconds: f64,
        rows: Vec<Measurement>,
        share: f64,
    ) -> ViewResult {
        let cores = std::thread::available_parallelism().unwrap().get() as f64;
        let cpu = CpuShares {
            wall_s: 60.0,
            renderers_s: share * 60.0 * cores,
            sma_s: 1.0,
            viewer_s: 1.0,
        };
        ViewResult {
            cpu: vec![(BEST_NOISE_AWARE.to_string(), cpu)],
            record: ViewRecord {
                label: "bracara".into(),
                scene: "bracara".into(),
                view: name.into(),
                width: 64,
                height: 48,
                gt_spp: 1024,
                seconds: 60.0,
                sample_counts: vec![1000, 2000],
                ground_truth: "gt.exr".into(),
                measured: String::new(),
                profile: sma::config::Profile::Today,
            },
            rows,
            direct: Direct {
                seconds: direct_seconds,
                flip: 0.05,
                measured: "2026-12-04 at abc1234".into(),
                recalled: false,
            },
            per_pixel: vec![],
        }
    }

    /// Every criterion falls as 0.5 / (1 + t); the best one by `best_gain` more.
    fn rows(best_gain: f64, busy: f64) -> Vec<Measurement> {
        let mut rows = Vec::new();
        for rival in RIVALS {
            rows.extend(run(rival, 60, |t| 0.5 / (1.0 + t), |_| 0.9));
        }
        rows.extend(run(
            BEST_NOISE_AWARE,
            60,
            |t| 0.5 / (1.0 + best_gain * t),
            |_| busy,
        ));
        rows
    }

    #[test]
    fn a_busy_falling_view_meets_what_it_can() {
        // The best criterion reaches 0.1 at 2 s (0.5 / (1 + 2·2) = 0.1): 40 s / 2 s = 20×.
        let md = section(&[&view("MC", 40.0, rows(2.0, 0.95), 0.9)]);
        assert!(md.contains("| bracara MC | 1 | 0.95 | 0.90 |"), "{md}");
        assert!(md.contains("| 20.0× |"), "{md}");
        assert!(
            md.contains(
                "Never idle (busy ≥ 0.8 in every 5-s window, every view): **met** (1 of 1)"
            ),
            "{md}"
        );
        assert!(md.contains("yes at 268.4 M paths"), "{md}");
        assert!(md.contains("Only 1 of the 6 default views"), "{md}");
    }

    #[test]
    fn idle_windows_and_a_worse_criterion_are_missed() {
        let md = section(&[&view("VT", 40.0, rows(0.5, 0.3), 0.9)]);
        assert!(md.contains("| bracara VT | 1 | 0.30 | 0.90 |"), "{md}");
        assert!(md.contains("no at 268.4 M paths"), "{md}");
        assert!(
            md.contains(
                "Never idle (busy ≥ 0.8 in every 5-s window, every view): **missed** (0 of 1)"
            ),
            "{md}"
        );
    }

    #[test]
    fn the_judged_figures_are_medians_over_its_runs() {
        // Three runs of the judged criterion: busy 0.95, 0.5 and 0.9, reaching FLIP 0.1 at 2 s,
        // never and 4 s. Medians: busy 0.90; the slowest-counting median time 4 s, 10×.
        let mut rows = rows(2.0, 0.95);
        let repeat = |k, gain: f64, busy: f64| {
            let label = crate::convergence::record::repeat_label(BEST_NOISE_AWARE, k);
            run(&label, 60, move |t| 0.5 / (1.0 + gain * t), move |_| busy)
        };
        rows.extend(repeat(2, 0.0, 0.5));
        rows.extend(repeat(3, 1.0, 0.9));
        let mut v = view("MC", 40.0, rows, 0.9);
        let cpu = v.cpu[0].1;
        for k in 2..=3 {
            let label = crate::convergence::record::repeat_label(BEST_NOISE_AWARE, k);
            v.cpu.push((label, cpu));
        }
        let md = section(&[&v]);
        assert!(md.contains("| bracara MC | 3 | 0.90 | 0.90 |"), "{md}");
        assert!(md.contains("| 10.0× |"), "{md}");
    }

    #[test]
    fn a_renderer_that_holds_work_but_does_not_compute_misses_the_stricter_check() {
        let md = section(&[&view("VR", 40.0, rows(2.0, 1.0), 0.1)]);
        assert!(md.contains("| bracara VR | 1 | 1.00 | 0.10 |"), "{md}");
        assert!(
            md.contains(
                "Never idle (busy ≥ 0.8 in every 5-s window, every view): **met** (1 of 1)"
            ),
            "{md}"
        );
        assert!(
            md.contains(
                "Stricter: renderer CPU share ≥ 0.8 (it computed while it held work), every view: **missed** (0 of 1)"
            ),
            "{md}"
        );
    }

    #[test]
    fn snapshots_before_the_first_statistics_are_no_reading() {
        // Pictures at 0.2 and 0.5 s, before the SMA's first statistics (busy 0: none yet), then
        // a busy renderer from the reading at 1 s on.
        let mut best = run(BEST_NOISE_AWARE, 12, |_| 0.1, |t| f64::from(t >= 1.0));
        for t in [0.2, 0.5] {
            best.push(Measurement {
                shown: 10,
                renderer_busy: 0.0,
                ..test_measurement(BEST_NOISE_AWARE, t, 10, 0.5)
            });
        }
        best.sort_by(|a, b| a.time_s.total_cmp(&b.time_s));
        let refs: Vec<&Measurement> = best.iter().collect();
        assert_eq!(min_window_busy(&refs), Some(1.0));
    }

    #[test]
    fn the_busy_windows_stop_at_the_stated_end() {
        let mut best = run(
            BEST_NOISE_AWARE,
            20,
            |_| 0.1,
            |t| if t <= 6.0 { 1.0 } else { 0.0 },
        );
        for m in best.iter_mut().filter(|m| m.time_s >= 6.0) {
            m.converged = true;
        }
        let refs: Vec<&Measurement> = best.iter().collect();
        // First picture at 1 s, converged at 6 s: one window (1, 6], all busy.
        assert_eq!(min_window_busy(&refs), Some(1.0));
        for m in best.iter_mut() {
            m.converged = false;
        }
        let refs: Vec<&Measurement> = best.iter().collect();
        assert_eq!(min_window_busy(&refs), Some(0.0));
    }
}
