use clap::Parser;

fn main() -> anyhow::Result<()> {
    renderer::cli::run(renderer::cli::Cli::parse())
}
