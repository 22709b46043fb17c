//! Measured snapshots of one view, kept as `<scene>-<view>.csv` under the output folder: the
//! convergence tables, plots and strips are drawn from them, and `bench accuracy` reads them back.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::bench::metrics::ImageError;

/// The run label of the control run with refinement switched off.
pub const NO_REFINE: &str = "no-refine";

/// What triggered a run's snapshots: the viewer takes either periodic snapshots or snapshots at
/// sample counts in one run, so each criterion is run once for each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Schedule {
    /// Every second from t = 0 (and, without refinement, when idle).
    Time,
    /// At fixed sample counts.
    Samples,
}

impl Schedule {
    pub fn as_str(self) -> &'static str {
        match self {
            Schedule::Time => "time",
            Schedule::Samples => "samples",
        }
    }

    fn parse(s: &str) -> anyhow::Result<Schedule> {
        match s {
            "time" => Ok(Schedule::Time),
            "samples" => Ok(Schedule::Samples),
            _ => anyhow::bail!("unknown schedule {s:?}"),
        }
    }
}

/// One snapshot of one run and its error against the ground truth.
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    /// The criterion, or [`NO_REFINE`].
    pub run: String,
    pub schedule: Schedule,
    pub time_s: f64,
    pub samples: u64,
    pub shown: u64,
    pub inserted: u64,
    pub removed: u64,
    pub outstanding: u64,
    pub error: ImageError,
    /// The viewer's linear image (in the raw runs folder; absent from CSVs read back).
    pub exr: Option<PathBuf>,
}

const HEADER: &str = "run,schedule,time_s,samples,shown,inserted,removed,outstanding,flip,rmse";

pub fn write_csv(path: &Path, rows: &[Measurement]) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?,
    );
    writeln!(out, "{HEADER}")?;
    for m in rows {
        writeln!(
            out,
            "{},{},{:.3},{},{},{},{},{},{:.5},{:.5}",
            m.run,
            m.schedule.as_str(),
            m.time_s,
            m.samples,
            m.shown,
            m.inserted,
            m.removed,
            m.outstanding,
            m.error.flip,
            m.error.rmse
        )?;
    }
    Ok(out.flush()?)
}

pub fn read_csv(path: &Path) -> anyhow::Result<Vec<Measurement>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut lines = text.lines();
    anyhow::ensure!(
        lines.next() == Some(HEADER),
        "{} does not start with {HEADER:?}",
        path.display()
    );
    lines
        .filter(|l| !l.is_empty())
        .map(|l| parse_row(l).with_context(|| format!("{}: {l:?}", path.display())))
        .collect()
}

fn parse_row(line: &str) -> anyhow::Result<Measurement> {
    let f: Vec<&str> = line.split(',').collect();
    anyhow::ensure!(f.len() == 10, "expected 10 fields");
    Ok(Measurement {
        run: f[0].to_string(),
        schedule: Schedule::parse(f[1])?,
        time_s: f[2].parse()?,
        samples: f[3].parse()?,
        shown: f[4].parse()?,
        inserted: f[5].parse()?,
        removed: f[6].parse()?,
        outstanding: f[7].parse()?,
        error: ImageError {
            flip: f[8].parse()?,
            rmse: f[9].parse()?,
        },
        exr: None,
    })
}

/// The rows of one run, in the order taken.
pub fn run_rows<'a>(rows: &'a [Measurement], run: &str) -> Vec<&'a Measurement> {
    rows.iter().filter(|m| m.run == run).collect()
}

/// The run labels in first-seen order.
pub fn run_labels(rows: &[Measurement]) -> Vec<String> {
    let mut labels: Vec<String> = Vec::new();
    for m in rows {
        if !labels.contains(&m.run) {
            labels.push(m.run.clone());
        }
    }
    labels
}

/// The rows of `run` taken on `schedule`.
pub fn scheduled<'a>(run: &[&'a Measurement], schedule: Schedule) -> Vec<&'a Measurement> {
    run.iter()
        .copied()
        .filter(|m| m.schedule == schedule)
        .collect()
}

/// The periodic snapshot taken at `t` seconds (the viewer's `--snapshot-every` ticks land within
/// a few milliseconds of the second; a quarter second of slack tolerates a busy machine).
pub fn at_time<'a>(run: &[&'a Measurement], t: f64) -> Option<&'a Measurement> {
    scheduled(run, Schedule::Time)
        .into_iter()
        .filter(|m| (m.time_s - t).abs() < 0.25)
        .min_by(|a, b| (a.time_s - t).abs().total_cmp(&(b.time_s - t).abs()))
}

/// The snapshot taken when the sample count first reached `n` (`--snapshot-at-samples`).
pub fn at_samples<'a>(run: &[&'a Measurement], n: u64) -> Option<&'a Measurement> {
    scheduled(run, Schedule::Samples)
        .into_iter()
        .find(|m| m.samples >= n)
}

/// The first snapshot time, periodic or at a sample count, at which the mean FLIP is at or
/// below `level`: the sample-count snapshots fall between the seconds, so a level reached in
/// the first second is timed more finely than to the second.
pub fn time_to_reach(run: &[&Measurement], level: f64) -> Option<f64> {
    run.iter()
        .filter(|m| m.error.flip <= level)
        .map(|m| m.time_s)
        .min_by(f64::total_cmp)
}

/// A periodic snapshot with made-up counts, for tests.
#[cfg(test)]
pub fn test_measurement(run: &str, time_s: f64, samples: u64, flip: f64) -> Measurement {
    Measurement {
        run: run.into(),
        schedule: Schedule::Time,
        time_s,
        samples,
        shown: 10,
        inserted: 12,
        removed: 2,
        outstanding: 0,
        error: ImageError {
            flip,
            rmse: flip / 2.0,
        },
        exr: None,
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
                schedule: Schedule::Samples,
                ..m(NO_REFINE, 2.5, 40, 0.5)
            },
        ];
        write_csv(&path, &rows).unwrap();
        assert_eq!(read_csv(&path).unwrap(), rows);
    }

    #[test]
    fn picks_snapshots_by_time_samples_and_level() {
        let by_samples = |time_s, samples, flip| Measurement {
            schedule: Schedule::Samples,
            ..m("a", time_s, samples, flip)
        };
        let rows = [
            m("a", 0.0, 0, 1.0),
            m("a", 1.01, 500, 0.3),
            by_samples(1.1, 1000, 0.2),
            m("a", 2.0, 1500, 0.09),
            by_samples(2.2, 2000, 0.05),
        ];
        let run: Vec<&Measurement> = rows.iter().collect();
        assert_eq!(at_time(&run, 1.0).unwrap().samples, 500);
        assert!(at_time(&run, 3.0).is_none());
        assert_eq!(at_samples(&run, 800).unwrap().time_s, 1.1);
        assert_eq!(at_samples(&run, 1500).unwrap().time_s, 2.2);
        assert_eq!(time_to_reach(&run, 0.2), Some(1.1));
        assert_eq!(time_to_reach(&run, 0.1), Some(2.0));
        assert_eq!(time_to_reach(&run, 0.05), Some(2.2));
        assert_eq!(time_to_reach(&run, 0.01), None);
    }
}
