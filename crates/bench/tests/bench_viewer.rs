//! The benchmark section runs end to end in its quick form and reports every figure it promises
//! (timings themselves are not judged here).

#[test]
fn quick_benchmark_section_reports_its_rows() {
    let md = bench::viewer::section(true).expect("benchmark section");
    assert!(md.starts_with("## Viewer"), "{md}");
    assert!(md.contains("updates applied, table only"), "{md}");
    if md.contains("No graphics adapter") {
        assert!(!viewer::gpu::gpu_required(), "{md}");
    } else {
        assert!(
            md.contains("updates applied + uploaded") && md.contains("frame time, 100000"),
            "{md}"
        );
    }
}
