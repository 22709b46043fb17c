//! GPU visibility, headless (DESIGN.md §3 steps 2–3; thesis §4.1).
//!
//! - `carry_over`: a view brought to a refined or coarsened mesh without a pass, the camera
//!   unchanged;
//! - `gpu`: the device (a GPU when there is one, else Mesa) and offscreen targets with readback;
//! - `guards`: leaves a viewer's rounding may show beside the visible ones, sent with them;
//! - [`id_pass`]: triangles into an R32Uint ID buffer with depth, per-triangle pixel coverage;
//! - `levels`: level 1 over the base mesh, level 2 over the leaves of visible base triangles;
//! - `luminance_pass`: the Gouraud luminance image of what a viewer shows, for `nld-is`;
//! - `pixel_leaves`: the leaf under each pixel of a view, as runs;
//! - `coverage_mask`: the pixels a set of triangles covers, for tests (behind the `testing`
//!   feature);
//! - `view`: a camera and depth range; every pass draws camera-relative.

mod carry_over;
#[cfg(any(test, feature = "testing"))]
mod coverage_mask;
mod gpu;
mod guards;
pub mod id_pass;
mod levels;
mod luminance_pass;
mod pixel_leaves;
mod view;

pub use carry_over::carry_over;
#[cfg(any(test, feature = "testing"))]
pub use coverage_mask::coverage;
pub use gpu::{Gpu, GpuError};
pub use id_pass::{Coverage, IdImage, IdPass, TriangleBuffer};
pub use levels::{LeafView, Visibility, scene_view, side_facing};
pub use luminance_pass::LuminancePass;
pub use pixel_leaves::PixelLeaves;
pub use view::View;
