//! Built-in scenes, generated in code and deterministic (DESIGN.md §11).

mod bracara;
mod cornell;
mod shapes;
mod textures;

use crate::error::SceneError;
use crate::model::Scene;

pub const BUILTIN_NAMES: [&str; 3] = ["bracara", "bracara-textured", "cornell"];

/// The built-in scene called `name`, or `None` if there is none.
pub fn build(name: &str) -> Option<Result<Scene, SceneError>> {
    let builder = match name {
        "bracara" => bracara::bracara(false),
        "bracara-textured" => bracara::bracara(true),
        "cornell" => cornell::cornell(),
        _ => return None,
    };
    Some(builder.build())
}
