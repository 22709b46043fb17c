//! Loading a scene by name: a built-in scene, or a scene file (TOML, DESIGN.md §7) naming an OBJ
//! relative to itself.

use std::path::Path;

use crate::builtin;
use crate::error::SceneError;
use crate::model::Scene;
use crate::obj::load_obj;
use crate::settings::SceneSettings;

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
    let settings = read_settings(path)?;
    if settings.obj.is_empty() {
        return Err(SceneError::NoObj {
            file: path.to_path_buf(),
        });
    }
    let obj = path.parent().unwrap_or(Path::new("")).join(&settings.obj);
    load_obj(&obj, settings)
}

pub fn read_settings(path: &Path) -> Result<SceneSettings, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    toml::from_str(&text).map_err(|e| SceneError::Toml {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}
