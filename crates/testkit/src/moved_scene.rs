//! A scene moved by an offset, geometry and viewpoints alike, rebuilt through the scene builder
//! (so welding, splits, normals and fingerprint are the moved scene's own), for real processes
//! to load once exported (`scene::export`): the check that a scene far from the origin
//! shades like a centred one (DESIGN.md §7: robust also far from the origin).
//!
//! Moving rounds positions to the f32 spacing where they land (about 0.008 at 1e5). Moving the
//! far copy back is exact, so `moved(&moved(s, d), -d)` is the far scene's geometry at the
//! centre: the pair to compare when only the arithmetic far away should differ.

use glam::Vec3;
use scene::{Scene, SceneBuilder, SceneError};

/// `scene` moved by `offset`: vertices, viewpoint eyes and targets; the sun, the sky and every
/// material unchanged.
pub fn moved(scene: &Scene, offset: Vec3) -> Result<Scene, SceneError> {
    let mut settings = scene.settings.clone();
    for vp in &mut settings.viewpoints {
        vp.eye = (Vec3::from(vp.eye) + offset).to_array();
        vp.target = (Vec3::from(vp.target) + offset).to_array();
    }
    let mut builder = SceneBuilder::new(settings);
    for m in &scene.materials {
        builder.material(m.clone());
    }
    for &p in &scene.mesh.positions {
        builder.vertex(p + offset);
    }
    for t in &scene.mesh.triangles {
        builder.triangle(t.vertices, t.material);
    }
    builder.build()
}
