//! `walkthrough-bench accuracy` (DESIGN.md §10 "What accuracy costs in time"): per view,
//! the time each criterion needs to reach several error levels (read from `bench convergence`'s
//! CSVs) against the time of the competitor, a direct per-pixel render at the interactive preset
//! (`renderer reference --spp 64 --bounces 2`, as the thesis timed Radiance in table 5.1); the
//! speed-up, and the end-to-end targets stated as met or missed. Above them, the headline: the
//! time to each level against the best per-pixel competitor of today, plain or denoised
//! (`per_pixel`, `denoise`, `headline`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::convergence::cpu;
use crate::convergence::manifest::{self, ViewRecord};
use crate::convergence::record::{self, Measurement, run_labels, run_rows, time_to_reach};
use sma::config::Profile;
use testkit::loopback::CpuShares;

mod denoise;
pub(crate) mod direct;
mod headline;
mod per_pixel;
mod targets;
mod textured;

use direct::Direct;
use per_pixel::{PerPixel, PerPixelRecords};

pub const SECTION: &str = "docs/bench/accuracy.md";
/// The headline table, which `report` puts first in BENCHMARKS.md.
pub const HEADLINE: &str = "docs/bench/headline.md";

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
    /// Paths per pixel of the per-pixel competitors, in rising order.
    pub per_pixel_spp: Vec<u32>,
    /// No per-pixel render above the first that takes longer than this.
    pub per_pixel_max_seconds: f64,
    /// Denoise the per-pixel renders (Intel Open Image Denoise through Python's `pyoidn`).
    pub denoise: bool,
    /// Do not write docs/bench/accuracy.md nor BENCHMARKS.md.
    pub no_report: bool,
    /// Write the textured views beside their untextured twins (`textured::SECTION`) instead of
    /// the accuracy and headline sections.
    pub textured: bool,
}

pub(crate) struct ViewResult {
    record: ViewRecord,
    rows: Vec<Measurement>,
    /// CPU seconds of each run's processes (`bench convergence`'s `-cpu.csv`).
    cpu: Vec<(String, CpuShares)>,
    direct: Direct,
    /// The per-pixel competitors, plain and denoised, by paths per pixel.
    per_pixel: Vec<PerPixel>,
}

pub fn run(args: AccuracyConfig) -> anyhow::Result<()> {
    let exe = crate::product::walkthrough_exe()?;
    let mut results = Vec::new();
    let mut stored = direct::read_records(&args.convergence)?;
    let mut per_pixel_stored = PerPixelRecords::read(&args.convergence)?;
    let records = manifest::read(&args.convergence)?;
    let measuring = records.iter().any(|r| Path::new(&r.ground_truth).is_file());
    let denoiser = if args.denoise && measuring && !args.per_pixel_spp.is_empty() {
        Some(denoise::Denoiser::find()?)
    } else {
        None
    };
    let mut measured_now = Vec::new();
    for record in records {
        let direct = direct::measure_or_recall(&exe, &record, &args, &mut stored)?;
        let per_pixel = per_pixel_stored.measure_or_recall(
            &exe,
            &record,
            &args,
            denoiser.as_ref(),
            &mut measured_now,
        )?;
        let rows = record::read_csv(&args.convergence.join(format!("{}.csv", record.stem())))?;
        let cpu = cpu::read_csv(&args.convergence.join(format!("{}-cpu.csv", record.stem())))?;
        results.push(ViewResult {
            record,
            rows,
            cpu,
            direct,
            per_pixel,
        });
    }
    // The direct renders' times are measurements of the convergence folder, kept with it
    // whether or not this run writes its section (`reproduction` reads them from there).
    direct::write_records(&args.convergence, &stored)?;
    per_pixel_stored.write(&args.convergence)?;
    if args.textured {
        let md = textured::section(&results, &args.convergence);
        print!("{md}");
        if !args.no_report {
            std::fs::write(textured::SECTION, &md)?;
            crate::report::assemble(Path::new("BENCHMARKS.md"))?;
        }
        return Ok(());
    }
    let md = section(&results, &args);
    print!("{md}");
    if !args.no_report {
        std::fs::write(SECTION, &md)?;
        std::fs::write(HEADLINE, headline_section(&results))?;
        crate::report::assemble(Path::new("BENCHMARKS.md"))?;
    }
    Ok(())
}

