//! Benchmarks: every measurement of the system lives here, none in the product crates. Speed and
//! memory targets are checked here, never by timed tests; `walkthrough bench report` regenerates
//! BENCHMARKS.md in one command, one section per part:
//!
//! - [`protocol`], [`scene`], [`renderer`], [`sma_core`], [`sma_service`], [`viewer`]: the
//!   sections of `bench report` (internals through each crate's `bench` feature);
//! - [`convergence`] and [`accuracy`]: the end-to-end measurements of DESIGN.md §10, with
//!   [`metrics`], [`plots`] and [`strips`];
//! - [`stats`] (medians, least squares) and [`machine`]: shared by all.

pub mod accuracy;
pub mod convergence;
pub mod machine;
pub mod metrics;
pub mod plots;
pub mod protocol;
pub mod renderer;
pub mod report;
pub mod scene;
pub mod sma_core;
pub mod sma_service;
pub mod stats;
pub mod strips;
pub mod viewer;

use std::path::PathBuf;

use clap::Subcommand;

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Runs every benchmark section and writes BENCHMARKS.md.
    Report {
        /// A few seconds per section instead of the full measurement (a smoke run).
        #[arg(long)]
        quick: bool,
        #[arg(long, default_value = "BENCHMARKS.md")]
        out: PathBuf,
        /// Only the sections whose name contains one of these (protocol, scene, renderer, sma-core,
        /// sma-service, viewer, convergence).
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
    },
    /// Convergence per viewpoint against the ground truth, per criterion (DESIGN.md §10).
    Convergence(convergence::ConvergenceArgs),
    /// Time to reach error levels against a direct per-pixel render (DESIGN.md §10).
    Accuracy(accuracy::AccuracyArgs),
    /// The receiving end of the loopback protocol benchmark (started by `report` as a child).
    #[command(hide = true)]
    LoopbackSink {
        #[arg(long)]
        listen: String,
    },
}

pub fn run(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Report { quick, out, only } => report::write(&out, quick, &only),
        BenchCommand::Convergence(args) => convergence::run(args),
        BenchCommand::Accuracy(args) => accuracy::run(args),
        BenchCommand::LoopbackSink { listen } => protocol::loopback_sink(&listen),
    }
}
