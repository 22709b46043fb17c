//! The error of a viewer image against a view's ground truth, on the fixed terms of DESIGN.md §10:
//! both linear images are tone-mapped the same way (Drago, eq. 4.2, with the ground truth's L_white,
//! then sRGB), and the error is the mean LDR-FLIP (67 pixels per degree) and the RMSE over the
//! pixels that see geometry. Pixels that see no geometry are left out of every error: the viewer
//! draws the sky there (its EXR marks them with alpha 0), the ground truth the sky too (its alpha
//! is the renderer's coverage), and the mask is the ground truth's coverage, so neither sky enters
//! an error.

use std::path::Path;

use conventions::luminance::luminance;
use conventions::tone_map::{ToneMap, srgb8};

/// LDR-FLIP's default observer: 0.7 m from a 0.7 m wide 4K monitor (DESIGN.md §10).
const FLIP_PIXELS_PER_DEGREE: f32 = 67.0;

/// The fraction of covered ground-truth pixels at or below L_white. A path-traced reference keeps a
/// few bright outliers even at 256 paths per pixel; letting one pixel set the white point would
/// darken the whole tone-mapped pair and shrink every error.
const L_WHITE_QUANTILE: f64 = 0.999;

/// A linear RGB image as the renderer's reference mode and the headless viewer write it (EXR).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    /// The alpha channel when the file has one.
    pub alpha: Option<Vec<f32>>,
}

impl LinearImage {
    /// The image of an EXR file, through the renderer's one EXR reader.
    pub fn read_exr(path: &Path) -> anyhow::Result<LinearImage> {
        let image = renderer::image_files::read_exr(path)?;
        Ok(LinearImage {
            width: image.width,
            height: image.height,
            rgb: image.pixels.iter().map(|p| p.to_array()).collect(),
            alpha: image.alpha,
        })
    }

    fn same_size(&self, other: &LinearImage) -> bool {
        self.width == other.width && self.height == other.height
    }
}

/// The tone map every error is taken after: Drago's operator (DESIGN.md §9, eq. 4.2) as the
/// viewer's shader applies it (`conventions::tone_map`), with the ground truth's white point, then
/// sRGB and 8-bit quantisation.
#[derive(Clone, Copy, Debug)]
pub struct GroundTruthToneMap {
    pub l_white: f32,
}

impl GroundTruthToneMap {
    /// White point from the ground truth's covered pixels (see [`L_WHITE_QUANTILE`]).
    pub fn of_ground_truth(gt: &LinearImage, covered: &[bool]) -> GroundTruthToneMap {
        let mut lum: Vec<f32> = gt
            .rgb
            .iter()
            .zip(covered)
            .filter(|(_, c)| **c)
            .map(|(p, _)| luminance(*p))
            .filter(|l| l.is_finite())
            .collect();
        lum.sort_by(f32::total_cmp);
        let at = ((lum.len() as f64 - 1.0) * L_WHITE_QUANTILE)
            .round()
            .max(0.0) as usize;
        GroundTruthToneMap {
            l_white: lum.get(at).copied().unwrap_or(1.0).max(1e-6),
        }
    }

    fn map(&self, rgb: [f32; 3]) -> [u8; 3] {
        ToneMap::Drago.display_rgb(rgb, self.l_white).map(srgb8)
    }

    /// Interleaved 8-bit sRGB, row by row.
    pub fn srgb8(&self, image: &LinearImage) -> Vec<u8> {
        image.rgb.iter().flat_map(|p| self.map(*p)).collect()
    }
}

/// Which pixels see geometry: the ground truth carries the renderer's coverage as alpha (0 where no
/// camera ray of the pixel hit anything, see `convergence::ground_truth`). A file without alpha is
/// taken as fully covered.
pub fn coverage(gt: &LinearImage) -> Vec<bool> {
    match &gt.alpha {
        Some(alpha) => alpha.iter().map(|a| *a > 0.5).collect(),
        None => vec![true; gt.rgb.len()],
    }
}

/// Error of one test image against the ground truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageError {
    /// Mean LDR-FLIP over covered pixels, 0 (identical) to 1.
    pub flip: f64,
    /// RMSE of the 8-bit sRGB values scaled to 0..1, over covered pixels and the three channels.
    pub rmse: f64,
}

/// A view's ground truth, prepared once and compared against many snapshots.
pub struct Reference {
    pub image: LinearImage,
    pub covered: Vec<bool>,
    pub tone_map: GroundTruthToneMap,
    /// Tone-mapped, with uncovered pixels black (see [`Reference::error_of`]).
    srgb: Vec<u8>,
}

impl Reference {
    pub fn new(image: LinearImage) -> Reference {
        let covered = coverage(&image);
        let tone_map = GroundTruthToneMap::of_ground_truth(&image, &covered);
        let srgb = masked(tone_map.srgb8(&image), &covered);
        Reference {
            image,
            covered,
            tone_map,
            srgb,
        }
    }

    pub fn read_exr(path: &Path) -> anyhow::Result<Reference> {
        Ok(Reference::new(LinearImage::read_exr(path)?))
    }

    pub fn covered_pixels(&self) -> usize {
        self.covered.iter().filter(|c| **c).count()
    }

