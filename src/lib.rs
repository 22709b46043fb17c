//! The launcher: composes the three processes (DESIGN.md §2). It is the only package that imports
//! the renderer, SMA and viewer crates; they meet each other only over TCP.
//!
//! - [`cli`]: `walkthrough [launch flags] | renderer … | sma … | viewer … | scene … | bench …`;
//! - [`launch`]: starts renderer(s), SMA and viewer as child processes on loopback, with
//!   `progress_bar` showing the viewer's progress;
//! - [`scene_cmd`]: `scene info` and `scene export`;
//! - [`bench`]: benchmarks that regenerate BENCHMARKS.md.

pub mod bench;
pub mod cli;
pub mod launch;
pub(crate) mod progress_bar;
pub mod scene_cmd;
