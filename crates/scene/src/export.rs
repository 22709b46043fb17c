//! Writing a scene as OBJ + MTL + scene file (DESIGN.md §11: built-ins are exportable), so other
//! renderers can check ours on the same scene, with each material's texture as a PNG beside them
//! (DESIGN.md §5) and the triangles' texture coordinates as `vt`. Loading the export gives the
//! same scene, with the same fingerprint; for a texture read from a JPEG, or a PNG written
//! otherwise, the rewritten file's bytes differ from the source's, and with them the
//! fingerprint, though not one texel.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::Vec2;

use crate::error::SceneError;
use crate::model::Scene;
use crate::settings::SceneSettings;
use crate::texture::Wrap;

/// Writes `<dir>/<name>.obj`, `.mtl` and `.toml`, and each texture as `<dir>/<file>.png`;
/// returns the scene file's path.
pub fn write_obj_mtl_toml(scene: &Scene, dir: &Path) -> Result<PathBuf, SceneError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| SceneError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let files = ["obj", "mtl", "toml"].map(|ext| format!("{}.{ext}", scene.name));
    let settings = SceneSettings {
        obj: files[0].clone(),
        ..scene.settings.clone()
    };
    let toml = toml::to_string(&settings).map_err(|e| SceneError::Settings(e.to_string()))?;
    let toml = format!(
        "# {} exported by `walkthrough scene export`\n{toml}",
        scene.name
    );
    let contents = [obj_text(scene, &files[1]), mtl_text(scene), toml];
    for (file, text) in files.iter().zip(contents) {
        let path = dir.join(file);
        std::fs::write(&path, text).map_err(io(&path))?;
    }
    for m in &scene.materials {
        if let Some(map) = &m.diffuse_map {
            let path = dir.join(png_name(&map.file));
            std::fs::write(&path, map.texture.png()).map_err(io(&path))?;
        }
    }
    Ok(dir.join(&files[2]))
}

/// Positions once each (split copies share a line: the loader splits them again), faces in
/// order, a `usemtl` wherever the material changes. Rust prints the shortest decimal that reads
/// back to the same f32, so positions survive exactly.
fn obj_text(scene: &Scene, mtl_file: &str) -> String {
    let mut out = format!(
        "# {} exported by walkthrough\nmtllib {mtl_file}\n",
        scene.name
    );
    let mut line_of: HashMap<[u32; 3], usize> = HashMap::new();
    let mut uv_line_of: HashMap<[u32; 2], usize> = HashMap::new();
    let mut texcoord_lines = String::new();
    let mut faces = String::new();
    let mut material = None;
    for (k, t) in scene.mesh.triangles.iter().enumerate() {
        if material != Some(t.material) {
            material = Some(t.material);
            let _ = writeln!(
                faces,
                "usemtl {}",
                scene.materials[t.material as usize].name
            );
        }
        let corners = t.vertices.map(|v| {
            let p = scene.mesh.positions[v as usize];
            let next = line_of.len() + 1;
            *line_of
                .entry(p.to_array().map(f32::to_bits))
                .or_insert_with(|| {
                    let _ = writeln!(out, "v {} {} {}", p.x, p.y, p.z);
                    next
                })
        });
        // Texture coordinates once each, like positions, where the scene has any.
        let uvs = scene.texcoords.get(k).map(|uvs| {
            uvs.map(|uv| {
                let next = uv_line_of.len() + 1;
                *uv_line_of
                    .entry(uv.to_array().map(f32::to_bits))
                    .or_insert_with(|| {
                        let _ = writeln!(texcoord_lines, "vt {} {}", uv.x, uv.y);
                        next
                    })
            })
        });
        let _ = match uvs {
            Some(uvs) => writeln!(
                faces,
                "f {}/{} {}/{} {}/{}",
                corners[0], uvs[0], corners[1], uvs[1], corners[2], uvs[2]
            ),
            None => writeln!(faces, "f {} {} {}", corners[0], corners[1], corners[2]),
        };
    }
    out + &texcoord_lines + &faces
}

/// The file a texture is exported as: its own name, beside the MTL, as PNG (the folders an MTL
/// named it in are left out, so nothing is written outside the export's folder).
fn png_name(file: &str) -> String {
    let stem = Path::new(file)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("texture");
    format!("{stem}.png")
}

fn mtl_text(scene: &Scene) -> String {
    let mut out = format!("# {} exported by walkthrough\n", scene.name);
    for m in &scene.materials {
        let _ = writeln!(out, "\nnewmtl {}", m.name);
        for (key, c) in [("Kd", m.kd), ("Ks", m.ks), ("Ke", m.ke)] {
            let _ = writeln!(out, "{key} {} {} {}", c.x, c.y, c.z);
        }
        let _ = writeln!(out, "Ns {}\nillum {}", m.ns, m.illum);
        if let Some(map) = &m.diffuse_map {
            let mut options = String::new();
            if map.scale != Vec2::ONE {
                let _ = write!(options, "-s {} {} 1 ", map.scale.x, map.scale.y);
            }
            if map.offset != Vec2::ZERO {
                let _ = write!(options, "-o {} {} 0 ", map.offset.x, map.offset.y);
            }
            if map.wrap == Wrap::Clamp {
                options.push_str("-clamp on ");
            }
            let _ = writeln!(out, "map_Kd {options}{}", png_name(&map.file));
        }
    }
    out
}
