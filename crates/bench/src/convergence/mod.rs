//! `walkthrough-bench convergence` (DESIGN.md §10, thesis §5.2 and appendix B): for each
//! view, the ground truth once; then for each criterion a fresh system on loopback (empty cache,
//! t = 0 at the viewer's first camera) with snapshots at 0, 1, 2, … s and at fixed sample counts;
//! and one run with refinement switched off. Every snapshot's error against the ground truth goes
//! into a CSV; tables, plots and strips are drawn from it into the output folder, and the Markdown
//! section into `docs/bench/convergence.md`.

pub mod cpu;
pub mod manifest;
pub mod record;
pub mod snapshots;
pub mod tables;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use sma::config::Profile;

use crate::metrics::{LinearImage, Reference};
use crate::{plots, strips};
use manifest::ViewRecord;
use record::{Measurement, NO_REFINE};
use testkit::ground_truth::GroundTruth;
use testkit::loopback::{CpuShares, System, SystemConfig, ViewerConfig};

/// Bounce depth of the interactive preset (DESIGN.md §10: 64 paths × 2 bounces per sample); the
/// ground truth uses the same estimator and depth, per pixel.
pub const INTERACTIVE_BOUNCES: u32 = 2;

/// The ground truth's random streams (per pixel). Fixed, so a cached image stays valid; anything
/// compared with it per pixel (the direct render of `bench accuracy`) must use another seed.
pub const GROUND_TRUTH_SEED: u64 = 1;

/// Where Sponza lives when the shared scenes are there (DESIGN.md §11).
const SHARED_SCENES: &str = "../shared/scenes";
pub(crate) const SPONZA: &str = "scenes/sponza.toml";

/// Whether Sponza can be loaded here: the shared scenes are beside the repository.
pub(crate) fn sponza_is_here() -> bool {
    Path::new(SHARED_SCENES).is_dir() && Path::new(SPONZA).is_file()
}

pub const SECTION: &str = "docs/bench/convergence.md";

/// The SMA's stats (and with them the renderers' busy share) once a second, as the snapshots.
const STATS_EVERY_SECOND: [&str; 2] = ["--stats-secs", "1"];

/// Time a run may take beyond its `--seconds`: processes start, wgpu opens Mesa, scenes load.
pub const START_ALLOWANCE: Duration = Duration::from_secs(90);

/// What `bench convergence` measures and where it writes.
#[derive(Debug, Clone)]
pub struct ConvergenceConfig {
    /// One scene (a TOML file or a built-in name). Default: `bracara`, and Sponza when
    /// ../shared/scenes is there.
    pub scene: Option<String>,
    /// Views to measure. Default: MC, VR, VT of bracara and S1, S2, S3 of Sponza; with --scene, all
    /// of that scene's views.
    pub views: Vec<String>,
    /// Criteria to compare. Default: [`default_criteria`] of the profile.
    pub criteria: Vec<String>,
    /// Which system every `walkthrough sma` runs (its `--profile`): the tables, plots and CSVs
    /// say which, and a view measured under each has files of its own.
    pub profile: Profile,
    /// Length of each run; snapshots every second.
    pub seconds: f64,
    /// Fixed sample counts at which snapshots are also taken.
    pub at_samples: Vec<u64>,
    pub width: u32,
    pub height: u32,
    /// Paths per pixel of the ground truth (DESIGN.md §10: at least 256).
    pub gt_spp: u32,
    /// Tables, plots, strips and CSVs (committed: keep it small).
    pub out: PathBuf,
    /// Ground truth EXRs (big: an ignored folder).
    pub gt_cache: PathBuf,
    /// Raw snapshots and process logs of every run (big: an ignored folder).
    pub runs: PathBuf,
    /// Renderer processes per run (the cores are shared among them).
    pub renderers: usize,
    /// Seed of the SMA's criteria and renderers.
    pub seed: u64,
    /// Flags passed on to every `walkthrough sma` (to measure a setting against its default),
    /// e.g. `--sma-flags=--max-selections,256`.
    pub sma_flags: Vec<String>,
    /// Runs of the best noise-aware criterion per view (the targets take medians over them).
    pub repetitions: usize,
    /// Keep the runs already in the output folder's CSVs and measure only the missing ones
    /// (repetitions added to an earlier measurement).
    pub add_repetitions: bool,
    /// Do not write docs/bench/convergence.md nor BENCHMARKS.md.
    pub no_report: bool,
    /// Measure nothing: redraw the plots, the section and BENCHMARKS.md from the CSVs in --out.
    pub report_only: bool,
    /// Render the views' missing ground truths and stop: they take minutes a view and time
    /// nothing, so they may render while the machine does other work; the runs may not.
    pub ground_truths_only: bool,
}

