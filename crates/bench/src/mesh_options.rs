//! `walkthrough-bench mesh-options`: the two options of the subdivision mesh that the thesis
//! describes and today's defaults leave off, measured against the default on the same views in
//! one command (thesis §4.2, fig. 4.7, and §6; DESIGN.md §4):
//!
//! - **the thesis's neighbour rule** (`--neighbour-rule thesis`) against red–green closure: the
//!   leaves it makes, their worst shape (the smallest angle of a leaf a split made, and its ratio
//!   to the base triangle's), how often its bound on propagation was reached, and the error;
//! - **merging by uniformity** (`--merge-uniform on`): the leaves and bytes it saves and what it
//!   costs in error, judged against the spread of the default's repetitions (kept on only if the
//!   error stays within it).
//!
//! The error is read at equal paths traced: at the paths the default's runs (their median)
//! reached at 5 s, and at the end at the paths of the run that traced the fewest, so a slower
//! option is not charged for its speed in the error, only in the paths column; leaves, bytes and
//! shapes are those of the last snapshot.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;

use crate::convergence::record::{self, Measurement};
use crate::convergence::snapshots::{self, MeshColumns};
use crate::convergence::{
    BEST_NOISE_AWARE, GROUND_TRUTH_SEED, START_ALLOWANCE, ViewSpec, measure_run, views,
};
use crate::metrics::Reference;
use crate::stats::median;
use testkit::ground_truth::GroundTruth;
use testkit::loopback::{SystemConfig, ViewerConfig};

pub const SECTION: &str = "docs/bench/mesh-options.md";

/// The early moment at which the error is compared (the thesis's tables stop at 5 s).
const EARLY_SECONDS: f64 = 5.0;

/// What `bench mesh-options` measures and where it writes.
#[derive(Debug, Clone)]
pub struct MeshOptionsConfig {
    /// Views; empty: the six default ones (MC, VR, VT; S1, S2, S3 when Sponza is there).
    pub views: Vec<String>,
    /// Length of each run.
    pub seconds: f64,
    /// Runs of the default per view, whose spread the options are judged against.
    pub repetitions: usize,
    /// Fixed sample counts at which snapshots are also taken (those of `bench convergence`).
    pub at_samples: Vec<u64>,
    pub width: u32,
    pub height: u32,
    pub gt_spp: u32,
    pub gt_cache: PathBuf,
    /// The readings' CSVs (committed: one small file per view).
    pub out: PathBuf,
    /// Raw snapshots and logs of every run (big: an ignored folder).
    pub runs: PathBuf,
    pub seed: u64,
    /// Measure nothing: rewrite the section from the CSVs in `out`.
    pub report_only: bool,
    pub no_report: bool,
}

/// A setting of the mesh measured against the default.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Variant {
    /// Today's defaults: red–green closure, no merging.
    Default,
    Merge,
    ThesisRule,
}

impl Variant {
    const ALL: [Variant; 3] = [Variant::Default, Variant::Merge, Variant::ThesisRule];

    fn label(self) -> &'static str {
        match self {
            Variant::Default => "red-green",
            Variant::Merge => "red-green + merge",
            Variant::ThesisRule => "thesis rule",
        }
    }

    fn sma_flags(self) -> &'static [&'static str] {
        match self {
            Variant::Default => &[],
            Variant::Merge => &["--merge-uniform", "on"],
            Variant::ThesisRule => &["--neighbour-rule", "thesis"],
        }
    }
}

/// One run's readings.
#[derive(Clone, Debug, PartialEq)]
struct Reading {
    /// The variant's label, `#k` for the k-th repetition of the default.
    run: String,
    /// The paths at which the error is read (the default's median at 5 s; at the end, those of
    /// the run that traced the fewest), and the run's error at them; `None` when the run never
    /// traced that many.
    early_paths: u64,
    early_flip: Option<f64>,
    late_paths: u64,
    late_flip: Option<f64>,
    /// Paths the run had traced by its end.
    paths: u64,
    mesh: MeshColumns,
}

pub fn run(args: MeshOptionsConfig) -> anyhow::Result<()> {
    std::fs::create_dir_all(&args.out)?;
    if !args.report_only {
        tables::write_settings(&args)?;
        let exe = crate::product::walkthrough_exe()?;
        for spec in views(None, &args.views)? {
            eprintln!("mesh-options: {} {}", spec.label, spec.view);
            let readings = measure_view(&args, &exe, &spec)?;
            write_csv(&view_csv(&args.out, &spec), &readings)?;
        }
    }
    let md = section(&args)?;
    print!("{md}");
    if !args.no_report {
        std::fs::write(SECTION, &md)?;
        crate::report::assemble(Path::new("BENCHMARKS.md"))?;
    }
    Ok(())
}

fn view_csv(out: &Path, spec: &ViewSpec) -> PathBuf {
    out.join(format!("{}-{}.csv", spec.label, spec.view))
}

