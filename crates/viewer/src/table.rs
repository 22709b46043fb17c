//! The viewer's triangle table, `triangle id -> 3 positions + what lights them` (DESIGN.md §2,
//! thesis §2.3): triangles stay available for drawing until the SMA orders their removal.
//!
//! The table is the CPU copy of the GPU vertex buffer, kept dense: slot `i` holds vertices
//! `3i..3i+3`, slots `0..len` are live and everything from `len` up to the buffer's capacity is free.
//! A removal moves the last live triangle into the freed slot (swap-remove), so insert, remove and
//! recolour each cost O(1) and touch at most two slots; the slots they touch are recorded so the GPU
//! copy is patched with partial uploads (`take_dirty_ranges`) instead of being re-sent. The thesis
//! had to sort its list to find triangles (§4.1, heapsort); a hash map from id to slot makes that
//! unnecessary.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use protocol::texture::Texcoords;
use protocol::viewer_link::{CornerShading, DirectShare, Recolour, ShownTriangle, TriangleId};

use crate::update::TableOp;

/// One vertex as the GPU reads it (DESIGN.md §5, "Parts, and textures"): position, the linear
/// RGB illumination the albedo multiplies, the share of it that is direct (0..1), which a
/// per-pixel direct tile replaces (`direct_image`), the view-dependent radiance added on top, and
/// the texture coordinates as the wire quantises them (`protocol::texture::Texcoords`): 16-bit
/// steps, with the triangle's material (low 16 bits of `surface`) and the steps' range (the 8
/// bits above), which `draw.wgsl` decodes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub illumination: [f32; 3],
    pub direct_share: f32,
    pub view_dependent: [f32; 3],
    pub texcoord: [u16; 2],
    pub surface: u32,
}

impl Vertex {
    /// The triangle's material, as `SceneInfo::materials` indexes it.
    pub fn material(&self) -> u16 {
        self.surface as u16
    }
}

/// Bytes of one triangle in the vertex buffer.
pub const TRIANGLE_BYTES: u64 = 3 * std::mem::size_of::<Vertex>() as u64;

/// What one batch of operations did, for logging and benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ApplyCounts {
    pub inserted: usize,
    /// Inserts of an id already held: the triangle is replaced in place.
    pub replaced: usize,
    pub removed: usize,
    pub recoloured: usize,
    /// Removes or recolours of ids the table does not hold, and triangles with non-finite positions.
    pub ignored: usize,
}

/// Axis-aligned box of everything ever inserted (it only grows; used for the depth range).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Extent {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

/// Hashes a triangle id with a 64-bit mixer (splitmix64's finaliser). The std SipHash guards
/// against adversarial keys, which the SMA's ids are not, at several times the cost; at a million
/// triangles the table's lookups are a large part of applying an update.
#[derive(Default)]
pub struct IdHasher(u64);

