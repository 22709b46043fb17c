//! A cached sample as callers see it (`CachedSample`) and as the cache stores it
//! (`PackedSample`): DESIGN.md §5.

use glam::Vec3;
use protocol::renderer_link::Quality;
use protocol::{PartEstimate, SampleParts};

use super::quantised::{SharedExponentRgb, ShortVariances, VARIANCES};
use crate::sample::{Depth, Estimate};

/// A sample as callers build and read it; stored packed (`PackedSample`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CachedSample {
    /// Per part, the mean of its paths and the sample variance of their luminance. Read back
    /// (`ShadingCache::get`), the parts are as displayed (`sample::display_radiance`), the
    /// indirect part the shown (filtered) one.
    pub parts: SampleParts,
    /// Paths averaged so far, and the bounce depth they were traced at.
    pub quality: Quality,
    /// Glossy or mirror: valid for `eye` only; ages as the eye moves (DESIGN.md §5).
    pub view_dependent: bool,
    /// The eye a view-dependent sample was shaded for. Only view-dependent samples keep it: the
    /// cache reads back `None` for the others, whose radiance holds for every eye.
    pub eye: Option<Vec3>,
    /// Frame or epoch counter of the caller when the sample was last visible. Stored as a `u32`,
    /// saturating: see `Stamp`.
    pub last_seen: u64,
}

#[cfg(test)]
impl CachedSample {
    /// A diffuse sample of `parts` at the interactive quality, never seen: what tests cache.
    pub(crate) fn diffuse(parts: SampleParts) -> CachedSample {
        CachedSample {
            parts,
            quality: Quality::INTERACTIVE,
            view_dependent: false,
            eye: None,
            last_seen: 0,
        }
    }
}

impl CachedSample {
    pub fn estimate(&self) -> Estimate {
        Estimate {
            parts: self.parts,
            paths: self.quality.paths,
            depth: Depth::of(self.quality.bounces),
        }
    }

    /// The sum of the parts (`Estimate::rgb`): read back, the displayed radiance.
    pub fn rgb(&self) -> [f32; 3] {
        self.estimate().rgb()
    }
}

/// `last_seen` as stored. The scheduler passes its count of visibility passes (frames), not a
/// clock: at 1,000 passes a second `u32` lasts 49 days of walkthrough. Beyond it every time
/// saturates to `u32::MAX`, which only makes eviction treat all later frames as one.
pub(super) type Stamp = u32;

pub(super) fn stamp(time: u64) -> Stamp {
    Stamp::try_from(time).unwrap_or(Stamp::MAX)
}

/// What the sample array holds per sample: for a view-dependent one, its latest eye's estimate
/// (the eyes are in `ShadingCache::eyes`). The parts are quantised (`quantised`: means within
/// about 2^-9 of their largest channel, variances within 2^-5) and the paths share a word with
/// the depth, so that a sample in four parts takes 32 bytes.
#[derive(Clone, Copy, Debug)]
pub(super) struct PackedSample {
    /// The direct part, the indirect part as answered, the indirect part as shown (the
    /// object-space filter's estimate, `indirect_filter`, in the units of the answered one: its
    /// variance is per path, the filtered mean's variance times `paths`; the answered one until
    /// the filter runs after a change), and the view-dependent part.
    means: [SharedExponentRgb; VARIANCES],
    /// The luminance variances of the same four.
    variances: ShortVariances,
    paths_and_depth: PathsAndDepth,
    pub(super) last_seen: Stamp,
}

const _: () = assert!(size_of::<PackedSample>() == 32);

const DIRECT: usize = 0;
const INDIRECT: usize = 1;
const SHOWN_INDIRECT: usize = 2;
const VIEW_DEPENDENT: usize = 3;

impl PackedSample {
    pub(super) fn new(e: &Estimate, view_dependent: bool, last_seen: Stamp) -> Self {
        let parts = [
            &e.parts.direct,
            &e.parts.indirect,
            &e.parts.indirect,
            &e.parts.view_dependent,
        ];
        PackedSample {
            means: parts.map(|p| SharedExponentRgb::encode(p.rgb)),
            variances: ShortVariances::encode(parts.map(|p| p.luminance_variance)),
            paths_and_depth: PathsAndDepth::new(e.paths, e.depth, view_dependent),
            last_seen,
        }
    }

