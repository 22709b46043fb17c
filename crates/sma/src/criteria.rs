//! Refinement criteria (thesis §4.3, DESIGN.md §6), one module each behind [`Criterion`]. Adding
//! one: a new file under `criteria/`, a `mod` line, a variant of [`CriterionKind`] with its name,
//! and an arm in [`make_criterion`].
//!
//! Every criterion returns at most R (`max`) leaves per call (§4.3.5) so the SMA's loop stays
//! responsive, keeps its progress between calls, and is deterministic for a seed.

mod nld_is;
mod nld_mm;
mod nld_os;
mod nld_px;
mod rnd;
#[cfg(any(test, feature = "testing"))]
pub mod synthetic;

use std::collections::HashSet;

use crate::cache::ShadingCache;
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh, set_bytes};
use crate::sample::{DisplayMap, Displayed, Estimate};
use crate::visible_set::VisibleSet;

pub use nld_is::NldIs;
pub use nld_mm::nld_mm;
pub use nld_os::NldOs;
pub use nld_px::NldPx;
pub use rnd::Rnd;

/// The current state as a criterion sees it.
pub struct CriterionInput<'a> {
    pub mesh: &'a SubdivisionMesh,
    pub cache: &'a ShadingCache,
    pub visible: &'a VisibleSet,
    /// L_max of eq. 4.3 (DESIGN.md §6).
    pub l_white: f32,
    /// The Gouraud-shaded luminance of the current state, for image-space criteria.
    pub image: Option<&'a LuminanceImage>,
}

/// A luminance image and the leaf seen at each pixel, row-major from the top-left.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LuminanceImage {
    pub width: u32,
    pub height: u32,
    pub luminance: Vec<f32>,
    /// Leaf `NodeId` per pixel, [`LuminanceImage::NONE`] where no geometry is seen.
    pub ids: Vec<u32>,
}

impl LuminanceImage {
    pub const NONE: u32 = u32::MAX;

    fn index(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }
}

pub trait Criterion: Send {
    fn kind(&self) -> CriterionKind;
    /// Whether `select` needs `CriterionInput::image`.
    fn needs_image(&self) -> bool;
    /// Up to `max` distinct leaves to refine; empty when nothing (more) is worth refining now.
    fn select(&mut self, input: &CriterionInput, max: usize) -> Vec<NodeId>;
    /// Start over (the camera moved).
    fn reset(&mut self);
    /// What its state for the current camera holds, by capacity: part of the viewer's share of
    /// the memory budget (`schedule::memory`).
    fn heap_bytes(&self) -> usize;
}

/// The criteria there are; on the wire and the command line by [`CriterionKind::name`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CriterionKind {
    /// RND, §4.3.1.
    Rnd,
    /// NLD_IS, §4.3.3.
    NldIs,
    /// NLD_OS, §4.3.4, noise-aware (DESIGN.md §6).
    NldOs,
    /// NLD_PX: noise-aware NLD_OS ranked by eq. 3.4's priority.
    NldPx,
    /// NLD_IS with the thesis's eq. 4.5 unchanged, to measure beside the noise-aware one.
    NldIsThesis,
    /// NLD_OS with the thesis's eq. 4.6 unchanged.
    NldOsThesis,
    /// NLD_MM, §4.3.2: NLD_OS's passes with the Shading Cache's max–min metric, eq. 4.4, over
    /// a leaf's three vertices (`nld_mm`), the thesis's yardstick for eq. 4.3.
    NldMm,
}

impl CriterionKind {
    pub const ALL: [CriterionKind; 7] = [
        CriterionKind::Rnd,
        CriterionKind::NldIs,
        CriterionKind::NldOs,
        CriterionKind::NldPx,
        CriterionKind::NldIsThesis,
        CriterionKind::NldOsThesis,
        CriterionKind::NldMm,
    ];

