//! Texture detail past a path's first diffuse bounce (DESIGN.md §5; README, "Textures").
//!
//! A path's vertex reached through a diffuse bounce stands for a cone of directions, not one
//! ray: its albedo is read from the texture prefiltered over the cone's footprint there (a mip
//! level, box-filtered in linear values), not from the full-resolution texels under one point.
//! The estimate keeps its expectation wherever the light arriving at that vertex is even across
//! the footprint, which at under two degrees of cone is everywhere but along shadow edges that
//! the texture's own pattern follows, and then only in light that has bounced at least once.
//! What it saves is memory traffic: full-resolution reads at bounce vertices miss the cache at
//! almost every read and were 13 % of a reference render of Sponza's view S3, making textured
//! paths 24 % slower than untextured ones; a coarse level of every texture stays in cache.
//!
//! A first vertex, and what a mirror or glossy lobe shows of it, are read at full resolution:
//! a cone widens only at a diffuse bounce.

use glam::Vec3;
use scene::{Scene, Texture};

use crate::counters::RayKind;

/// The angle, in radians, a diffuse bounce's cone opens to (under 2°): narrow beside any one
/// path's share of the hemisphere (2π sr over a sample's 16 to 1024 paths), so prefiltering over
/// its footprint blurs texture detail no path resolves, and wide enough that a read a few metres
/// away falls to a level of a few kilobytes.
pub(crate) const DIFFUSE_SPREAD: f32 = 1.0 / 32.0;

/// The width of a path's cone at its current vertex, and how fast it grows along the next ray.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Footprint {
    width: f32,
    spread: f32,
}

impl Footprint {
    /// A path's first vertex: one point.
    pub(crate) const POINT: Footprint = Footprint {
        width: 0.0,
        spread: 0.0,
    };

    /// The footprint at the next vertex, `distance` along a continuation ray of `kind`: a
    /// diffuse bounce opens the cone to [`DIFFUSE_SPREAD`]; a mirror or glossy one carries it on
    /// as it is (a glossy lobe taken as sharp, so its reflections keep their detail).
    pub(crate) fn after(self, kind: RayKind, distance: f32) -> Footprint {
        let spread = if kind == RayKind::Bounce {
            self.spread.max(DIFFUSE_SPREAD)
        } else {
            self.spread
        };
        Footprint {
            width: self.width + spread * distance.max(0.0),
            spread,
        }
    }

    pub(crate) fn width(self) -> f32 {
        self.width
    }
}

/// Every texture's mip chain.
pub(crate) struct TextureLod {
    /// Per material: its texture's levels below the full resolution (empty without a texture).
    levels: Vec<Vec<Texture>>,
}

impl TextureLod {
    pub(crate) fn new(scene: &Scene) -> TextureLod {
        let levels = scene
            .materials
            .iter()
            .map(|m| {
                m.diffuse_map
                    .as_ref()
                    .map_or_else(Vec::new, |map| map.texture.mip_levels())
            })
            .collect();
        TextureLod { levels }
    }

    /// The level to read on triangle `t`, whose corners are at `corners`, under a footprint
    /// `width` wide: `None` for the full resolution, else an index into the material's levels
    /// (the coarsest when past it).
    pub(crate) fn level(
        &self,
        scene: &Scene,
        t: usize,
        corners: [Vec3; 3],
        width: f32,
    ) -> Option<usize> {
        let levels = &self.levels[scene.mesh.triangles[t].material as usize];
        if levels.is_empty() || width <= 0.0 {
            return None;
        }
        let texels_across = width / texel_side(scene, t, corners);
        if texels_across.is_nan() || texels_across < 2.0 {
            return None;
        }
        // Level k (from 1) has texels 2^k wide: the one whose texels are as wide as the
        // footprint, rounded down to a power of two.
        let k = texels_across.log2().floor() as usize;
        Some(k.min(levels.len()) - 1)
    }

    /// The diffuse albedo at barycentric weights `bary` of triangle `t` (corners at `corners`),
    /// read under a footprint `width` wide.
    pub(crate) fn albedo_at(
        &self,
        scene: &Scene,
        t: usize,
        corners: [Vec3; 3],
        bary: [f32; 2],
        width: f32,
    ) -> Vec3 {
        let material = scene.material_of(t);
        let (Some(map), Some(k)) = (&material.diffuse_map, self.level(scene, t, corners, width))
        else {
            return scene.albedo_at(t, bary);
        };
        let level = &self.levels[scene.mesh.triangles[t].material as usize][k];
        map.albedo_at_level(level, material.kd, scene.texcoord_at(t, bary))
    }
}

/// The world-space side of one full-resolution texel of triangle `t`'s texture on it, whose
/// corners are at `corners` (the square root of its area over the texels it covers): infinite
/// without a texture or with texture coordinates that span no area, where every read stays at
/// full resolution. Worked out at each read from the corners the hit has just loaded, rather
/// than kept per triangle: a table would cost one more cache miss at every bounce vertex.
fn texel_side(scene: &Scene, t: usize, [p, q, r]: [Vec3; 3]) -> f32 {
    let (Some(map), Some([a, b, c])) = (
        &scene.material_of(t).diffuse_map,
        scene.texcoords.get(t).copied(),
    ) else {
        return f32::INFINITY;
    };
    let world_area = (q - p).cross(r - p).length();
    let uv_area = (b - a).perp_dot(c - a).abs() * (map.scale.x * map.scale.y).abs();
    let texels = uv_area * map.texture.width() as f32 * map.texture.height() as f32;
    let side = (world_area / texels).sqrt();
    if side.is_finite() && side > 0.0 {
        side
    } else {
        f32::INFINITY
    }
}

#[cfg(test)]
mod tests;
