use clap::Parser;

fn main() -> anyhow::Result<()> {
    viewer::cli::run(viewer::cli::Cli::parse())
}