    pub fn name(self) -> &'static str {
        match self {
            CriterionKind::Rnd => "rnd",
            CriterionKind::NldIs => "nld-is",
            CriterionKind::NldOs => "nld-os",
            CriterionKind::NldPx => "nld-px",
            CriterionKind::NldIsThesis => "nld-is-thesis",
            CriterionKind::NldOsThesis => "nld-os-thesis",
            CriterionKind::NldMm => "nld-mm",
        }
    }

    /// The criterion called `name`, if there is one.
    pub fn from_name(name: &str) -> Option<CriterionKind> {
        CriterionKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Every name, comma-separated (for messages).
    pub fn names() -> String {
        let names: Vec<&str> = CriterionKind::ALL.iter().map(|k| k.name()).collect();
        names.join(", ")
    }
}

impl std::fmt::Display for CriterionKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Every parameter of every criterion. Defaults and the measurements behind them are in
/// `Default` and in each criterion's module documentation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CriterionSettings {
    /// NLD_OS: first S_ref (§4.3.4).
    pub s_ref_start: f32,
    /// NLD_OS: S_ref decreases by this once a pass finds nothing above it.
    pub s_ref_step: f32,
    /// NLD_OS, NLD_PX with eq. 4.3 as the thesis has it (`*-thesis`): S at or below which a
    /// leaf is never selected for its shading (§4.3.4).
    pub s_min: f32,
    /// The noise-aware NLD_OS, NLD_PX and NLD_IS: S at or below which a leaf's variation is not
    /// significant, in displayed units (0..1 after tone map and sRGB). The schedule sets it to
    /// its own `display_error`, the threshold its stopping rule holds every sample to (DESIGN.md
    /// §5), so both halves of the stated end ask for the same thing: a picture within one
    /// display step.
    pub display_error: f32,
    /// The quality ladder's last rung, paths per sample (`ScheduleConfig::max_paths`, set by the
    /// schedule): a sample there has settled however noisy it still is (DESIGN.md §5).
    pub max_paths: u32,
    /// NLD_OS, NLD_PX: a leaf covering more than this fraction of the image is always selected
    /// (§4.3.5, fig. 4.10).
    pub large_triangle_fraction: f32,
    /// RND: a pass ends after this fraction of width × height pixels has been picked (§4.3.1).
    pub rnd_fraction: f32,
    /// NLD_IS: at most this fraction of width × height leaves is selected per camera (§4.3.3).
    pub nld_is_fraction: f32,
    /// No selection of a leaf covering fewer pixels (§4.3.3: 6, for NLD_IS).
    pub min_leaf_pixels: u32,
    /// NLD_IS's own minimum in place of `min_leaf_pixels` (None: that one). The thesis gives
    /// 6 pixels for NLD_IS alone (§4.3.3); its profile sets it here, and leaves the others at
    /// `min_leaf_pixels` (`config::Profile`).
    pub nld_is_min_leaf_pixels: Option<u32>,
    /// RND and NLD_IS: whether a pass over the image is followed by another.
    pub passes: Passes,
    /// NLD_PX: ε of eq. 3.4, the weight of a leaf's size alone in its priority
    /// `(ε + (1 - ε) S) × pixels`; it ranks large flat leaves (fig. 4.10) against shading edges.
    pub nld_px_epsilon: f32,
}

