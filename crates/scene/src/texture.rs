//! Diffuse textures (DESIGN.md §5): decoding (PNG and JPEG through `image`, within its limits),
//! the size cap, sRGB texels read as linear values, and bilinear lookup with wrap or clamp.
//!
//! Texels stay as the file's 8-bit sRGB codes (3 bytes each, a quarter of linear floats) and are
//! converted through a 256-entry table when read. Filtering blends the *linear* values: blending
//! the codes would darken every edge between a light and a dark texel.

use std::fmt;
use std::io::Cursor;
use std::path::Path;
use std::sync::{Arc, LazyLock};

use glam::{Vec2, Vec3};

use crate::settings::AlbedoRule;

/// The longest side a texture keeps. A larger one is downscaled on load, with a note in the log:
/// 4096 × 4096 texels are 48 MiB, and the renderer and the SMA each hold every texture.
pub const MAX_TEXTURE_SIDE: u32 = 4096;
/// Decoding limits (`image::Limits`): a small file announcing a huge image (a decompression
/// bomb) fails to decode, and falls back to `Kd` like any other unreadable texture, instead of
/// taking the machine's memory.
const MAX_DECODED_SIDE: u32 = 16_384;
const MAX_DECODE_ALLOC: u64 = 512 << 20;

/// An RGB texture, rows from the top of the image, texels as 8-bit sRGB.
#[derive(Clone, PartialEq, Eq)]
pub struct Texture {
    width: u32,
    height: u32,
    /// `3 × (width × y + x)` is texel (x, y)'s red.
    srgb: Vec<u8>,
}

/// A decoded texture, and the size of the file's image when it was larger than the cap.
#[derive(Debug)]
pub struct Decoded {
    pub texture: Texture,
    pub downscaled_from: Option<(u32, u32)>,
}

/// Texture addressing outside 0..1: MTL's default repeats the image; `-clamp on` holds the edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wrap {
    Repeat,
    Clamp,
}

impl fmt::Debug for Texture {
    /// The size only: the texels are megabytes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Texture({}×{})", self.width, self.height)
    }
}

/// Linear value of each 8-bit sRGB code.
static LINEAR: LazyLock<[f32; 256]> = LazyLock::new(|| {
    std::array::from_fn(|code| conventions::tone_map::srgb_decode(code as f32 / 255.0))
});

impl Texture {
    /// A texture of `width × height` texels given as 8-bit sRGB, row by row from the top.
    pub fn from_srgb8(width: u32, height: u32, texels: &[[u8; 3]]) -> Texture {
        assert!(width > 0 && height > 0, "a texture has texels");
        assert_eq!(texels.len(), width as usize * height as usize);
        Texture {
            width,
            height,
            srgb: texels.concat(),
        }
    }