    fn part(&self, part: usize, variances: &[f32; VARIANCES]) -> PartEstimate {
        PartEstimate {
            rgb: self.means[part].decode(),
            luminance_variance: variances[part],
        }
    }

    /// What further paths merge with.
    pub(super) fn raw(&self) -> Estimate {
        self.with_indirect(INDIRECT)
    }

    /// What the person sees, and every reader judges.
    pub(super) fn estimate(&self) -> Estimate {
        self.with_indirect(SHOWN_INDIRECT)
    }

    fn with_indirect(&self, indirect: usize) -> Estimate {
        let variances = self.variances.decode();
        Estimate {
            parts: SampleParts {
                direct: self.part(DIRECT, &variances),
                indirect: self.part(indirect, &variances),
                view_dependent: self.part(VIEW_DEPENDENT, &variances),
            },
            paths: self.paths_and_depth.paths(),
            depth: self.paths_and_depth.depth(),
        }
    }

    pub(super) fn view_dependent(&self) -> bool {
        self.paths_and_depth.view_dependent()
    }

    pub(super) fn set_view_dependent(&mut self, view_dependent: bool) {
        let p = self.paths_and_depth;
        self.paths_and_depth = PathsAndDepth::new(p.paths(), p.depth(), view_dependent);
    }

    /// Sets the indirect part shown until the sample changes (`indirect_filter`).
    pub(super) fn set_shown_indirect(&mut self, shown: &PartEstimate) {
        self.means[SHOWN_INDIRECT] = SharedExponentRgb::encode(shown.rgb);
        let mut variances = self.variances.decode();
        variances[SHOWN_INDIRECT] = shown.luminance_variance;
        self.variances = ShortVariances::encode(variances);
    }

    pub(super) fn set(&mut self, e: &Estimate) {
        *self = PackedSample::new(e, self.view_dependent(), self.last_seen);
    }
}

/// A sample's paths (24 bits), bounce depth (7) and view dependence (1) in one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct PathsAndDepth(u32);

/// Paths beyond this many are stored as this many: a vertex is settled long before (its
/// standard error is 1/4096 of one path's), and further batches then merge with a little more
/// weight than their share.
const MAX_PATHS: u32 = (1 << 24) - 1;
/// The depth code of unbounded paths (Russian roulette); bounded depths beyond it minus one are
/// stored as it minus one (the scenes trace at most a few dozen bounces).
const UNBOUNDED: u32 = 127;

impl PathsAndDepth {
    fn new(paths: u32, depth: Depth, view_dependent: bool) -> Self {
        let depth = depth.bounces().map_or(UNBOUNDED, |b| b.min(UNBOUNDED - 1));
        PathsAndDepth(paths.min(MAX_PATHS) | depth << 24 | u32::from(view_dependent) << 31)
    }

    fn paths(self) -> u32 {
        self.0 & MAX_PATHS
    }

    fn depth(self) -> Depth {
        let code = (self.0 >> 24) & UNBOUNDED;
        Depth::of((code != UNBOUNDED).then_some(code))
    }

    fn view_dependent(self) -> bool {
        self.0 >> 31 == 1
    }
}

/// A cached sample as callers read it.
pub(super) fn sample_of(
    e: &Estimate,
    view_dependent: bool,
    eye: Option<Vec3>,
    seen: Stamp,
) -> CachedSample {
    CachedSample {
        parts: e.parts,
        quality: e.quality(),
        view_dependent,
        eye,
        last_seen: u64::from(seen),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Paths, depth and view dependence come back as stored; beyond their ranges, saturated.
    #[test]
    fn paths_and_depth_round_trip() {
        for (paths, bounces, view_dependent) in [
            (1, Some(0), false),
            (64, Some(3), true),
            (MAX_PATHS, None, true),
            (12_345, Some(126), false),
        ] {
            let p = PathsAndDepth::new(paths, Depth::of(bounces), view_dependent);
            assert_eq!(
                (p.paths(), p.depth(), p.view_dependent()),
                (paths, Depth::of(bounces), view_dependent)
            );
        }
        let beyond = PathsAndDepth::new(u32::MAX, Depth::of(Some(200)), false);
        assert_eq!(
            (beyond.paths(), beyond.depth(), beyond.view_dependent()),
            (MAX_PATHS, Depth::of(Some(126)), false)
        );
    }
}
