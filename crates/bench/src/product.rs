//! Where the product binary is: the benchmarks start the renderer, SMA and viewer as real
//! processes from the `walkthrough` binary, which `cargo build --release --workspace` puts beside
//! `walkthrough-bench` in `target/release`. A test binary of this package sits one folder below
//! (`target/release/deps`), so the folder above is looked at too.

use std::path::PathBuf;

use anyhow::Context;

/// The `walkthrough` binary beside this process's own, or an error that says how to build it.
pub fn walkthrough_exe() -> anyhow::Result<PathBuf> {
    let me = std::env::current_exe().context("locating this benchmark binary")?;
    let name = format!("walkthrough{}", std::env::consts::EXE_SUFFIX);
    me.ancestors()
        .skip(1)
        .take(2)
        .map(|dir| dir.join(&name))
        .find(|candidate| candidate.is_file())
        .with_context(|| {
            format!(
                "no `{name}` binary beside {}: build it with `cargo build --release --workspace`",
                me.display()
            )
        })
}
