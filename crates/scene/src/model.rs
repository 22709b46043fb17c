//! The in-memory scene shared by renderer and SMA.
//!
//! Geometry is an indexed triangle mesh whose vertices are already split where materials differ
//! (thesis §4.1) and at creases, so each vertex has one canonical normal (DESIGN.md §5). Positions
//! of split copies stay bit-identical, so geometry stays crack-free.

use glam::Vec3;

use crate::settings::SceneSettings;

/// How a material scatters light (DESIGN.md §7).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scattering {
    /// Two-sided Lambertian (the default).
    Diffuse,
    /// Lambertian plus a normalised Blinn–Phong lobe (MTL `Ks` > 0, exponent `Ns`).
    Glossy,
    /// Perfect mirror (MTL `illum` 3 or 5), reflectance `Ks`.
    Mirror,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse albedo (MTL `Kd`); texture maps are ignored (DESIGN.md §5).
    pub kd: Vec3,
    /// Emitted radiance (MTL `Ke`), one-sided: toward the face's counter-clockwise normal.
    pub ke: Vec3,
    /// Specular reflectance (MTL `Ks`).
    pub ks: Vec3,
    /// Blinn–Phong exponent (MTL `Ns`).
    pub ns: f32,
    /// MTL `illum`.
    pub illum: u32,
    pub scattering: Scattering,
}

impl Material {
    /// A two-sided Lambertian material.
    pub fn diffuse(name: impl Into<String>, kd: Vec3) -> Material {
        Material {
            name: name.into(),
            kd,
            ke: Vec3::ZERO,
            ks: Vec3::ZERO,
            ns: 0.0,
            illum: 1,
            scattering: Scattering::Diffuse,
        }
    }

    /// A Lambertian reflector that also emits `ke` from its counter-clockwise side (DESIGN.md §7).
    pub fn emitter(name: impl Into<String>, kd: Vec3, ke: Vec3) -> Material {
        Material {
            ke,
            ..Material::diffuse(name, kd)
        }
    }

    /// A perfect mirror of reflectance `ks` (MTL `illum` 3).
    pub fn mirror(name: impl Into<String>, kd: Vec3, ks: Vec3) -> Material {
        Material::from_mtl(name, kd, Vec3::ZERO, ks, 0.0, 3)
    }

    /// A material as an MTL file states it; the scattering follows from `Ks` and `illum`: `illum`
    /// 3 or 5 with some `Ks` is a mirror, other `Ks` > 0 a Blinn–Phong lobe unless `illum` 0 or 1
    /// (the MTL models without highlights) turns it off.
    pub fn from_mtl(
        name: impl Into<String>,
        kd: Vec3,
        ke: Vec3,
        ks: Vec3,
        ns: f32,
        illum: u32,
    ) -> Material {
        let scattering = match (illum, ks.max_element() > 0.0) {
            (_, false) | (0 | 1, true) => Scattering::Diffuse,
            (3 | 5, true) => Scattering::Mirror,
            _ => Scattering::Glossy,
        };
        Material {
            name: name.into(),
            kd,
            ke,
            ks,
            ns,
            illum,
            scattering,
        }
    }

    pub fn is_emitter(&self) -> bool {
        self.ke.max_element() > 0.0
    }

    /// Whether outgoing radiance depends on the eye (glossy or mirror): such samples age as the
    /// eye moves (DESIGN.md §5).
    pub fn is_view_dependent(&self) -> bool {
        self.scattering != Scattering::Diffuse
    }
}

/// One triangle of the base mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Triangle {
    /// Indices into `Mesh::positions` / `Mesh::normals`, counter-clockwise as in the file.
    pub vertices: [u32; 3],
    pub material: u32,
}

#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    /// One canonical unit normal per vertex (DESIGN.md §5): from its faces, face normals first
    /// flipped into one hemisphere so mixed winding cannot cancel them.
    pub normals: Vec<Vec3>,
    pub triangles: Vec<Triangle>,
}

impl Mesh {
    /// Inlined across crates: the renderer reads a hit triangle's corner at every path vertex.
    #[inline]
    pub fn triangle_positions(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t].vertices;
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Unnormalised geometric normal of triangle `t` (counter-clockwise winding), length = 2·area.
    pub fn face_normal(&self, t: usize) -> Vec3 {
        let [a, b, c] = self.triangle_positions(t);
        (b - a).cross(c - a)
    }

    pub fn triangle_area(&self, t: usize) -> f32 {
        0.5 * self.face_normal(t).length()
    }

    pub fn bounds(&self) -> (Vec3, Vec3) {
        self.positions
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            })
    }
}

/// Which effects the scene calls for, so the renderer simulates only those (DESIGN.md §7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Effects {
    pub sun: bool,
    pub sky: bool,
    pub area_lights: bool,
    /// Diffuse interreflection: some non-black diffuse surface can receive and pass on light.
    pub interreflection: bool,
    pub glossy: bool,
    pub mirror: bool,
}

/// What loading found and fixed, for `scene info` and for tests.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LoadReport {
    /// Zero-area (or degenerate) triangles dropped.
    pub dropped_triangles: usize,
    /// Vertices of the file before splitting, and added by material and crease splits.
    pub source_vertices: usize,
    pub material_split_vertices: usize,
    pub crease_split_vertices: usize,
    pub warnings: Vec<String>,
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub settings: SceneSettings,
    pub mesh: Mesh,
    pub materials: Vec<Material>,
    pub effects: Effects,
    /// BLAKE3 over scene settings, geometry and materials: equal scenes, equal fingerprints.
    pub fingerprint: [u8; 32],
    pub report: LoadReport,
}

impl Scene {
    pub fn material_of(&self, t: usize) -> &Material {
        &self.materials[self.mesh.triangles[t].material as usize]
    }
}