/// Defaults from the synthetic convergence runs of the `sma-core` benchmark (8×8 grid at
/// 128×128, a hard shadow line, a shadow disc between vertices, a smooth ripple; mean absolute
/// luminance error after 300 / 600 / 1,200 samples, R = 16; figures in BENCHMARKS.md):
/// - `s_ref_start` 0.5, `s_ref_step` 0.1: the error did not move (0.0150 / 0.0091 / 0.0031)
///   over start 0.3–0.8 and step 0.05–0.2; the middle values are kept.
/// - `s_min` 0.02: 0.005, 0.02 and 0.05 gave the same error here, 0.1 a worse one at 1,200
///   (0.0032). End to end (`bench convergence --sma-flags=--s-min,…`, 10-s runs, R = 256)
///   NLD_OS stopped at 35k samples with 0.05 on Sponza S1 (mean FLIP 0.131 at 10 s) and went on
///   with 0.02 (49k samples, 0.123); bracara VT was alike (0.063 and 0.064).
/// - `large_triangle_fraction` 0.002: 0.0031 at 1,200 against 0.0034 at 0.005 and 0.0042 at
///   0.02 (the disc inside a square is found only when big leaves are split regardless of S);
///   0.005 is better early for NLD_OS (0.0087 / 0.0044 against 0.0150 / 0.0091), since it
///   spends fewer samples on flat leaves first; NLD_PX, which ranks them, needs no such trade.
/// - `nld_is_fraction` 0.1: 0.0045 at 1,200, same as 0.3, against 0.0051 at 0.02.
/// - `nld_px_epsilon` 0.05: 0.0062 / 0.0044 / 0.0031, against 0.0060 / 0.0045 / 0.0031 at 0 and
///   0.0099 / 0.0065 / 0.0031 at 0.3.
/// - `rnd_fraction` 0.1: as `nld_is_fraction`, so RND and NLD_IS passes select alike.
/// - `min_leaf_pixels` 2 (the thesis's §4.3.3 has 6), with the schedule's `min_split_pixels`:
///   end to end on bracara VT (`bench convergence`, 60 s, 512×384, machine shared with other
///   builds) mean FLIP at 5 / 20 / 60 s was 0.056 / 0.053 / 0.053 with 6 for `nld-px`, which
///   reached its stated end at 16 s, against 0.053 / 0.046 / 0.044 with 2, still falling at 60 s;
///   `nld-os` 0.056 / 0.053 / 0.053 against 0.050 / 0.047 / 0.045. Below 6 pixels a leaf's
///   Gouraud error still shows: it is what was left once a view had reached its stated end.
impl Default for CriterionSettings {
    fn default() -> Self {
        CriterionSettings {
            s_ref_start: 0.5,
            s_ref_step: 0.1,
            s_min: 0.02,
            // One step of an 8-bit display, as `ScheduleConfig::display_error`.
            display_error: 1.0 / 255.0,
            // As `ScheduleConfig::max_paths`.
            max_paths: 1024,
            large_triangle_fraction: 0.002,
            rnd_fraction: 0.1,
            nld_is_fraction: 0.1,
            min_leaf_pixels: 2,
            nld_is_min_leaf_pixels: None,
            nld_px_epsilon: 0.05,
            passes: Passes::UntilDry,
        }
    }
}

/// How many passes RND and NLD_IS make over one camera's image. NLD_OS (and NLD_MM) have no
/// such choice: their passes over the visible set, S_ref stepping down to S_min, are §4.3.4's
/// own rule ("the process ends when the S of every triangle is below S_ref").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Passes {
    /// A pass that selected something is followed by another over the image refined meanwhile
    /// (its new leaves are new candidates); one that selected nothing ends the criterion's work
    /// for the camera.
    #[default]
    UntilDry,
    /// One pass per camera, as the thesis ends them: RND once its picks reach a fraction of
    /// width × height (§4.3.1), NLD_IS at 1-pixel quadrants or once a fraction of the pixels is
    /// selected (§4.3.3).
    One,
}

/// A criterion of `kind`; `seed` feeds the random ones.
pub fn make_criterion(
    kind: CriterionKind,
    settings: &CriterionSettings,
    seed: u64,
) -> Box<dyn Criterion> {
    match kind {
        CriterionKind::Rnd => Box::new(Rnd::new(settings, seed)),
        CriterionKind::NldIs => Box::new(NldIs::new(settings, Metric::NoiseAware)),
        CriterionKind::NldOs => Box::new(NldOs::new(settings, Metric::NoiseAware)),
        CriterionKind::NldIsThesis => Box::new(NldIs::new(settings, Metric::Thesis)),
        CriterionKind::NldOsThesis => Box::new(NldOs::new(settings, Metric::Thesis)),
        CriterionKind::NldPx => Box::new(NldPx::new(settings)),
        CriterionKind::NldMm => Box::new(NldOs::new(settings, Metric::MaxMin)),
    }
}

