//! Image files for reference images: linear EXR, and a PNG tone-mapped with Drago's operator
//! (thesis eq. 4.2, DESIGN.md §9) then sRGB-encoded, by `conventions::tone_map`: the same mapping
//! the viewer applies, so images compare.

use std::path::Path;

use anyhow::Context;
use conventions::tone_map::{ToneMap, srgb8};
use glam::Vec3;

use crate::sampling::luminance;

/// The largest finite luminance among `pixels` (the default `L_white`).
pub fn max_luminance(pixels: impl IntoIterator<Item = Vec3>) -> f32 {
    pixels
        .into_iter()
        .map(luminance)
        .filter(|l| l.is_finite())
        .fold(0.0, f32::max)
}

/// 8-bit sRGB pixels (row-major RGB) of a linear image, Drago-mapped with `l_white`.
pub fn to_srgb8(pixels: &[Vec3], l_white: f32) -> Vec<u8> {
    pixels
        .iter()
        .flat_map(|&p| ToneMap::Drago.display_rgb(p.to_array(), l_white))
        .map(srgb8)
        .collect()
}

pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Vec3],
    l_white: f32,
) -> anyhow::Result<()> {
    let bytes = to_srgb8(pixels, l_white);
    image::save_buffer(path, &bytes, width, height, image::ExtendedColorType::Rgb8)
        .with_context(|| format!("writing {}", path.display()))
}

/// Linear RGB as 32-bit float EXR.
pub fn write_exr(path: &Path, width: u32, height: u32, pixels: &[Vec3]) -> anyhow::Result<()> {
    exr::prelude::write_rgb_file(path, width as usize, height as usize, |x, y| {
        let p = pixels[y * width as usize + x];
        (p.x, p.y, p.z)
    })
    .with_context(|| format!("writing {}", path.display()))
}

/// Reads a linear RGB EXR back (for tests and the convergence benchmark).
pub fn read_exr(path: &Path) -> anyhow::Result<(u32, u32, Vec<Vec3>)> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![Vec3::ZERO; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<Vec3>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = Vec3::new(r, g, b);
        },
    )
    .with_context(|| format!("reading {}", path.display()))?;
    let size = image.layer_data.size;
    let (_, pixels) = image.layer_data.channel_data.pixels;
    Ok((size.width() as u32, size.height() as u32, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_pixels_are_drago_then_srgb() {
        let px = [Vec3::new(2.0, 1.0, 0.5), Vec3::ZERO];
        let bytes = to_srgb8(&px, 4.0);
        let want = ToneMap::Drago.display_rgb([2.0, 1.0, 0.5], 4.0).map(srgb8);
        assert_eq!(bytes, [want[0], want[1], want[2], 0, 0, 0]);
    }

    #[test]
    fn exr_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.exr");
        let px: Vec<Vec3> = (0..6).map(|i| Vec3::new(i as f32, 0.5, 1e3)).collect();
        write_exr(&path, 3, 2, &px).unwrap();
        let (w, h, back) = read_exr(&path).unwrap();
        assert_eq!((w, h), (3, 2));
        assert_eq!(back, px);
    }
}
