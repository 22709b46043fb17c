//! The `walkthrough scene info` report (DESIGN.md §11); the launcher adds the visible
//! base triangles per viewpoint.

use std::fmt::Write as _;

use crate::fingerprint::hex;
use crate::model::Scene;

/// "off", or "on" with the albedo rule and how many materials have a texture.
fn textures(scene: &Scene) -> String {
    let t = &scene.settings.textures;
    if !t.enabled {
        return "off".into();
    }
    let textured = scene
        .materials
        .iter()
        .filter(|m| m.diffuse_map.is_some())
        .count();
    format!(
        "on, albedo {}, {textured} of {} materials textured",
        t.albedo.name(),
        scene.materials.len()
    )
}

pub fn describe(scene: &Scene) -> String {
    let (lo, hi) = scene.mesh.bounds();
    let r = &scene.report;
    let mut out = String::new();
    let _ = writeln!(out, "scene        {}", scene.name);
    let _ = writeln!(out, "triangles    {}", scene.mesh.triangles.len());
    let _ = writeln!(
        out,
        "vertices     {} (file {}; +{} at material seams, +{} at creases)",
        scene.mesh.positions.len(),
        r.source_vertices,
        r.material_split_vertices,
        r.crease_split_vertices
    );
    let _ = writeln!(out, "materials    {}", scene.materials.len());
    let _ = writeln!(out, "bounds       {lo} .. {hi} ({})", scene.settings.units);
    let _ = writeln!(
        out,
        "dropped      {} zero-area triangles",
        r.dropped_triangles
    );
    let _ = writeln!(out, "effects      {}", scene.effects);
    let _ = writeln!(out, "textures     {}", textures(scene));
    let _ = writeln!(out, "fingerprint  {}", hex(&scene.fingerprint));
    for n in &r.notes {
        let _ = writeln!(out, "note         {n}");
    }
    for w in &r.warnings {
        let _ = writeln!(out, "warning      {w}");
    }
    out
}