    /// The test image tone-mapped like the ground truth, uncovered pixels black.
    pub fn tone_mapped(&self, test: &LinearImage) -> Vec<u8> {
        masked(self.tone_map.srgb8(test), &self.covered)
    }

    pub fn error_of(&self, test: &LinearImage) -> anyhow::Result<ImageError> {
        anyhow::ensure!(
            self.image.same_size(test),
            "image is {}x{}, ground truth {}x{}",
            test.width,
            test.height,
            self.image.width,
            self.image.height
        );
        anyhow::ensure!(
            self.covered_pixels() > 0,
            "the ground truth sees no geometry"
        );
        let test = self.tone_mapped(test);
        Ok(ImageError {
            flip: self.mean_flip(&test),
            rmse: self.rmse(&test),
        })
    }

    /// FLIP filters across neighbouring pixels, so uncovered pixels are black in both images: equal
    /// there, they add no error of their own to the covered pixels next to them.
    fn mean_flip(&self, test: &[u8]) -> f64 {
        let (w, h) = (self.image.width, self.image.height);
        let reference = nv_flip::FlipImageRgb8::with_data(w, h, &self.srgb);
        let test = nv_flip::FlipImageRgb8::with_data(w, h, test);
        let map = nv_flip::flip(reference, test, FLIP_PIXELS_PER_DEGREE).to_vec();
        mean_over(&self.covered, |i| map[i] as f64)
    }

    fn rmse(&self, test: &[u8]) -> f64 {
        let sq = |i: usize| {
            (0..3)
                .map(|c| {
                    let d = (self.srgb[3 * i + c] as f64 - test[3 * i + c] as f64) / 255.0;
                    d * d
                })
                .sum::<f64>()
                / 3.0
        };
        mean_over(&self.covered, sq).sqrt()
    }
}

fn masked(mut srgb: Vec<u8>, covered: &[bool]) -> Vec<u8> {
    for (px, c) in srgb.chunks_exact_mut(3).zip(covered) {
        if !c {
            px.fill(0);
        }
    }
    srgb
}

fn mean_over(covered: &[bool], value: impl Fn(usize) -> f64) -> f64 {
    let (sum, n) = covered
        .iter()
        .enumerate()
        .filter(|(_, c)| **c)
        .fold((0.0, 0usize), |(s, n), (i, _)| (s + value(i), n + 1));
    sum / n.max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(width: u32, height: u32, rgb: [f32; 3]) -> LinearImage {
        let n = (width * height) as usize;
        LinearImage {
            width,
            height,
            rgb: vec![rgb; n],
            alpha: None,
        }
    }

    #[test]
    fn drago_maps_white_to_one_and_keeps_colour() {
        let tm = GroundTruthToneMap { l_white: 4.0 };
        assert_eq!(tm.map([4.0, 4.0, 4.0]), [255, 255, 255]);
        assert_eq!(tm.map([0.0; 3]), [0, 0, 0]);
        let [r, g, b] = tm.map([0.2, 0.1, 0.05]);
        assert!(r > g && g > b, "{r} {g} {b}");
    }

    #[test]
    fn identical_images_have_no_error_and_different_ones_do() {
        let gt = Reference::new(flat(64, 48, [0.5, 0.4, 0.3]));
        let same = gt.error_of(&flat(64, 48, [0.5, 0.4, 0.3])).unwrap();
        assert_eq!(
            same,
            ImageError {
                flip: 0.0,
                rmse: 0.0
            }
        );
        let darker = gt.error_of(&flat(64, 48, [0.1, 0.08, 0.06])).unwrap();
        assert!(darker.flip > 0.05 && darker.rmse > 0.05, "{darker:?}");
    }

    #[test]
    fn uncovered_pixels_are_left_out() {
        let mut gt = flat(64, 48, [0.5, 0.4, 0.3]);
        // Left half sees geometry, right half the sky.
        gt.alpha = Some(
            (0..64 * 48)
                .map(|i| if i % 64 < 32 { 1.0 } else { 0.0 })
                .collect(),
        );
        let reference = Reference::new(gt);
        assert_eq!(reference.covered_pixels(), 32 * 48);
        let mut test = flat(64, 48, [0.5, 0.4, 0.3]);
        for (i, p) in test.rgb.iter_mut().enumerate() {
            if i % 64 >= 32 {
                *p = [9.0, 0.0, 9.0];
            }
        }
        assert_eq!(
            reference.error_of(&test).unwrap(),
            ImageError {
                flip: 0.0,
                rmse: 0.0
            }
        );
    }

    #[test]
    fn white_point_ignores_a_few_outliers() {
        let mut gt = flat(100, 100, [1.0, 1.0, 1.0]);
        gt.rgb[0] = [1000.0; 3];
        let tm = GroundTruthToneMap::of_ground_truth(&gt, &[true; 10_000]);
        assert!((tm.l_white - 1.0).abs() < 1e-4, "{}", tm.l_white);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let gt = Reference::new(flat(8, 8, [1.0; 3]));
        assert!(gt.error_of(&flat(8, 4, [1.0; 3])).is_err());
    }
}