/// The headline of BENCHMARKS.md: today's system against the best per-pixel competitor.
fn headline_section(results: &[ViewResult]) -> String {
    let today: Vec<&ViewResult> = results
        .iter()
        .filter(|v| v.record.profile == Profile::Today)
        .collect();
    let mut md = String::from("## Headline: at rest, against a per-pixel path tracer\n\n");
    md.push_str(
        "Regenerated by `walkthrough-bench accuracy`. Per view, the time to each mean FLIP \
         level of the system (snapshots by time and sample count, as in \"accuracy\") and of \
         the best per-pixel competitor: the project's renderer per pixel at 1, 2, 4, … paths \
         per pixel (a timed `renderer reference`, the scene's load included), plain or \
         denoised by Intel Open Image Denoise 2.5 (\"high\", with albedo and normal; its \
         warm time added). The speed-up against the 64-spp direct render follows in \
         \"accuracy\".\n\n",
    );
    md.push_str(&headline::table(&today).unwrap_or_else(|| "Not measured yet.\n".into()));
    md
}

fn section(results: &[ViewResult], args: &AccuracyConfig) -> String {
    let mut md = String::from("## accuracy\n\n");
    md.push_str(
        "What accuracy costs in time (DESIGN.md §10), regenerated by `walkthrough-bench accuracy` from the CSVs of \
         `bench convergence`. Competitor: the direct per-pixel render of the view at the interactive preset \
         (`renderer reference --spp 64 --bounces 2`, wall time of the command, as the thesis timed Radiance in table \
         5.1: 55 s for MC, 39 s for VT). For each criterion: the first snapshot time at which the mean LDR-FLIP \
         against the ground truth is at or below each level (snapshots every second and at fixed sample counts, \
         whichever comes first), and the speed-up = direct time / that time (thesis, by eye: 11× on MC, 20× on VT).\n\n",
    );
    let _ = writeln!(md, "Machine: {}.\n", crate::machine::describe());
    for v in results {
        view_table(&mut md, v, &args.levels);
    }
    // The targets are this project's, judged on today's system; the thesis's runs are there to
    // be compared with in the tables above.
    let today: Vec<&ViewResult> = results
        .iter()
        .filter(|v| v.record.profile == Profile::Today)
        .collect();
    md.push_str(&targets::section(&today));
    md
}

fn view_table(md: &mut String, v: &ViewResult, levels: &[f64]) {
    let r = &v.record;
    let _ = writeln!(
        md,
        "### {} ({}×{}, runs of {} s{})\n\nDirect render: {:.1} s, its own mean FLIP {:.3} ({}).\n",
        r.title(),
        r.width,
        r.height,
        r.seconds,
        crate::convergence::measured_note(&r.measured),
        v.direct.seconds,
        v.direct.flip,
        v.direct.provenance()
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
                Some(t) => format!("{t:.1} s ({})", times(speedup(v.direct.seconds, t))),
                None => format!(
                    "> {} s (< {})",
                    r.seconds,
                    times(v.direct.seconds / r.seconds)
                ),
            };
            let _ = write!(md, " {cell} |");
        }
        md.push('\n');
    }
    md.push('\n');
}

/// A speed-up as a factor, to two significant digits below 10 (a run of 60 s against a direct
/// render of 3 s is 0.05×, not 0×).
fn times(factor: f64) -> String {
    if factor >= 10.0 {
        format!("{factor:.0}×")
    } else if factor >= 1.0 {
        format!("{factor:.1}×")
    } else {
        format!("{factor:.2}×")
    }
}

pub(crate) fn speedup(direct: f64, t: f64) -> f64 {
    // The snapshot at t = 0 shows an empty picture, so a level is reached later; the floor only
    // keeps a malformed CSV from dividing by zero.
    direct / t.max(1e-3)
}
