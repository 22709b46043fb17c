//! What the scene fuzz targets do with one input: load it as one file of a scene (the OBJ, its
//! MTL or the scene file, DESIGN.md §7), the other files fixed, through the loader the services
//! use, from memory. Every input is a scene or an error: a panic is a crash, and so is a scene
//! that breaks what renderer and SMA rely on (finite positions and normals, indices in range).
//! The scene crate's `fuzz_corpus` test includes this file to replay the corpus on stable Rust.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use scene::{Scene, load_scene_file_from};

/// The exported built-in scenes (DESIGN.md §11) that the fixed companion files come from.
const CORNELL_OBJ: &str = include_str!("../../scenes/cornell.obj");
const CORNELL_MTL: &str = include_str!("../../scenes/cornell.mtl");
const BRACARA_MTL: &str = include_str!("../../scenes/bracara.mtl");

/// The scene file of the OBJ and MTL targets: every setting that changes how faces are split
/// and which effects are traced, and textures on, so `map_Kd` statements are read (their files
/// are missing: each is a warning and its material keeps `Kd`).
const SCENE_TOML: &str = r#"name = "fuzz"
obj = "scene.obj"
crease_angle_deg = 30.0
[sun]
direction = [0.3, 1.0, 0.2]
radiance = [1.0e5, 1.0e5, 1.0e5]
angular_diameter_deg = 0.53
[sky]
kind = "uniform"
radiance = [0.5, 0.6, 0.9]
[textures]
enabled = true
"#;

/// The OBJ of the MTL target: a quad per material name of the built-in scenes' MTLs.
const MTL_TARGET_OBJ: &str = "mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
usemtl white
f 1 2 3
usemtl light
f 1 3 4
usemtl pool_water
f 1 5 6
usemtl marble
f 1 6 2
";

/// The input as the OBJ, beside the built-in scenes' MTLs (an OBJ piece of either names one).
pub fn obj(data: &[u8]) -> bool {
    load(&[
        ("scene.toml", SCENE_TOML.as_bytes()),
        ("scene.obj", data),
        ("cornell.mtl", CORNELL_MTL.as_bytes()),
        ("bracara.mtl", BRACARA_MTL.as_bytes()),
    ])
}

/// The input as the MTL of a small OBJ that uses the built-in scenes' material names.
pub fn mtl(data: &[u8]) -> bool {
    load(&[
        ("scene.toml", SCENE_TOML.as_bytes()),
        ("scene.obj", MTL_TARGET_OBJ.as_bytes()),
        ("scene.mtl", data),
    ])
}

/// The input as the scene file, beside the Cornell box's OBJ (as `scene.obj`) and MTL.
pub fn toml(data: &[u8]) -> bool {
    load(&[
        ("scene.toml", data),
        ("scene.obj", CORNELL_OBJ.as_bytes()),
        ("cornell.mtl", CORNELL_MTL.as_bytes()),
    ])
}

/// Loads `scene.toml` from the files given, all in one directory; true when it loaded.
fn load(files: &[(&str, &[u8])]) -> bool {
    let dir = Path::new("fuzz");
    let files: HashMap<PathBuf, Vec<u8>> = files
        .iter()
        .map(|(name, bytes)| (dir.join(name), bytes.to_vec()))
        .collect();
    let loaded = load_scene_file_from(&files, &dir.join("scene.toml"));
    if let Ok(scene) = &loaded {
        check_scene(scene);
    }
    loaded.is_ok()
}

/// What the renderer and the SMA index and divide by without checking again.
fn check_scene(scene: &Scene) {
    let mesh = &scene.mesh;
    assert!(!mesh.triangles.is_empty(), "a loaded scene has triangles");
    assert_eq!(
        mesh.normals.len(),
        mesh.positions.len(),
        "a normal per vertex"
    );
    assert!(
        mesh.positions.iter().all(|p| p.is_finite()),
        "finite positions"
    );
    assert!(
        mesh.normals.iter().all(|n| n.is_normalized()),
        "unit normals: {:?}",
        mesh.normals
    );
    for t in &mesh.triangles {
        assert!(
            t.vertices
                .iter()
                .all(|&v| (v as usize) < mesh.positions.len())
        );
        assert!((t.material as usize) < scene.materials.len());
    }
    assert!(
        scene.texcoords.is_empty() || scene.texcoords.len() == mesh.triangles.len(),
        "texture coordinates per triangle, or none"
    );
    assert!(
        scene.texcoords.iter().flatten().all(|uv| uv.is_finite()),
        "finite texture coordinates"
    );
}
