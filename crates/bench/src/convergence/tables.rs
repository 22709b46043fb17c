//! Markdown tables of one view in the form of the thesis's tables 5.2–5.4 (Δvis, Δins, Δrem per
//! criterion at 0, 1, 2, … s), with rows added for samples, paths, the renderers' busy share and
//! the measured error, and a second table of the error at equal paths traced (DESIGN.md §10).

use std::fmt::Write;

use super::manifest::ViewRecord;
use super::record::{Measurement, at_paths, at_time, run_labels, run_rows};

/// The columns of the time table: every second up to 5 s (the thesis's instants), every 5 s up
/// to 20 s, then every 10 s.
pub fn table_times(seconds: f64) -> Vec<f64> {
    let every_second = (0..=5).map(f64::from);
    let every_five = [10.0, 15.0, 20.0];
    let every_ten = (3..).map(|k| f64::from(10 * k));
    every_second
        .chain(every_five)
        .chain(every_ten)
        .take_while(|t| *t <= seconds + 1e-9)
        .collect()
}

/// Paths traced at which runs are compared: ×4 steps from a million.
pub const PATH_LEVELS: [u64; 7] = [
    1 << 20,
    1 << 22,
    1 << 24,
    1 << 26,
    1 << 28,
    1 << 30,
    1 << 32,
];

/// `4.2 M` paths.
pub fn millions(n: u64) -> String {
    format!("{:.1} M", n as f64 / 1e6)
}

type Cell = fn(&Measurement) -> String;

const TIME_ROWS: &[(&str, Cell)] = &[
    ("Δvis", |m| thousands(m.shown)),
    ("Δins", |m| thousands(m.inserted)),
    ("Δrem", |m| thousands(m.removed)),
    ("samples", |m| thousands(m.samples)),
    ("paths", |m| millions(m.paths)),
    ("busy", |m| format!("{:.2}", m.renderer_busy)),
    ("FLIP", |m| format!("{:.3}", m.error.flip)),
    ("RMSE", |m| format!("{:.3}", m.error.rmse)),
];

pub fn time_table(record: &ViewRecord, rows: &[Measurement]) -> String {
    let times = table_times(record.seconds);
    let mut md = format!("| Time (s) | {} |", record.profile.label());
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

/// Mean FLIP at the first snapshot at which each level of paths had been traced, and when.
pub fn paths_table(record: &ViewRecord, rows: &[Measurement]) -> String {
    let labels = run_labels(rows);
    let levels: Vec<u64> = PATH_LEVELS
        .into_iter()
        .filter(|n| {
            labels
                .iter()
                .any(|l| at_paths(&run_rows(rows, l), *n).is_some())
        })
        .collect();
    let mut md = format!("| Paths traced, {} |", record.profile.label());
    for n in &levels {
        let _ = write!(md, " {} |", millions(*n));
    }
    md.push_str("\n|---|");
    md.push_str(&"---:|".repeat(levels.len()));
    md.push('\n');
    for label in &labels {
        let run = run_rows(rows, label);
        let _ = write!(md, "| {label} |");
        for n in &levels {
            let cell =
                at_paths(&run, *n).map(|m| format!("{:.3} ({:.1} s)", m.error.flip, m.time_s));
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
    use crate::convergence::record::test_measurement;

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
            measured: String::new(),
            profile: sma::config::Profile::Today,
        }
    }

    #[test]
    fn times_follow_the_thesis_then_every_five_seconds() {
        assert_eq!(table_times(2.0), vec![0.0, 1.0, 2.0]);
        assert_eq!(
            table_times(20.0),
            vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 15.0, 20.0]
        );
        assert_eq!(table_times(60.0).last(), Some(&60.0));
        assert_eq!(table_times(60.0).len(), 13);
    }

    #[test]
    fn thousands_are_spaced() {
        assert_eq!(thousands(12863), "12\u{2009}863");
        assert_eq!(thousands(602), "602");
        assert_eq!(thousands(1_000_000), "1\u{2009}000\u{2009}000");
    }

    #[test]
    fn tables_hold_every_run_and_mark_missing_snapshots() {
        let rows = [
            m("nld-os", 0.0, 0, 0.9),
            m("nld-os", 1.0, 150, 0.3),
            m("rnd", 0.0, 0, 0.9),
            m("rnd", 2.0, 250, 0.2),
            m("rnd", 2.1, 20_000, 0.1),
        ];
        let time = time_table(&record(), &rows);
        assert!(
            time.contains("| nld-os | Δvis | 2\u{2009}511 | 2\u{2009}511 | — |"),
            "{time}"
        );
        assert!(time.contains("|  | FLIP | 0.900 | — | 0.200 |"), "{time}");
        assert!(time.contains("|  | paths | 0.0 M | — | 0.0 M |"), "{time}");
        // 20 000 samples × 64 paths = 1.28 M paths: past the first level only.
        let paths = paths_table(&record(), &rows);
        assert!(
            paths.starts_with("| Paths traced, today | 1.0 M |\n"),
            "{paths}"
        );
        assert!(time.starts_with("| Time (s) | today | 0 |"), "{time}");
        let thesis = ViewRecord {
            profile: sma::config::Profile::Thesis,
            ..record()
        };
        let time = time_table(&thesis, &rows);
        assert!(time.starts_with("| Time (s) | thesis (2006) |"), "{time}");
        assert!(paths.contains("| rnd | 0.100 (2.1 s) |"), "{paths}");
        assert!(paths.contains("| nld-os | — |"), "{paths}");
    }
}
