//! What the offscreen drawing tests share: the picture's size and white point, the colours the
//! shader must draw (from the Rust tone maps of `conventions`), and pixel comparisons.

use viewer::gpu::{Gpu, headless_or_skip};
use viewer::{Snapshot, ToneMap};

pub const W: u32 = 160;
pub const H: u32 = 120;
pub const L_WHITE: f32 = 4.0;

/// What the shader must draw: the Rust tone map of `conventions`, then 8-bit sRGB (unrounded, so
/// a tolerance of one level covers the GPU's rounding).
pub fn expected(rgb: [f32; 3], op: ToneMap) -> [f32; 3] {
    op.display_rgb(rgb, L_WHITE)
        .map(|c| conventions::tone_map::srgb_encode(c) * 255.0)
}

pub fn pixel(s: &Snapshot, x: u32, y: u32) -> [f32; 3] {
    let p = s.display.get_pixel(x, y).0;
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

pub fn assert_close(found: [f32; 3], want: [f32; 3], tol: f32, what: &str) {
    let ok = found.iter().zip(want).all(|(f, w)| (f - w).abs() <= tol);
    assert!(ok, "{what}: found {found:?}, expected {want:?} (±{tol})");
}

pub fn gpu(test: &str) -> Option<Gpu> {
    headless_or_skip(test).expect("a graphics adapter is required")
}

/// World x on the z = 0 plane seen through the centre of pixel column `px` (front camera).
pub fn world_x(px: u32) -> f32 {
    let half_width = 3.0 * 30f32.to_radians().tan() * W as f32 / H as f32;
    ((px as f32 + 0.5) / W as f32 * 2.0 - 1.0) * half_width
}
