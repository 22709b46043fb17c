//! Packet traversal of the eight-wide BVH (`wide_bvh`, DESIGN.md §7): up to [`PACKET`] rays that
//! share their direction octant walk the tree together. Coherent rays (a pixel tile's camera rays
//! from one eye, shadow rays toward the sun, which share nearly one direction) mostly enter the
//! same nodes, so a packet reads each node once for all of them, and the per-node work of the
//! one-ray traversal (stack, branches) is paid once per packet instead of once per ray.
//!
//! The stack holds (child, rays that entered it). At an inner node every ray of the entry is
//! tested against each occupied child box, eight rays per vector step (SIMD across rays, where
//! `wide_traversal` goes across children), which gives each child's rays directly. Sharing the
//! octant is what lets one plane choice (`near`) serve every ray. At a leaf each of the entry's
//! rays runs obvhs's triangle test, as in `wide_traversal`, with its own best distance; the box
//! arithmetic is the one-ray test's too, so every ray gets the answers of the one-ray traversal
//! (its closest hit, or its verdict for occlusion), only the order of visits differs.
//!
//! Both box tests ([`Sse`], [`Avx2`]) and both loops are `#[inline(always)]`, compiled inside each
//! of `bvh.rs`'s entry points with that entry point's target features.

use std::arch::x86_64::*;

use glam::Vec3;
use obvhs::ray::Ray;
use obvhs::rt_triangle::RtTriangle;

use crate::wide_bvh::{LEAF, WideBvh, WideNode};
use crate::wide_traversal::{
    Avx2, EXIT_SLACK, EntryDistance, Query, Sse, Stack, leaf_any, leaf_nearest,
};

/// Rays in a packet: one AVX register of lanes.
pub(crate) const PACKET: usize = crate::bvh::PACKET_RAYS;

/// A set of a packet's rays, a bit per lane.
type Lanes = u32;

/// The lanes of `lanes`, lowest first.
fn each_lane(mut lanes: Lanes) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        let lane = lanes.trailing_zeros() as usize;
        lanes &= lanes.wrapping_sub(1);
        (lane < PACKET).then_some(lane)
    })
}

/// Up to [`PACKET`] rays of one direction octant, prepared for box tests lane by lane (the
/// fields of `wide_traversal::Query`, structure of arrays). Unused lanes repeat the first ray
/// with tmax −∞, so no box test lets them in.
pub(crate) struct Packet {
    rays: [Ray; PACKET],
    /// The lanes that hold rays.
    live: Lanes,
    origin: [[f32; PACKET]; 3],
    inv: [[f32; PACKET]; 3],
    origin_inv: [[f32; PACKET]; 3],
    tmax: [f32; PACKET],
    /// Index into `WideNode::bounds` of the planes met first on each axis, shared by every ray
    /// (always below 6: the box tests read them unchecked).
    near: [usize; 3],
}

impl Packet {
    /// The segments `origins[k] + t dirs[k]`, t in (0, tmaxs[k]). None unless there are 1 to
    /// [`PACKET`] of them, all in one direction octant.
    pub(crate) fn new(origins: &[Vec3], dirs: &[Vec3], tmaxs: &[f32]) -> Option<Packet> {
        let len = origins.len();
        if len == 0 || len > PACKET || dirs.len() != len || tmaxs.len() != len {
            return None;
        }
        // Most mixed packets (bounce rays) show it in their directions' signs: refused before
        // any ray is prepared. `near` below has the last word.
        let signs = |dir: &Vec3| dir.cmplt(Vec3::ZERO).bitmask();
        if dirs.iter().any(|dir| signs(dir) != signs(&dirs[0])) {
            return None;
        }
        let first = Query::new(origins[0], dirs[0], tmaxs[0]);
        let mut packet = Packet {
            rays: [first.ray; PACKET],
            live: (1 << len) - 1,
            origin: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            origin_inv: [[0.0; PACKET]; 3],
            tmax: [f32::NEG_INFINITY; PACKET],
            near: first.near,
        };
        for lane in 0..PACKET {
            let q = if lane < len {
                Query::new(origins[lane], dirs[lane], tmaxs[lane])
            } else {
                Query::new(origins[0], dirs[0], f32::NEG_INFINITY)
            };
            if q.near != first.near {
                return None;
            }
            packet.rays[lane] = q.ray;
            packet.tmax[lane] = q.ray.tmax;
            for axis in 0..3 {
                packet.origin[axis][lane] = q.origin[axis];
                packet.inv[axis][lane] = q.inv[axis];
                packet.origin_inv[axis][lane] = q.origin_inv[axis];
            }
        }
        Some(packet)
    }
}