    /// Decodes an image file's bytes (format by content, else by `name`'s extension) into RGB,
    /// dropping alpha (cut-outs are not simulated), and downscales it to [`MAX_TEXTURE_SIDE`].
    pub fn decode(bytes: &[u8], name: &Path) -> Result<Decoded, String> {
        let mut reader = image::ImageReader::new(Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| e.to_string())?;
        if reader.format().is_none()
            && let Ok(format) = image::ImageFormat::from_path(name)
        {
            reader.set_format(format);
        }
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_DECODED_SIDE);
        limits.max_image_height = Some(MAX_DECODED_SIDE);
        limits.max_alloc = Some(MAX_DECODE_ALLOC);
        reader.limits(limits);
        let rgb = reader.decode().map_err(|e| e.to_string())?.into_rgb8();
        let (width, height) = rgb.dimensions();
        if width == 0 || height == 0 {
            return Err("the image has no pixels".into());
        }
        let full = Texture {
            width,
            height,
            srgb: rgb.into_raw(),
        };
        Ok(full.capped(MAX_TEXTURE_SIDE))
    }

    /// This texture, box-filtered (in linear values) down to at most `cap` texels a side,
    /// keeping its aspect ratio (the SMA sends viewers textures so capped).
    pub fn capped(self, cap: u32) -> Decoded {
        let longest = self.width.max(self.height);
        if longest <= cap {
            return Decoded {
                texture: self,
                downscaled_from: None,
            };
        }
        let scaled = |side: u32| {
            ((u64::from(side) * u64::from(cap) + u64::from(longest) / 2) / u64::from(longest))
                .max(1) as u32
        };
        let (w, h) = (scaled(self.width), scaled(self.height));
        // Source rows (columns) `span(i, …)` fall on target row (column) i: the spans partition
        // the source, so each texel is read once.
        let span = |i: u32, target: u32, source: u32| {
            let at = |k: u32| (u64::from(k) * u64::from(source) / u64::from(target)) as u32;
            at(i)..at(i + 1).max(at(i) + 1)
        };
        let mut srgb = Vec::with_capacity(3 * w as usize * h as usize);
        for ty in 0..h {
            for tx in 0..w {
                let mut sum = Vec3::ZERO;
                let mut count = 0u32;
                for y in span(ty, h, self.height) {
                    for x in span(tx, w, self.width) {
                        sum += self.texel(x, y);
                        count += 1;
                    }
                }
                let mean = sum / count as f32;
                srgb.extend(mean.to_array().map(conventions::tone_map::srgb8));
            }
        }
        Decoded {
            texture: Texture {
                width: w,
                height: h,
                srgb,
            },
            downscaled_from: Some((self.width, self.height)),
        }
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Texel (x, y) as linear RGB; (0, 0) is the image's top-left.
    #[inline]
    pub fn texel(&self, x: u32, y: u32) -> Vec3 {
        self.texel_in(&LINEAR, x, y)
    }

    /// [`Self::texel`] with the sRGB-to-linear table already at hand (one look at the lazy
    /// table per lookup, not per texel).
    #[inline]
    fn texel_in(&self, lin: &[f32; 256], x: u32, y: u32) -> Vec3 {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        Vec3::new(
            lin[self.srgb[i] as usize],
            lin[self.srgb[i + 1] as usize],
            lin[self.srgb[i + 2] as usize],
        )
    }

    /// Bilinear lookup at texture coordinates `uv` (OBJ's: v grows up the image, so v = 1 is
    /// the top row), texel centres at half-integers. A non-finite coordinate reads as 0.
    pub fn lookup(&self, uv: Vec2, wrap: Wrap) -> Vec3 {
        let lin = &*LINEAR;
        let (x0, x1, fx) = axis(uv.x, self.width, wrap);
        let (y0, y1, fy) = axis(1.0 - uv.y, self.height, wrap);
        let top = self
            .texel_in(lin, x0, y0)
            .lerp(self.texel_in(lin, x1, y0), fx);
        let bottom = self
            .texel_in(lin, x0, y1)
            .lerp(self.texel_in(lin, x1, y1), fx);
        top.lerp(bottom, fy)
    }

    /// The texel under texture coordinates `uv`, unfiltered: what a mip level is read with
    /// past a diffuse bounce, where the level's texels are as wide as the path's cone and
    /// blending neighbours would resolve nothing more (`renderer::texture_lod`).
    pub fn nearest(&self, uv: Vec2, wrap: Wrap) -> Vec3 {
        let x = axis_nearest(uv.x, self.width, wrap);
        let y = axis_nearest(1.0 - uv.y, self.height, wrap);
        self.texel(x, y)
    }

    /// The texture's mip chain below itself: each level half the previous one's size (at
    /// least one texel a side), box-filtered in linear values, down to a single texel. What the
    /// renderer reads past a diffuse bounce, where one path stands for a cone of directions
    /// wider than a texel (`renderer::texture_lod`; README, "Textures").
    pub fn mip_levels(&self) -> Vec<Texture> {
        let mut levels: Vec<Texture> = Vec::new();
        loop {
            let above = levels.last().unwrap_or(self);
            let longest = above.width.max(above.height);
            if longest == 1 {
                return levels;
            }
            levels.push(above.clone().capped(longest / 2).texture);
        }
    }

    /// The texture as a PNG file (8-bit RGB, the texels' own codes): what `scene export` writes,
    /// and, for a texture generated in code, the bytes its fingerprint hashes, so that the
    /// exported file reloads to the same scene. The encoding is deterministic.
    pub fn png(&self) -> Vec<u8> {
        use image::ImageEncoder as _;
        let mut bytes = Vec::new();
        image::codecs::png::PngEncoder::new(&mut bytes)
            .write_image(
                &self.srgb,
                self.width,
                self.height,
                image::ExtendedColorType::Rgb8,
            )
            .expect("a PNG of RGB texels encodes into memory");
        bytes
    }

    /// The mean linear colour over every texel (for comparing with a material's `Kd`).
    pub fn mean(&self) -> Vec3 {
        let mut sum = [0f64; 3];
        for texel in self.srgb.chunks_exact(3) {
            for (s, &code) in sum.iter_mut().zip(texel) {
                *s += f64::from(LINEAR[code as usize]);
            }
        }
        let n = (self.width as f64) * (self.height as f64);
        Vec3::from(sum.map(|s| (s / n) as f32))
    }
}

