//! Loading a scene by name: a built-in scene, or a scene file (TOML, DESIGN.md §7) naming an OBJ
//! relative to itself. The files are read through [`SceneFiles`], so the same loader serves the
//! disk and scenes held in memory (tests and the fuzz targets, which must not touch the disk for
//! each input).

use std::collections::HashMap;
use std::io;
use std::path::{Path, PathBuf};

use crate::builtin;
use crate::error::SceneError;
use crate::model::Scene;
use crate::obj::load_obj;
use crate::settings::SceneSettings;

/// Where the scene file, the OBJ and its MTL libraries are read from.
pub trait SceneFiles {
    fn read(&self, path: &Path) -> io::Result<Vec<u8>>;
}

/// The file system.
pub struct Disk;

impl SceneFiles for Disk {
    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        std::fs::read(path)
    }
}

/// Files held in memory by path; a path not in the map is not found.
impl SceneFiles for HashMap<PathBuf, Vec<u8>> {
    fn read(&self, path: &Path) -> io::Result<Vec<u8>> {
        self.get(path).cloned().ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::NotFound,
                "no such file among the scene's files",
            )
        })
    }
}

/// `spec` is a built-in scene's name ("bracara", "cornell") or the path of a scene file.
pub fn load(spec: &str) -> Result<Scene, SceneError> {
    if let Some(scene) = builtin::build(spec) {
        return scene;
    }
    let path = Path::new(spec);
    if !path.exists() && path.extension().is_none() && path.components().count() == 1 {
        return Err(SceneError::UnknownScene(spec.to_owned()));
    }
    load_scene_file(path)
}

pub fn load_scene_file(path: &Path) -> Result<Scene, SceneError> {
    load_scene_file_from(&Disk, path)
}

/// Loads the scene file at `path`, and the OBJ and MTL files it names, from `files`.
pub fn load_scene_file_from(files: &dyn SceneFiles, path: &Path) -> Result<Scene, SceneError> {
    let settings = read_settings(files, path)?;
    if settings.obj.is_empty() {
        return Err(SceneError::NoObj {
            file: path.to_path_buf(),
        });
    }
    let obj = path.parent().unwrap_or(Path::new("")).join(&settings.obj);
    load_obj(files, &obj, settings)
}

fn read_settings(files: &dyn SceneFiles, path: &Path) -> Result<SceneSettings, SceneError> {
    let text = read_utf8(files, path)?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| toml_error(path, e))?;
    if !table.contains_key(EXTENDS) {
        // Straight from the text, so that an error points at its line.
        return toml::from_str(&text).map_err(|e| toml_error(path, e));
    }
    let merged = with_base(files, path, table, 0)?;
    merged.try_into().map_err(|e| toml_error(path, e))
}

/// How deep `extends` may chain: far more than a scene needs, and a cycle ends in an error.
const MAX_EXTENDS_DEPTH: usize = 8;

/// The scene file's table over the file it `extends` (a path relative to it): the base's keys
/// overridden by this file's, one table by one, any other value as a whole (so a file's
/// `[[viewpoint]]` list replaces its base's). A variant of a scene, such as Sponza with its
/// textures on, is then a few lines and not a copy (DESIGN.md §7).
fn with_base(
    files: &dyn SceneFiles,
    path: &Path,
    mut table: toml::Table,
    depth: usize,
) -> Result<toml::Table, SceneError> {
    let Some(extends) = table.remove(EXTENDS) else {
        return Ok(table);
    };
    let message = |m: &str| SceneError::Toml {
        file: path.to_path_buf(),
        message: m.to_string(),
    };
    let base = extends
        .as_str()
        .ok_or_else(|| message("`extends` must be the path of a scene file"))?;
    if depth >= MAX_EXTENDS_DEPTH {
        return Err(message("`extends` chains too deep (a cycle?)"));
    }
    let base_path = path.parent().unwrap_or(Path::new("")).join(base);
    let base_table =
        toml::from_str(&read_utf8(files, &base_path)?).map_err(|e| toml_error(&base_path, e))?;
    let mut merged = with_base(files, &base_path, base_table, depth + 1)?;
    // The base's OBJ is relative to the base, and this file's paths to this file.
    if let Some(toml::Value::String(obj)) = merged.get_mut("obj") {
        let from_here = Path::new(base)
            .parent()
            .unwrap_or(Path::new(""))
            .join(&*obj);
        *obj = from_here.to_string_lossy().into_owned();
    }
    override_table(&mut merged, table);
    Ok(merged)
}

