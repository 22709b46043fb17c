//! One wanted sample (DESIGN.md §3 step 5, §5): what it asks the renderers for, why it is wanted
//! (its urgency), and its place in the request queue. The plan (`plan`) makes needs; the queue
//! (`requests`) orders and batches them.

use protocol::renderer_link::{Quality, ShadePoint};

/// Why a sample is wanted; lower goes first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Urgency {
    /// A visible leaf cannot be shown without it (cheap quality first: a complete picture fast).
    Missing,
    /// A pending refinement step waits for it (DESIGN.md §4).
    Refinement,
    /// A shown direct-light sample to upgrade to the ladder's early rung (or, without one, to
    /// the scene's quality), or a view-dependent one to retake for the eye that moved (DESIGN.md
    /// §5, §7).
    Better,
    /// An early-rung sample's paths up to the scene's quality (the quality ladder, DESIGN.md
    /// §5). Refinement never waits for them (each round's new vertices would otherwise cost the
    /// scene's quality again before the next round), but while refinement runs they take a share
    /// of the paths traced (`Requests::new`'s `top_up_share`): without one, a scene whose
    /// refinement never stops within the run keeps most of its shown samples at the early
    /// rung's noise.
    TopUp,
    /// More paths for a sample whose noise the person can still see: the work that fills the
    /// renderers whenever nothing above waits, so rest time is never idle.
    Paths,
    /// More paths for a sample whose noise is already below the threshold, while refinement
    /// still runs: a refinement round waits for its samples and a pass, and near the end those
    /// are all the work there is, a batch or two for two workers. This fills those waits with
    /// paths that still lower the displayed error; once the criterion finds nothing, the plan
    /// drops them and the stated end comes (DESIGN.md §3: rest time goes to the renderers).
    Polish,
}

/// One wanted sample.
#[derive(Clone, Copy, Debug)]
pub struct Need {
    pub point: ShadePoint,
    /// What the batch traces: the scene's quality, or the paths a rung of the ladder adds.
    pub quality: Quality,
    /// What the cached sample is to reach: `quality` itself, or for more paths the rung's total.
    pub target: Quality,
    pub urgency: Urgency,
    /// Larger first: on-screen size weighted toward the image centre.
    pub priority: f32,
    /// Wanted although a sample of this quality is cached: its eye is out of date.
    pub new_eye: bool,
}

/// Whether a need is one a picture or a refinement step waits for.
pub fn awaited(urgency: Urgency) -> bool {
    urgency < Urgency::TopUp
}

/// A need's place in the queue as one integer, smaller first: its urgency, then its priority,
/// larger first (the bits of an `f32` in descending `total_cmp` order).
pub fn queue_order(need: &Need) -> u64 {
    let bits = need.priority.to_bits();
    // `total_cmp`'s key: flip the magnitude of negatives, then the sign, so that unsigned order
    // is numeric order; inverted, larger priorities come first.
    let ascending = if bits >> 31 == 1 {
        !bits
    } else {
        bits | 1 << 31
    };
    (need.urgency as u64) << 32 | u64::from(!ascending)
}
