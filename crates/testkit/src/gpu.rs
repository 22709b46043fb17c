//! Tests that need a wgpu adapter are skipped without one (said on stderr), or fail where
//! `WALKTHROUGH_REQUIRE_GPU` is set (CI sets it): the rule of `conventions::require_gpu`.

use conventions::require_gpu;

/// The adapter of a test that needs one: `None` (the test returns) when there is none, unless
/// one is required (`conventions::require_gpu`), where it panics.
pub fn gpu_or_skip<T, E: std::fmt::Display>(gpu: Result<T, E>) -> Option<T> {
    match gpu {
        Ok(gpu) => Some(gpu),
        Err(e) if require_gpu::required() => {
            panic!("{} is set but no adapter: {e}", require_gpu::VAR)
        }
        Err(e) => {
            eprintln!(
                "SKIPPED: no wgpu adapter ({e}); set {} to make this fail",
                require_gpu::VAR
            );
            None
        }
    }
}
