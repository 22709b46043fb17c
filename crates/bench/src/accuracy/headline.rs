//! The headline of BENCHMARKS.md (DESIGN.md §10): per view, the time the system takes to each
//! mean-FLIP level against the best per-pixel competitor, plain or denoised
//! ([`super::per_pixel`]). The system's time is the median over the runs of the criterion the
//! targets judge ([`BEST_NOISE_AWARE`]) where the view has them, else over the launcher's
//! default criterion's; a run that never reaches a level counts as the slowest.

use std::fmt::Write as _;

mod verdicts;

use super::ViewResult;
use super::per_pixel::time_to_level;
use crate::convergence::BEST_NOISE_AWARE;
use crate::convergence::record::{repetitions, time_to_reach};

/// The levels of the headline: where a person stops seeing noise, and below.
pub(crate) const LEVELS: [f64; 4] = [0.1, 0.07, 0.05, 0.03];

/// The criterion the launcher starts with, judged where the best one was not run.
const LAUNCHER_DEFAULT: &str = "nld-os";

/// The headline table, or `None` when no view has per-pixel competitors.
pub(crate) fn table(results: &[&ViewResult]) -> Option<String> {
    if results.iter().all(|v| v.per_pixel.is_empty()) {
        return None;
    }
    let mut md = String::from("| view | system's criterion |");
    for level in LEVELS {
        let _ = write!(md, " FLIP ≤ {level}: system / best per-pixel |");
    }
    md.push_str("\n|---|---|");
    md.push_str(&"---:|".repeat(LEVELS.len()));
    md.push('\n');
    for v in results.iter().filter(|v| !v.per_pixel.is_empty()) {
        let criterion = judged_criterion(v);
        let _ = write!(md, "| {} | {criterion} |", v.record.title());
        for level in LEVELS {
            let _ = write!(
                md,
                " {} |",
                cell(system_time(v, criterion, level), competitor(v, level))
            );
        }
        md.push('\n');
    }
    md.push_str(
        "\nEach cell: the system's time, then the best competitor's (\"plain\" or \"denoised\"), and \
         how many times faster the system is (below 1×: slower). \"–\": not reached within the \
         run or the renders measured.\n",
    );
    let figures: Vec<verdicts::ViewFigures> = results
        .iter()
        .filter(|v| !v.per_pixel.is_empty())
        .map(|v| verdicts::ViewFigures::of(v))
        .collect();
    md.push_str(&verdicts::lines(&figures));
    Some(md)
}

fn judged_criterion(v: &ViewResult) -> &'static str {
    if v.rows.iter().any(|m| m.run == BEST_NOISE_AWARE) {
        BEST_NOISE_AWARE
    } else {
        LAUNCHER_DEFAULT
    }
}

/// The median over the criterion's runs of the time to `level`.
fn system_time(v: &ViewResult, criterion: &str, level: f64) -> Option<f64> {
    let times: Vec<f64> = repetitions(&v.rows, criterion)
        .iter()
        .map(|(_, rows)| time_to_reach(rows, level).unwrap_or(f64::INFINITY))
        .collect();
    if times.is_empty() {
        return None;
    }
    Some(crate::stats::median(times)).filter(|t| t.is_finite())
}

/// The fastest competitor to `level`, and which.
fn competitor(v: &ViewResult, level: f64) -> Option<(f64, &'static str)> {
    let plain = time_to_level(&v.per_pixel, level, false).map(|t| (t, "plain"));
    let denoised = time_to_level(&v.per_pixel, level, true).map(|t| (t, "denoised"));
    [plain, denoised]
        .into_iter()
        .flatten()
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

fn cell(system: Option<f64>, best: Option<(f64, &str)>) -> String {
    let seconds = |t: Option<f64>| t.map_or("–".to_string(), |t| format!("{t:.2} s"));
    match best {
        Some((c, which)) => {
            let ratio = system.map_or(String::new(), |s| {
                format!(", {}", super::times(c / s.max(1e-3)))
            });
            format!("{} / {} {which}{ratio}", seconds(system), seconds(Some(c)))
        }
        None => format!("{} / –", seconds(system)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cell_names_the_competitor_and_the_ratio() {
        assert_eq!(
            cell(Some(0.5), Some((2.0, "denoised"))),
            "0.50 s / 2.00 s denoised, 4.0×"
        );
        assert_eq!(
            cell(Some(4.0), Some((1.0, "plain"))),
            "4.00 s / 1.00 s plain, 0.25×"
        );
        assert_eq!(cell(None, Some((1.0, "plain"))), "– / 1.00 s plain");
        assert_eq!(cell(Some(1.0), None), "1.00 s / –");
    }
}