/// A view of a scene to measure.
#[derive(Clone, Debug)]
pub(crate) struct ViewSpec {
    pub scene: String,
    /// The scene's name.
    pub label: String,
    pub view: String,
}

pub fn run(args: ConvergenceConfig) -> anyhow::Result<()> {
    let exe = crate::product::walkthrough_exe()?;
    let criteria = criteria_under(args.profile, &args.criteria)?;
    std::fs::create_dir_all(&args.out)?;
    let specs = if args.report_only {
        vec![]
    } else {
        views(args.scene.as_deref(), &args.views)?
    };
    for spec in specs {
        if args.ground_truths_only {
            ground_truth(&args, &spec).ensure(&args.gt_cache)?;
            continue;
        }
        eprintln!("convergence: {} {}", spec.label, spec.view);
        let record = measure_view(&args, &exe, &spec, &criteria)?;
        manifest::upsert(&args.out, &record)?;
    }
    if !args.no_report && !args.ground_truths_only {
        std::fs::create_dir_all(Path::new(SECTION).parent().expect("a folder"))?;
        std::fs::write(SECTION, section(&args.out)?)?;
        crate::report::assemble(Path::new("BENCHMARKS.md"))?;
    }
    Ok(())
}

/// The noise-aware criterion measured against the thesis's (DESIGN.md §6): the best of the three
/// in the 20-s runs of the previous measurement.
pub const BEST_NOISE_AWARE: &str = "nld-px";
/// What it is compared with at equal paths traced: random selection and the thesis's eq. 4.3
/// criteria as the thesis defined them.
pub const RIVALS: [&str; 3] = ["rnd", "nld-is-thesis", "nld-os-thesis"];

/// The rivals, then the best noise-aware criterion; any other by `--criteria`.
pub fn default_criteria() -> Vec<String> {
    RIVALS
        .iter()
        .chain(std::iter::once(&BEST_NOISE_AWARE))
        .map(|c| c.to_string())
        .collect()
}

/// The criteria to run under `profile`, named as what runs (`nld-os` under the thesis's is
/// `nld-os-thesis`), so that the labels say what ran; `asked` empty: the default ones, which
/// under the thesis's profile are its own three (§5.2), the rivals. A criterion the profile does
/// not offer (`nld-px` under the thesis's) is refused before anything runs.
pub fn criteria_under(profile: Profile, asked: &[String]) -> anyhow::Result<Vec<String>> {
    let asked = match (asked.is_empty(), profile) {
        (false, _) => asked.to_vec(),
        (true, Profile::Today) => default_criteria(),
        (true, Profile::Thesis) => RIVALS.iter().map(|c| c.to_string()).collect(),
    };
    asked
        .iter()
        .map(|name| Ok(profile.criterion_named(name)?.name().to_string()))
        .collect()
}

