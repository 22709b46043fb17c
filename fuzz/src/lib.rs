//! The fuzzed code of each target, kept apart from the `fuzz_targets/` entry points so that the
//! protocol and scene crates' stable tests replay the corpus through exactly the same calls.

pub mod frames;
pub mod scene_files;
