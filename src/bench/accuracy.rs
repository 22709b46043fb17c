//! `walkthrough bench accuracy` (DESIGN.md §10 "What accuracy costs in time"): per view,
//! the time each criterion needs to reach several error levels (read from `bench convergence`'s
//! CSVs) against the time of the competitor, a direct per-pixel render at the interactive preset
//! (`renderer reference --spp 64 --bounces 2`, as the thesis timed Radiance in table 5.1); the
//! speed-up, and the end-to-end targets stated as met or missed.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::Context;

use crate::bench::convergence::manifest::{self, ViewRecord};
use crate::bench::convergence::record::{
    self, Measurement, NO_REFINE, at_samples, run_labels, run_rows, time_to_reach,
};
use crate::bench::convergence::{GROUND_TRUTH_SEED, INTERACTIVE_BOUNCES, default_criteria};
use crate::bench::metrics::Reference;

pub const SECTION: &str = "docs/bench/accuracy.md";

/// The end-to-end targets: the speed-up to this mean FLIP…
const TARGET_FLIP: f64 = 0.1;
/// …at least this on every view…
const SPEEDUP_EVERY_VIEW: f64 = 10.0;
/// …and at least this on half of them.
const SPEEDUP_HALF_THE_VIEWS: f64 = 20.0;
/// The criterion the thesis found best (§5.3), compared at equal samples with the thesis's others.
const THESIS_BEST: &str = "nld-os";
const THESIS_RIVALS: [&str; 2] = ["rnd", "nld-is"];

/// What `bench accuracy` measures and where it writes.
#[derive(Debug, Clone)]
pub struct AccuracyConfig {
    /// The output folder of `bench convergence`.
    pub convergence: PathBuf,
    /// Mean FLIP levels to reach.
    pub levels: Vec<f64>,
    /// Paths per pixel of the direct render (the interactive preset: 64).
    pub spp: u32,
    /// The direct renders' images (an ignored folder).
    pub direct: PathBuf,
    /// Do not write docs/bench/accuracy.md nor BENCHMARKS.md.
    pub no_report: bool,
}

/// The competitor on one view.
struct Direct {
    seconds: f64,
    flip: f64,
}

struct ViewResult {
    record: ViewRecord,
    rows: Vec<Measurement>,
    direct: Direct,
}

pub fn run(args: AccuracyConfig) -> anyhow::Result<()> {
    let exe = std::env::current_exe().context("locating the walkthrough binary")?;
    let mut results = Vec::new();
    for record in manifest::read(&args.convergence)? {
        eprintln!(
            "accuracy: direct render of {} {} at {} paths per pixel…",
            record.label, record.view, args.spp
        );
        let direct = direct_render(&exe, &record, &args)?;
        let rows = record::read_csv(&args.convergence.join(format!("{}.csv", record.stem())))?;
        results.push(ViewResult {
            record,
            rows,
            direct,
        });
    }
    let md = section(&results, &args);
    print!("{md}");
    if !args.no_report {
        std::fs::write(SECTION, &md)?;
        crate::bench::report::assemble(Path::new("BENCHMARKS.md"))?;
    }
    Ok(())
}

