//! The `walkthrough scene info` report (DESIGN.md §11); the launcher adds the visible
//! base triangles per viewpoint.

use std::fmt::Write as _;

use crate::fingerprint::hex;
use crate::model::Scene;

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
    let _ = writeln!(out, "fingerprint  {}", hex(&scene.fingerprint));
    for w in &r.warnings {
        let _ = writeln!(out, "warning      {w}");
    }
    out
}