/// The default's repetitions and each option once, then the readings at equal paths.
fn measure_view(
    args: &MeshOptionsConfig,
    exe: &Path,
    spec: &ViewSpec,
) -> anyhow::Result<Vec<Reading>> {
    let truth = GroundTruth {
        scene: spec.scene.clone(),
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        spp: args.gt_spp,
        bounces: crate::convergence::INTERACTIVE_BOUNCES,
        seed: GROUND_TRUTH_SEED,
    };
    let reference = Reference::read_exr(&truth.ensure(&args.gt_cache)?)?;
    let mut runs: Vec<(String, Vec<Measurement>, MeshColumns)> = Vec::new();
    for (variant, k) in planned(args.repetitions) {
        let label = match k {
            1 => variant.label().to_string(),
            k => record::repeat_label(variant.label(), k),
        };
        eprintln!("  {label}…");
        let dir = args
            .runs
            .join(format!("{}-{}", spec.label, spec.view))
            .join(label.replace([' ', '+'], "_"));
        let (rows, _) = measure_run(
            &system(args, exe, spec, variant, k),
            &viewer(args, spec),
            &label,
            &reference,
            &dir,
        )?;
        let last = snapshots::read_run(&dir.join("snapshots"))?
            .into_iter()
            .rev()
            .find_map(|s| s.mesh)
            .context("the viewer wrote no mesh columns")?;
        runs.push((label, rows, last));
    }
    Ok(readings(&runs))
}

/// The default `repetitions` times, then each option once.
fn planned(repetitions: usize) -> Vec<(Variant, usize)> {
    let mut runs: Vec<(Variant, usize)> = (1..=repetitions.max(1))
        .map(|k| (Variant::Default, k))
        .collect();
    runs.extend(Variant::ALL[1..].iter().map(|&v| (v, 1)));
    runs
}

fn system(
    args: &MeshOptionsConfig,
    exe: &Path,
    spec: &ViewSpec,
    variant: Variant,
    repetition: usize,
) -> SystemConfig {
    let flags = ["--stats-secs", "1"].iter().chain(variant.sma_flags());
    SystemConfig {
        exe: exe.to_path_buf(),
        scene: spec.scene.clone(),
        criterion: BEST_NOISE_AWARE.to_string(),
        refine: true,
        // Repetitions differ by their seed, so their spread is the system's, not one draw's.
        seed: args.seed + repetition as u64 - 1,
        renderers: 1,
        sma_flags: flags.map(|f| f.to_string()).collect(),
    }
}

fn viewer(args: &MeshOptionsConfig, spec: &ViewSpec) -> ViewerConfig {
    ViewerConfig {
        view: spec.view.clone(),
        width: args.width,
        height: args.height,
        seconds: Some(args.seconds),
        time_limit: Duration::from_secs_f64(args.seconds) + START_ALLOWANCE,
        every_seconds: Some(1.0),
        at_samples: args.at_samples.clone(),
        when_idle: false,
    }
}

/// Each run's readings at the default's median paths at 5 s and at the paths of the run that
/// traced the fewest.
fn readings(runs: &[(String, Vec<Measurement>, MeshColumns)]) -> Vec<Reading> {
    let defaults: Vec<&Vec<Measurement>> = runs
        .iter()
        .filter(|(label, _, _)| label.starts_with(Variant::Default.label()))
        .map(|(_, rows, _)| rows)
        .collect();
    let median_paths = |pick: &dyn Fn(&[&Measurement]) -> Option<u64>| {
        let paths: Vec<f64> = defaults
            .iter()
            .filter_map(|rows| pick(&rows.iter().collect::<Vec<_>>()))
            .map(|p| p as f64)
            .collect();
        if paths.is_empty() {
            0
        } else {
            median(paths) as u64
        }
    };
    let early_paths = median_paths(&|r| record::by_time(r, EARLY_SECONDS).map(|m| m.paths));
    // The end at the paths every run reached, so each has a reading there.
    let late_paths = runs
        .iter()
        .filter_map(|(_, rows, _)| rows.last().map(|m| m.paths))
        .min()
        .unwrap_or(0);
    runs.iter()
        .map(|(label, rows, mesh)| {
            let rows: Vec<&Measurement> = rows.iter().collect();
            let flip_at = |paths| record::at_paths(&rows, paths).map(|m| m.error.flip);
            Reading {
                run: label.clone(),
                early_paths,
                early_flip: flip_at(early_paths),
                late_paths,
                late_flip: flip_at(late_paths),
                paths: rows.last().map_or(0, |m| m.paths),
                mesh: mesh.clone(),
            }
        })
        .collect()
}

const HEADER: &str = "run,early_paths,early_flip,late_paths,late_flip,paths,leaves,\
                      cached_samples,mesh_bytes,cache_bytes,smallest_angle_deg,\
                      smallest_angle_ratio,bound_hits,uniform_merges";

