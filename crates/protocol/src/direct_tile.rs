//! Per-pixel direct light of a resting view (DESIGN.md §3 step 8; §5, "samples in parts"): the direct
//! part is sharp (shadows, highlights) where the indirect part is smooth, so while a viewer's
//! camera rests the SMA asks the renderers for the direct part of that very view, pixel by pixel,
//! in tiles, and forwards their accumulation to the viewer, which shows it beside the
//! interpolated vertices' indirect part.
//!
//! Both links carry a tile: the renderer link its request ([`TileRequest`]) and answer
//! ([`TileAnswer`], full precision, per pixel an estimate with its uncertainty), the viewer link
//! the accumulated estimate ([`ViewerTile`], quantised). A tile of the wrong size, outside its
//! image, or with a non-finite or negative value is refused by the `check` of its type, which
//! every receiver runs right after decoding: the reason is logged, the link goes on.

use serde::{Deserialize, Serialize};

use crate::types::PartEstimate;
use crate::viewer_link::Camera;

/// The largest side of a tile, in pixels: a tile answer stays a few tens of kilobytes.
pub const MAX_TILE_SIDE: u32 = 64;

/// The side of the tiles the SMA cuts an image into.
pub const TILE_SIDE: u32 = 32;

/// A rectangle of an image's pixels, from its top-left pixel (the camera convention's rows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct TileRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl TileRect {
    /// The rectangle's pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// A tile inside an image of `width` × `height`, neither empty nor larger than
    /// [`MAX_TILE_SIDE`] a side.
    pub fn check(&self, width: u32, height: u32) -> Result<(), String> {
        let sides = 1..=MAX_TILE_SIDE;
        if !sides.contains(&self.width) || !sides.contains(&self.height) {
            return Err(format!(
                "tile of {}×{} pixels: each side must be 1..={MAX_TILE_SIDE}",
                self.width, self.height
            ));
        }
        let inside = |start: u32, len: u32, limit: u32| {
            start.checked_add(len).is_some_and(|end| end <= limit)
        };
        if !inside(self.x, self.width, width) || !inside(self.y, self.height, height) {
            return Err(format!(
                "tile {}×{} at ({}, {}) outside the {width}×{height} image",
                self.width, self.height, self.x, self.y
            ));
        }
        Ok(())
    }

    /// The tiles of [`TILE_SIDE`] covering an image of `width` × `height`, row by row (the last
    /// row and column cut short).
    pub fn cover(width: u32, height: u32) -> Vec<TileRect> {
        let mut out = Vec::new();
        for y in (0..height).step_by(TILE_SIDE as usize) {
            for x in (0..width).step_by(TILE_SIDE as usize) {
                out.push(TileRect {
                    x,
                    y,
                    width: TILE_SIDE.min(width - x),
                    height: TILE_SIDE.min(height - y),
                });
            }
        }
        out
    }
}

/// Which lights a tile traces per pixel. Only [`DirectLights::All`] stands in for the vertices'
/// whole direct part; a tile of fewer lights stands in for those lights' share of it, which the
/// vertices' parts do not hold apart (DESIGN.md §5): it measures what each light costs and how
/// noisy it is per pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum DirectLights {
    /// The sun only: the sharpest shadows, and one shadow ray per sample.
    Sun,
    /// The sun and the sky's direct part (an occlusion integral: soft, and noisy per pixel).
    SunSky,
    /// Everything the vertices' direct part holds: every light, and the emission the camera
    /// sees at the first hit, so that a tile replaces the vertices' direct part whole.
    #[default]
    All,
}

impl DirectLights {
    pub const ALL: [DirectLights; 3] = [DirectLights::Sun, DirectLights::SunSky, DirectLights::All];

    pub fn name(self) -> &'static str {
        match self {
            DirectLights::Sun => "sun",
            DirectLights::SunSky => "sun-sky",
            DirectLights::All => "all",
        }
    }
}

/// SMA -> renderer: one pass over one tile of a viewer's camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileRequest {
    /// Echoed in the answer.
    pub tile_id: u64,
    /// The view, whose size the rectangle lies in.
    pub camera: Camera,
    pub rect: TileRect,
    /// Camera rays per pixel in this pass, each jittered over the pixel (a box filter, as a
    /// reference image's).
    pub samples_per_pixel: u32,
    /// The pass's index: with the camera's sequence number it seeds the tile's random streams,
    /// so passes of one tile draw different numbers and their answers average.
    pub pass: u32,
    pub lights: DirectLights,
}

