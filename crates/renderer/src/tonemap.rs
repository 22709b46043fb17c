//! Tone mapping and image files for reference images. Drago's logarithmic operator (thesis eq. 4.2,
//! DESIGN.md §9), `L_d = log(1 + L) / log(1 + L_white)`, applied to Rec. 709 luminance with the
//! colour kept, then sRGB encoding: the same mapping the viewer applies, so images compare.

use std::path::Path;

use anyhow::Context;
use glam::Vec3;

use crate::sampling::luminance;

/// Drago-mapped display RGB (0..1 where `L <= L_white`) of linear radiance `rgb`.
pub fn drago(rgb: Vec3, l_white: f32) -> Vec3 {
    let l = luminance(rgb);
    // Also rejects NaN: comparisons with NaN are false.
    let usable = l > 0.0 && l_white > 0.0;
    if !usable {
        return Vec3::ZERO;
    }
    let ld = (1.0 + l).ln() / (1.0 + l_white).ln();
    rgb * (ld / l)
}

/// sRGB transfer function of a linear value in 0..1.
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

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
        .flat_map(|&p| drago(p, l_white).to_array())
        .map(|c| (srgb_encode(c) * 255.0 + 0.5) as u8)
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
    fn drago_maps_white_to_one_and_keeps_colour_ratios() {
        let white = drago(Vec3::splat(5.0), 5.0);
        assert!((luminance(white) - 1.0).abs() < 1e-5);
        let c = drago(Vec3::new(2.0, 1.0, 0.5), 10.0);
        assert!((c.x / c.y - 2.0).abs() < 1e-5 && (c.y / c.z - 2.0).abs() < 1e-5);
        assert_eq!(drago(Vec3::ZERO, 1.0), Vec3::ZERO);
        assert_eq!(drago(Vec3::splat(f32::NAN), 1.0), Vec3::ZERO);
    }

    #[test]
    fn srgb_endpoints_and_monotone() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!(srgb_encode(0.2) > srgb_encode(0.1));
        assert!((srgb_encode(0.5) - 0.7354).abs() < 1e-3);
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
