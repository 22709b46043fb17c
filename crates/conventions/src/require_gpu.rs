//! The rule for checks that need a wgpu adapter: without one they say so and step aside, unless
//! `WALKTHROUGH_REQUIRE_GPU` is set (CI sets it), where a missing adapter is a failure.

/// The variable that makes a missing adapter a failure.
pub const VAR: &str = "WALKTHROUGH_REQUIRE_GPU";

/// Whether a check that finds no adapter must fail rather than skip.
pub fn required() -> bool {
    std::env::var_os(VAR).is_some()
}
