//! Scene model shared by renderer and SMA (DESIGN.md §2, §4, §5, §7, §11).

pub mod model;
pub mod settings;

pub use model::{Effects, LoadReport, Material, Mesh, Scattering, Scene, Triangle};
pub use settings::{SceneSettings, Sky, Sun, ViewpointSetting};
