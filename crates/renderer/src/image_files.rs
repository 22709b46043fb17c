//! Image files: a reference image written as linear EXR, and as a PNG tone-mapped with Drago's
//! operator (thesis eq. 4.2, DESIGN.md §9) then sRGB-encoded, by `conventions::tone_map`: the
//! same mapping the viewer applies, so images compare. Also the one EXR reader ([`read_exr`]),
//! for every linear image the system writes: references, ground truths, viewer snapshots.

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

/// A linear image read from an EXR file, row-major from the top-left pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct ExrImage {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Vec3>,
    /// The alpha channel, when the file has one: a reference image written by [`write_exr`] has
    /// none; a ground truth's alpha is the renderer's coverage and a viewer snapshot's marks the
    /// pixels that see geometry, which error metrics keep (DESIGN.md §10).
    pub alpha: Option<Vec<f32>>,
}

/// Reads the first RGB(A) layer of an EXR file as linear f32 (tests, and the benchmarks' error
/// metrics). A channel the file lacks reads as exr's default: 0 for colour, 1 for alpha, but
/// [`ExrImage::alpha`] is `None` when the file has no alpha channel at all.
pub fn read_exr(path: &Path) -> anyhow::Result<ExrImage> {
    use exr::prelude::*;
    struct Pixels {
        width: usize,
        rgb: Vec<Vec3>,
        alpha: Option<Vec<f32>>,
    }
    let image = read_first_rgba_layer_from_file(
        path,
        |size, channels: &RgbaChannels| Pixels {
            width: size.width(),
            rgb: vec![Vec3::ZERO; size.area()],
            alpha: channels.3.as_ref().map(|_| vec![1.0; size.area()]),
        },
        |px: &mut Pixels, pos, (r, g, b, a): (f32, f32, f32, f32)| {
            let i = pos.y() * px.width + pos.x();
            px.rgb[i] = Vec3::new(r, g, b);
            if let Some(alpha) = px.alpha.as_mut() {
                alpha[i] = a;
            }
        },
    )
    .with_context(|| format!("reading {}", path.display()))?;
    let size = image.layer_data.size;
    let Pixels { rgb, alpha, .. } = image.layer_data.channel_data.pixels;
    Ok(ExrImage {
        width: size.width() as u32,
        height: size.height() as u32,
        pixels: rgb,
        alpha,
    })
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
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        assert_eq!(back.pixels, px);
        assert_eq!(back.alpha, None, "a reference image has no alpha");
    }

    /// A ground truth's or a snapshot's alpha comes back with its colour.
    #[test]
    fn exr_alpha_is_read_when_present() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rgba.exr");
        exr::prelude::write_rgba_file(&path, 2, 2, |x, y| {
            (
                x as f32,
                y as f32,
                0.25f32,
                if x == y { 1.0f32 } else { 0.0 },
            )
        })
        .unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (2, 2));
        assert_eq!(back.pixels[1], Vec3::new(1.0, 0.0, 0.25));
        assert_eq!(back.pixels[2], Vec3::new(0.0, 1.0, 0.25));
        assert_eq!(back.alpha, Some(vec![1.0, 0.0, 0.0, 1.0]));
    }

    #[test]
    fn a_missing_exr_is_an_error_naming_it() {
        let e = read_exr(Path::new("no/such/image.exr")).unwrap_err();
        assert!(format!("{e:#}").contains("no/such/image.exr"), "{e:#}");
    }
}
