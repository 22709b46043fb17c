//! The scene fingerprint checked in the renderer handshake (DESIGN.md §8): BLAKE3 over the
//! settings, the finished geometry and the materials. Everything the renderer and the SMA must
//! agree on goes in (vertex numbering and normals included, since samples are keyed by vertex
//! and side); where the files sit does not (the OBJ path is left out), so a scene exported and
//! reloaded keeps its fingerprint.
//!
//! With textures on (DESIGN.md §5), the texture settings, each material's map (its file's bytes,
//! options and decoded size) and every triangle's texture coordinates go in as well: a renderer
//! with other textures is refused, and a ground truth cached by fingerprint is never taken for
//! a scene with other textures, or for the untextured one. With textures off they change nothing
//! a process computes, so they stay out, and an untextured scene keeps the fingerprint it had
//! before textures existed (with the ground truths cached under it).

use glam::Vec2;

use crate::model::{Material, Mesh, Scattering};
use crate::settings::{QualitySetting, SceneSettings, Sky, Sun, ViewpointSetting};
use crate::texture::{DiffuseMap, Wrap};

const DOMAIN: &[u8] = b"walkthrough scene fingerprint v1";

pub fn fingerprint(
    settings: &SceneSettings,
    mesh: &Mesh,
    materials: &[Material],
    texcoords: &[[Vec2; 3]],
) -> [u8; 32] {
    let mut h = blake3::Hasher::new();
    h.update(DOMAIN);
    text(&mut h, &settings_text(settings));
    count(&mut h, mesh.positions.len());
    for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
        floats(&mut h, &p.to_array());
        floats(&mut h, &n.to_array());
    }
    count(&mut h, mesh.triangles.len());
    for t in &mesh.triangles {
        for i in t.vertices.iter().chain([&t.material]) {
            h.update(&i.to_le_bytes());
        }
    }
    count(&mut h, materials.len());
    for m in materials {
        text(&mut h, &m.name);
        for v in [m.kd, m.ke, m.ks] {
            floats(&mut h, &v.to_array());
        }
        floats(&mut h, &[m.ns]);
        h.update(&m.illum.to_le_bytes());
        h.update(&[match m.scattering {
            Scattering::Diffuse => 0,
            Scattering::Glossy => 1,
            Scattering::Mirror => 2,
        }]);
    }
    if settings.textures.enabled {
        textures(&mut h, settings, materials, texcoords);
    }
    *h.finalize().as_bytes()
}

/// The textures' part: their settings, each material's map (or its absence: a texture that
/// failed to load leaves its material on `Kd`), and the texture coordinates.
fn textures(
    h: &mut blake3::Hasher,
    settings: &SceneSettings,
    materials: &[Material],
    texcoords: &[[Vec2; 3]],
) {
    text(h, &format!("textures {:?}", settings.textures));
    for m in materials {
        let Some(map) = &m.diffuse_map else {
            h.update(&[0]);
            continue;
        };
        let DiffuseMap {
            texture,
            scale,
            offset,
            wrap,
            rule,
            file: _,
            source,
        } = map;
        h.update(&[1]);
        h.update(source);
        h.update(&texture.width().to_le_bytes());
        h.update(&texture.height().to_le_bytes());
        floats(h, &[scale.x, scale.y, offset.x, offset.y]);
        h.update(&[u8::from(*wrap == Wrap::Clamp)]);
        text(h, &format!("{rule:?}"));
    }
    count(h, texcoords.len());
    for corners in texcoords {
        for uv in corners {
            floats(h, &uv.to_array());
        }
    }
}

/// The settings as text, without the OBJ's path and the texture settings: the derived `Debug`
/// of a struct of `SceneSettings`' name and its other fields, which is exactly the text hashed
/// before textures existed. Destructured in full, so a field added to `SceneSettings` does not
/// compile here until it is decided how it enters the fingerprint.
fn settings_text(settings: &SceneSettings) -> String {
    #[derive(Debug)]
    #[allow(dead_code)] // read through `Debug`
    struct SceneSettings<'a> {
        name: &'a String,
        obj: &'a str,
        units: &'a String,
        crease_angle_deg: &'a f32,
        sun: &'a Option<Sun>,
        sky: &'a Sky,
        quality: &'a QualitySetting,
        viewpoints: &'a Vec<ViewpointSetting>,
    }
    let crate::settings::SceneSettings {
        name,
        obj: _,
        units,
        crease_angle_deg,
        sun,
        sky,
        quality,
        viewpoints,
        textures: _,
    } = settings;
    format!(
        "{:?}",
        SceneSettings {
            name,
            obj: "",
            units,
            crease_angle_deg,
            sun,
            sky,
            quality,
            viewpoints,
        }
    )
}

/// Lower-case hex, as `scene info` prints it.
pub fn hex(fingerprint: &[u8; 32]) -> String {
    fingerprint.iter().map(|b| format!("{b:02x}")).collect()
}

fn count(h: &mut blake3::Hasher, n: usize) {
    h.update(&(n as u64).to_le_bytes());
}

fn text(h: &mut blake3::Hasher, s: &str) {
    count(h, s.len());
    h.update(s.as_bytes());
}

fn floats(h: &mut blake3::Hasher, values: &[f32]) {
    for v in values {
        h.update(&v.to_le_bytes());
    }
}