/// A coordinate folded into 0..1 (repeating) or clamped there; a non-finite one reads as 0.
#[inline]
fn fold(t: f32, wrap: Wrap) -> f32 {
    let t = if t.is_finite() { t } else { 0.0 };
    match wrap {
        // Exact: t and its floor are within a factor of two of each other, or the floor is 0
        // (a far coordinate, u = 1e6, keeps whatever fraction f32 gave it). `rem_euclid` would
        // call libm's fmodf at every lookup.
        Wrap::Repeat => t - t.floor(),
        Wrap::Clamp => t.clamp(0.0, 1.0),
    }
}

/// The two texels a coordinate falls between along an axis of `size` texels, and the weight of
/// the second.
#[inline]
fn axis(t: f32, size: u32, wrap: Wrap) -> (u32, u32, f32) {
    let x = fold(t, wrap) * size as f32 - 0.5;
    let base = x.floor();
    // `x` lies in -0.5..=size - 0.5: `base` in -1..=size - 1.
    let below = base < 0.0;
    let i0 = if below {
        size - 1
    } else {
        (base as u32).min(size - 1)
    };
    let f = (x - base).clamp(0.0, 1.0);
    match wrap {
        Wrap::Repeat => (i0, if i0 + 1 == size { 0 } else { i0 + 1 }, f),
        // Clamped, the edge texel's outer half reads the edge alone.
        Wrap::Clamp if below => (0, 0, 0.0),
        Wrap::Clamp => (i0, (i0 + 1).min(size - 1), f),
    }
}

/// The texel a coordinate falls in along an axis of `size` texels.
#[inline]
fn axis_nearest(t: f32, size: u32, wrap: Wrap) -> u32 {
    ((fold(t, wrap) * size as f32) as u32).min(size - 1)
}

/// A material's `map_Kd` as the renderer reads it (DESIGN.md §5).
#[derive(Clone, Debug, PartialEq)]
pub struct DiffuseMap {
    pub texture: Arc<Texture>,
    /// MTL `-s` and `-o` (u and v; w is for 3D textures): coordinates become `uv × scale +
    /// offset` before the lookup.
    pub scale: Vec2,
    pub offset: Vec2,
    pub wrap: Wrap,
    pub rule: AlbedoRule,
    /// The file as the MTL names it, and BLAKE3 of its bytes (the fingerprint's part).
    pub file: String,
    pub source: [u8; 32],
}

impl DiffuseMap {
    /// A map of a texture generated in code (the built-in scenes), repeated, without options,
    /// under `rule`: its file is `file`, a PNG of the texels (`Texture::png`), as `scene
    /// export` writes it.
    pub fn generated(texture: Texture, file: String, rule: AlbedoRule) -> DiffuseMap {
        DiffuseMap {
            source: *blake3::hash(&texture.png()).as_bytes(),
            texture: Arc::new(texture),
            scale: Vec2::ONE,
            offset: Vec2::ZERO,
            wrap: Wrap::Repeat,
            rule,
            file,
        }
    }

    /// The albedo at texture coordinates `uv` of a material of diffuse colour `kd`.
    #[inline]
    pub fn albedo(&self, kd: Vec3, uv: Vec2) -> Vec3 {
        self.by_rule(kd, self.texture.lookup(self.placed(uv), self.wrap))
    }

    /// [`Self::albedo`] read from `level`, one of this map's texture's mip levels
    /// ([`Texture::mip_levels`]), at its nearest texel ([`Texture::nearest`]).
    #[inline]
    pub fn albedo_at_level(&self, level: &Texture, kd: Vec3, uv: Vec2) -> Vec3 {
        self.by_rule(kd, level.nearest(self.placed(uv), self.wrap))
    }

    /// Texture coordinates `uv` as the map's `-s` and `-o` place them.
    #[inline]
    fn placed(&self, uv: Vec2) -> Vec2 {
        uv * self.scale + self.offset
    }

    #[inline]
    fn by_rule(&self, kd: Vec3, texel: Vec3) -> Vec3 {
        match self.rule {
            AlbedoRule::KdTimesTexture => kd * texel,
            AlbedoRule::Texture => texel,
        }
    }
}

#[cfg(test)]
mod tests;