/// The views to measure: `views` (all of them when empty) of `scene`, or by default of bracara
/// and, when the shared scenes are there, Sponza.
pub(crate) fn views(scene: Option<&str>, views: &[String]) -> anyhow::Result<Vec<ViewSpec>> {
    let scenes: Vec<(String, Vec<String>)> = match scene {
        Some(scene) => vec![(scene.to_string(), vec![])],
        None => {
            let mut s = vec![("bracara".to_string(), strings(&["MC", "VR", "VT"]))];
            if sponza_is_here() {
                s.push((SPONZA.to_string(), strings(&["S1", "S2", "S3"])));
            }
            s
        }
    };
    let mut specs = Vec::new();
    for (scene, defaults) in scenes {
        let loaded = scene::load(&scene).with_context(|| format!("loading {scene}"))?;
        let known: Vec<String> = loaded
            .settings
            .viewpoints
            .iter()
            .map(|v| v.name.clone())
            .collect();
        let wanted = if !views.is_empty() {
            views
                .iter()
                .filter(|v| known.contains(v))
                .cloned()
                .collect()
        } else if defaults.is_empty() {
            known.clone()
        } else {
            defaults
        };
        for view in wanted {
            anyhow::ensure!(
                known.contains(&view),
                "scene {scene} has no view {view} (it has {known:?})"
            );
            specs.push(ViewSpec {
                scene: scene.clone(),
                label: loaded.name.clone(),
                view,
            });
        }
    }
    anyhow::ensure!(
        !specs.is_empty(),
        "no view to measure: {views:?} matches none of the scenes' views"
    );
    Ok(specs)
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// "; measured …" for a view's heading, nothing for a record older than the stamp.
pub(crate) fn measured_note(measured: &str) -> String {
    if measured.is_empty() {
        String::new()
    } else {
        format!("; measured {measured}")
    }
}

/// The view's ground truth at the runs' size and the interactive depth.
fn ground_truth(args: &ConvergenceConfig, spec: &ViewSpec) -> GroundTruth {
    GroundTruth {
        scene: spec.scene.clone(),
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        spp: args.gt_spp,
        bounces: INTERACTIVE_BOUNCES,
        seed: GROUND_TRUTH_SEED,
    }
}

/// Ground truth, the run without refinement and one run per criterion; writes the view's CSV and
/// strip (the plot is drawn with the section, from the CSV).
fn measure_view(
    args: &ConvergenceConfig,
    exe: &Path,
    spec: &ViewSpec,
    criteria: &[String],
) -> anyhow::Result<ViewRecord> {
    let gt = ground_truth(args, spec).ensure(&args.gt_cache)?;
    let reference = Reference::read_exr(&gt)?;
    let record = ViewRecord {
        label: spec.label.clone(),
        scene: spec.scene.clone(),
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        gt_spp: args.gt_spp,
        seconds: args.seconds,
        sample_counts: args.at_samples.clone(),
        ground_truth: gt.to_string_lossy().into_owned(),
        measured: crate::machine::measured_stamp(),
        profile: args.profile,
    };
    let runs_dir = args.runs.join(record.stem());
    let csv = args.out.join(format!("{}.csv", record.stem()));
    let cpu_csv = args.out.join(format!("{}-cpu.csv", record.stem()));
    let (mut rows, mut shares) = if args.add_repetitions {
        (record::read_csv(&csv)?, cpu::read_csv(&cpu_csv)?)
    } else {
        (Vec::new(), Vec::new())
    };
    let measured_before = !shares.is_empty();
    for run in planned_runs(args, exe, spec, criteria) {
        if shares.iter().any(|(label, _)| *label == run.label) {
            continue;
        }
        eprintln!("  {}…", run.label);
        let dir = runs_dir.join(&run.label);
        let (measured, cpu) = measure_run(&run.system, &run.viewer, &run.label, &reference, &dir)?;
        let profile = args.profile;
        rows.extend(measured.into_iter().map(|m| Measurement { profile, ..m }));
        shares.push((run.label.clone(), cpu));
    }
    record::write_csv(&csv, &rows)?;
    cpu::write_csv(&cpu_csv, &shares)?;
    if measured_before {
        // The strip needs the first runs' images, which a CSV read back does not name.
        return Ok(record);
    }
    let base = base_mesh(&rows);
    strips::write_strip(
        &args.out.join(format!("{}-strip.png", record.stem())),
        &reference,
        &rows,
        base,
        criteria,
    )?;
    Ok(record)
}

/// One run of the system for a view.
struct PlannedRun {
    label: String,
    system: SystemConfig,
    viewer: ViewerConfig,
}

/// The run without refinement (periodic snapshots, and one when first idle: the base mesh at full
/// quality), then for each criterion a run with snapshots every second and at the fixed sample
/// counts, then the repetitions of the best noise-aware criterion.
fn planned_runs(
    args: &ConvergenceConfig,
    exe: &Path,
    spec: &ViewSpec,
    criteria: &[String],
) -> Vec<PlannedRun> {
    let system = |criterion: &str, refine: bool| SystemConfig {
        exe: exe.to_path_buf(),
        scene: spec.scene.clone(),
        criterion: criterion.to_string(),
        refine,
        seed: args.seed,
        renderers: args.renderers,
        // A busy share for every one-second snapshot; the profile before the flags given, which
        // may change what it sets.
        sma_flags: [
            STATS_EVERY_SECOND.map(String::from).as_slice(),
            &["--profile".to_string(), args.profile.name().to_string()],
            &args.sma_flags,
        ]
        .concat(),
    };
    let viewer = |every_seconds: Option<f64>, at_samples: Vec<u64>, when_idle: bool| ViewerConfig {
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        seconds: Some(args.seconds),
        time_limit: Duration::from_secs_f64(args.seconds) + START_ALLOWANCE,
        every_seconds,
        at_samples,
        when_idle,
    };
    let mut runs = vec![PlannedRun {
        label: NO_REFINE.to_string(),
        system: system(&criteria[0], false),
        viewer: viewer(Some(1.0), vec![], true),
    }];
    runs.extend(criteria.iter().map(|criterion| PlannedRun {
        label: criterion.clone(),
        system: system(criterion, true),
        viewer: viewer(Some(1.0), args.at_samples.clone(), false),
    }));
    // The criterion the targets are judged on, again: their figures are medians over its runs.
    if criteria.iter().any(|c| c == BEST_NOISE_AWARE) {
        runs.extend((2..=args.repetitions).map(|k| PlannedRun {
            label: record::repeat_label(BEST_NOISE_AWARE, k),
            system: system(BEST_NOISE_AWARE, true),
            viewer: viewer(Some(1.0), args.at_samples.clone(), false),
        }));
    }
    runs
}

/// What a view's section says of the system that ran.
fn profile_note(profile: Profile) -> &'static str {
    match profile {
        Profile::Today => "System: today's (`--profile today`).\n\n",
        Profile::Thesis => {
            "System: the thesis as published (`--profile thesis`, README \"The thesis as \
             published\"): every sample at the scene's fixed quality, no ladder and no further \
             paths; L_white the maximum; the criteria without noise discounting, one pass of RND \
             and NLD_IS per camera, NLD_IS leaves of 6 pixels at least; the thesis's neighbour \
             rule; no coarsening.\n\n"
        }
    }
}