impl Hasher for IdHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(self.0 ^ u64::from(b));
        }
    }

    fn write_u64(&mut self, id: u64) {
        let mut x = id ^ self.0.rotate_left(5);
        x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        self.0 = x ^ (x >> 31);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

#[derive(Default)]
pub struct TriangleTable {
    slot_of: HashMap<TriangleId, u32, BuildHasherDefault<IdHasher>>,
    /// The id held by each live slot.
    ids: Vec<TriangleId>,
    vertices: Vec<Vertex>,
    /// Slots written since the last `take_dirty_ranges`, possibly repeated or past `len`.
    dirty: Vec<u32>,
    extent: Option<Extent>,
}

impl TriangleTable {
    pub fn new() -> Self {
        Self::default()
    }

    /// Live triangles.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    pub fn contains(&self, id: TriangleId) -> bool {
        self.slot_of.contains_key(&id)
    }

    /// The triangle held under `id`, as it would be drawn.
    pub fn get(&self, id: TriangleId) -> Option<ShownTriangle> {
        let slot = *self.slot_of.get(&id)? as usize;
        let v: [Vertex; 3] = std::array::from_fn(|k| self.vertices[3 * slot + k]);
        let mut texcoords = [0u8; 13];
        texcoords[0] = (v[0].surface >> 16) as u8;
        for (k, vertex) in v.iter().enumerate() {
            for (a, q) in vertex.texcoord.iter().enumerate() {
                texcoords[1 + 4 * k + 2 * a..3 + 4 * k + 2 * a].copy_from_slice(&q.to_le_bytes());
            }
        }
        let view_dependent = v.map(|v| v.view_dependent);
        Some(ShownTriangle {
            id,
            positions: v.map(|v| v.position),
            material: v[0].material(),
            texcoords: Texcoords(texcoords),
            shading: CornerShading {
                illumination: v.map(|v| v.illumination),
                direct_share: v.map(|v| DirectShare((v.direct_share * 255.0).round() as u8)),
                view_dependent: view_dependent
                    .iter()
                    .flatten()
                    .any(|&c| c != 0.0)
                    .then_some(view_dependent),
            },
        })
    }

    /// Ids of all live triangles, in slot order.
    pub fn ids(&self) -> &[TriangleId] {
        &self.ids
    }

    /// The live vertices, three per triangle.
    pub fn vertices(&self) -> &[Vertex] {
        &self.vertices
    }

    pub fn extent(&self) -> Option<Extent> {
        self.extent
    }

    /// Applies one closed update in message order (DESIGN.md §3: the SMA may insert children and
    /// remove their parent in the same update).
    pub fn apply(&mut self, ops: &[TableOp]) -> ApplyCounts {
        let mut counts = ApplyCounts::default();
        for op in ops {
            match op {
                TableOp::Insert(triangles) => {
                    for t in triangles {
                        self.insert(t, &mut counts);
                    }
                }
                TableOp::Remove(ids) => {
                    for &id in ids {
                        if self.remove(id) {
                            counts.removed += 1;
                        } else {
                            counts.ignored += 1;
                        }
                    }
                }
                TableOp::Recolour(recolours) => {
                    for r in recolours {
                        if self.recolour(r) {
                            counts.recoloured += 1;
                        } else {
                            counts.ignored += 1;
                        }
                    }
                }
            }
        }
        counts
    }

    fn insert(&mut self, t: &ShownTriangle, counts: &mut ApplyCounts) {
        if !t.positions.iter().flatten().all(|c| c.is_finite()) {
            counts.ignored += 1;
            return;
        }
        let slot = match self.slot_of.get(&t.id) {
            Some(&slot) => {
                counts.replaced += 1;
                slot
            }
            None => {
                let slot = self.ids.len() as u32;
                self.slot_of.insert(t.id, slot);
                self.ids.push(t.id);
                self.vertices.extend([Vertex::default(); 3]);
                counts.inserted += 1;
                slot
            }
        };
        let base = 3 * slot as usize;
        let range = u32::from(t.texcoords.0[0]);
        for k in 0..3 {
            let q = |a: usize| {
                let i = 1 + 4 * k + 2 * a;
                u16::from_le_bytes([t.texcoords.0[i], t.texcoords.0[i + 1]])
            };
            let vertex = &mut self.vertices[base + k];
            *vertex = Vertex {
                position: t.positions[k],
                texcoord: [q(0), q(1)],
                surface: u32::from(t.material) | range << 16,
                ..Vertex::default()
            };
            shade(vertex, &t.shading, k);
        }
        self.grow_extent(&t.positions);
        self.dirty.push(slot);
    }

    /// Swap-remove: the last live triangle fills the hole, so live slots stay dense.
    fn remove(&mut self, id: TriangleId) -> bool {
        let Some(slot) = self.slot_of.remove(&id) else {
            return false;
        };
        let slot = slot as usize;
        let last = self.ids.len() - 1;
        if slot != last {
            let moved = self.ids[last];
            self.ids[slot] = moved;
            self.vertices.copy_within(3 * last..3 * last + 3, 3 * slot);
            self.slot_of.insert(moved, slot as u32);
            self.dirty.push(slot as u32);
        }
        self.ids.truncate(last);
        self.vertices.truncate(3 * last);
        true
    }

    fn recolour(&mut self, r: &Recolour) -> bool {
        let Some(&slot) = self.slot_of.get(&r.id) else {
            return false;
        };
        let base = 3 * slot as usize;
        for k in 0..3 {
            shade(&mut self.vertices[base + k], &r.shading, k);
        }
        self.dirty.push(slot);
        true
    }

    fn grow_extent(&mut self, positions: &[[f32; 3]; 3]) {
        for &p in positions {
            let e = self.extent.get_or_insert(Extent { min: p, max: p });
            e.min = Vec3::from(e.min).min(Vec3::from(p)).to_array();
            e.max = Vec3::from(e.max).max(Vec3::from(p)).to_array();
        }
    }

    /// Empties the table (a new SMA session starts from nothing).
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Live slot ranges changed since the last call, sorted and coalesced; ranges closer than
    /// `merge_gap` slots are merged, because one larger upload costs less than many small ones.
    pub fn take_dirty_ranges(&mut self, merge_gap: u32) -> Vec<Range<u32>> {
        let len = self.ids.len() as u32;
        let mut slots = std::mem::take(&mut self.dirty);
        slots.retain(|&s| s < len);
        slots.sort_unstable();
        slots.dedup();
        let mut ranges: Vec<Range<u32>> = Vec::new();
        for s in slots {
            match ranges.last_mut() {
                Some(r) if s <= r.end + merge_gap => r.end = s + 1,
                _ => ranges.push(s..s + 1),
            }
        }
        ranges
    }

    /// Forgets pending changes (after a full upload).
    pub fn clear_dirty(&mut self) {
        self.dirty.clear();
    }
}

