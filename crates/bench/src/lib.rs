//! Benchmarks: every measurement of the system lives here, none in the product crates. Speed and
//! memory targets are checked here, never by timed tests; `walkthrough-bench report` regenerates
//! BENCHMARKS.md in one command, one section per part:
//!
//! - [`protocol`], [`scene`], [`renderer`], [`sma_core`], [`sma_service`], [`cache_file`],
//!   [`viewer`], [`textures`], [`farm`]: the sections of `bench report` (internals through each crate's `bench` feature; the farm's
//!   faults and uneven hosts with real processes);
//! - [`convergence`], [`accuracy`] and [`cost`]: the end-to-end measurements of DESIGN.md §10,
//!   with [`metrics`], [`plots`] and [`strips`]; [`reproduction`]: the thesis's findings beside
//!   ours, from convergence runs of both profiles; [`mesh_options`]: the thesis's neighbour rule
//!   and merging by uniformity against the default mesh;
//! - [`walk`]: a scripted walk of each scene, the system against a per-pixel viewport;
//! - [`ray_throughput`]: the ray-throughput table of the [`renderer`] section;
//! - [`stats`] (medians, least squares) and [`machine`]: shared by all;
//! - [`product`]: where the `walkthrough` binary the benchmarks start is;
//! - [`cli`]: the command line of `walkthrough-bench`, the only module that knows clap.

pub mod accuracy;
pub mod cache_file;
pub mod cli;
pub mod convergence;
pub mod cost;
pub mod farm;
pub mod machine;
pub mod mesh_options;
pub mod metrics;
pub mod plots;
pub mod product;
pub mod protocol;
pub mod ray_throughput;
pub mod renderer;
pub mod report;
pub mod reproduction;
pub mod scene;
pub mod sma_core;
pub mod sma_service;
pub mod stats;
pub mod strips;
pub mod textures;
pub mod viewer;
pub mod walk;
