//! Measured snapshots of one view, kept as `<scene>-<view>.csv` under the output folder: the
//! convergence tables, plots and strips are drawn from them, and `bench accuracy` reads them back.
//! One run per criterion takes its snapshots every second and when the sample count reaches each
//! fixed count (which falls between the seconds early on, timing the first second finely).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use sma::config::Profile;

use crate::metrics::ImageError;

/// The run label of the control run with refinement switched off.
pub const NO_REFINE: &str = "no-refine";

/// One snapshot of one run and its error against the ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// The criterion, or [`NO_REFINE`].
    pub run: String,
    pub time_s: f64,
    pub samples: u64,
    /// Paths traced for those samples: the cost at which runs are compared (DESIGN.md §10).
    pub paths: u64,
    pub shown: u64,
    pub inserted: u64,
    pub removed: u64,
    pub outstanding: u64,
    /// The renderers' busy share over the SMA's latest stats interval (about the second before).
    pub renderer_busy: f64,
    /// The SMA said the view is at its stated end (DESIGN.md §5).
    pub converged: bool,
    pub error: ImageError,
    /// The viewer's linear image (in the raw runs folder; absent from CSVs read back).
    pub exr: Option<PathBuf>,
    /// Which system ran (the SMA's `--profile`), by its label in the CSV: "today" or
    /// "thesis (2006)".
    pub profile: Profile,
}

const HEADER: &str = "run,time_s,samples,paths,shown,inserted,removed,outstanding,renderer_busy,\
                      converged,flip,rmse,profile";
/// The header of a CSV written before the profile column: its runs are today's.
const HEADER_BEFORE_PROFILES: &str = "run,time_s,samples,paths,shown,inserted,removed,\
                                      outstanding,renderer_busy,converged,flip,rmse";

/// The profile whose label is `label`.
fn profile_labelled(label: &str) -> anyhow::Result<Profile> {
    Profile::ALL
        .into_iter()
        .find(|p| p.label() == label)
        .with_context(|| format!("no profile is labelled {label:?}"))
}

pub fn write_csv(path: &Path, rows: &[Measurement]) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(out, "{HEADER}")?;
    for m in rows {
        writeln!(
            out,
            "{},{:.3},{},{},{},{},{},{},{:.3},{},{:.5},{:.5},{}",
            m.run,
            m.time_s,
            m.samples,
            m.paths,
            m.shown,
            m.inserted,
            m.removed,
            m.outstanding,
            m.renderer_busy,
            u8::from(m.converged),
            m.error.flip,
            m.error.rmse,
            m.profile.label()
        )?;
    }
    Ok(out.flush()?)
}

pub fn read_csv(path: &Path) -> anyhow::Result<Vec<Measurement>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next();
    anyhow::ensure!(
        header == Some(HEADER) || header == Some(HEADER_BEFORE_PROFILES),
        "{} does not start with {HEADER:?} (measured by an older `bench convergence`: measure again)",
        path.display()
    );
    lines
        .filter(|l| !l.is_empty())
        .map(|l| parse_row(l).with_context(|| format!("{}: {l:?}", path.display())))
        .collect()
}

fn parse_row(line: &str) -> anyhow::Result<Measurement> {
    let f: Vec<&str> = line.split(',').collect();
    anyhow::ensure!(
        f.len() == 12 || f.len() == 13,
        "expected 13 fields (12 before `profile`)"
    );
    Ok(Measurement {
        run: f[0].to_string(),
        time_s: f[1].parse()?,
        samples: f[2].parse()?,
        paths: f[3].parse()?,
        shown: f[4].parse()?,
        inserted: f[5].parse()?,
        removed: f[6].parse()?,
        outstanding: f[7].parse()?,
        renderer_busy: f[8].parse()?,
        converged: f[9] == "1",
        error: ImageError {
            flip: f[10].parse()?,
            rmse: f[11].parse()?,
        },
        exr: None,
        profile: f
            .get(12)
            .map_or(Ok(Profile::Today), |l| profile_labelled(l))?,
    })
}

/// The rows of one run, in the order taken.
pub fn run_rows<'a>(rows: &'a [Measurement], run: &str) -> Vec<&'a Measurement> {
    rows.iter().filter(|m| m.run == run).collect()
}

/// Repetitions of a run are labelled `<run>#<k>`, k = 2, 3, …: tables, plots and strips show
/// the first run; the end-to-end targets take medians over all of them (DESIGN.md §10).
const REPEAT_MARK: char = '#';

/// The label of the `k`-th run of `run` (k ≥ 2).
pub fn repeat_label(run: &str, k: usize) -> String {
    format!("{run}{REPEAT_MARK}{k}")
}

/// The run labels in first-seen order, repetitions left out.
pub fn run_labels(rows: &[Measurement]) -> Vec<String> {
    let mut labels: Vec<String> = Vec::new();
    for m in rows.iter().filter(|m| !m.run.contains(REPEAT_MARK)) {
        if !labels.contains(&m.run) {
            labels.push(m.run.clone());
        }
    }
    labels
}