/// The children of a node that a packet's rays enter.
pub(crate) trait PacketBoxTest {
    /// For each occupied child slot of `node`, which of the rays `rays` enter its box within
    /// (0, tmax[lane]) (`enter[slot]`) and the nearest of their entry distances
    /// (`nearest[slot]`); returns the slots some ray enters (only those are written).
    ///
    /// # Safety
    /// The CPU must have the implementation's instructions.
    unsafe fn packet_hits(
        node: &WideNode,
        p: &Packet,
        tmax: &[f32; PACKET],
        rays: Lanes,
        enter: &mut [Lanes; 8],
        nearest: &mut [f32; 8],
    ) -> u32;
}

/// The slots of `node` that hold a child (an empty one has lower plane +∞ above upper −∞).
#[inline(always)]
fn occupied_slots(node: &WideNode) -> u32 {
    let mut slots = 0;
    for slot in 0..8 {
        slots |= u32::from(node.bounds[0][slot] <= node.bounds[1][slot]) << slot;
    }
    slots
}

/// Plane `index` (of `WideNode::bounds`) of child `slot`.
///
/// # Safety
/// `index` below 6 and `slot` below 8.
#[inline(always)]
unsafe fn plane(node: &WideNode, index: usize, slot: usize) -> f32 {
    // SAFETY: the caller keeps both indices in range.
    unsafe { *node.bounds.get_unchecked(index).get_unchecked(slot) }
}

/// The least of four lanes.
#[inline(always)]
unsafe fn min_lane4(v: __m128) -> f32 {
    // SAFETY: SSE is part of x86-64.
    unsafe {
        let v = _mm_min_ps(v, _mm_movehl_ps(v, v));
        _mm_cvtss_f32(_mm_min_ss(v, _mm_shuffle_ps::<1>(v, v)))
    }
}

/// Entry and exit distances of four rays (lanes `half..half + 4`) through child `slot`'s slab
/// on one axis: `wide_traversal`'s SSE arithmetic, lane by lane.
#[inline(always)]
unsafe fn slab_sse(
    node: &WideNode,
    p: &Packet,
    axis: usize,
    slot: usize,
    half: usize,
) -> (__m128, __m128) {
    // SAFETY: SSE is part of x86-64; `near` and `near ^ 1` are below 6, `slot` below 8, and the
    // four lanes from `half` (0 or 4) lie inside the packet's arrays.
    unsafe {
        let o = _mm_loadu_ps(p.origin.get_unchecked(axis).as_ptr().add(half));
        let inv = _mm_loadu_ps(p.inv.get_unchecked(axis).as_ptr().add(half));
        let near = _mm_set1_ps(plane(node, p.near[axis], slot));
        let far = _mm_set1_ps(plane(node, p.near[axis] ^ 1, slot));
        (
            _mm_mul_ps(_mm_sub_ps(near, o), inv),
            _mm_mul_ps(_mm_sub_ps(far, o), inv),
        )
    }
}

