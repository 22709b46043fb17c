//! Building a validated [`Scene`] from raw triangles: the one path every scene takes, whether it
//! comes from an OBJ file or is generated in code, so both get the same welding, degenerate
//! triangle removal, vertex splits, normals, effects and fingerprint.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use crate::effects::analyse_effects;
use crate::error::SceneError;
use crate::fingerprint::fingerprint;
use crate::model::{LoadReport, Material, Scene, Triangle};
use crate::settings::SceneSettings;
use crate::vertex_split::split_vertices;

pub struct SceneBuilder {
    settings: SceneSettings,
    materials: Vec<Material>,
    positions: Vec<Vec3>,
    triangles: Vec<Triangle>,
    /// One per triangle; all (0, 0) until a triangle is given texture coordinates.
    texcoords: Vec<[Vec2; 3]>,
    any_texcoords: bool,
    warnings: Vec<String>,
    notes: Vec<String>,
}

impl SceneBuilder {
    pub fn new(settings: SceneSettings) -> SceneBuilder {
        SceneBuilder {
            settings,
            materials: Vec::new(),
            positions: Vec::new(),
            triangles: Vec::new(),
            texcoords: Vec::new(),
            any_texcoords: false,
            warnings: Vec::new(),
            notes: Vec::new(),
        }
    }

    pub fn material(&mut self, material: Material) -> u32 {
        self.materials.push(material);
        self.materials.len() as u32 - 1
    }

    pub fn vertex(&mut self, position: Vec3) -> u32 {
        self.positions.push(position);
        self.positions.len() as u32 - 1
    }

    /// A triangle, counter-clockwise as seen from the side an emitter shines to.
    pub fn triangle(&mut self, vertices: [u32; 3], material: u32) {
        self.triangles.push(Triangle { vertices, material });
        self.texcoords.push([Vec2::ZERO; 3]);
    }

    /// A triangle with texture coordinates at its corners (in the order of `vertices`).
    pub fn textured_triangle(&mut self, vertices: [u32; 3], material: u32, uv: [Vec2; 3]) {
        self.triangle(vertices, material);
        *self.texcoords.last_mut().expect("just pushed") = uv;
        self.any_texcoords = true;
    }

    /// Gives each triangle so far the texture coordinates `uv(material, corners)` returns for
    /// it, if any: a projection for scenes generated in code (`builtin`).
    pub fn project_texcoords(&mut self, uv: impl Fn(u32, [Vec3; 3]) -> Option<[Vec2; 3]>) {
        for (t, corners) in self.triangles.iter().zip(&mut self.texcoords) {
            let positions = t.vertices.map(|v| self.positions[v as usize]);
            if let Some(projected) = uv(t.material, positions) {
                *corners = projected;
                self.any_texcoords = true;
            }
        }
    }

    /// Something the scene's user should know (a missing MTL, say), kept in the report.
    /// Logged as well, for services that load a scene without printing its report.
    pub fn warn(&mut self, warning: String) {
        tracing::warn!("{}: {warning}", self.settings.name);
        self.warnings.push(warning);
    }

    /// Something loading did that is worth knowing but needs no action (a texture downscaled),
    /// kept in the report and logged.
    pub fn note(&mut self, note: String) {
        tracing::info!("{}: {note}", self.settings.name);
        self.notes.push(note);
    }

    /// Validates and finishes the scene: bit-identical positions are welded (so adjacency does
    /// not depend on how the source numbered its vertices), zero-area triangles are dropped and
    /// counted, vertices are split at material seams and creases, and effects and fingerprint
    /// are computed.
    pub fn build(self) -> Result<Scene, SceneError> {
        self.settings.validate().map_err(SceneError::Settings)?;
        self.check_references()?;
        let (positions, welded) = weld(&self.positions);
        let mut kept = Vec::with_capacity(self.triangles.len());
        let mut texcoords = Vec::new();
        for (t, uv) in self.triangles.iter().zip(&self.texcoords) {
            let vertices = t.vertices.map(|v| welded[v as usize]);
            if !is_degenerate(vertices.map(|v| positions[v as usize])) {
                kept.push(Triangle {
                    vertices,
                    material: t.material,
                });
                if self.any_texcoords {
                    texcoords.push(*uv);
                }
            }
        }
        if kept.is_empty() {
            return Err(SceneError::Empty);
        }
        // Splitting keeps the triangles' order, so `texcoords` stays parallel to them.
        let split = split_vertices(&positions, &kept, self.settings.crease_angle_deg);
        let effects = analyse_effects(&self.settings, &self.materials, &split.mesh);
        let fingerprint = fingerprint(&self.settings, &split.mesh, &self.materials, &texcoords);
        let report = LoadReport {
            dropped_triangles: self.triangles.len() - kept.len(),
            source_vertices: self.positions.len(),
            material_split_vertices: split.material_splits,
            crease_split_vertices: split.crease_splits,
            warnings: self.warnings,
            notes: self.notes,
        };
        Ok(Scene {
            name: self.settings.name.clone(),
            settings: self.settings,
            mesh: split.mesh,
            materials: self.materials,
            texcoords,
            effects,
            fingerprint,
            report,
        })
    }

