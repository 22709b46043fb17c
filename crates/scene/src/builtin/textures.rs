//! Bracara's textures, generated in code (DESIGN.md §5, §11): paving, stone blocks, roof tiles,
//! plaster and water, each a small tiling image built deterministically at load from an integer
//! hash (no file, no random state), and the box projection that gives the town's faces their
//! texture coordinates.
//!
//! Each texel is the material's `Kd` times a pattern factor around one, so under the albedo rule
//! `texture` (the texel alone) a textured material keeps about the colour it had untextured:
//! the town looks the same from afar, with joints, blocks and tiles up close.

use glam::{Vec2, Vec3};

use crate::texture::Texture;

/// Texels a side: 256 × 256 × 3 bytes, 192 KiB per texture.
pub const SIDE: u32 = 256;

/// The patterns, each a factor (about 0.5 to 1.3) of the material's `Kd` at texture coordinates
/// `(u, v)` in 0..1, tiling across the edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pattern {
    /// Square slabs in a running bond with mortar joints, each slab its own shade.
    Paving,
    /// Ashlar: courses of long blocks, each course offset by half a block.
    StoneBlocks,
    /// Rows of curved tiles, each darker toward its lower edge where the next row overlaps it.
    RoofTiles,
    /// Mottled lime plaster with a few broad stains.
    Plaster,
    /// Ripples on still water.
    Water,
}

impl Pattern {
    /// The pattern's image for a material of colour `kd` (linear RGB).
    pub fn texture(self, kd: Vec3) -> Texture {
        let texels: Vec<[u8; 3]> = (0..SIDE * SIDE)
            .map(|i| {
                let (x, y) = (i % SIDE, i / SIDE);
                let (u, v) = (
                    (x as f32 + 0.5) / SIDE as f32,
                    (y as f32 + 0.5) / SIDE as f32,
                );
                let linear = (kd * self.factor(u, v)).min(Vec3::ONE);
                linear.to_array().map(conventions::tone_map::srgb8)
            })
            .collect();
        Texture::from_srgb8(SIDE, SIDE, &texels)
    }

    /// Metres of the scene one repeat of the image covers.
    pub fn repeat_m(self) -> f32 {
        match self {
            Pattern::Paving => 4.0,
            Pattern::StoneBlocks => 3.0,
            Pattern::RoofTiles => 2.0,
            Pattern::Plaster => 6.0,
            Pattern::Water => 4.0,
        }
    }

    fn factor(self, u: f32, v: f32) -> f32 {
        let grain = 0.08 * (fbm(u, v, 16, 4, self as u32) - 0.5);
        match self {
            Pattern::Paving => bond(u, v, 4, 4, 0.03, 1) + grain,
            Pattern::StoneBlocks => bond(u, v, 3, 6, 0.025, 2) + grain,
            Pattern::RoofTiles => {
                let (rows, across) = (8.0, 8.0);
                let (row, along) = ((v * rows).floor(), (v * rows).fract());
                let shift = if row as u32 % 2 == 1 { 0.5 } else { 0.0 };
                let column = (u * across + shift).floor();
                // A curved tile: lit on its crown, shaded toward its sides and its lower edge.
                let across_tile = (u * across + shift).fract();
                let crown = (std::f32::consts::PI * across_tile).sin();
                let shade = 0.75 + 0.3 * crown - 0.25 * (1.0 - along).powi(4);
                let tint = 0.88 + 0.24 * hash(column as u32 % 8, row as u32, 3);
                shade * tint + grain
            }
            Pattern::Plaster => {
                0.82 + 0.34 * fbm(u, v, 4, 5, 4) + 0.12 * (fbm(u, v, 32, 2, 5) - 0.5)
            }
            Pattern::Water => {
                let tau = std::f32::consts::TAU;
                let ripple = (tau * (3.0 * u + 2.0 * v) + 2.0 * fbm(u, v, 4, 3, 6)).sin()
                    * (tau * (5.0 * v - u) + 3.0 * fbm(u, v, 8, 2, 7)).sin();
                1.0 + 0.25 * ripple
            }
        }
    }
}

/// Blocks `across` per row and `rows` rows per image, every other row shifted by half a block,
/// with joints `joint` wide (a fraction of the image) at 0.55: each block its own shade.
fn bond(u: f32, v: f32, across: u32, rows: u32, joint: f32, seed: u32) -> f32 {
    let row = (v * rows as f32).floor() as u32 % rows;
    let shift = if row % 2 == 1 { 0.5 } else { 0.0 };
    let x = u * across as f32 + shift;
    let column = x.floor() as u32 % across;
    let (fx, fy) = (x.fract(), (v * rows as f32).fract());
    let (jx, jy) = (joint * across as f32, joint * rows as f32);
    if fx < jx || fy < jy {
        return 0.55;
    }
    0.85 + 0.3 * hash(column, row, seed)
}