/// All-ones in the lanes `half..half + 4` of `rays`, as a mask for four-wide values.
#[inline(always)]
unsafe fn lane_mask4(rays: Lanes, half: usize) -> __m128 {
    // SAFETY: SSE2 is part of x86-64.
    unsafe {
        let bits = _mm_setr_epi32(1, 2, 4, 8);
        let set = _mm_and_si128(_mm_set1_epi32((rays >> half) as i32), bits);
        _mm_castsi128_ps(_mm_cmpeq_epi32(set, bits))
    }
}

impl PacketBoxTest for Sse {
    #[inline(always)]
    unsafe fn packet_hits(
        node: &WideNode,
        p: &Packet,
        tmax: &[f32; PACKET],
        rays: Lanes,
        enter: &mut [Lanes; 8],
        nearest: &mut [f32; 8],
    ) -> u32 {
        // SAFETY: SSE is part of x86-64; the loads stay inside `tmax`.
        unsafe {
            let lanes = [lane_mask4(rays, 0), lane_mask4(rays, 4)];
            let tmax = [
                _mm_loadu_ps(tmax.as_ptr()),
                _mm_loadu_ps(tmax.as_ptr().add(4)),
            ];
            let far_away = _mm_set1_ps(f32::INFINITY);
            let mut children = 0;
            let mut slots = occupied_slots(node);
            while slots != 0 {
                let slot = slots.trailing_zeros() as usize;
                slots &= slots - 1;
                let mut entered = 0;
                let mut closest = far_away;
                for (k, half) in [0, 4].into_iter().enumerate() {
                    let (nx, fx) = slab_sse(node, p, 0, slot, half);
                    let (ny, fy) = slab_sse(node, p, 1, slot, half);
                    let (nz, fz) = slab_sse(node, p, 2, slot, half);
                    let entry = _mm_max_ps(_mm_max_ps(nx, ny), _mm_max_ps(nz, _mm_setzero_ps()));
                    let exit = _mm_min_ps(_mm_min_ps(fx, fy), _mm_min_ps(fz, tmax[k]));
                    let exit = _mm_mul_ps(exit, _mm_set1_ps(EXIT_SLACK));
                    let hit = _mm_and_ps(_mm_cmple_ps(entry, exit), lanes[k]);
                    entered |= (_mm_movemask_ps(hit) as u32) << half;
                    let entry = _mm_or_ps(_mm_and_ps(hit, entry), _mm_andnot_ps(hit, far_away));
                    closest = _mm_min_ps(closest, entry);
                }
                if entered != 0 {
                    children |= 1 << slot;
                    enter[slot] = entered;
                    nearest[slot] = min_lane4(closest);
                }
            }
            children
        }
    }
}

/// Entry and exit distances of the packet's eight rays through child `slot`'s slab on one axis:
/// `wide_traversal`'s fused AVX arithmetic, lane by lane.
#[inline(always)]
unsafe fn slab_avx(node: &WideNode, p: &Packet, axis: usize, slot: usize) -> (__m256, __m256) {
    // SAFETY: the caller runs with AVX and FMA enabled; `near` and `near ^ 1` are below 6,
    // `slot` below 8, `axis` below 3.
    unsafe {
        let inv = _mm256_loadu_ps(p.inv.get_unchecked(axis).as_ptr());
        let o_inv = _mm256_loadu_ps(p.origin_inv.get_unchecked(axis).as_ptr());
        let near = _mm256_set1_ps(plane(node, p.near[axis], slot));
        let far = _mm256_set1_ps(plane(node, p.near[axis] ^ 1, slot));
        (
            _mm256_fmsub_ps(near, inv, o_inv),
            _mm256_fmsub_ps(far, inv, o_inv),
        )
    }
}

