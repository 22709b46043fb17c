//! `walkthrough-bench cost` (DESIGN.md §10, "What accuracy costs in time"): the error a person
//! sees after 10 s and after 60 s at rest, for each setting that trades accuracy for time — the
//! quality ladder's cap (`--max-paths`) × the bounce depth (`--bounces`) × the criterion — on a
//! few views. Each bounce depth is judged against its own ground truth (the same estimator per
//! pixel, at that depth), so a shallower setting is not charged for the light it leaves out by
//! design, only for how well it converges to its own answer; the ground truths' render times
//! show what the extra bounce costs per pixel.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::convergence::record::Measurement;
use crate::convergence::{GROUND_TRUTH_SEED, START_ALLOWANCE, ViewSpec, measure_run, views};
use crate::metrics::Reference;
use testkit::ground_truth::GroundTruth;
use testkit::loopback::{SystemConfig, ViewerConfig};

pub const SECTION: &str = "docs/bench/cost.md";

/// What `bench cost` measures and where it writes.
#[derive(Debug, Clone)]
pub struct CostConfig {
    /// Views (of bracara and, when the shared scenes are there, Sponza).
    pub views: Vec<String>,
    /// Ladder caps: paths per sample at the last rung.
    pub caps: Vec<u32>,
    /// Bounce depths.
    pub depths: Vec<u32>,
    pub criteria: Vec<String>,
    /// Length of each run.
    pub seconds: f64,
    /// Times at which the error is read.
    pub at: Vec<f64>,
    pub width: u32,
    pub height: u32,
    pub gt_spp: u32,
    pub gt_cache: PathBuf,
    pub runs: PathBuf,
    pub seed: u64,
    pub no_report: bool,
}

/// One run's readings.
struct Row {
    view: String,
    depth: u32,
    cap: u32,
    criterion: String,
    /// The snapshot at or just before each of `CostConfig::at`.
    at: Vec<Option<Measurement>>,
    /// When the SMA first said `converged`, if it did.
    converged_at: Option<f64>,
}

pub fn run(args: CostConfig) -> anyhow::Result<()> {
    let exe = crate::product::walkthrough_exe()?;
    let mut rows = Vec::new();
    let mut truths = Vec::new();
    for spec in views(None, &args.views)? {
        for &depth in &args.depths {
            let (reference, seconds) = ground_truth(&args, &spec, depth)?;
            truths.push((spec.view.clone(), depth, seconds));
            for &cap in &args.caps {
                for criterion in &args.criteria {
                    eprintln!(
                        "cost: {} {}, {depth} bounces, cap {cap}, {criterion}…",
                        spec.label, spec.view
                    );
                    rows.push(measure(
                        &args, &exe, &spec, depth, cap, criterion, &reference,
                    )?);
                }
            }
        }
    }
    let md = section(&args, &rows, &truths);
    print!("{md}");
    if !args.no_report {
        std::fs::write(SECTION, &md)?;
        crate::report::assemble(Path::new("BENCHMARKS.md"))?;
    }
    Ok(())
}

/// The view's ground truth at `depth` bounces, and how long rendering it took (None: cached).
fn ground_truth(
    args: &CostConfig,
    spec: &ViewSpec,
    depth: u32,
) -> anyhow::Result<(Reference, Option<f64>)> {
    let truth = GroundTruth {
        scene: spec.scene.clone(),
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        spp: args.gt_spp,
        bounces: depth,
        seed: GROUND_TRUTH_SEED,
    };
    let (path, took) = truth.ensure_timed(&args.gt_cache)?;
    Ok((Reference::read_exr(&path)?, took.map(|d| d.as_secs_f64())))
}