/// Corner `k` of `shading` into `vertex`.
fn shade(vertex: &mut Vertex, shading: &CornerShading, k: usize) {
    vertex.illumination = sanitize(shading.illumination[k]);
    vertex.direct_share = shading.direct_share[k].fraction();
    vertex.view_dependent = shading.view_dependent.map_or([0.0; 3], |v| sanitize(v[k]));
}

/// Values the shader can tone-map: non-finite or negative ones become 0 (never trust the wire).
fn sanitize(rgb: [f32; 3]) -> [f32; 3] {
    rgb.map(|c| if c.is_finite() && c > 0.0 { c } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(id: TriangleId, x: f32) -> ShownTriangle {
        ShownTriangle {
            id,
            positions: [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]],
            material: 2,
            texcoords: Texcoords::encode([[x, 0.5], [x + 0.25, 0.5], [x, 0.75]], false),
            shading: CornerShading {
                illumination: [[x; 3]; 3],
                direct_share: [DirectShare(9); 3],
                view_dependent: (x > 1.0).then_some([[0.5, 0.0, x]; 3]),
            },
        }
    }

    #[test]
    fn remove_keeps_slots_dense_and_marks_the_moved_slot() {
        let mut t = TriangleTable::new();
        t.apply(&[TableOp::Insert((0..4).map(|i| tri(i, i as f32)).collect())]);
        assert_eq!(t.take_dirty_ranges(0), vec![0..4]);
        let c = t.apply(&[TableOp::Remove(vec![1, 99])]);
        assert_eq!((c.removed, c.ignored), (1, 1));
        assert_eq!(t.ids(), &[0, 3, 2]);
        assert_eq!(t.get(3), Some(tri(3, 3.0)));
        assert_eq!(t.take_dirty_ranges(0), vec![1..2]);
    }

    #[test]
    fn dirty_ranges_merge_across_small_gaps_and_drop_dead_slots() {
        let mut t = TriangleTable::new();
        t.apply(&[TableOp::Insert((0..20).map(|i| tri(i, 0.0)).collect())]);
        t.clear_dirty();
        let recolour = |id| Recolour {
            id,
            shading: CornerShading::default(),
        };
        t.apply(&[TableOp::Recolour(vec![
            recolour(2),
            recolour(4),
            recolour(15),
        ])]);
        assert_eq!(t.take_dirty_ranges(2), vec![2..5, 15..16]);
        t.apply(&[
            TableOp::Recolour(vec![recolour(19)]),
            TableOp::Remove(vec![19]),
        ]);
        assert!(t.take_dirty_ranges(0).is_empty());
    }

    #[test]
    fn bad_values_from_the_wire_are_contained() {
        let mut t = TriangleTable::new();
        let mut nan_pos = tri(1, 0.0);
        nan_pos.positions[0][1] = f32::NAN;
        let mut bad_light = tri(2, 0.0);
        bad_light.shading.illumination[1] = [f32::INFINITY, -3.0, 2.0];
        bad_light.shading.view_dependent = Some([[f32::NAN, 1.0, -1.0]; 3]);
        let c = t.apply(&[TableOp::Insert(vec![nan_pos, bad_light])]);
        assert_eq!((c.inserted, c.ignored), (1, 1));
        let shading = t.get(2).unwrap().shading;
        assert_eq!(shading.illumination[1], [0.0, 0.0, 2.0]);
        assert_eq!(shading.view_dependent, Some([[0.0, 1.0, 0.0]; 3]));
    }
}
