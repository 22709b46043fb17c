#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    walkthrough_fuzz::frames::viewer_link(data);
});
