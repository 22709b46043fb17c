//! A cached sample as callers see it (`CachedSample`) and as the cache stores it
//! (`PackedSample`): DESIGN.md §5.

use glam::Vec3;
use protocol::renderer_link::Quality;
use protocol::{PartEstimate, SampleParts};

use crate::sample::{Depth, Estimate};

/// A sample as callers build and read it; stored packed (`PackedSample`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CachedSample {
    /// Per part, the mean radiance of its paths and the sample variance of their luminance. Read
    /// back, the indirect part is the shown (filtered) one.
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

impl CachedSample {
    pub fn estimate(&self) -> Estimate {
        Estimate {
            parts: self.parts,
            paths: self.quality.paths,
            depth: Depth::of(self.quality.bounces),
        }
    }

    /// The displayed radiance, the sum of the parts (`Estimate::rgb`).
    pub fn rgb(&self) -> [f32; 3] {
        self.parts.rgb()
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
/// (the eyes are in `ShadingCache::eyes`).
#[derive(Clone, Copy, Debug)]
pub(super) struct PackedSample {
    pub(super) parts: SampleParts,
    /// The indirect part as shown: the object-space filter's estimate (`indirect_filter`), in
    /// the units of `parts.indirect` (its variance is per path, the filtered mean's variance
    /// times `paths`); `parts.indirect` itself until the filter runs after a change.
    pub(super) shown_indirect: PartEstimate,
    pub(super) paths: u32,
    pub(super) last_seen: Stamp,
    pub(super) depth: Depth,
    pub(super) view_dependent: bool,
}

const _: () = assert!(size_of::<PackedSample>() == 60);

impl PackedSample {
    pub(super) fn new(e: &Estimate, view_dependent: bool, last_seen: Stamp) -> Self {
        PackedSample {
            parts: e.parts,
            shown_indirect: e.parts.indirect,
            paths: e.paths,
            last_seen,
            depth: e.depth,
            view_dependent,
        }
    }

    /// What further paths merge with.
    pub(super) fn raw(&self) -> Estimate {
        Estimate {
            parts: self.parts,
            paths: self.paths,
            depth: self.depth,
        }
    }

    /// What the person sees, and every reader judges.
    pub(super) fn estimate(&self) -> Estimate {
        Estimate {
            parts: SampleParts {
                indirect: self.shown_indirect,
                ..self.parts
            },
            ..self.raw()
        }
    }

    pub(super) fn set(&mut self, e: &Estimate) {
        *self = PackedSample::new(e, self.view_dependent, self.last_seen);
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
