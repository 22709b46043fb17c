//! What the estimator needs of a scene, prepared once: the BVH, the lights the scene calls for,
//! each material's scattering (its albedo read from its texture per point, where it has one),
//! unit face normals and the origin offsetter.
//!
//! The world works in a **local frame**: the scene moved by a round origin near its centre
//! ([`World::to_local`]), so a scene far from the world origin (coordinates around 1e5, where f32
//! spacing is about 0.008, DESIGN.md §7) is traced at the precision of a centred one. In world
//! coordinates its rounding would set the ray offsets (`offset`) to centimetres and move every
//! shading point decimetres off its vertex; locally they are those of the centred scene. The
//! origin is a multiple of a power of two at least the scene's extent, so a centred scene is not
//! moved at all and moving a far one is exact. Shading points come in object space (base
//! triangle, barycentric coordinates), so only eyes and ray origins given in world coordinates
//! need [`World::to_local`].

use glam::{DVec3, Vec3};
use protocol::SceneIdentity;
use scene::{Effects, Scene};

use crate::bvh::{BuildPreset, Hit, PACKET_RAYS, SceneBvh};
use crate::counters::{RayCounts, RayKind};
use crate::estimator::Estimator;
use crate::lights::Lights;
use crate::material::Bsdf;
use crate::offset::Offsetter;
use crate::point::barycentrics;
use crate::strata::FirstBounce;
use crate::texture_lod::{Footprint, TextureLod};

/// A point on a surface, on the side being shaded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Surface {
    /// In the local frame ([`World::to_local`]).
    pub position: Vec3,
    /// Unit geometric normal of the shaded side.
    pub normal: Vec3,
    pub triangle: u32,
}

pub struct World {
    /// The scene, its positions in the local frame.
    pub scene: Scene,
    pub bvh: SceneBvh,
    pub lights: Lights,
    pub offset: Offsetter,
    /// Length of the scene's bounding-box diagonal.
    pub extent: f32,
    /// How shade batches and reference images schedule their paths (both use this one).
    pub estimator: Estimator,
    /// How the first bounce of a point's or pixel's paths is sampled (stratified by default).
    pub first_bounce: FirstBounce,
    /// Whether the wavefront estimator traces its most coherent rays eight at a time as packets
    /// (`SceneBvh`'s packet queries): a reference pixel's camera rays, and the sun shadow rays of
    /// a point's paths, which share an origin and nearly one direction (DESIGN.md §7). The
    /// answers are the same either way; docs/bench/renderer.md measures the cost.
    pub packets: bool,
    bsdfs: Vec<Bsdf>,
    texture_lod: TextureLod,
    /// Unit counter-clockwise normal per triangle (zero for a degenerate one).
    face_normals: Vec<Vec3>,
    /// The world position of the local frame's origin.
    origin: DVec3,
    /// The scene's bounds in the local frame.
    bounds: (Vec3, Vec3),
}

impl World {
    /// The tree [`World::new`] builds: obvhs's best (`BuildPreset::VerySlow`), on which the wide
    /// traversal traces fastest, for a build of a fraction of a second once per scene.
    pub const PRESET: BuildPreset = BuildPreset::VerySlow;

    pub fn new(scene: Scene) -> World {
        World::with_preset(scene, World::PRESET)
    }

    pub fn with_preset(mut scene: Scene, preset: BuildPreset) -> World {
        let (lo, hi) = scene.mesh.bounds();
        let extent = if lo.is_finite() && hi.is_finite() {
            (hi - lo).length()
        } else {
            1.0
        };
        let origin = local_origin(lo, hi, extent);
        for p in &mut scene.mesh.positions {
            *p = conventions::camera::relative_to(*p, origin);
        }
        let bvh = SceneBvh::build(&scene.mesh, preset);
        let bounds = scene.mesh.bounds();
        let lights = Lights::from_scene(&scene);
        let face_normals = (0..scene.mesh.triangles.len())
            .map(|t| scene.mesh.face_normal(t).normalize_or_zero())
            .collect();
        let bsdfs = scene.materials.iter().map(Bsdf::from_material).collect();
        let texture_lod = TextureLod::new(&scene);
        World {
            offset: Offsetter::new(extent),
            extent,
            estimator: Estimator::default(),
            first_bounce: FirstBounce::default(),
            packets: true,
            bvh,
            lights,
            bsdfs,
            texture_lod,
            face_normals,
            scene,
            origin,
            bounds,
        }
    }

