//! What a viewer needs to multiply the diffuse albedo in per pixel (DESIGN.md §5, "Parts, and
//! textures"): each scene material's look ([`MaterialLook`]), the scene's textures
//! ([`TextureInfo`] in `SceneInfo`, their images as [`TextureImage`], sent once before the first
//! triangle that uses them), and a shown triangle's texture coordinates in 14 bytes
//! ([`Texcoords`]).

use serde::{Deserialize, Serialize};

use crate::types::Rgb;

/// The longest side of a texture as a viewer is sent it: larger ones are downscaled by the SMA.
/// A 1024² RGB PNG is at most about 3 MiB, far within the frame limit.
pub const MAX_SENT_TEXTURE_SIDE: u32 = 1024;

/// The most bytes a texture's image may take on the wire (a PNG of [`MAX_SENT_TEXTURE_SIDE`]
/// squared RGB texels, uncompressed, with room for its chunks).
pub const MAX_TEXTURE_BYTES: usize = 4 * (MAX_SENT_TEXTURE_SIDE as usize).pow(2) + 64 * 1024;

/// How one scene material's diffuse albedo is made: `kd`, times the texel of `texture` at the
/// pixel's coordinates where it has one (or the texel alone, under the texture albedo rule).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MaterialLook {
    /// The material's flat diffuse colour (linear RGB): its albedo without a texture, and what
    /// a viewer shows where the texture does not decode.
    pub kd: Rgb,
    pub texture: Option<MaterialTexture>,
}

impl MaterialLook {
    /// The factor the texel is multiplied by (`kd`, or one under the texture rule), or `kd`
    /// alone where there is no usable texture.
    pub fn factor(&self, texture_usable: bool) -> Rgb {
        match &self.texture {
            Some(t) if texture_usable && !t.times_kd => [1.0; 3],
            _ => self.kd,
        }
    }
}

/// A material's texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct MaterialTexture {
    /// Index into `SceneInfo::texture_table`.
    pub index: u32,
    /// `kd × texel` (MTL's usual rule); false: the texel alone.
    pub times_kd: bool,
    /// Coordinates outside 0..1 hold the edge (MTL `-clamp on`); false: the image repeats.
    pub clamp: bool,
}

/// One texture as `SceneInfo` lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TextureInfo {
    /// The file as the scene's MTL names it (for the log).
    pub name: String,
    pub width: u32,
    pub height: u32,
    /// Bytes of its image as [`TextureImage`] carries it.
    pub bytes: u64,
}

/// SMA -> viewer: the image of texture `index` (`SceneInfo::texture_table`), a PNG of 8-bit
/// sRGB texels, sent once per viewer before the first `Insert` whose material uses it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TextureImage {
    pub index: u32,
    pub png: Vec<u8>,
}

impl TextureImage {
    /// A texture of the scene's table (of `textures` entries), of some bytes, at most
    /// [`MAX_TEXTURE_BYTES`]. Whether the bytes decode is the viewer's to find out.
    pub fn check(&self, textures: usize) -> Result<(), String> {
        if self.index as usize >= textures {
            return Err(format!(
                "texture {} of a scene of {textures} textures",
                self.index
            ));
        }
        if self.png.is_empty() || self.png.len() > MAX_TEXTURE_BYTES {
            return Err(format!(
                "texture {} of {} bytes (1..={MAX_TEXTURE_BYTES})",
                self.index,
                self.png.len()
            ));
        }
        Ok(())
    }
}

/// A triangle's three corners' texture coordinates, quantised: each coordinate less an integer
/// origin (per axis, the floor of the smallest corner's: under repeat the image looks the same
/// shifted by whole periods) in 16-bit fixed point over `0..2^range` (`range` the smallest
/// power that holds the triangle's span). A subdivided leaf spans little, so its steps are
/// 2^-16 of the image; a base triangle repeating a texture twenty times has steps of 2^-11, half
/// a texel of a 1024² image. Corners shared by two triangles of one range land on the same grid,
/// so no seam opens between them. On the wire a byte string of 13 bytes, 14 with its length
/// (postcard writes a `u16` as a varint, three bytes for most values, and an array element by
/// element, which decodes several times slower than one copy).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Texcoords(pub [u8; 13]);

impl Serialize for Texcoords {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(&self.0)
    }
}

impl<'de> Deserialize<'de> for Texcoords {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Bytes;
        impl serde::de::Visitor<'_> for Bytes {
            type Value = Texcoords;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("13 bytes of texture coordinates")
            }

            fn visit_bytes<E: serde::de::Error>(self, bytes: &[u8]) -> Result<Texcoords, E> {
                bytes
                    .try_into()
                    .map(Texcoords)
                    .map_err(|_| E::invalid_length(bytes.len(), &self))
            }
        }
        deserializer.deserialize_bytes(Bytes)
    }
}

/// The widest span a triangle's coordinates may have: 2^15 periods of its texture.
const MAX_RANGE: u8 = 15;

