//! What a viewer learns of the scene's materials and textures (DESIGN.md §5, "Parts, and
//! textures"): each material's look for `SceneInfo`, and each texture, once, as a PNG of at most
//! `MAX_SENT_TEXTURE_SIDE` texels a side, sent to every viewer right after `SceneInfo`, so that
//! it holds them before the first `Insert` (a viewer that joins late too).

use std::sync::Arc;

use protocol::texture::{
    MAX_SENT_TEXTURE_SIDE, MaterialLook, MaterialTexture, TextureImage, TextureInfo,
};
use protocol::viewer_link::SmaToViewer;
use scene::{AlbedoRule, Scene, Texture, Wrap};

/// The scene's materials and textures as viewers are sent them.
#[derive(Clone, Debug, Default)]
pub struct SceneLooks {
    pub materials: Vec<MaterialLook>,
    pub texture_table: Vec<TextureInfo>,
    /// `SmaToViewer::Texture` of each entry of `texture_table`, in order: encoded once.
    pub images: Arc<[SmaToViewer]>,
}

impl SceneLooks {
    /// Each material's look, and each distinct texture (materials sharing a file share it)
    /// encoded as PNG, downscaled to the cap. Empty texture lists with textures off.
    pub fn of(scene: &Scene) -> SceneLooks {
        let mut textures: Vec<&Arc<Texture>> = Vec::new();
        let mut names = Vec::new();
        let materials = scene
            .materials
            .iter()
            .map(|m| MaterialLook {
                kd: m.kd.to_array(),
                texture: m.diffuse_map.as_ref().map(|map| {
                    let index = match textures.iter().position(|t| Arc::ptr_eq(t, &map.texture)) {
                        Some(i) => i,
                        None => {
                            textures.push(&map.texture);
                            names.push(map.file.clone());
                            textures.len() - 1
                        }
                    };
                    MaterialTexture {
                        index: index as u32,
                        times_kd: map.rule == AlbedoRule::KdTimesTexture,
                        clamp: map.wrap == Wrap::Clamp,
                    }
                }),
            })
            .collect();
        let (texture_table, images) = textures
            .iter()
            .zip(names)
            .enumerate()
            .map(|(index, (texture, name))| {
                let sent = Texture::clone(texture)
                    .capped(MAX_SENT_TEXTURE_SIDE)
                    .texture;
                let png = sent.png();
                let info = TextureInfo {
                    name,
                    width: sent.width(),
                    height: sent.height(),
                    bytes: png.len() as u64,
                };
                let image = SmaToViewer::Texture(TextureImage {
                    index: index as u32,
                    png,
                });
                (info, image)
            })
            .unzip::<_, _, Vec<_>, Vec<_>>();
        SceneLooks {
            materials,
            texture_table,
            images: images.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// bracara-textured's textured materials share their files' entries, each image decodes to
    /// the size the table states, and an untextured material says so.
    #[test]
    fn every_texture_is_listed_once_and_sent_as_the_table_says() {
        let scene = scene::load("bracara-textured").expect("built-in");
        let looks = SceneLooks::of(&scene);
        assert_eq!(looks.materials.len(), scene.materials.len());
        assert!(!looks.texture_table.is_empty());
        assert_eq!(looks.images.len(), looks.texture_table.len());
        for (m, look) in scene.materials.iter().zip(&looks.materials) {
            assert_eq!(look.kd, m.kd.to_array());
            assert_eq!(look.texture.is_some(), m.diffuse_map.is_some());
        }
        assert!(looks.materials.iter().any(|m| m.texture.is_none()));
        for (i, (info, image)) in looks
            .texture_table
            .iter()
            .zip(looks.images.iter())
            .enumerate()
        {
            let SmaToViewer::Texture(image) = image else {
                panic!("a texture message")
            };
            assert_eq!(image.index as usize, i);
            image
                .check(looks.texture_table.len())
                .expect("a valid texture");
            assert_eq!(info.bytes, image.png.len() as u64);
            let decoded = Texture::decode(&image.png, "t.png".as_ref()).expect("decodes");
            assert_eq!(
                (decoded.texture.width(), decoded.texture.height()),
                (info.width, info.height)
            );
        }
        let untextured = scene::load("bracara").expect("built-in");
        assert!(SceneLooks::of(&untextured).texture_table.is_empty());
    }
}
