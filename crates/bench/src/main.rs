//! `walkthrough-bench`: the benchmarks. See `walkthrough-bench --help`.

use clap::Parser;

fn main() -> anyhow::Result<()> {
    bench::cli::run(bench::cli::Cli::parse())
}
