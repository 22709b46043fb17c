//! The quality ladder of progressive shading (DESIGN.md §5, §7): which quality a sample gets
//! first, what it is upgraded to, and the rungs of more paths up to the cap. The plan (`plan`)
//! climbs it; nothing here knows what is visible.

use protocol::renderer_link::Quality;

/// The quality ladder of progressive shading (DESIGN.md §5, §7): a cheap direct-light sample
/// first where it is cheaper than the scene's; then an early rung, a quarter of the scene's paths
/// at its depth; then the scene's quality, which the early rung's paths count toward (same depth:
/// they accumulate); then four times the paths at each further rung, up to `cap_paths`.
///
/// The early rung is what new vertices of a refinement step get, and what a direct-light sample
/// is upgraded to first: a refinement round waits for its samples, and at a quarter of the paths
/// the rounds that find the picture's shadow edges and light pools come four times as fast. The
/// noise-aware criteria weigh the early samples' larger noise (DESIGN.md §4), and every shown
/// sample is still brought to the scene's quality, whatever its noise shows, as a top-up
/// (`Urgency::TopUp`: refinement does not wait for it, but it gets a share of the paths) once
/// the viewer has a tone map.
#[derive(Clone, Copy, Debug)]
pub struct Qualities {
    pub first: Quality,
    pub early: Quality,
    pub full: Quality,
    pub cap_paths: u32,
}

/// Paths grow by this factor from one rung to the next: each rung halves the standard error.
const RUNG_FACTOR: u32 = 4;

/// The fewest paths of an early rung: below it a sample's variance, which the criteria and the
/// stopping rule read, says too little.
const EARLY_MIN_PATHS: u32 = 8;

impl Qualities {
    /// Without `early_rung`, the early rung is the scene's quality itself.
    pub fn new(full: Quality, cap_paths: u32, early_rung: bool) -> Self {
        let first = if Quality::DIRECT.rank() < full.rank() {
            Quality::DIRECT
        } else {
            full
        };
        let early_paths = full.paths / RUNG_FACTOR;
        let early = if early_rung && early_paths >= EARLY_MIN_PATHS {
            Quality {
                paths: early_paths,
                bounces: full.bounces,
            }
        } else {
            full
        };
        Qualities {
            first,
            early,
            full,
            cap_paths: cap_paths.max(full.paths),
        }
    }

    /// No ladder: every sample is traced once at `full` and never gets more paths, as the
    /// thesis's renderer returned one fixed-quality value per vertex (the thesis profile,
    /// `ScheduleConfig::ladder`).
    pub fn fixed(full: Quality) -> Self {
        Qualities {
            first: full,
            early: full,
            full,
            cap_paths: full.paths,
        }
    }

    /// What a shown sample below the scene's quality is upgraded with: (paths traced, total
    /// reached). One at the scene's depth gets the paths that make up the scene's quality; one
    /// at another depth (direct light) is replaced by an early-rung sample.
    pub fn upgrade(&self, cached: Quality) -> (Quality, Quality) {
        if cached.bounces == self.full.bounces && cached.paths < self.full.paths {
            let added = Quality {
                paths: self.full.paths - cached.paths,
                bounces: self.full.bounces,
            };
            (added, self.full)
        } else {
            (self.early, self.early)
        }
    }

    /// Whether a sample's variance may be believed: from the first rung above the scene's
    /// quality (or the cap). A variance read from the scene's 64 paths may miss what is rare,
    /// a path that finds a small bright opening, and call the sample settled: bracara VT reached
    /// its stated end at 31–35 s and mean FLIP 0.035–0.036 in 6 of 8 60-s runs that believed
    /// it, where the other two went on to 0.032; with this rule it went on to 0.032 (43 s).
    pub fn trusts(&self, cached: Quality) -> bool {
        cached.paths
            >= self
                .full
                .paths
                .saturating_mul(RUNG_FACTOR)
                .min(self.cap_paths)
    }

    /// For a sample at the scene's depth with `paths` so far: the paths the next rung adds and
    /// the total it reaches; `None` at the cap or off the scene's depth.
    pub fn next_rung(&self, cached: Quality) -> Option<(Quality, Quality)> {
        if cached.bounces != self.full.bounces || cached.paths >= self.cap_paths {
            return None;
        }
        let mut total = self.full.paths.max(1);
        while total <= cached.paths {
            total = total.saturating_mul(RUNG_FACTOR);
        }
        let total = total.min(self.cap_paths);
        let step = |paths| Quality {
            paths,
            bounces: self.full.bounces,
        };
        Some((step(total - cached.paths), step(total)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn direct_light_is_upgraded_to_the_early_rung_whose_paths_then_count_toward_the_scene_quality()
    {
        let q = Qualities::new(Quality::INTERACTIVE, 1024, true);
        let at = |paths, bounces| Quality { paths, bounces };
        assert_eq!(q.early, at(16, Some(2)));
        assert_eq!(q.upgrade(at(16, Some(0))), (q.early, q.early));
        assert_eq!(
            q.upgrade(at(16, Some(2))),
            (at(48, Some(2)), at(64, Some(2)))
        );
        let few = Qualities::new(at(16, Some(1)), 1024, true);
        assert_eq!(few.early, few.full, "no early rung under eight paths");
        let off = Qualities::new(Quality::INTERACTIVE, 1024, false);
        assert_eq!(off.early, off.full);
        assert_eq!(off.upgrade(at(16, Some(0))), (off.full, off.full));
    }

    #[test]
    fn a_fixed_quality_has_one_rung_the_scenes() {
        let q = Qualities::fixed(Quality::INTERACTIVE);
        assert_eq!(
            (q.first, q.early, q.full),
            (
                Quality::INTERACTIVE,
                Quality::INTERACTIVE,
                Quality::INTERACTIVE
            )
        );
        assert_eq!(q.next_rung(Quality::INTERACTIVE), None, "no rung above it");
        assert!(q.trusts(Quality::INTERACTIVE));
    }

    #[test]
    fn the_ladder_climbs_by_four_at_the_scene_depth_up_to_its_cap() {
        let q = Qualities::new(Quality::INTERACTIVE, 1024, true);
        let at = |paths, bounces| Quality { paths, bounces };
        assert_eq!(q.first, Quality::DIRECT);
        assert_eq!(
            q.next_rung(at(64, Some(2))),
            Some((at(192, Some(2)), at(256, Some(2))))
        );
        assert_eq!(
            q.next_rung(at(256, Some(2))),
            Some((at(768, Some(2)), at(1024, Some(2))))
        );
        assert_eq!(q.next_rung(at(1024, Some(2))), None, "at the cap");
        assert_eq!(
            q.next_rung(at(16, Some(0))),
            None,
            "direct light is upgraded, not climbed"
        );
        let capped = Qualities::new(Quality::INTERACTIVE, 500, true);
        assert_eq!(
            capped.next_rung(at(256, Some(2))),
            Some((at(244, Some(2)), at(500, Some(2))))
        );
    }
}
