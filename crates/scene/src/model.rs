//! The in-memory scene shared by renderer and SMA.
//!
//! Geometry is an indexed triangle mesh whose vertices are already split where materials differ
//! (thesis §4.1) and at creases, so each vertex has one canonical normal (DESIGN.md §5). Positions
//! of split copies stay bit-identical, so geometry stays crack-free.

use glam::{Vec2, Vec3};

use crate::settings::SceneSettings;
use crate::texture::DiffuseMap;

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
    /// Diffuse albedo (MTL `Kd`); with a `diffuse_map`, what its albedo rule makes of it.
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
    /// MTL `map_Kd`, when the scene's textures are on and the file loaded (DESIGN.md §5).
    pub diffuse_map: Option<DiffuseMap>,
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
            diffuse_map: None,
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
            diffuse_map: None,
        }
    }

    /// The diffuse albedo at texture coordinates `uv`: `Kd` without a texture, else what the
    /// map's albedo rule makes of `Kd` and the texel there.
    #[inline]
    pub fn albedo_at(&self, uv: Vec2) -> Vec3 {
        match &self.diffuse_map {
            None => self.kd,
            Some(map) => map.albedo(self.kd, uv),
        }
    }

    /// Whether the diffuse lobe can reflect anything: a non-black `Kd`, or a texture (whose
    /// texels the rule `texture` uses alone).
    pub fn reflects_diffusely(&self) -> bool {
        self.kd.max_element() > 0.0 || self.diffuse_map.is_some()
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
    /// What loading did that needs no action (a texture downscaled to the cap).
    pub notes: Vec<String>,
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub settings: SceneSettings,
    pub mesh: Mesh,
    pub materials: Vec<Material>,
    /// Texture coordinates of each triangle's corners, in `mesh.triangles`' order (OBJ `vt`;
    /// (0, 0) for a face without them), or empty when the source has none. Kept per corner, so
    /// a seam in the texture splits no vertex: the mesh's vertices are shading samples'.
    pub texcoords: Vec<[Vec2; 3]>,
    pub effects: Effects,
    /// BLAKE3 over scene settings, geometry and materials, and with textures on, over their
    /// bytes and the texture coordinates: equal scenes, equal fingerprints.
    pub fingerprint: [u8; 32],
    pub report: LoadReport,
}

impl Scene {
    pub fn material_of(&self, t: usize) -> &Material {
        &self.materials[self.mesh.triangles[t].material as usize]
    }

    /// Texture coordinates at barycentric weights `[u, v]` of corners 1 and 2 of triangle `t`.
    #[inline]
    pub fn texcoord_at(&self, t: usize, [u, v]: [f32; 2]) -> Vec2 {
        match self.texcoords.get(t) {
            Some([a, b, c]) => *a * (1.0 - u - v) + *b * u + *c * v,
            None => Vec2::ZERO,
        }
    }

    /// Diffuse albedo at barycentric weights `[u, v]` of triangle `t`.
    #[inline]
    pub fn albedo_at(&self, t: usize, bary: [f32; 2]) -> Vec3 {
        let material = self.material_of(t);
        match material.diffuse_map {
            None => material.kd,
            Some(_) => material.albedo_at(self.texcoord_at(t, bary)),
        }
    }
}