    /// The scene's bounds in the local frame (where rays are traced).
    pub(crate) fn bounds(&self) -> (Vec3, Vec3) {
        self.bounds
    }

    /// A world position (an eye, a ray origin) in the local frame.
    pub fn to_local(&self, p: Vec3) -> Vec3 {
        conventions::camera::relative_to(p, self.origin)
    }

    /// The scene as the handshake compares it: fingerprint and textures on or off (DESIGN.md
    /// §5, §8).
    pub fn identity(&self) -> SceneIdentity {
        SceneIdentity {
            fingerprint: self.scene.fingerprint,
            textures: self.scene.settings.textures.enabled,
        }
    }

    pub fn effects(&self) -> Effects {
        self.scene.effects
    }

    pub fn triangle_count(&self) -> usize {
        self.face_normals.len()
    }

    /// How the surface at `s` scatters: its material's, with the albedo read from the material's
    /// texture at `s` where it has one (DESIGN.md §5), prefiltered over a path's `footprint`
    /// there (`texture_lod`).
    #[inline]
    pub(crate) fn bsdf_at(&self, s: &Surface, footprint: Footprint) -> Bsdf {
        let t = s.triangle as usize;
        let material = self.scene.mesh.triangles[t].material as usize;
        let bsdf = self.bsdfs[material];
        if self.scene.materials[material].diffuse_map.is_none() {
            return bsdf;
        }
        let corners = self.scene.mesh.triangle_positions(t);
        let [a, b, c] = corners;
        let bary = barycentrics(s.position, a, b, c);
        Bsdf {
            kd: self
                .texture_lod
                .albedo_at(&self.scene, t, corners, bary, footprint.width()),
            ..bsdf
        }
    }

    /// The surface at `s` as the first vertex of a point's or pixel's paths sees it: its diffuse
    /// lobe with a unit albedo (where the material reflects diffusely at all), so that the paths
    /// estimate the illumination there and the albedo, read per pixel or per vertex, multiplies
    /// it on display (DESIGN.md §5, "Parts, and textures"): nothing is divided by an albedo, and
    /// a dark texel does not darken the estimate its neighbours share. The glossy and mirror
    /// lobes stay as they are.
    #[inline]
    pub(crate) fn illumination_bsdf_at(&self, s: &Surface) -> Bsdf {
        let material = self.scene.mesh.triangles[s.triangle as usize].material as usize;
        let unit = if self.scene.materials[material].reflects_diffusely() {
            Vec3::ONE
        } else {
            Vec3::ZERO
        };
        Bsdf {
            kd: unit,
            ..self.bsdfs[material]
        }
    }

    /// The diffuse albedo at `s`: the texel of its material's texture there, or its `Kd`. What
    /// the illumination of a path's first vertex is multiplied by (`PathParts::radiance`).
    pub fn albedo_at(&self, s: &Surface) -> Vec3 {
        self.bsdf_at(s, Footprint::POINT).kd
    }

    pub fn face_normal(&self, triangle: u32) -> Vec3 {
        self.face_normals[triangle as usize]
    }

    /// Radiance a ray travelling along `dir` receives from emitting triangle `triangle`: its `Ke`
    /// when it arrives on the counter-clockwise side (emitters are one-sided, DESIGN.md §7).
    pub fn emission(&self, triangle: u32, dir: Vec3) -> Vec3 {
        let ke = self.scene.material_of(triangle as usize).ke;
        if self.face_normal(triangle).dot(dir) < 0.0 {
            ke
        } else {
            Vec3::ZERO
        }
    }

    /// Whether a scattering ray of this kind belongs to an effect the scene calls for.
    pub fn simulates(&self, kind: RayKind) -> bool {
        let e = self.effects();
        match kind {
            RayKind::Bounce => e.interreflection,
            RayKind::Glossy => e.glossy,
            RayKind::Mirror => e.mirror,
            _ => true,
        }
    }

    pub fn trace(
        &self,
        origin: Vec3,
        dir: Vec3,
        kind: RayKind,
        counts: &mut RayCounts,
    ) -> Option<Hit> {
        self.trace_within(origin, dir, f32::INFINITY, kind, counts)
    }

    /// Closest hit closer than `tmax`.
    pub fn trace_within(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
        kind: RayKind,
        counts: &mut RayCounts,
    ) -> Option<Hit> {
        counts.count(kind);
        self.bvh.closest_hit(origin, dir, tmax)
    }