impl PacketBoxTest for Avx2 {
    #[inline(always)]
    unsafe fn packet_hits(
        node: &WideNode,
        p: &Packet,
        tmax: &[f32; PACKET],
        rays: Lanes,
        enter: &mut [Lanes; 8],
        nearest: &mut [f32; 8],
    ) -> u32 {
        // SAFETY: the caller runs with AVX2 and FMA enabled; the load stays inside `tmax`.
        unsafe {
            let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let set = _mm256_and_si256(_mm256_set1_epi32(rays as i32), bits);
            let lanes = _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, bits));
            let tmax = _mm256_loadu_ps(tmax.as_ptr());
            let far_away = _mm256_set1_ps(f32::INFINITY);
            let mut children = 0;
            let mut slots = occupied_slots(node);
            while slots != 0 {
                let slot = slots.trailing_zeros() as usize;
                slots &= slots - 1;
                let (nx, fx) = slab_avx(node, p, 0, slot);
                let (ny, fy) = slab_avx(node, p, 1, slot);
                let (nz, fz) = slab_avx(node, p, 2, slot);
                let entry = _mm256_max_ps(
                    _mm256_max_ps(nx, ny),
                    _mm256_max_ps(nz, _mm256_setzero_ps()),
                );
                let exit = _mm256_min_ps(_mm256_min_ps(fx, fy), _mm256_min_ps(fz, tmax));
                let exit = _mm256_mul_ps(exit, _mm256_set1_ps(EXIT_SLACK));
                let hit = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(entry, exit), lanes);
                let entered = _mm256_movemask_ps(hit) as u32;
                if entered != 0 {
                    children |= 1 << slot;
                    enter[slot] = entered;
                    let entry = _mm256_blendv_ps(far_away, entry, hit);
                    nearest[slot] = min_lane4(_mm_min_ps(
                        _mm256_castps256_ps128(entry),
                        _mm256_extractf128_ps::<1>(entry),
                    ));
                }
            }
            children
        }
    }
}

/// A closest-hit stack entry: a child, the rays that entered it, and the nearest of their entry
/// distances.
#[derive(Clone, Copy)]
struct Pending {
    child: u32,
    rays: Lanes,
    nearest: f32,
}

impl EntryDistance for Pending {
    #[inline(always)]
    fn entry_distance(&self) -> f32 {
        self.nearest
    }
}

/// The farthest of the live lanes' distances: no child entered beyond it can improve any ray.
#[inline(always)]
fn farthest(best: &[f32; PACKET], live: Lanes) -> f32 {
    each_lane(live).fold(f32::NEG_INFINITY, |far, lane| far.max(best[lane]))
}

/// Each ray's closest hit before its tmax: (BVH primitive, distance), by lane.
///
/// # Safety
/// The CPU must have `B`'s instructions.
#[inline(always)]
pub(crate) unsafe fn closest<B: PacketBoxTest>(
    bvh: &WideBvh,
    prims: &[RtTriangle],
    p: &Packet,
    hits: &mut [Option<(u32, f32)>; PACKET],
) {
    *hits = [None; PACKET];
    if bvh.nodes.is_empty() {
        return;
    }
    let mut stack = Stack::<Pending>::new();
    let mut best = p.tmax;
    let mut farthest_best = farthest(&best, p.live);
    let (mut enter, mut nearest) = ([0; 8], [0f32; 8]);
    let (mut current, mut rays) = (0u32, p.live);
    'visit: loop {
        if current & LEAF == 0 {
            let node = &bvh.nodes[current as usize];
            // SAFETY: the caller guarantees `B`'s instructions.
            let mut children =
                unsafe { B::packet_hits(node, p, &best, rays, &mut enter, &mut nearest) };
            if children != 0 {
                let first = children.trailing_zeros() as usize;
                children &= children - 1;
                if children == 0 {
                    (current, rays) = (node.child[first], enter[first]);
                    continue 'visit;
                }
                // Several children: nearest on top (by the nearest ray's entry), as in
                // `wide_traversal::closest`.
                let base = stack.len;
                let pending = |slot: usize| Pending {
                    child: node.child[slot],
                    rays: enter[slot],
                    nearest: nearest[slot],
                };
                stack.insert_sorted(base, pending(first));
                while children != 0 {
                    let slot = children.trailing_zeros() as usize;
                    children &= children - 1;
                    stack.insert_sorted(base, pending(slot));
                }
            }
        } else {
            let mut improved = false;
            for lane in each_lane(rays) {
                if let Some((prim, t)) = leaf_nearest(prims, current, &p.rays[lane], best[lane]) {
                    best[lane] = t;
                    hits[lane] = Some((prim, t));
                    improved = true;
                }
            }
            if improved {
                farthest_best = farthest(&best, p.live);
            }
        }
        // Next on the stack, skipping children that every ray enters only beyond its best hit.
        loop {
            let Some(next) = stack.pop() else {
                return;
            };
            if next.nearest <= farthest_best {
                (current, rays) = (next.child, next.rays);
                continue 'visit;
            }
        }
    }
}