/// Starts a fresh system, runs the viewer, and measures every snapshot it wrote; with the CPU
/// time each process used.
pub fn measure_run(
    system: &SystemConfig,
    viewer: &ViewerConfig,
    label: &str,
    reference: &Reference,
    dir: &Path,
) -> anyhow::Result<(Vec<Measurement>, CpuShares)> {
    if dir.exists() {
        std::fs::remove_dir_all(dir)?;
    }
    let snapshots_dir = dir.join("snapshots");
    let cpu = System::start(system, dir)?.run_viewer(viewer, &snapshots_dir)?;
    Ok((measure_snapshots(label, reference, &snapshots_dir)?, cpu))
}

/// The error of every snapshot a viewer wrote into `dir`, as today's profile's (the caller that
/// ran another says so: `measure_view`).
pub fn measure_snapshots(
    label: &str,
    reference: &Reference,
    dir: &Path,
) -> anyhow::Result<Vec<Measurement>> {
    snapshots::read_run(dir)?
        .into_iter()
        .map(|s| {
            let error = reference.error_of(&LinearImage::read_exr(&s.exr)?)?;
            Ok(Measurement {
                run: label.to_string(),
                time_s: s.time_s,
                samples: s.samples,
                paths: s.paths,
                renderer_busy: s.renderer_busy,
                converged: s.converged,
                shown: s.shown,
                inserted: s.inserted,
                removed: s.removed,
                outstanding: s.outstanding,
                error,
                exr: Some(s.exr),
                profile: Profile::Today,
            })
        })
        .collect()
}

/// The unrefined base mesh at full quality: the last snapshot of the run without refinement taken
/// with no request outstanding (the last one when it never got there).
pub fn base_mesh(rows: &[Measurement]) -> Option<&Measurement> {
    let run = record::run_rows(rows, NO_REFINE);
    run.iter()
        .rev()
        .find(|m| m.outstanding == 0)
        .or(run.last())
        .copied()
}

