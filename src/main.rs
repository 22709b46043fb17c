//! `walkthrough`: the launcher. See `walkthrough --help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    walkthrough::cli::run(walkthrough::cli::Cli::parse())
}