impl TileRequest {
    pub fn check(&self, max_samples: u32) -> Result<(), String> {
        self.rect.check(self.camera.width, self.camera.height)?;
        if self.samples_per_pixel == 0 || self.samples_per_pixel > max_samples {
            return Err(format!(
                "{} samples per pixel outside 1..={max_samples}",
                self.samples_per_pixel
            ));
        }
        let c = &self.camera;
        let finite = c.eye.iter().chain(&c.orientation).all(|v| v.is_finite());
        let fov = c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0;
        if !(finite && fov) {
            return Err("a camera with a non-finite eye, orientation or field of view".into());
        }
        Ok(())
    }
}

/// renderer -> SMA: a tile's direct part per pixel, row by row from its top-left pixel: the mean
/// RGB of the pass's samples and the sample variance of their luminance (an estimate with its
/// uncertainty, as a vertex's part is, DESIGN.md §5). A pixel whose rays all missed the scene is
/// zero.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileAnswer {
    pub tile_id: u64,
    pub camera_seq: u64,
    pub rect: TileRect,
    pub pass: u32,
    pub samples_per_pixel: u32,
    pub pixels: Vec<PartEstimate>,
    /// Renderer-side time for the tile, microseconds.
    pub micros: u64,
}

impl TileAnswer {
    /// One estimate per pixel of the rectangle, each finite and non-negative, from at least one
    /// sample.
    pub fn check(&self, width: u32, height: u32) -> Result<(), String> {
        self.rect.check(width, height)?;
        if self.samples_per_pixel == 0 {
            return Err("a tile of no samples".into());
        }
        check_count(self.pixels.len(), &self.rect)?;
        match self.pixels.iter().position(|p| !p.is_valid()) {
            Some(i) => Err(format!(
                "pixel {i} of the tile is non-finite or negative: {:?}",
                self.pixels[i]
            )),
            None => Ok(()),
        }
    }
}

fn check_count(count: usize, rect: &TileRect) -> Result<(), String> {
    if count != rect.pixels() {
        return Err(format!(
            "{count} pixels for a {}×{} tile",
            rect.width, rect.height
        ));
    }
    Ok(())
}

/// One pixel of a [`ViewerTile`]: the direct part's mean RGB and its displayed standard error
/// (the standard deviation of the mean's luminance), each a [`Half`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TilePixel {
    pub rgb: [Half; 3],
    pub standard_error: Half,
}

impl TilePixel {
    pub fn new(rgb: [f32; 3], standard_error: f32) -> TilePixel {
        TilePixel {
            rgb: rgb.map(Half::encode),
            standard_error: Half::encode(standard_error),
        }
    }
}

/// SMA -> viewer: the latest accumulation of one tile of the viewer's camera `camera_seq`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewerTile {
    pub camera_seq: u64,
    pub rect: TileRect,
    /// Samples per pixel accumulated so far.
    pub samples: u32,
    pub pixels: Vec<TilePixel>,
}

impl ViewerTile {
    /// One pixel per pixel of the rectangle, inside the image, every value finite and
    /// non-negative.
    pub fn check(&self, width: u32, height: u32) -> Result<(), String> {
        self.rect.check(width, height)?;
        check_count(self.pixels.len(), &self.rect)?;
        let bad = |p: &TilePixel| {
            p.rgb
                .iter()
                .chain([&p.standard_error])
                .any(|h| !h.is_finite_non_negative())
        };
        match self.pixels.iter().position(bad) {
            Some(i) => Err(format!("pixel {i} of the tile is non-finite or negative")),
            None => Ok(()),
        }
    }
}

/// A float in 16 bits: an `f32`'s sign, exponent and top 7 mantissa bits (bfloat16), rounded to
/// nearest. Its range is the `f32`'s, so radiance of any scene fits, within 2⁻⁸ of its value:
/// below what an 8-bit display shows after tone mapping. Two little-endian bytes on the wire
/// (postcard writes a `u16` as a varint, three bytes for most radiance values).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Half(pub [u8; 2]);

impl Half {
    pub fn encode(v: f32) -> Half {
        let bits = v.to_bits();
        let high = if v.is_nan() {
            (bits >> 16) as u16 | 0x40
        } else {
            // Round to nearest even; a value that rounds past the largest finite one becomes
            // infinite, as a refusal should see.
            let round = 0x7fff + ((bits >> 16) & 1);
            (bits.saturating_add(round) >> 16) as u16
        };
        Half(high.to_le_bytes())
    }

    pub fn decode(self) -> f32 {
        f32::from_bits(u32::from(u16::from_le_bytes(self.0)) << 16)
    }

