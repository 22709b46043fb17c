#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    walkthrough_fuzz::scene_files::toml(data);
});
