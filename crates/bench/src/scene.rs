//! The scene section of BENCHMARKS.md: load + validate + fingerprint of Dabrovic
//! Sponza, target at most 0.5 s; the built-ins' generation and the CPU visibility estimate
//! beside it. Measured, never asserted in a test.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::Context;

use scene::{VisibilityEstimator, load};

use super::stats::median_seconds;

/// The Sponza scene file, wherever the benchmark is started from.
pub(crate) const SPONZA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/sponza.toml");
/// The same with its textures on.
pub(crate) const SPONZA_TEXTURED: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../scenes/sponza-textured.toml"
);
const TARGET_SECONDS: f64 = 0.5;

pub fn section(quick: bool) -> anyhow::Result<String> {
    let runs = if quick { 3 } else { 11 };
    let mut out = String::from("## scene\n\n");
    let sponza = Path::new(SPONZA);
    let scene = load(SPONZA).with_context(|| {
        format!(
            "loading {} (needs ../shared/scenes/sponza)",
            sponza.display()
        )
    })?;
    // Loaded once above, so a failure here is not expected; a failed load would time nothing.
    let t = median_seconds(runs, || drop(load(SPONZA)));
    let verdict = if t <= TARGET_SECONDS {
        "met"
    } else {
        "NOT met"
    };
    writeln!(
        out,
        "Load + validate + fingerprint of Dabrovic Sponza ({} triangles, {} vertices after splits; \
         `scene::load`, reading the files included), median of {runs}: **{:.3} s** (target ≤ {TARGET_SECONDS} s: {verdict}).\n",
        scene.mesh.triangles.len(),
        scene.mesh.positions.len(),
        t
    )?;
    writeln!(
        out,
        "| scene | build (median of {runs}) | triangles | CPU visibility estimate at 1024×768 |"
    )?;
    writeln!(out, "|---|---|---|---|")?;
    for spec in ["bracara", "cornell", SPONZA] {
        let scene = load(spec)?;
        let t = median_seconds(runs, || drop(load(spec)));
        let started = Instant::now();
        let estimator = VisibilityEstimator::new(&scene);
        let views: Vec<String> = scene
            .settings
            .viewpoints
            .iter()
            .map(|v| format!("{} {}", v.name, estimator.count_visible(v, 1024, 768)))
            .collect();
        let per_view = started.elapsed().as_secs_f64() / views.len().max(1) as f64;
        writeln!(
            out,
            "| {} | {:.2} ms | {} | {} visible ({:.0} ms a view) |",
            scene.name,
            t * 1e3,
            scene.mesh.triangles.len(),
            views.join(", "),
            per_view * 1e3
        )?;
    }
    Ok(out)
}
