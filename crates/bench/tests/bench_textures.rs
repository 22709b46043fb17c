//! The textures section runs end to end in its quick form and reports every figure it promises
//! (timings themselves are not judged here).

#[test]
fn quick_textures_section_reports_its_rows() {
    let md = bench::textures::section(true).expect("benchmark section");
    assert!(md.starts_with("## Textures"), "{md}");
    for row in [
        "| textured diffuse (material, 16-bit coordinates) |",
        "| untextured material (material, zero coordinates) |",
        "| bracara-textured |",
        "| Sponza (textures on) |",
    ] {
        assert!(md.contains(row), "{row} missing:\n{md}");
    }
    if bench::product::walkthrough_exe().is_ok() && viewer::gpu::gpu_required() {
        // bracara-textured's textures arrived: their memory and the frame are measured.
        assert!(!md.contains("| bracara-textured | not measured"), "{md}");
        assert!(
            md.contains("| textured |") && md.contains("Textured frame"),
            "{md}"
        );
    }
}
