//! The launcher: composes the three processes (DESIGN.md §2). It is the only package that imports
//! the renderer, SMA and viewer crates; they meet each other only over TCP.
//!
//! - [`cli`]: `walkthrough [launch flags] | renderer … | sma … | viewer … | scene …`;
//! - [`launch`]: starts renderer(s), SMA and viewer as child processes on loopback, with
//!   `progress_bar` showing the viewer's progress;
//! - [`scene_cmd`]: `scene info` and `scene export`.
//!
//! The benchmarks are a package of their own (`crates/bench`, `walkthrough-bench`), so the shipped
//! binary links no plotting, metric or test-harness crate.

pub mod cli;
pub mod launch;
pub(crate) mod progress_bar;
pub mod scene_cmd;