fn read_utf8(files: &dyn SceneFiles, path: &Path) -> Result<String, SceneError> {
    let io_error = |source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = files.read(path).map_err(io_error)?;
    // TOML is UTF-8 by definition: a file that is not is refused as unreadable text.
    String::from_utf8(bytes).map_err(|e| io_error(io::Error::new(io::ErrorKind::InvalidData, e)))
}

const EXTENDS: &str = "extends";

/// `over`'s keys replace `base`'s; where both hold a table, key by key.
fn override_table(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(inner)), toml::Value::Table(value)) => {
                override_table(inner, value)
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

fn toml_error(path: &Path, e: toml::de::Error) -> SceneError {
    SceneError::Toml {
        file: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// An OBJ or MTL file as text. Comments in them are not always UTF-8; geometry always is ASCII.
pub(crate) fn read_text(files: &dyn SceneFiles, path: &Path) -> Result<String, SceneError> {
    let bytes = files.read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files(entries: &[(&str, &str)]) -> HashMap<PathBuf, Vec<u8>> {
        entries
            .iter()
            .map(|(p, t)| (PathBuf::from(p), t.as_bytes().to_vec()))
            .collect()
    }

    const BASE: &str = r#"
        name = "base"
        obj = "../models/town.obj"
        crease_angle_deg = 30.0
        [sky]
        kind = "uniform"
        radiance = [0.1, 0.2, 0.3]
        [textures]
        albedo = "texture"
        [[viewpoint]]
        name = "A"
        eye = [0.0, 1.0, 0.0]
        target = [1.0, 1.0, 0.0]
    "#;

    #[test]
    fn a_variant_overrides_its_base_key_by_key() {
        let variant = r#"
            extends = "base.toml"
            name = "variant"
            [textures]
            enabled = true
        "#;
        let f = files(&[("s/base.toml", BASE), ("s/variant.toml", variant)]);
        let base = read_settings(&f, Path::new("s/base.toml")).expect("base");
        let got = read_settings(&f, Path::new("s/variant.toml")).expect("variant");
        assert_eq!(got.name, "variant");
        assert!(got.textures.enabled && !base.textures.enabled);
        // Kept from the base: the rule beside the overridden flag, the sky, the views.
        assert_eq!(got.textures.albedo, base.textures.albedo);
        assert_eq!((got.sky, got.viewpoints), (base.sky, base.viewpoints));
        assert_eq!(got.crease_angle_deg, 30.0);
    }

    #[test]
    fn the_base_obj_stays_relative_to_the_base() {
        let variant = "extends = \"../s/base.toml\"\nname = \"v\"";
        // In memory, paths are not normalised: the base is found by the joined path.
        let f = files(&[("t/../s/base.toml", BASE), ("t/variant.toml", variant)]);
        let got = read_settings(&f, Path::new("t/variant.toml")).expect("variant");
        // t/ + ../s/ + ../models/town.obj names the same file as s/ + ../models/town.obj.
        assert_eq!(got.obj, "../s/../models/town.obj");
    }

    #[test]
    fn a_cycle_or_a_missing_base_is_a_clear_error() {
        let f = files(&[
            ("a.toml", "extends = \"b.toml\"\nname = \"a\""),
            ("b.toml", "extends = \"a.toml\"\nname = \"b\""),
            ("c.toml", "extends = \"none.toml\"\nname = \"c\""),
            ("d.toml", "extends = 3\nname = \"d\""),
        ]);
        let error = |p: &str| read_settings(&f, Path::new(p)).unwrap_err().to_string();
        assert!(error("a.toml").contains("too deep"), "{}", error("a.toml"));
        assert!(error("c.toml").contains("none.toml"), "{}", error("c.toml"));
        assert!(error("d.toml").contains("path of a scene file"));
    }
}
