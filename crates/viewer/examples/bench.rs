//! Prints the viewer's BENCHMARKS.md section: `cargo run --release -p viewer --example bench
//! [-- --quick]`.

fn main() -> anyhow::Result<()> {
    let quick = std::env::args().any(|a| a == "--quick");
    print!("{}", viewer::bench::section(quick)?);
    Ok(())
}