    fn check_references(&self) -> Result<(), SceneError> {
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(SceneError::Builder(format!("vertex {i} is not finite")));
        }
        for (i, t) in self.triangles.iter().enumerate() {
            if let Some(v) = t
                .vertices
                .iter()
                .find(|&&v| v as usize >= self.positions.len())
            {
                return Err(SceneError::Builder(format!(
                    "triangle {i} uses undefined vertex {v}"
                )));
            }
            if t.material as usize >= self.materials.len() {
                return Err(SceneError::Builder(format!(
                    "triangle {i} uses undefined material {}",
                    t.material
                )));
            }
        }
        Ok(())
    }
}

/// Merges bit-identical positions (-0.0 counts as 0.0); returns the unique positions and, per
/// input vertex, its unique index.
fn weld(positions: &[Vec3]) -> (Vec<Vec3>, Vec<u32>) {
    let mut index: HashMap<[u32; 3], u32> = HashMap::with_capacity(positions.len());
    let mut unique = Vec::with_capacity(positions.len());
    let welded = positions
        .iter()
        .map(|p| {
            let p = *p + Vec3::ZERO;
            *index
                .entry(p.to_array().map(f32::to_bits))
                .or_insert_with(|| {
                    unique.push(p);
                    unique.len() as u32 - 1
                })
        })
        .collect();
    (unique, welded)
}