/// The Markdown section over every view in the output folder's manifest.
pub fn section(out: &Path) -> anyhow::Result<String> {
    let records = manifest::read(out)?;
    let mut md = String::from("## convergence\n\n");
    md.push_str(
        "Convergence per viewpoint (thesis §5.2, DESIGN.md §10), regenerated by `walkthrough-bench convergence` \
         (options: `--views`, `--criteria`, `--seconds`, `--width/--height`, `--gt-spp`; `--report-only` redraws this \
         section and the plots from the CSVs). For each view and criterion a fresh renderer + SMA + headless viewer run \
         on loopback, as separate processes, from an empty cache (t = 0 at the viewer's first camera), with snapshots \
         every second and when the sample count passes each of `--at-samples` (by default quarter steps of a doubling from 1 000 to 8 000, \
         sixteenth steps to 128 000, where the views cross FLIP 0.1, quarter steps to 256 000); samples climb the quality ladder \
         (direct light, the scene's 64 paths × 2 bounces, then ×4 paths up to the SMA's `--max-paths`, DESIGN.md §5). \
         Δvis = triangles shown, Δins / Δrem = triangles inserted / removed since t = 0 (as in the thesis's tables \
         5.2–5.4), samples = vertex samples computed, paths = paths traced for them (the cost at which runs are \
         compared), busy = the share of the second before the snapshot during which the renderer had a batch in hand \
         (the SMA's stats interval, set to 1 s). The error is against the renderer's per-pixel ground truth at the same bounce depth, both images \
         tone-mapped alike (Drago with the ground truth's L_white, sRGB), over the pixels that see geometry (sky \
         pixels are left out): mean LDR-FLIP (67 ppd) and RMSE. `no-refine` is the same system with refinement \
         switched off: the unrefined base mesh, its samples still climbing the ladder. Strips (appendix B): first row \
         without refinement; one row per criterion at 1, 2, 3, 4, 5 s; last row the ground truth.\n\n",
    );
    let _ = writeln!(md, "Machine: {}.\n", crate::machine::describe());
    for record in &records {
        let rows = record::read_csv(&out.join(format!("{}.csv", record.stem())))?;
        let title = format!("{}: error against the ground truth", record.title());
        plots::error_panels(&out.join(format!("{}.svg", record.stem())), &title, &rows)?;
        let _ = writeln!(
            md,
            "### {} ({}×{}, ground truth {} paths per pixel, runs of {} s{})\n",
            record.title(),
            record.width,
            record.height,
            record.gt_spp,
            record.seconds,
            measured_note(&record.measured)
        );
        md.push_str(profile_note(record.profile));
        if let Some(base) = base_mesh(&rows) {
            let _ = writeln!(
                md,
                "Without refinement: {} triangles shown, {} samples, FLIP {:.3}, RMSE {:.3} (at {:.1} s).\n",
                tables::thousands(base.shown),
                tables::thousands(base.samples),
                base.error.flip,
                base.error.rmse,
                base.time_s
            );
        }
        md.push_str(&tables::time_table(record, &rows));
        md.push_str("\nMean FLIP at equal paths traced (time when reached):\n\n");
        md.push_str(&tables::paths_table(record, &rows));
        let shares = cpu::read_csv(&out.join(format!("{}-cpu.csv", record.stem())))?;
        if !shares.is_empty() {
            md.push_str(
                "\nWhere the CPU went over each run (share of all cores, until the viewer's run \
                 ended; the viewer holds its snapshots and draws them after the run, or during \
                 it at idle priority once they fill half its memory budget):\n\n",
            );
            md.push_str(&cpu::table(&shares));
        }
        let dir = out.to_string_lossy();
        let stem = record.stem();
        let _ = writeln!(
            md,
            "\n![error plots]({dir}/{stem}.svg)\n\n![strip]({dir}/{stem}-strip.png)\n"
        );
    }
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_criteria_are_named_as_what_runs_under_the_profile() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            criteria_under(Profile::Today, &[]).unwrap(),
            default_criteria()
        );
        assert_eq!(
            criteria_under(Profile::Thesis, &[]).unwrap(),
            names(&RIVALS)
        );
        assert_eq!(
            criteria_under(Profile::Thesis, &names(&["nld-os", "nld-mm"])).unwrap(),
            names(&["nld-os-thesis", "nld-mm"])
        );
        assert!(criteria_under(Profile::Thesis, &names(&["nld-px"])).is_err());
        assert!(criteria_under(Profile::Today, &names(&["nope"])).is_err());
    }
}
