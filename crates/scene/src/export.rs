//! Writing a scene as OBJ + MTL + scene file (DESIGN.md §11: built-ins are exportable), so other
//! renderers can check ours on the same scene. Loading the export gives the same scene, with the
//! same fingerprint.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::SceneError;
use crate::model::Scene;
use crate::settings::SceneSettings;

/// Writes `<dir>/<name>.obj`, `.mtl` and `.toml`; returns the scene file's path.
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
    let mut faces = String::new();
    let mut material = None;
    for t in &scene.mesh.triangles {
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
        let _ = writeln!(faces, "f {} {} {}", corners[0], corners[1], corners[2]);
    }
    out + &faces
}

fn mtl_text(scene: &Scene) -> String {
    let mut out = format!("# {} exported by walkthrough\n", scene.name);
    for m in &scene.materials {
        let _ = writeln!(out, "\nnewmtl {}", m.name);
        for (key, c) in [("Kd", m.kd), ("Ks", m.ks), ("Ke", m.ke)] {
            let _ = writeln!(out, "{key} {} {} {}", c.x, c.y, c.z);
        }
        let _ = writeln!(out, "Ns {}\nillum {}", m.ns, m.illum);
    }
    out
}