/// Every run of `run` that has rows, the first one first, with its label.
pub fn repetitions<'a>(rows: &'a [Measurement], run: &str) -> Vec<(String, Vec<&'a Measurement>)> {
    let mut runs = vec![(run.to_string(), run_rows(rows, run))];
    for k in 2.. {
        let label = repeat_label(run, k);
        let rows = run_rows(rows, &label);
        if rows.is_empty() {
            break;
        }
        runs.push((label, rows));
    }
    runs.retain(|(_, r)| !r.is_empty());
    runs
}

/// The snapshot nearest `t` seconds, within a quarter second (the viewer's `--snapshot-every`
/// ticks land within a few milliseconds of the second; the slack tolerates a busy machine).
pub fn at_time<'a>(run: &[&'a Measurement], t: f64) -> Option<&'a Measurement> {
    run.iter()
        .copied()
        .filter(|m| (m.time_s - t).abs() < 0.25)
        .min_by(|a, b| (a.time_s - t).abs().total_cmp(&(b.time_s - t).abs()))
}

/// The first snapshot at which the sample count had reached `n`.
pub fn at_samples<'a>(run: &[&'a Measurement], n: u64) -> Option<&'a Measurement> {
    run.iter().copied().find(|m| m.samples >= n)
}

/// The first snapshot at which `n` paths had been traced.
pub fn at_paths<'a>(run: &[&'a Measurement], n: u64) -> Option<&'a Measurement> {
    run.iter().copied().find(|m| m.paths >= n)
}

/// The last snapshot at or before `t` seconds: the picture the person saw then.
pub fn by_time<'a>(run: &[&'a Measurement], t: f64) -> Option<&'a Measurement> {
    run.iter()
        .copied()
        .take_while(|m| m.time_s <= t + 0.25)
        .last()
}

/// The first snapshot time at which the mean FLIP is at or below `level`.
pub fn time_to_reach(run: &[&Measurement], level: f64) -> Option<f64> {
    run.iter()
        .filter(|m| m.error.flip <= level)
        .map(|m| m.time_s)
        .min_by(f64::total_cmp)
}

/// A snapshot with made-up counts (64 paths per sample), for tests.
#[cfg(test)]
pub fn test_measurement(run: &str, time_s: f64, samples: u64, flip: f64) -> Measurement {
    Measurement {
        run: run.into(),
        time_s,
        samples,
        paths: samples * 64,
        shown: 10,
        inserted: 12,
        removed: 2,
        outstanding: 0,
        renderer_busy: 0.9,
        converged: false,
        error: ImageError {
            flip,
            rmse: flip / 2.0,
        },
        exr: None,
        profile: Profile::Today,
    }
}

#[cfg(test)]
mod tests {
    use super::test_measurement as m;
    use super::*;

    #[test]
    fn csv_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.csv");
        let rows = vec![
            m("nld-os", 1.0, 100, 0.25),
            Measurement {
                converged: true,
                renderer_busy: 0.125,
                ..m(NO_REFINE, 2.5, 40, 0.5)
            },
        ];
        write_csv(&path, &rows).unwrap();
        assert_eq!(read_csv(&path).unwrap(), rows);
        let thesis = vec![Measurement {
            profile: Profile::Thesis,
            ..m("nld-os-thesis", 1.0, 100, 0.25)
        }];
        write_csv(&path, &thesis).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.lines().nth(1).unwrap().ends_with(",thesis (2006)"),
            "{text}"
        );
        assert_eq!(read_csv(&path).unwrap(), thesis);
    }

    #[test]
    fn a_csv_from_before_the_profile_column_reads_as_today() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("old.csv");
        std::fs::write(
            &path,
            format!(
                "{HEADER_BEFORE_PROFILES}\nrnd,1.000,100,6400,10,12,2,0,0.900,0,0.25000,0.12500\n"
            ),
        )
        .unwrap();
        assert_eq!(read_csv(&path).unwrap(), vec![m("rnd", 1.0, 100, 0.25)]);
    }

    #[test]
    fn picks_snapshots_by_time_samples_paths_and_level() {
        let rows = [
            m("a", 0.0, 0, 1.0),
            m("a", 1.01, 500, 0.3),
            m("a", 1.1, 1000, 0.2),
            m("a", 2.0, 1500, 0.09),
            m("a", 2.2, 2000, 0.05),
        ];
        let run: Vec<&Measurement> = rows.iter().collect();
        assert_eq!(at_time(&run, 1.0).unwrap().samples, 500);
        assert!(at_time(&run, 3.0).is_none());
        assert_eq!(at_samples(&run, 800).unwrap().time_s, 1.1);
        assert_eq!(at_samples(&run, 1500).unwrap().time_s, 2.0);
        assert_eq!(at_paths(&run, 64 * 1600).unwrap().time_s, 2.2);
        assert_eq!(by_time(&run, 1.5).unwrap().time_s, 1.1);
        assert_eq!(by_time(&run, 60.0).unwrap().time_s, 2.2);
        assert_eq!(time_to_reach(&run, 0.2), Some(1.1));
        assert_eq!(time_to_reach(&run, 0.1), Some(2.0));
        assert_eq!(time_to_reach(&run, 0.05), Some(2.2));
        assert_eq!(time_to_reach(&run, 0.01), None);
    }
}
