//! The command line of the launcher. Each process crate's own command line is embedded whole, so
//! `walkthrough renderer …` is exactly `renderer …`, and tests start real separate processes from
//! one binary.

use clap::{Parser, Subcommand};

use crate::bench::BenchCommand;
use crate::launch::LaunchArgs;
use crate::scene_cmd::SceneCommand;

#[derive(Parser, Debug)]
#[command(
    name = "walkthrough",
    version,
    about = "Interactive walkthroughs with progressive global illumination",
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// With no subcommand: run renderer(s), SMA and viewer on loopback.
    #[command(flatten)]
    pub launch: LaunchArgs,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// The path-tracing renderer service (`serve`) and reference images (`reference`).
    Renderer(renderer::cli::Cli),
    /// The Shading Management Agent.
    Sma(sma::cli::Cli),
    /// The viewer, in a window or headless.
    Viewer(viewer::cli::Cli),
    /// Scene tools.
    #[command(subcommand)]
    Scene(SceneCommand),
    /// Benchmarks (BENCHMARKS.md).
    #[command(subcommand)]
    Bench(BenchCommand),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        None => crate::launch::run(cli.launch),
        Some(Command::Renderer(c)) => renderer::cli::run(c),
        Some(Command::Sma(c)) => sma::cli::run(c),
        Some(Command::Viewer(c)) => viewer::cli::run(c),
        Some(Command::Scene(c)) => crate::scene_cmd::run(c),
        Some(Command::Bench(c)) => crate::bench::run(c),
    }
}
