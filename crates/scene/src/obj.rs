//! OBJ/MTL loading with tobj (DESIGN.md §7): positions, faces and their texture coordinates,
//! materials from `Kd`, `Ke`, `Ks`, `Ns` and `illum`, and with the scene's textures on, `map_Kd`
//! (DESIGN.md §5). File normals are ignored (DESIGN.md §5 defines the canonical normal from the
//! faces); so are the other maps (`map_d` cut-outs, bump maps).

use std::cell::Cell;
use std::collections::HashMap;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::builder::SceneBuilder;
use crate::error::SceneError;
use crate::map_kd::MapLoader;
use crate::model::{Material, Scene};
use crate::obj_check::{check_mtl, check_obj};
use crate::scene_file::{SceneFiles, read_text};
use crate::settings::SceneSettings;

/// What a face with no (or an unknown) material gets, and every face when the MTL is missing.
fn default_material() -> Material {
    Material::diffuse("default", Vec3::splat(0.7))
}

pub fn load_obj(
    files: &dyn SceneFiles,
    path: &Path,
    settings: SceneSettings,
) -> Result<Scene, SceneError> {
    let text = read_text(files, path)?;
    let summary = check_obj(path, &text)?;
    let textures = settings.textures.clone();
    let mut builder = SceneBuilder::new(settings);
    let (libraries, folders) =
        read_material_libraries(files, path, &summary.material_libraries, &mut builder)?;
    let options = tobj::LoadOptions {
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    // The line check above rejects every input known to make tobj 4.0.5 panic; should another
    // slip through, it is still an error value, never a crash of the server loading it.
    // tobj takes an `Fn` loader: an MTL error tobj finds goes out through a cell.
    let mtl_error = Cell::new(None);
    let parsed = catch_unwind(AssertUnwindSafe(|| {
        tobj::load_obj_buf(&mut text.as_bytes(), &options, |library| {
            match libraries.get(library) {
                Some(mtl) => tobj::load_mtl_buf(&mut mtl.as_bytes())
                    .inspect_err(|e| mtl_error.set(Some((library.to_path_buf(), *e)))),
                None => Err(tobj::LoadError::OpenFileFailed),
            }
        })
    }));
    let tobj_error = |file: PathBuf, message: String| SceneError::Obj { file, message };
    let (models, materials) = parsed
        .map_err(|_| {
            tobj_error(
                path.to_path_buf(),
                "the OBJ parser failed on this file".into(),
            )
        })?
        .map_err(|e| tobj_error(path.to_path_buf(), e.to_string()))?;
    if let Some((library, e)) = mtl_error.take() {
        let dir = path.parent().unwrap_or(Path::new(""));
        return Err(tobj_error(dir.join(library), e.to_string()));
    }
    // Libraries that failed to open were reported as missing and their faces get the default.
    let materials = materials.unwrap_or_default();
    let mut converted: Vec<Material> = materials.iter().map(convert_material).collect();
    // Only the textures of materials some face uses are read (and warned about).
    let used: Vec<bool> = (0..materials.len())
        .map(|i| models.iter().any(|m| m.mesh.material_id == Some(i)))
        .collect();
    let textured: Vec<usize> = (0..materials.len())
        .filter(|&i| used[i] && materials[i].diffuse_texture.is_some())
        .collect();
    if textures.enabled {
        let mut loader = MapLoader::new(files, textures.albedo);
        let obj_dir = path.parent().unwrap_or(Path::new(""));
        for i in textured {
            let m = &materials[i];
            let argument = m.diffuse_texture.as_deref().unwrap_or_default();
            let dir = folders.get(&m.name).map_or(obj_dir, PathBuf::as_path);
            converted[i].diffuse_map = loader.load(&m.name, argument, dir, &mut builder);
        }
    } else if !textured.is_empty() {
        builder.note(format!(
            "{} of the materials in use have a map_Kd texture, not read: the scene's textures \
             are off ([textures] enabled = false)",
            textured.len()
        ));
    }
    add_geometry(&mut builder, &models, converted);
    builder.build()
}

/// The text of each library by its `mtllib` name, and the folder of the library that first
/// defines each material (its `map_Kd` files are relative to it).
type Libraries = (HashMap<PathBuf, String>, HashMap<String, PathBuf>);

/// Reads and checks each `mtllib` (relative to the OBJ); a missing one is a warning, not an
/// error: its faces get the default material.
fn read_material_libraries(
    files: &dyn SceneFiles,
    obj: &Path,
    names: &[String],
    builder: &mut SceneBuilder,
) -> Result<Libraries, SceneError> {
    let dir = obj.parent().unwrap_or(Path::new(""));
    let mut libraries = HashMap::new();
    let mut folders = HashMap::new();
    for name in names {
        let path = dir.join(name);
        match read_text(files, &path) {
            Ok(text) => {
                let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
                for material in check_mtl(&path, &text)? {
                    folders.entry(material).or_insert_with(|| folder.clone());
                }
                libraries.insert(PathBuf::from(name), text);
            }
            Err(e) => builder.warn(format!("{e}; its materials are replaced by a default one")),
        }
    }
    Ok((libraries, folders))
}

fn add_geometry(builder: &mut SceneBuilder, models: &[tobj::Model], materials: Vec<Material>) {
    let ids: Vec<u32> = materials.into_iter().map(|m| builder.material(m)).collect();
    let mut fallback = None;
    let mut faces_without_material = 0;
    for model in models {
        let mesh = &model.mesh;
        let material = match mesh.material_id.and_then(|i| ids.get(i)) {
            Some(&id) => id,
            None => {
                faces_without_material += mesh.indices.len() / 3;
                *fallback.get_or_insert_with(|| builder.material(default_material()))
            }
        };
        // tobj numbers each model's positions from 0; they follow the builder's earlier ones.
        let mut first = None;
        for p in mesh.positions.chunks_exact(3) {
            let id = builder.vertex(Vec3::new(p[0], p[1], p[2]));
            first.get_or_insert(id);
        }
        let Some(first) = first else { continue };
        // Texture coordinates come with their own indices, one per corner (`single_index` off),
        // so corners that share a position but not a `vt` need no vertex of their own.
        let uv = |k: usize| {
            let i = 2 * mesh.texcoord_indices[k] as usize;
            match mesh.texcoords.get(i..i + 2) {
                Some(&[u, v]) => Vec2::new(u, v),
                _ => Vec2::ZERO,
            }
        };
        let has_texcoords = mesh.texcoord_indices.len() == mesh.indices.len();
        for (k, t) in mesh.indices.chunks_exact(3).enumerate() {
            let vertices = [t[0] + first, t[1] + first, t[2] + first];
            if has_texcoords {
                let uvs = [uv(3 * k), uv(3 * k + 1), uv(3 * k + 2)];
                builder.textured_triangle(vertices, material, uvs);
            } else {
                builder.triangle(vertices, material);
            }
        }
    }
    if faces_without_material > 0 {
        builder.warn(format!(
            "{faces_without_material} faces have no known material; default material used"
        ));
    }
}

fn convert_material(m: &tobj::Material) -> Material {
    let rgb = |c: Option<[f32; 3]>| c.map_or(Vec3::ZERO, Vec3::from);
    Material::from_mtl(
        m.name.clone(),
        m.diffuse.map_or(default_material().kd, Vec3::from),
        rgb(m.emissive),
        rgb(m.specular),
        m.shininess.unwrap_or(0.0),
        // MTL's usual model when none is given: diffuse plus highlights.
        m.illumination_model.map_or(2, u32::from),
    )
}