/// Whether a visible leaf covers more than `fraction` of the image (§4.3.5).
fn is_large(pixels: u32, visible: &VisibleSet, fraction: f32) -> bool {
    f64::from(pixels) > f64::from(fraction) * visible.image_pixels() as f64
}

/// Which S the NLD criteria compute.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    /// Eq. 4.3 on radiance luminance over L_max, as in the thesis: a difference between two
    /// noisy samples reads as shading variation.
    Thesis,
    /// `nld::noise_aware_nld` in displayed units: what the samples' standard errors explain is
    /// discounted (DESIGN.md §6, beyond the thesis).
    NoiseAware,
    /// Eq. 4.4 (NLD_MM) on radiance luminance over L_max: eq. 4.3 over only the largest and the
    /// smallest of the samples (`nld_mm`). Object space only: `NldIs` refuses it.
    MaxMin,
}

impl CriterionSettings {
    /// The lowest S that counts as significant, for criteria that compare S with a floor
    /// (NLD_OS's S_min, NLD_IS's quadrants). Eq. 4.3 as the thesis has it keeps `thesis`, its
    /// own floor. The noise-aware metric has already taken off what the samples' noise explains
    /// ([`crate::nld::noise_aware_nld`]), so what is left is shading the Gouraud leaf may miss;
    /// it matters once it can change a displayed 8-bit value, so its floor is one display step
    /// (DESIGN.md §5, §6). S_min = 0.02 is five such steps: leaves left under it were the visible
    /// error of a view that had reached its stated end.
    pub(crate) fn significance_floor(&self, metric: Metric, thesis: f32) -> f32 {
        match metric {
            Metric::Thesis | Metric::MaxMin => thesis,
            Metric::NoiseAware => self.display_error,
        }
    }
}

/// The floor a leaf's S must exceed for its shading to count (§4.3.4's S_min), by `metric`.
/// Noise-aware: one display step once all three vertex samples have settled (DESIGN.md §5: a
/// displayed standard error within one step, or the ladder's cap), `s_min` before. The noise
/// discount (2 standard errors) still lets one pure-noise difference in twenty through, by a
/// margin that scales with the noise: against one step it would split about one flat 64-path
/// leaf in seven (the noisy-patch tests), and every split brings three more noisy samples. Once
/// settled, noise alone must reach 2√2 + 1 of the samples' standard errors to pass, under one
/// leaf in a hundred, and the ladder settles the samples while the view rests: the view still
/// refines down to one step, after its samples, not before.
fn leaf_floor(
    settings: &CriterionSettings,
    estimates: &[Estimate; 3],
    shown: &[Displayed; 3],
    metric: Metric,
) -> f32 {
    let settled = estimates
        .iter()
        .zip(shown)
        .all(|(e, d)| e.paths >= settings.max_paths || d.standard_error <= settings.display_error);
    match metric {
        Metric::NoiseAware if settled => settings.display_error,
        Metric::Thesis | Metric::MaxMin | Metric::NoiseAware => settings.s_min,
    }
}

/// S over a leaf's three cached vertex samples by `metric`, and the [`leaf_floor`] it must
/// exceed to count; `None` while a sample is missing.
fn leaf_nld_and_floor(
    input: &CriterionInput,
    settings: &CriterionSettings,
    leaf: NodeId,
    side: protocol::Side,
    metric: Metric,
) -> Option<(f32, f32)> {
    let estimates = input.cache.leaf_estimates(input.mesh, leaf, side)?;
    let shown = displayed(input, &estimates);
    Some((
        nld_of(input, &estimates, &shown, metric),
        leaf_floor(settings, &estimates, &shown, metric),
    ))
}

/// The three estimates as the person sees them.
fn displayed(input: &CriterionInput, estimates: &[Estimate; 3]) -> [Displayed; 3] {
    let map = DisplayMap::new(input.l_white);
    estimates.map(|e| e.displayed(&map))
}

