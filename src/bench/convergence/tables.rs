//! Markdown tables of one view in the form of the thesis's tables 5.2–5.4 (Δvis, Δins, Δrem per
//! criterion at 0, 1, 2, … s), with rows added for samples and the measured error, and a second
//! table of the error at fixed sample counts.

use std::fmt::Write;

use super::manifest::ViewRecord;
use super::record::{Measurement, at_samples, at_time, run_labels, run_rows};

/// The columns of the time table: every second up to 5 s (the thesis's instants), then every 5 s.
pub fn table_times(seconds: f64) -> Vec<f64> {
    let every_second = (0..=5).map(f64::from);
    let every_five = (2..).map(|k| f64::from(5 * k));
    every_second
        .chain(every_five)
        .take_while(|t| *t <= seconds + 1e-9)
        .collect()
}

type Cell = fn(&Measurement) -> String;

const TIME_ROWS: &[(&str, Cell)] = &[
    ("Δvis", |m| thousands(m.shown)),
    ("Δins", |m| thousands(m.inserted)),
    ("Δrem", |m| thousands(m.removed)),
    ("samples", |m| thousands(m.samples)),
    ("FLIP", |m| format!("{:.3}", m.error.flip)),
    ("RMSE", |m| format!("{:.3}", m.error.rmse)),
];

pub fn time_table(record: &ViewRecord, rows: &[Measurement]) -> String {
    let times = table_times(record.seconds);
    let mut md = String::from("| Time (s) | |");
    for t in &times {
        let _ = write!(md, " {t} |");
    }
    md.push_str("\n|---|---|");
    md.push_str(&"---:|".repeat(times.len()));
    md.push('\n');
    for label in run_labels(rows) {
        let run = run_rows(rows, &label);
        for (i, (name, cell)) in TIME_ROWS.iter().enumerate() {
            let first = if i == 0 { label.as_str() } else { "" };
            let _ = write!(md, "| {first} | {name} |");
            for t in &times {
                let _ = write!(
                    md,
                    " {} |",
                    at_time(&run, *t).map(cell).unwrap_or_else(|| "—".into())
                );
            }
            md.push('\n');
        }
    }
    md
}

/// Mean FLIP at the first snapshot with at least n samples, and when it was taken.
pub fn samples_table(record: &ViewRecord, rows: &[Measurement]) -> String {
    let labels = run_labels(rows);
    let counts: Vec<u64> = record
        .sample_counts
        .iter()
        .copied()
        .filter(|n| {
            labels
                .iter()
                .any(|l| at_samples(&run_rows(rows, l), *n).is_some())
        })
        .collect();
    let mut md = String::from("| Samples |");
    for n in &counts {
        let _ = write!(md, " {} |", thousands(*n));
    }
    md.push_str("\n|---|");
    md.push_str(&"---:|".repeat(counts.len()));
    md.push('\n');
    for label in &labels {
        let run = run_rows(rows, label);
        let _ = write!(md, "| {label} |");
        for n in &counts {
            let cell =
                at_samples(&run, *n).map(|m| format!("{:.3} ({:.1} s)", m.error.flip, m.time_s));
            let _ = write!(md, " {} |", cell.unwrap_or_else(|| "—".into()));
        }
        md.push('\n');
    }
    md
}

/// `12 863` as the thesis writes it, with a thin space between thousands.
pub fn thousands(n: u64) -> String {
    let reversed: Vec<char> = n.to_string().chars().rev().collect();
    let groups: Vec<String> = reversed
        .chunks(3)
        .rev()
        .map(|g| g.iter().rev().collect())
        .collect();
    groups.join("\u{2009}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::convergence::record::{Schedule, test_measurement};

    fn m(run: &str, time_s: f64, samples: u64, flip: f64) -> Measurement {
        Measurement {
            shown: 2511,
            ..test_measurement(run, time_s, samples, flip)
        }
    }

    fn record() -> ViewRecord {
        ViewRecord {
            label: "bracara".into(),
            scene: "bracara".into(),
            view: "MC".into(),
            width: 64,
            height: 48,
            gt_spp: 16,
            seconds: 2.0,
            sample_counts: vec![100, 200, 400],
            ground_truth: "gt.exr".into(),
        }
    }

    #[test]
    fn times_follow_the_thesis_then_every_five_seconds() {
        assert_eq!(table_times(2.0), vec![0.0, 1.0, 2.0]);
        assert_eq!(
            table_times(20.0),
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 15.0, 20.0]
        );
    }

    #[test]
    fn thousands_are_spaced() {
        assert_eq!(thousands(12863), "12\u{2009}863");
        assert_eq!(thousands(602), "602");
        assert_eq!(thousands(1_000_000), "1\u{2009}000\u{2009}000");
    }

    #[test]
    fn tables_hold_every_run_and_mark_missing_snapshots() {
        let by_samples = Measurement {
            schedule: Schedule::Samples,
            ..m("rnd", 2.1, 250, 0.2)
        };
        let rows = [
            m("nld-os", 0.0, 0, 0.9),
            m("nld-os", 1.0, 150, 0.3),
            m("rnd", 0.0, 0, 0.9),
            m("rnd", 2.0, 250, 0.2),
            by_samples,
        ];
        let time = time_table(&record(), &rows);
        assert!(
            time.contains("| nld-os | Δvis | 2\u{2009}511 | 2\u{2009}511 | — |"),
            "{time}"
        );
        assert!(time.contains("|  | FLIP | 0.900 | — | 0.200 |"), "{time}");
        let samples = samples_table(&record(), &rows);
        assert!(
            samples.starts_with("| Samples | 100 | 200 |\n"),
            "{samples}"
        );
        assert!(
            samples.contains("| rnd | 0.200 (2.1 s) | 0.200 (2.1 s) |"),
            "{samples}"
        );
        assert!(samples.contains("| nld-os | — | — |"), "{samples}");
    }
}