    pub fn is_finite_non_negative(self) -> bool {
        let v = self.decode();
        v.is_finite() && v >= 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(width: u32, height: u32) -> Camera {
        Camera {
            seq: 4,
            eye: [0.0, 1.0, 2.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 50.0,
            width,
            height,
        }
    }

    #[test]
    fn the_cover_tiles_every_pixel_once() {
        let (w, h) = (100, 70);
        let mut seen = vec![0u8; (w * h) as usize];
        for t in TileRect::cover(w, h) {
            t.check(w, h).expect("a covering tile is valid");
            for y in t.y..t.y + t.height {
                for x in t.x..t.x + t.width {
                    seen[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
    }

    #[test]
    fn tiles_outside_the_image_or_of_a_bad_size_are_refused() {
        let ok = TileRect {
            x: 32,
            y: 0,
            width: 32,
            height: 16,
        };
        assert!(ok.check(64, 16).is_ok());
        for bad in [
            TileRect { x: 33, ..ok },
            TileRect { width: 0, ..ok },
            TileRect { height: 65, ..ok },
            TileRect { x: u32::MAX, ..ok },
        ] {
            assert!(bad.check(64, 16).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn answers_of_the_wrong_size_or_non_finite_values_are_refused() {
        let rect = TileRect {
            x: 0,
            y: 0,
            width: 2,
            height: 2,
        };
        let pixel = PartEstimate {
            rgb: [0.5, 1.0, 2.0],
            luminance_variance: 0.1,
        };
        let answer = TileAnswer {
            tile_id: 1,
            camera_seq: 4,
            rect,
            pass: 0,
            samples_per_pixel: 4,
            pixels: vec![pixel; 4],
            micros: 10,
        };
        assert!(answer.check(8, 8).is_ok());
        let short = TileAnswer {
            pixels: vec![pixel; 3],
            ..answer.clone()
        };
        assert!(short.check(8, 8).unwrap_err().contains("3 pixels"));
        for bad in [f32::NAN, f32::INFINITY, -1.0] {
            let mut a = answer.clone();
            a.pixels[2].rgb[1] = bad;
            assert!(a.check(8, 8).is_err(), "{bad}");
            let mut a = answer.clone();
            a.pixels[1].luminance_variance = bad;
            assert!(a.check(8, 8).is_err(), "{bad}");
        }
        assert!(answer.check(1, 8).is_err(), "outside a narrower image");
    }

    #[test]
    fn requests_are_checked_against_their_camera() {
        let request = TileRequest {
            tile_id: 1,
            camera: camera(64, 48),
            rect: TileRect {
                x: 32,
                y: 32,
                width: 32,
                height: 16,
            },
            samples_per_pixel: 4,
            pass: 0,
            lights: DirectLights::All,
        };
        assert!(request.check(64).is_ok());
        let mut r = request.clone();
        r.camera.height = 40;
        assert!(r.check(64).is_err());
        let mut r = request.clone();
        r.samples_per_pixel = 0;
        assert!(r.check(64).is_err());
        let mut r = request;
        r.camera.eye[0] = f32::NAN;
        assert!(r.check(64).is_err());
    }

    #[test]
    fn halves_round_trip_within_their_precision() {
        for v in [0.0f32, 1e-30, 0.1, 1.0, 3.7, 1.6e5, 3e38] {
            let back = Half::encode(v).decode();
            assert!((back - v).abs() <= v * 2f32.powi(-8), "{v} -> {back}");
            assert!(Half::encode(v).is_finite_non_negative());
        }
        for bad in [f32::NAN, f32::INFINITY, -1.0, f32::MAX] {
            assert!(!Half::encode(bad).is_finite_non_negative(), "{bad}");
        }
    }

    #[test]
    fn viewer_tiles_of_the_wrong_size_or_bad_values_are_refused() {
        let tile = ViewerTile {
            camera_seq: 4,
            rect: TileRect {
                x: 0,
                y: 0,
                width: 3,
                height: 1,
            },
            samples: 8,
            pixels: vec![TilePixel::new([0.2, 0.3, 0.4], 0.01); 3],
        };
        assert!(tile.check(3, 1).is_ok());
        let mut t = tile.clone();
        t.pixels.pop();
        assert!(t.check(3, 1).is_err());
        let mut t = tile.clone();
        t.pixels[0].standard_error = Half::encode(f32::NAN);
        assert!(t.check(3, 1).is_err());
        let mut t = tile;
        t.pixels[2].rgb[0] = Half::encode(-0.5);
        assert!(t.check(3, 1).is_err());
    }
}