fn measure(
    args: &CostConfig,
    exe: &Path,
    spec: &ViewSpec,
    depth: u32,
    cap: u32,
    criterion: &str,
    reference: &Reference,
) -> anyhow::Result<Row> {
    let system = SystemConfig {
        exe: exe.to_path_buf(),
        scene: spec.scene.clone(),
        criterion: criterion.to_string(),
        refine: true,
        seed: args.seed,
        renderers: 1,
        sma_flags: [
            "--stats-secs",
            "1",
            "--max-paths",
            &cap.to_string(),
            "--bounces",
            &depth.to_string(),
        ]
        .map(String::from)
        .to_vec(),
    };
    let viewer = ViewerConfig {
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        seconds: Some(args.seconds),
        time_limit: Duration::from_secs_f64(args.seconds) + START_ALLOWANCE,
        every_seconds: Some(1.0),
        at_samples: vec![],
        when_idle: false,
    };
    let label = format!("{}-{depth}b-{cap}p-{criterion}", spec.view);
    let dir = args.runs.join(&label);
    let (measured, _) = measure_run(&system, &viewer, criterion, reference, &dir)?;
    Ok(Row {
        view: spec.view.clone(),
        depth,
        cap,
        criterion: criterion.to_string(),
        at: args.at.iter().map(|&t| reading_at(&measured, t)).collect(),
        converged_at: measured.iter().find(|m| m.converged).map(|m| m.time_s),
    })
}

/// The last snapshot taken by `t` (snapshots come every second, a few milliseconds late).
fn reading_at(measured: &[Measurement], t: f64) -> Option<Measurement> {
    measured
        .iter()
        .filter(|m| m.time_s <= t + 0.5)
        .max_by(|a, b| a.time_s.total_cmp(&b.time_s))
        .cloned()
}

fn section(args: &CostConfig, rows: &[Row], truths: &[(String, u32, Option<f64>)]) -> String {
    let mut md = String::from("## cost\n\n");
    md.push_str(
        "What accuracy costs in time (DESIGN.md §10), regenerated by `walkthrough-bench cost`: for each view, bounce \
         depth (the SMA's `--bounces`), ladder cap (`--max-paths`) and criterion, a fresh system on loopback from an \
         empty cache, its mean LDR-FLIP against the ground truth at the same depth after the times below at rest, the \
         paths traced by then, and when the SMA reached its stated end (`converged`). Each depth has its own ground \
         truth, so a shallower setting is judged on how well it converges to its own answer; what it leaves out of \
         the light is the difference between the two ground truths, a property of the estimator, not of the system.\n\n",
    );
    let _ = writeln!(
        md,
        "Machine: {}. Image {}×{}, ground truths {} paths per pixel, runs of {} s, one repetition each.\n",
        crate::machine::describe(),
        args.width,
        args.height,
        args.gt_spp,
        args.seconds
    );
    md.push_str("| view | bounces | cap | criterion |");
    for t in &args.at {
        let _ = write!(md, " FLIP at {t} s | paths at {t} s |");
    }
    md.push_str(" converged |\n|---|---:|---:|---|");
    md.push_str(&"---:|---:|".repeat(args.at.len()));
    md.push_str("---:|\n");
    for row in rows {
        let _ = write!(
            md,
            "| {} | {} | {} | {} |",
            row.view, row.depth, row.cap, row.criterion
        );
        for reading in &row.at {
            match reading {
                Some(m) => {
                    let _ = write!(md, " {:.4} | {:.1} M |", m.error.flip, m.paths as f64 / 1e6);
                }
                None => md.push_str(" — | — |"),
            }
        }
        match row.converged_at {
            Some(t) => {
                let _ = writeln!(md, " at {t:.0} s |");
            }
            None => md.push_str(" no |\n"),
        }
    }
    let rendered: Vec<String> = truths
        .iter()
        .filter_map(|(view, depth, s)| s.map(|s| format!("{view} at {depth} bounces {s:.0} s")))
        .collect();
    if !rendered.is_empty() {
        let _ = writeln!(
            md,
            "\nGround truths rendered for this run (2 threads): {}.",
            rendered.join(", ")
        );
    }
    md.push('\n');
    md
}
