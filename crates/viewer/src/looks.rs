//! The scene's materials and textures as the viewer holds them (DESIGN.md §5, "Parts, and
//! textures"): each material's look from `SceneInfo`, each texture as its `Texture` message
//! decoded it, and the table `draw.wgsl` reads per triangle: the factor the texel is multiplied
//! by and the layer of the texture array (`looks_texture`) that holds the texture. An untextured
//! material, or one whose texture did not decode, is its flat `kd` times layer 0, white: one
//! path through the shader.
//!
//! Texture bytes that do not decode, or a texture the scene does not list, give one warning and
//! the material's flat colour, never a panic.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use protocol::texture::{MAX_SENT_TEXTURE_SIDE, MaterialLook, TextureImage};
use protocol::viewer_link::SceneInfo;

mod layers;

pub use layers::{Layers, chain_bytes, layer_side, mip_levels};

/// A decoded texture: 8-bit sRGB RGB texels, rows from the top.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TextureTexels {
    pub width: u32,
    pub height: u32,
    pub srgb: Vec<[u8; 3]>,
}

/// What the viewer knows of the scene's surfaces. Shared (`Arc`) with the snapshots copied
/// while it holds: it changes only when a texture arrives.
#[derive(Clone, Debug, Default)]
pub struct Looks {
    materials: Vec<MaterialLook>,
    /// By `SceneInfo::texture_table`'s index: decoded, or `None` (not yet arrived, or refused).
    textures: Vec<Option<Arc<TextureTexels>>>,
    /// Changes with every change of the set, unique across sessions: the GPU copy rebuilds
    /// when it holds another.
    generation: u64,
}

/// Generations handed out so far.
static GENERATIONS: AtomicU64 = AtomicU64::new(0);

fn next_generation() -> u64 {
    GENERATIONS.fetch_add(1, Ordering::Relaxed) + 1
}

/// One material as `draw.wgsl` reads it: linear RGB factor, and the texture array layer (0:
/// white), negated where the texture clamps rather than repeats.
pub type MaterialTexel = [f32; 4];

impl Looks {
    /// The looks of a new session's scene, without its textures yet.
    pub fn of(scene: &SceneInfo) -> Looks {
        Looks {
            materials: scene.materials.clone(),
            textures: vec![None; scene.texture_table.len()],
            generation: next_generation(),
        }
    }

    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Takes texture `image`: decoded into its place, or refused with a warning (its
    /// materials keep their flat colour). Whether the set changed.
    pub fn accept(&mut self, image: &TextureImage) -> bool {
        if let Err(reason) = image.check(self.textures.len()) {
            tracing::warn!(%reason, "a texture the scene does not list: ignored");
            return false;
        }
        match decode(&image.png) {
            Ok(texels) => {
                self.textures[image.index as usize] = Some(Arc::new(texels));
                self.generation = next_generation();
                true
            }
            Err(reason) => {
                tracing::warn!(
                    texture = image.index,
                    %reason,
                    "a texture that does not decode: its materials show their flat colour"
                );
                false
            }
        }
    }

    /// The decoded textures that are drawn, in layer order (layer `i + 1` of the array), with
    /// each texture's layer; `None` for those not drawn.
    pub fn drawn(&self, max_layers: u32) -> (Vec<Arc<TextureTexels>>, Vec<Option<u32>>) {
        let mut drawn = Vec::new();
        let layer_of = self
            .textures
            .iter()
            .map(|t| {
                let t = t.as_ref()?;
                if drawn.len() as u32 + 1 >= max_layers {
                    return None;
                }
                drawn.push(Arc::clone(t));
                Some(drawn.len() as u32)
            })
            .collect();
        (drawn, layer_of)
    }

    /// One texel per material, in `materials`' order, for the table `draw.wgsl` reads, given
    /// where each texture lies (`layer_of`, from [`Self::drawn`]).
    pub fn material_texels(&self, layer_of: &[Option<u32>]) -> Vec<MaterialTexel> {
        self.materials
            .iter()
            .map(|m| {
                let texture = m.texture.as_ref();
                let layer = texture.and_then(|t| layer_of.get(t.index as usize).copied().flatten());
                let [r, g, b] = m.factor(layer.is_some());
                let clamp = texture.is_some_and(|t| t.clamp);
                let layer = layer.unwrap_or(0) as f32;
                [r, g, b, if clamp { -layer } else { layer }]
            })
            .collect()
    }
}

/// A texture's PNG (or any format `image` reads) as sRGB texels, within the sent size's bounds:
/// anything larger than the SMA sends is refused before it is decoded.
fn decode(bytes: &[u8]) -> Result<TextureTexels, String> {
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_SENT_TEXTURE_SIDE);
    limits.max_image_height = Some(MAX_SENT_TEXTURE_SIDE);
    limits.max_alloc = Some(64 << 20);
    reader.limits(limits);
    let rgb = reader.decode().map_err(|e| e.to_string())?.into_rgb8();
    let (width, height) = rgb.dimensions();
    if width == 0 || height == 0 {
        return Err("the image has no pixels".into());
    }
    Ok(TextureTexels {
        width,
        height,
        srgb: rgb.pixels().map(|p| p.0).collect(),
    })
}