/// For each ray, some primitive (BVH order) hit before its tmax, by lane: the first found, not
/// the nearest. A ray that finds one leaves the packet; the walk ends when none is left.
///
/// # Safety
/// The CPU must have `B`'s instructions.
#[inline(always)]
pub(crate) unsafe fn any<B: PacketBoxTest>(
    bvh: &WideBvh,
    prims: &[RtTriangle],
    p: &Packet,
    occluders: &mut [Option<u32>; PACKET],
) {
    *occluders = [None; PACKET];
    if bvh.nodes.is_empty() {
        return;
    }
    let mut stack = Stack::<(u32, Lanes)>::new();
    // A blocked ray's tmax becomes −∞, so no box lets it in again.
    let mut tmax = p.tmax;
    let mut unblocked = p.live;
    let (mut enter, mut nearest) = ([0; 8], [0f32; 8]);
    let (mut current, mut rays) = (0u32, p.live);
    loop {
        if current & LEAF == 0 {
            let node = &bvh.nodes[current as usize];
            // SAFETY: the caller guarantees `B`'s instructions.
            let mut children =
                unsafe { B::packet_hits(node, p, &tmax, rays, &mut enter, &mut nearest) };
            while children != 0 {
                let slot = children.trailing_zeros() as usize;
                children &= children - 1;
                stack.push((node.child[slot], enter[slot]));
            }
        } else {
            for lane in each_lane(rays) {
                if let Some(prim) = leaf_any(prims, current, &p.rays[lane]) {
                    occluders[lane] = Some(prim);
                    tmax[lane] = f32::NEG_INFINITY;
                    unblocked &= !(1 << lane);
                }
            }
            if unblocked == 0 {
                return;
            }
        }
        // Next on the stack, dropping the rays blocked since it was pushed.
        loop {
            let Some((child, entered)) = stack.pop() else {
                return;
            };
            if entered & unblocked != 0 {
                (current, rays) = (child, entered & unblocked);
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_packet_holds_one_to_eight_rays_of_one_octant() {
        let dirs = [Vec3::new(0.1, 1.0, -0.2), Vec3::new(0.3, 0.5, -0.1)];
        let (origins, tmaxs) = ([Vec3::ZERO; 2], [1.0; 2]);
        let packet = Packet::new(&origins, &dirs, &tmaxs).expect("one octant");
        assert_eq!(packet.live, 0b11);
        assert_eq!(packet.tmax[2..], [f32::NEG_INFINITY; PACKET - 2]);
        let mixed = [dirs[0], Vec3::new(-0.3, 0.5, -0.1)];
        assert!(Packet::new(&origins, &mixed, &tmaxs).is_none());
        assert!(Packet::new(&[], &[], &[]).is_none());
        let nine = [Vec3::ONE; PACKET + 1];
        assert!(Packet::new(&nine, &nine, &[1.0; PACKET + 1]).is_none());
    }

    #[test]
    fn each_lane_lists_the_set_bits_lowest_first() {
        assert_eq!(each_lane(0b1010_0101).collect::<Vec<_>>(), [0, 2, 5, 7]);
        assert_eq!(each_lane(0).count(), 0);
    }
}
