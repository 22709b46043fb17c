//! `sma`: the Shading Management Agent alone (for a LAN); `walkthrough sma …` is the same.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    sma::cli::run(sma::cli::Cli::parse())
}