/// A hash of a lattice point to 0..1.
fn hash(x: u32, y: u32, seed: u32) -> f32 {
    let mut h =
        x.wrapping_mul(0x8da6_b343) ^ y.wrapping_mul(0xd816_3841) ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0x00ff_ffff) as f32 / 16_777_216.0
}

/// Value noise with `cells` cells across the image, smoothly interpolated, tiling.
fn value_noise(u: f32, v: f32, cells: u32, seed: u32) -> f32 {
    let (x, y) = (u * cells as f32, v * cells as f32);
    let (x0, y0) = (x.floor(), y.floor());
    let smooth = |t: f32| t * t * (3.0 - 2.0 * t);
    let (fx, fy) = (smooth(x - x0), smooth(y - y0));
    let at = |i: f32, j: f32| {
        hash(
            (i as i64).rem_euclid(cells as i64) as u32,
            (j as i64).rem_euclid(cells as i64) as u32,
            seed,
        )
    };
    let top = at(x0, y0) + (at(x0 + 1.0, y0) - at(x0, y0)) * fx;
    let bottom = at(x0, y0 + 1.0) + (at(x0 + 1.0, y0 + 1.0) - at(x0, y0 + 1.0)) * fx;
    top + (bottom - top) * fy
}

/// `octaves` of value noise from `cells` cells up, each half the weight of the last: 0..1.
fn fbm(u: f32, v: f32, cells: u32, octaves: u32, seed: u32) -> f32 {
    let (mut sum, mut weight, mut total) = (0.0, 1.0, 0.0);
    for k in 0..octaves {
        sum += weight * value_noise(u, v, cells << k, seed.wrapping_add(k));
        total += weight;
        weight *= 0.5;
    }
    sum / total
}

/// Box projection: a triangle's texture coordinates are its corners' coordinates across the axis
/// its normal is closest to, in repeats of `repeat_m` metres, so a face of any orientation gets
/// the pattern at its true size (stretched at most by √2 on a face at 45° to two axes).
pub fn box_projection(corners: [Vec3; 3], repeat_m: f32) -> [Vec2; 3] {
    let n = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .abs();
    let plane = |p: Vec3| {
        if n.y >= n.x && n.y >= n.z {
            Vec2::new(p.x, -p.z)
        } else if n.x >= n.z {
            Vec2::new(-p.z, p.y)
        } else {
            Vec2::new(p.x, p.y)
        }
    };
    corners.map(|p| plane(p) / repeat_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Pattern; 5] = [
        Pattern::Paving,
        Pattern::StoneBlocks,
        Pattern::RoofTiles,
        Pattern::Plaster,
        Pattern::Water,
    ];

    /// Each pattern is the same image every time, shows a pattern (not a flat colour), and keeps
    /// about the material's colour on average.
    #[test]
    fn patterns_are_deterministic_varied_and_about_kd_on_average() {
        let kd = Vec3::new(0.5, 0.4, 0.3);
        for pattern in ALL {
            let texture = pattern.texture(kd);
            assert_eq!(texture, pattern.texture(kd), "{pattern:?} is deterministic");
            let mean = texture.mean();
            assert!(
                (mean / kd - Vec3::ONE).abs().max_element() < 0.15,
                "{pattern:?}: mean {mean} for Kd {kd}"
            );
            let lum = |t: Vec3| conventions::luminance(t.to_array());
            let (mut lo, mut hi) = (f32::MAX, 0.0f32);
            for y in 0..SIDE {
                for x in 0..SIDE {
                    let l = lum(texture.texel(x, y));
                    lo = lo.min(l);
                    hi = hi.max(l);
                }
            }
            assert!(hi > 1.3 * lo, "{pattern:?} varies: {lo}..{hi}");
        }
    }

    /// The patterns tile: the first and last columns (rows) are as close as neighbouring ones.
    #[test]
    fn noise_tiles_across_the_edges() {
        for cells in [4, 16] {
            let (a, b) = (
                value_noise(0.0, 0.3, cells, 1),
                value_noise(1.0, 0.3, cells, 1),
            );
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
    }

    /// Box projection keeps lengths on an axis-aligned face: a 4 m edge is one repeat of 4 m.
    #[test]
    fn box_projection_keeps_true_size() {
        let floor = [
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 4.0),
            Vec3::new(4.0, 0.0, 0.0),
        ];
        let uv = box_projection(floor, 4.0);
        assert_eq!((uv[1] - uv[0]).length(), 1.0);
        assert_eq!((uv[2] - uv[0]).length(), 1.0);
        let wall = [
            Vec3::ZERO,
            Vec3::new(3.0, 0.0, 0.0),
            Vec3::new(0.0, 3.0, 0.0),
        ];
        let uv = box_projection(wall, 3.0);
        assert_eq!(uv[1] - uv[0], Vec2::X);
        assert_eq!(uv[2] - uv[0], Vec2::Y);
    }
}