fn write_csv(path: &Path, readings: &[Reading]) -> anyhow::Result<()> {
    let cell = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:.5}"));
    let mut text = format!("{HEADER}\n");
    for r in readings {
        let m = &r.mesh;
        writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.run,
            r.early_paths,
            cell(r.early_flip),
            r.late_paths,
            cell(r.late_flip),
            r.paths,
            m.leaves,
            m.cached_samples,
            m.mesh_bytes,
            m.cache_bytes,
            cell(m.smallest_split_angle_deg),
            cell(m.smallest_split_angle_ratio),
            m.neighbour_bound_hits,
            m.uniform_merges
        )?;
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn read_csv(path: &Path) -> anyhow::Result<Vec<Reading>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some(HEADER),
        "{}: not a mesh-options CSV",
        path.display()
    );
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|line| parse_row(line).with_context(|| format!("{}: {line:?}", path.display())))
        .collect()
}

fn parse_row(line: &str) -> anyhow::Result<Reading> {
    let f: Vec<&str> = line.split(',').collect();
    anyhow::ensure!(f.len() == 14, "{} fields, not 14", f.len());
    let int = |i: usize| {
        f[i].parse::<u64>()
            .with_context(|| format!("field {:?}", f[i]))
    };
    let optional = |i: usize| -> anyhow::Result<Option<f64>> {
        (!f[i].is_empty())
            .then(|| {
                f[i].parse::<f64>()
                    .with_context(|| format!("field {:?}", f[i]))
            })
            .transpose()
    };
    Ok(Reading {
        run: f[0].to_string(),
        early_paths: int(1)?,
        early_flip: optional(2)?,
        late_paths: int(3)?,
        late_flip: optional(4)?,
        paths: int(5)?,
        mesh: MeshColumns {
            leaves: int(6)?,
            cached_samples: int(7)?,
            mesh_bytes: int(8)?,
            cache_bytes: int(9)?,
            smallest_split_angle_deg: optional(10)?,
            smallest_split_angle_ratio: optional(11)?,
            neighbour_bound_hits: int(12)?,
            uniform_merges: int(13)?,
        },
    })
}

mod tables;
use tables::section;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convergence::record::test_measurement;

    fn run(
        label: &str,
        flips: &[(f64, u64, f64)],
        leaves: u64,
    ) -> (String, Vec<Measurement>, MeshColumns) {
        let rows = flips
            .iter()
            .map(|&(t, paths, flip)| Measurement {
                paths,
                ..test_measurement(label, t, paths / 64, flip)
            })
            .collect();
        let mesh = MeshColumns {
            leaves,
            ..MeshColumns::default()
        };
        (label.to_string(), rows, mesh)
    }

    #[test]
    fn options_are_read_at_the_defaults_median_paths() {
        let runs = vec![
            run("red-green", &[(5.0, 1000, 0.2), (60.0, 9000, 0.05)], 100),
            run("red-green#2", &[(5.0, 1200, 0.2), (60.0, 11000, 0.05)], 100),
            run("red-green#3", &[(5.0, 1100, 0.2), (60.0, 10000, 0.05)], 100),
            // Slower: it reaches the early paths only at 6 s, and never the late ones.
            run(
                "red-green + merge",
                &[(5.0, 900, 0.3), (6.0, 1150, 0.25), (60.0, 9500, 0.06)],
                80,
            ),
        ];
        let r = readings(&runs);
        assert_eq!((r[0].early_paths, r[0].late_paths), (1100, 9000));
        assert_eq!(r[3].early_flip, Some(0.25));
        assert_eq!(r[3].late_flip, Some(0.06));
        assert_eq!((r[3].paths, r[3].mesh.leaves), (9500, 80));
        assert_eq!(r[0].early_flip, Some(0.05));
    }

    #[test]
    fn csv_round_trip() {
        let mut mesh = MeshColumns {
            leaves: 7,
            smallest_split_angle_deg: Some(12.5),
            neighbour_bound_hits: 3,
            ..MeshColumns::default()
        };
        mesh.cache_bytes = 1 << 20;
        let reading = Reading {
            run: "thesis rule".into(),
            early_paths: 10,
            early_flip: Some(0.125),
            late_paths: 20,
            late_flip: None,
            paths: 30,
            mesh,
        };
        let path = std::env::temp_dir().join(format!("mesh-options-{}.csv", std::process::id()));
        write_csv(&path, std::slice::from_ref(&reading)).unwrap();
        assert_eq!(read_csv(&path).unwrap(), vec![reading]);
        std::fs::remove_file(path).unwrap();
    }

    #[test]
    fn the_default_runs_first_then_each_option_once() {
        assert_eq!(
            planned(3),
            vec![
                (Variant::Default, 1),
                (Variant::Default, 2),
                (Variant::Default, 3),
                (Variant::Merge, 1),
                (Variant::ThesisRule, 1)
            ]
        );
    }
}
