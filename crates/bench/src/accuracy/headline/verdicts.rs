//! The rest-quality targets of the headline (DESIGN.md §10), each stated as met or missed with
//! its count of views: the system against the per-pixel competitors of [`super::per_pixel`], on
//! the medians over the judged criterion's runs.

use std::fmt::Write as _;

use super::super::ViewResult;
use super::super::per_pixel::{PerPixel, time_to_level};
use super::{judged_criterion, system_time};
use crate::convergence::record::{by_time, repetitions};

/// The six default views: a target stated over them needs them all.
const VIEWS: usize = 6;

/// One view's figures for the targets.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct ViewFigures {
    /// Time to mean FLIP 0.05: the system's, and per-pixel + denoiser's.
    pub to_005: (Option<f64>, Option<f64>),
    /// Mean FLIP at 20 s: the system's, and the best denoised image finished by 20 s.
    pub at_20: (Option<f64>, Option<f64>),
    /// Mean FLIP at 60 s, and the plain 64-spp per-pixel render's.
    pub at_60: (Option<f64>, Option<f64>),
    /// Time to mean FLIP 0.1.
    pub to_01: Option<f64>,
}

impl ViewFigures {
    pub(crate) fn of(v: &ViewResult) -> ViewFigures {
        let criterion = judged_criterion(v);
        ViewFigures {
            to_005: (
                system_time(v, criterion, 0.05),
                time_to_level(&v.per_pixel, 0.05, true),
            ),
            at_20: (
                system_flip_at(v, criterion, 20.0),
                best_denoised_by(&v.per_pixel, 20.0),
            ),
            at_60: (
                system_flip_at(v, criterion, 60.0),
                plain_at(&v.per_pixel, 64),
            ),
            to_01: system_time(v, criterion, 0.1),
        }
    }
}

/// The median over the criterion's runs of the mean FLIP of the last snapshot by `t`.
fn system_flip_at(v: &ViewResult, criterion: &str, t: f64) -> Option<f64> {
    let flips: Vec<f64> = repetitions(&v.rows, criterion)
        .iter()
        .filter_map(|(_, rows)| {
            rows.last()
                .filter(|last| last.time_s >= t - 0.5)
                .and(by_time(rows, t))
                .map(|m| m.error.flip)
        })
        .collect();
    (!flips.is_empty()).then(|| crate::stats::median(flips))
}

fn best_denoised_by(renders: &[PerPixel], t: f64) -> Option<f64> {
    renders
        .iter()
        .filter_map(|p| p.denoised)
        .filter(|&(seconds, _)| seconds <= t)
        .map(|(_, flip)| flip)
        .min_by(f64::total_cmp)
}

fn plain_at(renders: &[PerPixel], spp: u32) -> Option<f64> {
    renders.iter().find(|p| p.spp == spp).map(|p| p.flip)
}

/// The targets' lines: one bullet each, "met" or "missed" with the views that meet it.
pub(crate) fn lines(views: &[ViewFigures]) -> String {
    let count = |test: &dyn Fn(&ViewFigures) -> bool| views.iter().filter(|v| test(v)).count();
    let at_most = |a: Option<f64>, b: Option<f64>, factor: f64| match (a, b) {
        (Some(a), Some(b)) => a <= factor * b,
        (Some(_), None) => false,
        (None, _) => false,
    };
    let n = views.len();
    let verdict = |met: bool, k: usize| {
        let word = if met && n >= VIEWS {
            "**met**"
        } else {
            "**missed**"
        };
        format!("{word} ({k} of {n})")
    };
    let faster = count(&|v| at_most(v.to_005.0, v.to_005.1, 1.0));
    let within = count(&|v| at_most(v.to_005.0, v.to_005.1, 1.5));
    let at_20 = count(&|v| at_most(v.at_20.0, v.at_20.1, 1.0));
    let at_60 = count(&|v| at_most(v.at_60.0, v.at_60.1, 1.0));
    let second = count(&|v| v.to_01.is_some_and(|t| t <= 1.0));
    let mut md = String::from("\nTargets (medians over the judged criterion's runs):\n\n");
    let _ = writeln!(
        md,
        "- Time to mean FLIP 0.05 at most per-pixel + denoiser's on at least 4 of 6 views: {}; \
         at most 1.5× it on all six: {}.",
        verdict(faster >= 4, faster),
        verdict(within == n, within)
    );
    let _ = writeln!(
        md,
        "- FLIP at 20 s at or below the best denoised image finished by 20 s on at least 4 of 6: {}.",
        verdict(at_20 >= 4, at_20)
    );
    let _ = writeln!(
        md,
        "- No floor above the per-pixel render: FLIP at 60 s at or below the plain 64-spp render's \
         on all six: {}.",
        verdict(at_60 == n, at_60)
    );
    let _ = writeln!(
        md,
        "- Mean FLIP 0.1 within 1 s on all six: {}.",
        verdict(second == n, second)
    );
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(system_005: f64, denoised_005: f64, at_60: f64, to_01: f64) -> ViewFigures {
        ViewFigures {
            to_005: (Some(system_005), Some(denoised_005)),
            at_20: (Some(0.03), Some(0.04)),
            at_60: (Some(at_60), Some(0.02)),
            to_01: Some(to_01),
        }
    }

    #[test]
    fn counts_decide_each_target_and_fewer_than_six_views_meet_none() {
        let mut views = vec![view(1.0, 2.0, 0.02, 0.5); 4];
        views.push(view(2.9, 2.0, 0.019, 0.9));
        views.push(view(3.1, 2.0, 0.03, 1.2));
        let text = lines(&views);
        assert!(
            text.contains(
                "4 of 6 views: **met** (4 of 6); at most 1.5× it on all six: **missed** (5 of 6)"
            ),
            "{text}"
        );
        assert!(
            text.contains("finished by 20 s on at least 4 of 6: **met** (6 of 6)"),
            "{text}"
        );
        assert!(
            text.contains("plain 64-spp render's on all six: **missed** (5 of 6)"),
            "{text}"
        );
        assert!(
            text.contains("within 1 s on all six: **missed** (5 of 6)"),
            "{text}"
        );
        let fewer = lines(&views[..4]);
        assert!(
            fewer.contains("within 1 s on all six: **missed** (4 of 4)"),
            "{fewer}"
        );
    }

    #[test]
    fn a_level_never_reached_is_not_met() {
        let mut v = view(1.0, 2.0, 0.02, 0.5);
        v.to_005.0 = None;
        let text = lines(&[v; 6]);
        assert!(text.contains("4 of 6 views: **missed** (0 of 6)"), "{text}");
    }

    #[test]
    fn the_best_denoised_image_by_a_time_and_the_plain_render_at_a_count() {
        let render = |spp, seconds, flip, denoised| PerPixel {
            spp,
            seconds,
            flip,
            denoised: Some(denoised),
            measured: String::new(),
        };
        let renders = [
            render(1, 1.0, 0.1, (2.0, 0.05)),
            render(8, 10.0, 0.04, (11.0, 0.03)),
            render(64, 30.0, 0.02, (31.0, 0.015)),
        ];
        assert_eq!(best_denoised_by(&renders, 20.0), Some(0.03));
        assert_eq!(best_denoised_by(&renders, 1.5), None);
        assert_eq!(plain_at(&renders, 64), Some(0.02));
        assert_eq!(plain_at(&renders, 32), None);
    }
}