/// S over a leaf's three cached vertex samples by `metric`, `None` while one is missing.
#[cfg(test)]
fn leaf_nld(
    input: &CriterionInput,
    leaf: NodeId,
    side: protocol::Side,
    metric: Metric,
) -> Option<f32> {
    let estimates = input.cache.leaf_estimates(input.mesh, leaf, side)?;
    Some(nld_of(
        input,
        &estimates,
        &displayed(input, &estimates),
        metric,
    ))
}

/// S over three vertex estimates (`shown`: as displayed) by `metric`.
fn nld_of(
    input: &CriterionInput,
    estimates: &[Estimate; 3],
    shown: &[Displayed; 3],
    metric: Metric,
) -> f32 {
    match metric {
        Metric::Thesis => crate::nld::nld3(
            estimates.map(|e| conventions::luminance(e.rgb())),
            input.l_white,
        ),
        Metric::MaxMin => nld_mm(
            &estimates.map(|e| conventions::luminance(e.rgb())),
            input.l_white,
        ),
        Metric::NoiseAware => {
            crate::nld::noise_aware_nld(&shown.map(|d| (d.luminance, d.standard_error)))
        }
    }
}

/// The displayed standard error of a leaf: the mean of its vertices' (0 while one is missing).
fn leaf_display_error(input: &CriterionInput, leaf: NodeId, side: protocol::Side) -> f32 {
    input
        .cache
        .leaf_estimates(input.mesh, leaf, side)
        .map_or(0.0, |e| {
            displayed(input, &e)
                .iter()
                .map(|d| d.standard_error)
                .sum::<f32>()
                / 3.0
        })
}

/// The leaves a criterion has returned since its last reset: each is offered once per camera,
/// since one the schedule declined to split (too small, too short) would be declined again.
///
/// Its ids are the mesh's, which a recycle renames (`SubdivisionMesh::recycle_removed`: removed
/// blocks are reused by later splits, live ones moved down): after one, an id offered before may
/// name another leaf, which the criterion would then never judge, and a view would reach its
/// stated end (DESIGN.md §5) with leaves its criterion never looked at, which a fresh criterion
/// (the same view after a look elsewhere, or restored from the cache file) splits at once. So
/// the set is forgotten at each recycle (`follow`): a declined leaf is offered once more, and
/// declined again. How many were returned since the reset is kept across recycles, for the
/// criteria whose budget counts them.
#[derive(Debug, Default)]
pub(crate) struct Offered {
    leaves: HashSet<NodeId, FastHash>,
    /// The mesh's recycles when `leaves` was last valid.
    recycles: u64,
    returned: usize,
}

impl Offered {
    /// Forgets the leaves when `mesh` has recycled since the last call.
    pub(crate) fn follow(&mut self, mesh: &SubdivisionMesh) {
        if mesh.recycles() != self.recycles {
            self.recycles = mesh.recycles();
            // A new set, not a cleared one: its capacity goes back to the memory budget.
            self.leaves = HashSet::default();
        }
    }

    pub(crate) fn contains(&self, leaf: NodeId) -> bool {
        self.leaves.contains(&leaf)
    }

    /// Notes `leaf` as returned; false when it was already.
    pub(crate) fn insert(&mut self, leaf: NodeId) -> bool {
        let new = self.leaves.insert(leaf);
        self.returned += usize::from(new);
        new
    }

    /// Leaves returned since the reset, recycles or not.
    pub(crate) fn returned(&self) -> usize {
        self.returned
    }

    /// Start over (a new camera).
    pub(crate) fn reset(&mut self) {
        *self = Offered {
            recycles: self.recycles,
            ..Offered::default()
        };
    }

    pub(crate) fn heap_bytes(&self) -> usize {
        set_bytes(&self.leaves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_is_made_and_found_by_its_name() {
        for kind in CriterionKind::ALL {
            let c = make_criterion(kind, &CriterionSettings::default(), 1);
            assert_eq!(c.kind(), kind);
            assert_eq!(CriterionKind::from_name(kind.name()), Some(kind));
        }
        assert_eq!(CriterionKind::from_name("nope"), None);
    }
}
