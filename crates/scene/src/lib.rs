//! Scene model shared by renderer and SMA (DESIGN.md §2, §4, §5, §7, §11): OBJ/MTL and scene file
//! loading with validation, diffuse textures, vertex splits and canonical normals, effects
//! analysis, the fingerprint of the handshake, built-in scenes, their export, and a CPU estimate
//! of what a viewpoint sees.

mod builder;
mod builtin;
mod effects;
mod error;
mod fingerprint;
mod map_kd;
mod obj;
mod obj_check;
mod scene_file;
mod vertex_split;

pub mod bvh;
mod cpu_visibility;
pub mod export;
pub mod info;
mod model;
pub mod settings;
pub mod texture;

pub use builder::SceneBuilder;
pub use builtin::BUILTIN_NAMES;
pub use cpu_visibility::{VisibilityEstimator, visible_base_triangles};
pub use error::SceneError;
pub use fingerprint::hex as fingerprint_hex;
pub use model::{Effects, LoadReport, Material, Mesh, Scattering, Scene, Triangle};
pub use scene_file::{Disk, SceneFiles, load, load_scene_file, load_scene_file_from};
pub use settings::{
    AlbedoRule, QualitySetting, SceneSettings, Sky, Sun, TextureSettings, ViewpointSetting,
};
pub use texture::{DiffuseMap, Texture, Wrap};
