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
    let io_error = |source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    };
    let bytes = files.read(path).map_err(io_error)?;
    // TOML is UTF-8 by definition: a file that is not is refused as unreadable text.
    let text = String::from_utf8(bytes)
        .map_err(|e| io_error(io::Error::new(io::ErrorKind::InvalidData, e)))?;
    toml::from_str(&text).map_err(|e| SceneError::Toml {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// An OBJ or MTL file as text. Comments in them are not always UTF-8; geometry always is ASCII.
pub(crate) fn read_text(files: &dyn SceneFiles, path: &Path) -> Result<String, SceneError> {
    let bytes = files.read(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}