/// Zero area, or so thin that its normal means nothing: twice its area is below 1e-7 of its
/// longest edge squared (a sine of the smallest angle below ~1e-7). Also a triangle whose
/// normal cannot be made unit in `f32`: its squared length overflows (edges beyond ~4e9) or
/// falls to zero or into subnormals (twice the area below ~1e-19), where normalising gives a
/// zero or inexact vector instead of the unit normal the renderer and the SMA rely on.
fn is_degenerate([a, b, c]: [Vec3; 3]) -> bool {
    let twice_area_squared = (b - a).cross(c - a).length_squared();
    let longest = (b - a)
        .length_squared()
        .max((c - b).length_squared())
        .max((a - c).length_squared());
    !twice_area_squared.is_normal() || twice_area_squared.sqrt() <= 1e-7 * longest
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn unit_quad(b: &mut SceneBuilder, material: u32) {
        let v = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0), Vec3::NEG_Z].map(|p| b.vertex(p));
        b.triangle([v[0], v[1], v[2]], material);
        b.triangle([v[0], v[2], v[3]], material);
    }

    fn settings() -> SceneSettings {
        toml::from_str("name = \"t\"").expect("minimal settings parse")
    }

    #[test]
    fn welds_duplicates_and_drops_degenerates() {
        let mut b = SceneBuilder::new(settings());
        let m = b.material(Material::diffuse("grey", Vec3::splat(0.5)));
        unit_quad(&mut b, m);
        unit_quad(&mut b, m); // the same quad again: welded onto the first one's vertices
        let p = b.vertex(Vec3::new(2.0, 0.0, 0.0));
        let q = b.vertex(Vec3::new(3.0, 0.0, 0.0));
        let r = b.vertex(Vec3::new(4.0, 0.0, 0.0));
        b.triangle([p, q, r], m); // collinear
        b.triangle([p, p, q], m); // repeated vertex
        let s = b.build().expect("valid scene");
        assert_eq!(s.report.dropped_triangles, 2);
        assert_eq!(s.report.source_vertices, 11);
        assert_eq!(s.mesh.positions.len(), 4);
        assert_eq!(s.mesh.triangles.len(), 4);
        assert!(
            s.mesh
                .normals
                .iter()
                .all(|n| n.abs_diff_eq(Vec3::Y, 1e-6) || n.abs_diff_eq(Vec3::NEG_Y, 1e-6))
        );
    }

    /// A needle (sine of its smallest angle 1e-6) is a triangle like any other, with unit
    /// normals; a sliver under the bound (1e-8) has no meaningful normal and is dropped.
    #[test]
    fn needles_are_kept_and_slivers_below_the_bound_dropped() {
        let mut b = SceneBuilder::new(settings());
        let m = b.material(Material::diffuse("grey", Vec3::splat(0.5)));
        let [o, x, needle, sliver] = [
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(1.0, 1e-6, 0.0),
            Vec3::new(1.0, 1e-8, 0.0),
        ]
        .map(|p| b.vertex(p));
        b.triangle([o, x, needle], m);
        b.triangle([o, x, sliver], m);
        let s = b.build().expect("the needle makes a scene");
        assert_eq!(s.report.dropped_triangles, 1);
        assert_eq!(s.mesh.triangles.len(), 1);
        let normals = s.mesh.triangles[0]
            .vertices
            .map(|v| s.mesh.normals[v as usize]);
        assert!(
            normals
                .iter()
                .all(|n| n.is_finite() && (n.length() - 1.0).abs() < 1e-6),
            "{normals:?}"
        );
    }

    #[test]
    fn undefined_references_are_errors_not_panics() {
        let mut b = SceneBuilder::new(settings());
        let m = b.material(Material::diffuse("grey", Vec3::splat(0.5)));
        b.triangle([0, 1, 2], m);
        assert!(
            matches!(b.build(), Err(SceneError::Builder(msg)) if msg == "triangle 0 uses undefined vertex 0")
        );

        let mut b = SceneBuilder::new(settings());
        unit_quad(&mut b, 3);
        assert!(
            matches!(b.build(), Err(SceneError::Builder(msg)) if msg == "triangle 0 uses undefined material 3")
        );

        let mut b = SceneBuilder::new(settings());
        b.vertex(Vec3::new(f32::NAN, 0.0, 0.0));
        assert!(
            matches!(b.build(), Err(SceneError::Builder(msg)) if msg == "vertex 0 is not finite")
        );
    }

    #[test]
    fn a_scene_of_only_degenerate_triangles_is_empty() {
        let mut b = SceneBuilder::new(settings());
        let m = b.material(Material::diffuse("grey", Vec3::splat(0.5)));
        let v = b.vertex(Vec3::ONE);
        b.triangle([v, v, v], m);
        assert!(matches!(b.build(), Err(SceneError::Empty)));
    }

    #[test]
    fn triangles_whose_normal_overflows_or_underflows_are_dropped() {
        let mut b = SceneBuilder::new(settings());
        let m = b.material(Material::diffuse("grey", Vec3::splat(0.5)));
        for scale in [1e10, 1e-20, 1.0] {
            let [p, q, r] = [Vec3::ZERO, Vec3::X, Vec3::Y].map(|v| b.vertex(v * scale));
            b.triangle([p, q, r], m);
        }
        let scene = b.build().expect("the unit triangle is kept");
        assert_eq!(scene.report.dropped_triangles, 2);
        assert_eq!(scene.mesh.triangles.len(), 1);
        assert!(scene.mesh.normals.iter().all(|n| n.is_normalized()));
    }

    /// A random triangle soup over a small grid of points (so vertices are shared, welded,
    /// duplicated and degenerate triangles occur), with two materials.
    fn soup() -> impl Strategy<Value = (Vec<Vec3>, Vec<([u32; 3], u32)>)> {
        let point = (0..3i32, 0..3i32, 0..2i32)
            .prop_map(|(x, y, z)| Vec3::new(x as f32, y as f32, z as f32));
        prop::collection::vec(point, 3..12).prop_flat_map(|points| {
            let n = points.len() as u32;
            let triangle = ([0..n, 0..n, 0..n], 0..2u32);
            (Just(points), prop::collection::vec(triangle, 1..20))
        })
    }

    fn build_soup(
        points: &[Vec3],
        triangles: &[([u32; 3], u32)],
        order: &[usize],
    ) -> Result<Scene, SceneError> {
        let mut b = SceneBuilder::new(settings());
        b.material(Material::diffuse("a", Vec3::splat(0.5)));
        b.material(Material::diffuse("b", Vec3::splat(0.6)));
        // Add the points in `order`; `slot[i]` is where point i went.
        let mut slot = vec![0; points.len()];
        for &i in order {
            slot[i] = b.vertex(points[i]);
        }
        for (v, m) in triangles {
            b.triangle(v.map(|i| slot[i as usize]), *m);
        }
        b.build()
    }

    proptest! {
        #[test]
        fn splitting_keeps_geometry_and_separates_materials((points, triangles) in soup(), seed in any::<u64>()) {
            let identity: Vec<usize> = (0..points.len()).collect();
            let Ok(scene) = build_soup(&points, &triangles, &identity) else {
                // Only a soup of degenerate triangles may fail.
                prop_assert!(triangles.iter().all(|(v, _)| is_degenerate(v.map(|i| points[i as usize]))));
                return Ok(());
            };
            let kept: Vec<_> = triangles.iter().filter(|(v, _)| !is_degenerate(v.map(|i| points[i as usize]))).collect();
            prop_assert_eq!(scene.mesh.triangles.len(), kept.len());
            prop_assert_eq!(scene.report.dropped_triangles, triangles.len() - kept.len());
            let mut material_of_vertex = vec![None; scene.mesh.positions.len()];
            for (t, (v, m)) in scene.mesh.triangles.iter().zip(kept) {
                prop_assert_eq!(t.material, *m);
                for k in 0..3 {
                    prop_assert_eq!(scene.mesh.positions[t.vertices[k] as usize], points[v[k] as usize]);
                    let owner = material_of_vertex[t.vertices[k] as usize].get_or_insert(*m);
                    prop_assert_eq!(*owner, *m);
                }
            }
            prop_assert!(scene.mesh.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-5));
            // The same soup with its vertices added in another order gives the same scene.
            let mut order = identity.clone();
            order.rotate_left(seed as usize % points.len());
            let again = build_soup(&points, &triangles, &order).expect("same triangles");
            prop_assert_eq!(again.fingerprint, scene.fingerprint);
        }
    }
}
