//! Tests that need a wgpu adapter are skipped without one (said on stderr), or fail where
//! `WALKTHROUGH_REQUIRE_GPU` is set (CI sets it, DESIGN.md §10 runs need one).

/// Whether a test that finds no adapter must fail rather than skip.
pub fn gpu_required() -> bool {
    std::env::var_os("WALKTHROUGH_REQUIRE_GPU").is_some()
}

/// The adapter of a test that needs one: `None` (the test returns) when there is none, unless
/// [`gpu_required`], where it panics.
pub fn gpu_or_skip<T, E: std::fmt::Display>(gpu: Result<T, E>) -> Option<T> {
    match gpu {
        Ok(gpu) => Some(gpu),
        Err(e) if gpu_required() => {
            panic!("WALKTHROUGH_REQUIRE_GPU is set but no adapter: {e}")
        }
        Err(e) => {
            eprintln!(
                "SKIPPED: no wgpu adapter ({e}); set WALKTHROUGH_REQUIRE_GPU to make this fail"
            );
            None
        }
    }
}