impl Texcoords {
    /// Quantises `uv` (already scaled and offset by the material's map options). Under
    /// `clamp` the coordinates are first held to 0..1 per corner, where they lie for a clamped
    /// map in practice; under repeat a non-finite coordinate reads as 0.
    pub fn encode(uv: [[f32; 2]; 3], clamp: bool) -> Texcoords {
        let uv = uv.map(|c| {
            c.map(|x| {
                let x = if x.is_finite() { x } else { 0.0 };
                if clamp { x.clamp(0.0, 1.0) } else { x }
            })
        });
        let mut bytes = [0u8; 13];
        let origin: [f32; 2] = if clamp {
            [0.0; 2]
        } else {
            std::array::from_fn(|a| {
                uv.iter()
                    .map(|c| c[a])
                    .fold(f32::INFINITY, f32::min)
                    .floor()
            })
        };
        let span = uv
            .iter()
            .flat_map(|c| [c[0] - origin[0], c[1] - origin[1]])
            .fold(0.0f32, f32::max);
        let range = (0..MAX_RANGE)
            .find(|&r| span < f32::from(1u16 << r))
            .unwrap_or(MAX_RANGE);
        bytes[0] = range;
        let steps = 65_536.0 / f32::from(1u16 << range);
        for (k, corner) in uv.iter().enumerate() {
            for a in 0..2 {
                let q = ((corner[a] - origin[a]) * steps)
                    .round()
                    .clamp(0.0, f32::from(u16::MAX)) as u16;
                bytes[1 + 4 * k + 2 * a..3 + 4 * k + 2 * a].copy_from_slice(&q.to_le_bytes());
            }
        }
        Texcoords(bytes)
    }

    /// The coordinates as the viewer samples with them: whole periods off the original under
    /// repeat, the same under clamp. A range beyond the largest reads as the largest.
    pub fn decode(&self) -> [[f32; 2]; 3] {
        let range = self.0[0].min(MAX_RANGE);
        let step = f32::from(1u16 << range) / 65_536.0;
        std::array::from_fn(|k| {
            std::array::from_fn(|a| {
                let i = 1 + 4 * k + 2 * a;
                f32::from(u16::from_le_bytes([self.0[i], self.0[i + 1]])) * step
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn worst_error(uv: [[f32; 2]; 3], clamp: bool) -> f32 {
        let back = Texcoords::encode(uv, clamp).decode();
        let shift: [f32; 2] = std::array::from_fn(|a| (uv[0][a] - back[0][a]).round());
        let mut worst = 0.0f32;
        for k in 0..3 {
            for a in 0..2 {
                worst = worst.max((uv[k][a] - shift[a] - back[k][a]).abs());
            }
        }
        worst
    }

    #[test]
    fn a_small_triangle_keeps_its_coordinates_to_a_fraction_of_a_texel() {
        let uv = [[3.25, -7.5], [3.3, -7.45], [3.27, -7.41]];
        // Whole periods off, and within 2^-17 (range 0: steps of 2^-16).
        assert!(worst_error(uv, false) <= 1.0 / 131_072.0 + 1e-6);
        let back = Texcoords::encode(uv, false).decode();
        assert_eq!(back[0][0].floor(), 0.0);
    }

    #[test]
    fn a_wide_triangle_keeps_half_a_step_of_its_range() {
        // Twenty periods: range 5, steps of 2^-11.
        let uv = [[0.1, 0.2], [20.1, 0.2], [0.1, 20.2]];
        assert_eq!(Texcoords::encode(uv, false).0[0], 5);
        assert!(worst_error(uv, false) <= 1.0 / 4096.0 + 1e-5);
    }

    #[test]
    fn corners_shared_by_two_triangles_of_one_range_decode_alike() {
        let shared = [[0.3, 0.6], [0.35, 0.61]];
        let a = Texcoords::encode([shared[0], shared[1], [0.31, 0.7]], false).decode();
        let b = Texcoords::encode([shared[1], shared[0], [0.4, 0.55]], false).decode();
        assert_eq!((a[0], a[1]), (b[1], b[0]));
    }

    #[test]
    fn clamped_coordinates_are_held_to_the_image_and_bad_ones_read_as_zero() {
        let back = Texcoords::encode([[-0.5, 0.5], [1.5, 1.0], [f32::NAN, 0.0]], true).decode();
        assert_eq!(back, [[0.0, 0.5], [1.0, 1.0], [0.0, 0.0]]);
        let huge = Texcoords::encode([[0.0; 2], [1e9, 0.0], [0.0, f32::INFINITY]], false);
        assert_eq!(huge.0[0], MAX_RANGE);
        assert!(huge.decode().iter().flatten().all(|x| x.is_finite()));
    }

    #[test]
    fn a_texture_outside_the_table_or_of_no_bytes_is_refused() {
        let image = |index, len| TextureImage {
            index,
            png: vec![0; len],
        };
        assert!(image(1, 10).check(2).is_ok());
        assert!(image(2, 10).check(2).is_err());
        assert!(image(0, 0).check(2).is_err());
        assert!(image(0, MAX_TEXTURE_BYTES + 1).check(2).is_err());
    }
}