/// Times `walkthrough renderer reference` at the interactive preset as a user would run it (scene
/// load and BVH build included, as in the thesis's Radiance times), and measures its image.
fn direct_render(exe: &Path, r: &ViewRecord, args: &AccuracyConfig) -> anyhow::Result<Direct> {
    std::fs::create_dir_all(&args.direct)?;
    let out = args.direct.join(format!(
        "{}-{}x{}-{}spp.exr",
        r.stem(),
        r.width,
        r.height,
        args.spp
    ));
    let started = Instant::now();
    let status = Command::new(exe)
        .args([
            "renderer",
            "reference",
            "--scene",
            &r.scene,
            "--view",
            &r.view,
        ])
        .args([
            "--width",
            &r.width.to_string(),
            "--height",
            &r.height.to_string(),
        ])
        .args([
            "--spp",
            &args.spp.to_string(),
            "--bounces",
            &INTERACTIVE_BOUNCES.to_string(),
        ])
        // Sharing the ground truth's per-pixel streams would replay its first paths and flatter
        // the direct render's error.
        .args(["--seed", &(GROUND_TRUTH_SEED + 1).to_string()])
        .arg("--out")
        .arg(&out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .status()
        .context("starting the direct render")?;
    let seconds = started.elapsed().as_secs_f64();
    anyhow::ensure!(
        status.success(),
        "the direct render of {} failed ({status})",
        r.stem()
    );
    let reference = Reference::read_exr(Path::new(&r.ground_truth))?;
    let flip = reference
        .error_of(&crate::bench::metrics::LinearImage::read_exr(&out)?)?
        .flip;
    Ok(Direct { seconds, flip })
}

fn criteria_of(rows: &[Measurement]) -> Vec<String> {
    run_labels(rows)
        .into_iter()
        .filter(|l| l != NO_REFINE)
        .collect()
}

fn section(results: &[ViewResult], args: &AccuracyConfig) -> String {
    let mut md = String::from("## accuracy\n\n");
    md.push_str(
        "What accuracy costs in time (DESIGN.md §10), regenerated by `walkthrough bench accuracy` from the CSVs of \
         `bench convergence`. Competitor: the direct per-pixel render of the view at the interactive preset \
         (`renderer reference --spp 64 --bounces 2`, wall time of the command, as the thesis timed Radiance in table \
         5.1: 55 s for MC, 39 s for VT). For each criterion: the first snapshot time at which the mean LDR-FLIP \
         against the ground truth is at or below each level (snapshots every second and at fixed sample counts, \
         whichever comes first), and the speed-up = direct time / that time (thesis, by eye: 11× on MC, 20× on VT).\n\n",
    );
    let _ = writeln!(md, "Machine: {}.\n", crate::bench::machine::describe());
    for v in results {
        view_table(&mut md, v, &args.levels);
    }
    md.push_str(&targets(results));
    md
}

fn view_table(md: &mut String, v: &ViewResult, levels: &[f64]) {
    let r = &v.record;
    let _ = writeln!(
        md,
        "### {} {} ({}×{}, runs of {} s)\n\nDirect render: {:.1} s, its own mean FLIP {:.3}.\n",
        r.label, r.view, r.width, r.height, r.seconds, v.direct.seconds, v.direct.flip
    );
    md.push_str("| criterion |");
    for level in levels {
        let _ = write!(md, " FLIP ≤ {level} |");
    }
    md.push_str("\n|---|");
    md.push_str(&"---:|".repeat(levels.len()));
    md.push('\n');
    for criterion in run_labels(&v.rows) {
        let run = run_rows(&v.rows, &criterion);
        let _ = write!(md, "| {criterion} |");
        for level in levels {
            let cell = match time_to_reach(&run, *level) {
                Some(t) => format!("{t:.1} s ({:.0}×)", speedup(v.direct.seconds, t)),
                None => format!("> {} s (< {:.0}×)", r.seconds, v.direct.seconds / r.seconds),
            };
            let _ = write!(md, " {cell} |");
        }
        md.push('\n');
    }
    md.push('\n');
}

fn speedup(direct: f64, t: f64) -> f64 {
    // The snapshot at t = 0 shows an empty picture, so a level is reached later; the floor only
    // keeps a malformed CSV from dividing by zero.
    direct / t.max(1e-3)
}

/// The best speed-up to [`TARGET_FLIP`] of `criterion` on a view, `None` when never reached.
fn target_speedup(v: &ViewResult, criterion: &str) -> Option<f64> {
    time_to_reach(&run_rows(&v.rows, criterion), TARGET_FLIP).map(|t| speedup(v.direct.seconds, t))
}

fn targets(results: &[ViewResult]) -> String {
    let mut md = String::from("### End-to-end targets\n\n");
    let n = results.len();
    let criteria: Vec<String> = results
        .first()
        .map(|v| criteria_of(&v.rows))
        .unwrap_or_else(default_criteria);
    md.push_str("| view |");
    for c in &criteria {
        let _ = write!(md, " {c}: speed-up to FLIP {TARGET_FLIP} |");
    }
    let _ = writeln!(
        md,
        " {THESIS_BEST} ≤ rnd, nld-is at equal samples |\n|---|{}---|",
        "---:|".repeat(criteria.len())
    );
    let mut best_speedups = Vec::new();
    let mut equal_sample_wins = 0;
    for v in results {
        let _ = write!(md, "| {} {} |", v.record.label, v.record.view);
        for c in &criteria {
            let cell = target_speedup(v, c)
                .map(|s| format!("{s:.1}×"))
                .unwrap_or_else(|| "not reached".into());
            let _ = write!(md, " {cell} |");
        }
        best_speedups.push(
            criteria
                .iter()
                .filter_map(|c| target_speedup(v, c))
                .max_by(f64::total_cmp),
        );
        let (holds, text) = equal_samples(v);
        equal_sample_wins += usize::from(holds);
        let _ = writeln!(md, " {text} |");
    }
    let every = best_speedups
        .iter()
        .all(|s| s.is_some_and(|s| s >= SPEEDUP_EVERY_VIEW));
    let twenty = best_speedups
        .iter()
        .filter(|s| s.is_some_and(|s| s >= SPEEDUP_HALF_THE_VIEWS))
        .count();
    let verdict = |met: bool| if met { "**met**" } else { "**missed**" };
    let _ = writeln!(
        md,
        "\n- Speed-up to mean FLIP {TARGET_FLIP} (best criterion per view) ≥ {SPEEDUP_EVERY_VIEW}× on every view: {} \
         (best per view: {}).\n- ≥ {SPEEDUP_HALF_THE_VIEWS}× on at least half of the views: {} ({twenty} of {n}).\n\
         - At equal samples, {THESIS_BEST}'s error ≤ rnd's and ≤ nld-is's on at least 5 of the 6 default views: {} \
         ({equal_sample_wins} of {n} measured views).{}\n",
        verdict(every && n > 0),
        best_speedups
            .iter()
            .map(|s| s.map_or("not reached".into(), |s| format!("{s:.1}×")))
            .collect::<Vec<_>>()
            .join(", "),
        verdict(2 * twenty >= n && n > 0),
        verdict(equal_sample_wins >= 5),
        if n < 6 {
            " Fewer than the 6 default views were measured, so this target cannot be met by these figures."
        } else {
            ""
        }
    );
    md
}

/// Whether [`THESIS_BEST`]'s FLIP is at most each of [`THESIS_RIVALS`]' at the largest fixed
/// sample count every criterion reached, with the figures of all.
fn equal_samples(v: &ViewResult) -> (bool, String) {
    let criteria = criteria_of(&v.rows);
    let reached_by_all = |n: u64| {
        criteria
            .iter()
            .all(|c| at_samples(&run_rows(&v.rows, c), n).is_some())
    };
    let Some(n) = v
        .record
        .sample_counts
        .iter()
        .rev()
        .copied()
        .find(|n| reached_by_all(*n))
    else {
        return (false, "no common sample count".into());
    };
    let flip = |c: &str| {
        at_samples(&run_rows(&v.rows, c), n)
            .map(|m| m.error.flip)
            .unwrap_or(f64::NAN)
    };
    let best = flip(THESIS_BEST);
    let holds = THESIS_RIVALS.iter().all(|c| best <= flip(c));
    let figures: Vec<String> = criteria
        .iter()
        .map(|c| format!("{c} {:.3}", flip(c)))
        .collect();
    (
        holds,
        format!(
            "{} at {n} samples: {}",
            if holds { "yes" } else { "no" },
            figures.join(", ")
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::convergence::record::Schedule;
    use crate::bench::metrics::ImageError;

    fn m(run: &str, schedule: Schedule, time_s: f64, samples: u64, flip: f64) -> Measurement {
        Measurement {
            run: run.into(),
            schedule,
            time_s,
            samples,
            shown: 1,
            inserted: 1,
            removed: 0,
            outstanding: 0,
            error: ImageError { flip, rmse: flip },
            exr: None,
        }
    }

    fn view(name: &str, direct_seconds: f64, rows: Vec<Measurement>) -> ViewResult {
        let record = ViewRecord {
            label: "bracara".into(),
            scene: "bracara".into(),
            view: name.into(),
            width: 64,
            height: 48,
            gt_spp: 256,
            seconds: 10.0,
            sample_counts: vec![1000, 2000],
            ground_truth: "gt.exr".into(),
        };
        ViewResult {
            record,
            rows,
            direct: Direct {
                seconds: direct_seconds,
                flip: 0.05,
            },
        }
    }

    /// nld-os reaches FLIP 0.1 at `os_time` s and beats the others at 2000 samples when `os_wins`.
    fn rows(os_time: f64, os_wins: bool) -> Vec<Measurement> {
        let os_flip = if os_wins { 0.05 } else { 0.2 };
        vec![
            m("rnd", Schedule::Time, 3.0, 900, 0.09),
            m("rnd", Schedule::Samples, 4.0, 2000, 0.1),
            m("nld-is", Schedule::Samples, 5.0, 2000, 0.12),
            m("nld-os", Schedule::Time, os_time, 900, 0.08),
            m("nld-os", Schedule::Samples, 6.0, 2000, os_flip),
        ]
    }

    #[test]
    fn speedups_and_equal_samples_are_judged_against_the_targets() {
        // MC: 40 s / 1 s = 40×; VT: 40 s / 3 s (rnd, faster than nld-os's 5 s) ≈ 13×.
        let results = [
            view("MC", 40.0, rows(1.0, true)),
            view("VT", 40.0, rows(5.0, false)),
        ];
        let md = targets(&results);
        assert!(
            md.contains("| bracara MC | 13.3× | not reached | 40.0× | yes at 2000 samples"),
            "{md}"
        );
        assert!(
            md.contains("| bracara VT | 13.3× | not reached | 8.0× | no at 2000 samples"),
            "{md}"
        );
        assert!(
            md.contains("on every view: **met** (best per view: 40.0×, 13.3×)"),
            "{md}"
        );
        assert!(md.contains("half of the views: **met** (1 of 2)"), "{md}");
        assert!(
            md.contains("default views: **missed** (1 of 2 measured views)"),
            "{md}"
        );
    }

    #[test]
    fn a_view_where_no_criterion_reaches_the_level_misses_the_target() {
        let never = vec![m("nld-os", Schedule::Time, 1.0, 900, 0.3)];
        let md = targets(&[view("MC", 40.0, rows(1.0, true)), view("VR", 40.0, never)]);
        assert!(
            md.contains("on every view: **missed** (best per view: 40.0×, not reached)"),
            "{md}"
        );
    }

    #[test]
    fn a_view_without_a_common_sample_count_does_not_count_for_nld_os() {
        let v = view(
            "VR",
            40.0,
            vec![
                m("rnd", Schedule::Samples, 1.0, 1000, 0.1),
                m("nld-os", Schedule::Time, 1.0, 500, 0.1),
            ],
        );
        assert_eq!(
            equal_samples(&v),
            (false, "no common sample count".to_string())
        );
    }
}