    /// [`trace`](Self::trace) for each ray `origins[k] + t dirs[k]`, into `hits[k]`: as packets
    /// (`SceneBvh::closest_hit_packet`) when [`packets`](Self::packets) says so, else one by
    /// one. For coherent rays, such as neighbouring pixels' camera rays.
    pub(crate) fn trace_packet(
        &self,
        origins: &[Vec3],
        dirs: &[Vec3],
        kind: RayKind,
        hits: &mut [Option<Hit>],
        counts: &mut RayCounts,
    ) {
        const UNBOUNDED: [f32; PACKET_RAYS] = [f32::INFINITY; PACKET_RAYS];
        for (k, hits) in hits.chunks_mut(PACKET_RAYS).enumerate() {
            let rays = k * PACKET_RAYS..k * PACKET_RAYS + hits.len();
            for _ in rays.clone() {
                counts.count(kind);
            }
            let (origins, dirs) = (&origins[rays.clone()], &dirs[rays]);
            if self.packets {
                let tmaxs = &UNBOUNDED[..hits.len()];
                self.bvh.closest_hit_packet(origins, dirs, tmaxs, hits);
            } else {
                for (k, hit) in hits.iter_mut().enumerate() {
                    *hit = self.bvh.closest_hit(origins[k], dirs[k], f32::INFINITY);
                }
            }
        }
    }

    pub fn occluded(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
        kind: RayKind,
        counts: &mut RayCounts,
    ) -> bool {
        counts.count(kind);
        self.bvh.occluded(origin, dir, tmax)
    }

    /// As [`occluded`](Self::occluded), trying `last` first: the primitive that blocked an
    /// earlier ray of the stream, updated to this ray's blocker. The shadow rays of one shading
    /// point toward the sun share their origin and nearly their direction (DESIGN.md §7), so one
    /// triangle test settles most of the blocked ones; the answer is the traversal's.
    pub(crate) fn occluded_after(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
        kind: RayKind,
        last: &mut Option<u32>,
        counts: &mut RayCounts,
    ) -> bool {
        counts.count(kind);
        if let Some(prim) = *last
            && self.bvh.blocks(prim, origin, dir, tmax)
        {
            return true;
        }
        let blocker = self.bvh.occluder(origin, dir, tmax);
        if blocker.is_some() {
            *last = blocker;
        }
        blocker.is_some()
    }

    /// The surface a ray from `origin` along unit `dir` hit, on the side it arrived from. The
    /// position is projected onto the triangle's plane, which removes most of the rounding of
    /// `origin + t dir` along the normal (the direction that matters for the next ray's origin).
    pub fn surface_at(&self, origin: Vec3, dir: Vec3, hit: Hit) -> Surface {
        let n = self.face_normal(hit.triangle);
        let v0 = self.scene.mesh.triangle_positions(hit.triangle as usize)[0];
        let p = origin + dir * hit.t;
        let position = p - n * n.dot(p - v0);
        let normal = if n.dot(dir) > 0.0 { -n } else { n };
        Surface {
            position,
            normal,
            triangle: hit.triangle,
        }
    }
}

/// The local frame's origin: the centre of the bounds rounded to a multiple of the power of two
/// at or above the extent (zero for a scene around the world origin; exact subtraction, since
/// every coordinate far enough out to be moved is a multiple of a finer power of two).
fn local_origin(lo: Vec3, hi: Vec3, extent: f32) -> DVec3 {
    if !(lo.is_finite() && hi.is_finite() && extent.is_finite()) {
        return DVec3::ZERO;
    }
    let grid = f64::from(extent.max(1.0)).log2().ceil().exp2();
    let centre = 0.5 * (lo.as_dvec3() + hi.as_dvec3());
    (centre / grid).round() * grid
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_local_origin_is_zero_near_the_world_origin_and_round_far_from_it() {
        let (lo, hi) = (
            Vec3::new(-120.0, 0.0, -120.0),
            Vec3::new(120.0, 16.4, 120.0),
        );
        let extent = (hi - lo).length();
        assert_eq!(local_origin(lo, hi, extent), DVec3::ZERO);
        let far = Vec3::new(1.0e5, 0.0, 1.0e5);
        let origin = local_origin(lo + far, hi + far, extent);
        assert_eq!(origin, DVec3::new(99_840.0, 0.0, 99_840.0));
        let p = Vec3::new(100_003.01, 5.5, 99_877.5);
        let local = conventions::camera::relative_to(p, origin);
        assert_eq!(local.as_dvec3() + origin, p.as_dvec3(), "moving is exact");
    }
}