#[cfg(test)]
mod tests {
    use protocol::texture::{MaterialTexture, TextureInfo};

    use super::*;

    /// A PNG of `width × height` texels of one colour.
    pub(super) fn png(width: u32, height: u32, rgb: [u8; 3]) -> Vec<u8> {
        let image = image::RgbImage::from_pixel(width, height, image::Rgb(rgb));
        let mut bytes = Vec::new();
        image
            .write_to(
                &mut std::io::Cursor::new(&mut bytes),
                image::ImageFormat::Png,
            )
            .expect("encodes");
        bytes
    }

    fn scene() -> SceneInfo {
        let textured = |index, times_kd, clamp| MaterialLook {
            kd: [0.5, 0.25, 1.0],
            texture: Some(MaterialTexture {
                index,
                times_kd,
                clamp,
            }),
        };
        let info = |name: &str| TextureInfo {
            name: name.into(),
            width: 2,
            height: 2,
            bytes: 0,
        };
        SceneInfo {
            name: "s".into(),
            fingerprint: [0; 32],
            bounds: protocol::types::Bounds {
                min: [0.0; 3],
                max: [1.0; 3],
            },
            viewpoints: vec![],
            criteria: vec![],
            sky: Default::default(),
            quality: protocol::renderer_link::Quality::INTERACTIVE,
            textures: true,
            materials: vec![
                MaterialLook {
                    kd: [0.7, 0.6, 0.5],
                    texture: None,
                },
                textured(0, true, false),
                textured(1, false, true),
            ],
            texture_table: vec![info("a.png"), info("b.png")],
        }
    }

    #[test]
    fn materials_show_their_texture_once_it_decodes_and_their_kd_until_then() {
        let mut looks = Looks::of(&scene());
        let flat = looks.material_texels(&looks.drawn(256).1);
        assert_eq!(
            flat,
            [
                [0.7, 0.6, 0.5, 0.0],
                [0.5, 0.25, 1.0, 0.0],
                [0.5, 0.25, 1.0, 0.0]
            ]
        );
        let before = looks.generation();
        assert!(looks.accept(&TextureImage {
            index: 1,
            png: png(2, 2, [10, 20, 30]),
        }));
        assert_ne!(looks.generation(), before);
        let (drawn, layer_of) = looks.drawn(256);
        assert_eq!((drawn.len(), layer_of), (1, vec![None, Some(1)]));
        assert_eq!(drawn[0].srgb, vec![[10, 20, 30]; 4]);
        // The texel alone (factor one), clamped: the layer negated.
        assert_eq!(
            looks.material_texels(&looks.drawn(256).1)[2],
            [1.0, 1.0, 1.0, -1.0]
        );
    }

    #[test]
    fn bytes_that_do_not_decode_or_a_texture_not_listed_change_nothing() {
        let mut looks = Looks::of(&scene());
        let before = looks.generation();
        for (index, bytes) in [(0, b"not a png".to_vec()), (7, png(1, 1, [1; 3]))] {
            assert!(!looks.accept(&TextureImage { index, png: bytes }));
        }
        assert!(!looks.accept(&TextureImage {
            index: 0,
            png: png(MAX_SENT_TEXTURE_SIDE + 1, 1, [1; 3]),
        }));
        assert_eq!(looks.generation(), before);
        assert!(looks.drawn(256).0.is_empty());
    }

    #[test]
    fn textures_beyond_the_adapters_layers_show_their_flat_colour() {
        let mut looks = Looks::of(&scene());
        for index in 0..2 {
            looks.accept(&TextureImage {
                index,
                png: png(1, 1, [200; 3]),
            });
        }
        // Two layers: white and one texture.
        let (drawn, layer_of) = looks.drawn(2);
        assert_eq!((drawn.len(), layer_of), (1, vec![Some(1), None]));
    }
}
