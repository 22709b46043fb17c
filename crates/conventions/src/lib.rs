//! One home for each convention the processes of the system share (DESIGN.md §2): they meet only
//! over TCP, so whatever they must agree on without the wire saying it lives here, once.
//!
//! - [`camera`]: the pinhole camera (frame, pixel centres, wgpu depth range), so the SMA's
//!   visibility pass, the viewer's drawing and the renderer's reference images agree pixel for pixel;
//! - [`luminance`]: Rec. 709 luminance (DESIGN.md §6: one set of weights everywhere);
//! - [`tone_map`]: Drago (eq. 4.2) and Reinhard (eq. 4.1) on luminance, colour kept, and sRGB
//!   encoding (DESIGN.md §9); the viewer's WGSL restates them and a test holds it to these;
//! - [`logging`]: the one log format of all processes (tracing, `RUST_LOG`, colour on a terminal);
//! - [`listening`]: the `listening on ADDR` line a server prints once bound, and reading it back;
//! - [`require_gpu`]: when a check that finds no wgpu adapter fails rather than skips.
//!
//! This crate depends on none of ours.

pub mod camera;
pub mod listening;
pub mod logging;
pub mod luminance;
pub mod require_gpu;
pub mod tone_map;

pub use luminance::{REC709, luminance};
pub use tone_map::ToneMap;
