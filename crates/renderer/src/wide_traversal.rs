//! Traversal of the eight-wide BVH (`wide_bvh`, DESIGN.md §7): one ray against eight child boxes
//! at a time, nearest child first, a stack of (child, entry distance) pairs so that a closest-hit
//! query skips what lies beyond its best hit.
//!
//! The leaf children a ray enters are tested at once, during their parent's visit, and only the
//! inner children go onto the stack: a hit found there narrows the closest-hit query before it
//! descends (and ends an occlusion query), and a leaf never costs a push, a pop and a
//! mispredicted "leaf or node?" branch. On Sponza S1 this made the path estimator's samples about
//! 4 % faster (old and new timed in turn, as in BENCHMARKS.md's samples per second). A leaf's triangles (one to three) are tested one by
//! one with obvhs's own test, from the primitive list in BVH order: a four-wide test of them
//! needed a padded copy of every leaf, three times the memory, and measured slower (the leaves
//! stop fitting in cache). A compact 48-byte triangle gained nothing, and prefetching a node's
//! leaves was slower.
//!
//! Where a ray enters several inner children, they go onto the stack farthest first: by
//! insertion at the baseline level; with AVX2 by a sorting network over eight keys in one
//! register (the entry distance's bits with the slot in their low bits), whose results are
//! written as eight stack entries at once. The network has no data-dependent branch, where
//! insertion mispredicts; it made samples about 4 % faster. Used for one inner child as well
//! (instead of descending into it directly) it was 6 % slower: its latency then lies on every
//! step.
//!
//! Measured and rejected on the same scene: ordering an occlusion query's children nearest first
//! (much slower: the sort costs more than the order saves), keeping only the nearest child on top
//! of the stack instead of sorting them, and walking four rays in turns with prefetches (the
//! traversal is not bound by memory latency here).
//!
//! The box test comes in two widths behind [`BoxTest`]: [`Sse`] (two four-wide halves, the
//! x86-64 baseline) and [`Avx2`] (one eight-wide step, for `x86-64-v3`). Both loops are
//! `#[inline(always)]`, so each of `bvh.rs`'s entry points compiles them with its own target
//! features.

use std::arch::x86_64::*;
use std::mem::MaybeUninit;

use glam::Vec3;

use obvhs::ray::Ray;
use obvhs::rt_triangle::RtTriangle;

use crate::wide_bvh::{STACK, WideBvh, WideNode, leaf_range};

/// A ray prepared for box tests: obvhs's ray (for the triangle test), and per axis its origin,
/// reciprocal direction (obvhs's `safe_inverse`: an axis-parallel ray gets a large finite one,
/// so a plane through the origin gives 0, never 0 · ∞), their product, and which of a node's
/// plane arrays the ray meets first.
pub(crate) struct Query {
    pub(crate) ray: Ray,
    pub(crate) origin: [f32; 3],
    pub(crate) inv: [f32; 3],
    /// origin · inv, for the fused slab test.
    pub(crate) origin_inv: [f32; 3],
    /// Index into `WideNode::bounds` of the planes met first on each axis (always below 6: the
    /// box tests read them unchecked).
    pub(crate) near: [usize; 3],
}

impl Query {
    /// The segment `origin + t dir`, t in (0, tmax).
    pub(crate) fn new(origin: Vec3, dir: Vec3, tmax: f32) -> Query {
        let ray = Ray::new(origin.into(), dir.into(), 0.0, tmax);
        let origin = origin.to_array();
        let inv = ray.inv_direction.to_array();
        Query {
            ray,
            origin,
            inv,
            origin_inv: [0, 1, 2].map(|axis| origin[axis] * inv[axis]),
            near: [0, 1, 2].map(|axis| 2 * axis + usize::from(inv[axis] < 0.0)),
        }
    }
}

/// Slack on a box's exit distance, so rounding in the slab test never loses a box the ray
/// grazes (a few ulps, as in robust BVH traversal).
pub(crate) const EXIT_SLACK: f32 = 1.0 + 4.0 * f32::EPSILON;

/// The children of a node that a ray enters within (0, tmax): a bit per slot, and each slot's
/// entry distance in `entry`.
pub(crate) trait BoxTest {
    /// # Safety
    /// The CPU must have the implementation's instructions.
    unsafe fn hits(node: &WideNode, q: &Query, tmax: f32, entry: &mut [f32; 8]) -> u32;

    /// Pushes the children of `node` in `slots` (a bit per slot, two or more), entered at
    /// `entry`, onto `stack`, farthest deepest, so the nearest is on top. By insertion here; the
    /// AVX2 test sorts them in registers.
    ///
    /// # Safety
    /// As [`hits`](Self::hits).
    #[inline(always)]
    unsafe fn push_nearest_last(
        node: &WideNode,
        entry: &[f32; 8],
        mut slots: u32,
        stack: &mut Stack<Entered>,
    ) {
        let base = stack.len;
        while slots != 0 {
            let slot = slots.trailing_zeros() as usize;
            slots &= slots - 1;
            stack.insert_sorted(base, Entered::new(node.child[slot], entry[slot]));
        }
    }
}

/// Two four-wide SSE halves: every x86-64 has them.
pub(crate) struct Sse;

/// Entry and exit distances through four children's slabs (from `half`) on one axis.
#[inline(always)]
unsafe fn slabs4(node: &WideNode, q: &Query, axis: usize, half: usize) -> (__m128, __m128) {
    // SAFETY: SSE is part of x86-64; loads stay inside the node's arrays (`half` is 0 or 4,
    // `near` and `near ^ 1` below 6).
    unsafe {
        let o = _mm_set1_ps(q.origin[axis]);
        let inv = _mm_set1_ps(q.inv[axis]);
        let near = _mm_loadu_ps(node.bounds.get_unchecked(q.near[axis]).as_ptr().add(half));
        let far = _mm_loadu_ps(
            node.bounds
                .get_unchecked(q.near[axis] ^ 1)
                .as_ptr()
                .add(half),
        );
        (
            _mm_mul_ps(_mm_sub_ps(near, o), inv),
            _mm_mul_ps(_mm_sub_ps(far, o), inv),
        )
    }
}

impl BoxTest for Sse {
    #[inline(always)]
    unsafe fn hits(node: &WideNode, q: &Query, tmax: f32, entry: &mut [f32; 8]) -> u32 {
        // SAFETY: SSE is part of x86-64.
        unsafe {
            let mut mask = 0;
            for half in [0, 4] {
                let (nx, fx) = slabs4(node, q, 0, half);
                let (ny, fy) = slabs4(node, q, 1, half);
                let (nz, fz) = slabs4(node, q, 2, half);
                let enter = _mm_max_ps(_mm_max_ps(nx, ny), _mm_max_ps(nz, _mm_setzero_ps()));
                let exit = _mm_min_ps(_mm_min_ps(fx, fy), _mm_min_ps(fz, _mm_set1_ps(tmax)));
                let exit = _mm_mul_ps(exit, _mm_set1_ps(EXIT_SLACK));
                _mm_storeu_ps(entry.as_mut_ptr().add(half), enter);
                mask |= (_mm_movemask_ps(_mm_cmple_ps(enter, exit)) as u32) << half;
            }
            mask
        }
    }
}

/// One eight-wide AVX step.
pub(crate) struct Avx2;

/// Entry and exit distances of the ray through eight children's slabs on one axis. A function,
/// not a closure: a closure would not inherit the caller's target features, and 256-bit values
/// crossing a call compiled without AVX cost more than the whole test.
#[inline(always)]
unsafe fn slabs8(node: &WideNode, q: &Query, axis: usize) -> (__m256, __m256) {
    // SAFETY: the caller runs with AVX enabled; `WideNode` is 64-byte aligned, so each 32-byte
    // plane array is aligned; `near` and `near ^ 1` are below 6.
    unsafe {
        let o_inv = _mm256_set1_ps(q.origin_inv[axis]);
        let inv = _mm256_set1_ps(q.inv[axis]);
        let near = _mm256_load_ps(node.bounds.get_unchecked(q.near[axis]).as_ptr());
        let far = _mm256_load_ps(node.bounds.get_unchecked(q.near[axis] ^ 1).as_ptr());
        (
            _mm256_fmsub_ps(near, inv, o_inv),
            _mm256_fmsub_ps(far, inv, o_inv),
        )
    }
}

/// One layer of compare-exchanges of a descending sorting network: each lane meets lane
/// `partner[lane]` and keeps the larger of the two where it is the lower lane of its pair, the
/// smaller where it is the upper one (its bit set in `UPPER_IS_MIN`).
#[inline(always)]
unsafe fn exchange<const UPPER_IS_MIN: i32>(v: __m256i, partner: __m256i) -> __m256i {
    // SAFETY: the caller runs with AVX2.
    unsafe {
        let p = _mm256_permutevar8x32_epi32(v, partner);
        let (lo, hi) = (_mm256_min_epu32(v, p), _mm256_max_epu32(v, p));
        _mm256_blend_epi32::<UPPER_IS_MIN>(hi, lo)
    }
}

impl BoxTest for Avx2 {
    #[inline(always)]
    unsafe fn push_nearest_last(
        node: &WideNode,
        entry: &[f32; 8],
        slots: u32,
        stack: &mut Stack<Entered>,
    ) {
        // SAFETY: the caller runs with AVX2; `spare` has room for eight entries.
        unsafe {
            // Keys: the entry distance's bits (never negative nor NaN: `hits` clamps it at 0, so
            // the bits order as integers) with the slot in the three low bits and the top bit
            // set; 0 for a slot not pushed.
            let lanes = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let pushed = _mm256_cmpeq_epi32(
                _mm256_and_si256(_mm256_set1_epi32(slots as i32), lanes),
                lanes,
            );
            let bits = _mm256_castps_si256(_mm256_loadu_ps(entry.as_ptr()));
            let key = _mm256_or_si256(
                _mm256_and_si256(bits, _mm256_set1_epi32(!7)),
                _mm256_setr_epi32(
                    i32::MIN,
                    i32::MIN | 1,
                    i32::MIN | 2,
                    i32::MIN | 3,
                    i32::MIN | 4,
                    i32::MIN | 5,
                    i32::MIN | 6,
                    i32::MIN | 7,
                ),
            );
            let mut k = _mm256_and_si256(key, pushed);
            // Knuth's 19-comparator, depth-6 network for eight, descending: the farthest first,
            // the lanes not pushed last.
            k = exchange::<0b1100_1100>(k, _mm256_setr_epi32(2, 3, 0, 1, 6, 7, 4, 5));
            k = exchange::<0b1111_0000>(k, _mm256_setr_epi32(4, 5, 6, 7, 0, 1, 2, 3));
            k = exchange::<0b1010_1010>(k, _mm256_setr_epi32(1, 0, 3, 2, 5, 4, 7, 6));
            k = exchange::<0b0011_0000>(k, _mm256_setr_epi32(0, 1, 4, 5, 2, 3, 6, 7));
            k = exchange::<0b0101_0000>(k, _mm256_setr_epi32(0, 4, 2, 6, 1, 5, 3, 7));
            k = exchange::<0b0101_0100>(k, _mm256_setr_epi32(0, 2, 1, 4, 3, 6, 5, 7));
            let children = _mm256_permutevar8x32_epi32(
                _mm256_loadu_si256(node.child.as_ptr() as *const __m256i),
                _mm256_and_si256(k, _mm256_set1_epi32(7)),
            );
            // The distance without its slot bits: at most the true one, so no child is
            // skipped that could hold a nearer hit.
            let distances = _mm256_and_si256(k, _mm256_set1_epi32(0x7fff_fff8));
            // (child, distance) pairs in stack order.
            let low = _mm256_unpacklo_epi32(children, distances);
            let high = _mm256_unpackhi_epi32(children, distances);
            let spare = stack.spare() as *mut __m256i;
            _mm256_storeu_si256(spare, _mm256_permute2x128_si256::<0x20>(low, high));
            _mm256_storeu_si256(spare.add(1), _mm256_permute2x128_si256::<0x31>(low, high));
            stack.len += slots.count_ones() as usize;
        }
    }

    #[inline(always)]
    unsafe fn hits(node: &WideNode, q: &Query, tmax: f32, entry: &mut [f32; 8]) -> u32 {
        // SAFETY: the caller runs with AVX enabled.
        unsafe {
            let (nx, fx) = slabs8(node, q, 0);
            let (ny, fy) = slabs8(node, q, 1);
            let (nz, fz) = slabs8(node, q, 2);
            let enter = _mm256_max_ps(
                _mm256_max_ps(nx, ny),
                _mm256_max_ps(nz, _mm256_setzero_ps()),
            );
            let exit = _mm256_min_ps(
                _mm256_min_ps(fx, fy),
                _mm256_min_ps(fz, _mm256_set1_ps(tmax)),
            );
            let exit = _mm256_mul_ps(exit, _mm256_set1_ps(EXIT_SLACK));
            _mm256_storeu_ps(entry.as_mut_ptr(), enter);
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(enter, exit)) as u32
        }
    }
}

/// The nearest of a leaf's triangles hit before `tmax`: (primitive, distance). obvhs's own
/// triangle test, so the answers are its traversal's.
#[inline(always)]
pub(crate) fn leaf_nearest(
    prims: &[RtTriangle],
    leaf: u32,
    ray: &Ray,
    tmax: f32,
) -> Option<(u32, f32)> {
    let mut nearest = None;
    let mut best = tmax;
    for prim in leaf_range(leaf) {
        let t = prims[prim].intersect(ray);
        if t < best {
            best = t;
            nearest = Some((prim as u32, t));
        }
    }
    nearest
}

/// Some triangle of a leaf hit before `tmax`.
#[inline(always)]
pub(crate) fn leaf_any(prims: &[RtTriangle], leaf: u32, ray: &Ray) -> Option<u32> {
    leaf_range(leaf)
        .find(|&prim| prims[prim].intersect(ray) < ray.tmax)
        .map(|prim| prim as u32)
}

/// A traversal's stack: [`STACK`] entries left uninitialised, since clearing them would cost
/// more than many node visits (a ray is traced in about a microsecond).
pub(crate) struct Stack<T: Copy> {
    /// Eight spare entries above [`STACK`], which `spare` hands out whole.
    items: [MaybeUninit<T>; STACK + 8],
    pub(crate) len: usize,
}

impl<T: Copy> Stack<T> {
    #[inline(always)]
    pub(crate) fn new() -> Stack<T> {
        Stack {
            items: [const { MaybeUninit::uninit() }; STACK + 8],
            len: 0,
        }
    }

    /// The eight entries above the top, for a caller that writes several at once and then
    /// raises `len` by the number written. Panics past [`STACK`] entries.
    #[inline(always)]
    pub(crate) fn spare(&mut self) -> *mut T {
        assert!(self.len <= STACK, "a tree deeper than the stack serves");
        self.items[self.len..].as_mut_ptr() as *mut T
    }

    /// Panics past [`STACK`] entries, which a tree of at most `wide_bvh::MAX_DEPTH` levels
    /// never reaches.
    #[inline(always)]
    pub(crate) fn push(&mut self, item: T) {
        assert!(self.len < STACK, "a tree deeper than the stack serves");
        self.items[self.len] = MaybeUninit::new(item);
        self.len += 1;
    }

    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<T> {
        self.len = self.len.checked_sub(1)?;
        // SAFETY: every entry below `len` was written by `push`, `insert_sorted` or through
        // `spare`.
        Some(unsafe { self.items[self.len].assume_init() })
    }
}

/// A stack entry that a nearest-first traversal orders by the distance at which its child is
/// entered.
pub(crate) trait EntryDistance: Copy {
    fn entry_distance(&self) -> f32;
}

/// A child on the closest-hit query's stack and the distance at which the ray enters it; laid
/// out as two 32-bit words, which the AVX2 sort writes eight at a time.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub(crate) struct Entered {
    child: u32,
    distance: f32,
}

impl Entered {
    #[inline(always)]
    fn new(child: u32, distance: f32) -> Entered {
        Entered { child, distance }
    }
}

impl EntryDistance for Entered {
    #[inline(always)]
    fn entry_distance(&self) -> f32 {
        self.distance
    }
}

impl<T: EntryDistance> Stack<T> {
    /// Pushes `item` among the entries above `base`, which are kept farthest first, so the
    /// nearest is on top.
    #[inline(always)]
    pub(crate) fn insert_sorted(&mut self, base: usize, item: T) {
        assert!(self.len < STACK, "a tree deeper than the stack serves");
        let mut at = self.len;
        while at > base {
            // SAFETY: `base..len` were written.
            let below = unsafe { self.items[at - 1].assume_init() };
            if below.entry_distance() >= item.entry_distance() {
                break;
            }
            self.items[at] = MaybeUninit::new(below);
            at -= 1;
        }
        self.items[at] = MaybeUninit::new(item);
        self.len += 1;
    }
}

/// The closest hit before `tmax`: (BVH primitive, distance).
///
/// # Safety
/// The CPU must have `B`'s instructions.
#[inline(always)]
pub(crate) unsafe fn closest<B: BoxTest>(
    bvh: &WideBvh,
    prims: &[RtTriangle],
    q: &Query,
) -> Option<(u32, f32)> {
    if bvh.nodes.is_empty() {
        return None;
    }
    let mut stack = Stack::<Entered>::new();
    let mut best = None;
    let mut best_t = q.ray.tmax;
    let mut entry = [0f32; 8];
    let mut current = 0u32;
    'visit: loop {
        let node = &bvh.nodes[current as usize];
        // SAFETY: the caller guarantees `B`'s instructions.
        let hit = unsafe { B::hits(node, q, best_t, &mut entry) };
        // Leaves at once, where they are met: each hit found narrows the boxes worth entering.
        let mut leaves = hit & node.leaves;
        while leaves != 0 {
            let slot = leaves.trailing_zeros() as usize;
            leaves &= leaves - 1;
            if entry[slot] <= best_t
                && let Some((prim, t)) = leaf_nearest(prims, node.child[slot], &q.ray, best_t)
            {
                best_t = t;
                best = Some((prim, t));
            }
        }
        let mut inner = hit & !node.leaves;
        if inner != 0 {
            let first = inner.trailing_zeros() as usize;
            inner &= inner - 1;
            if inner == 0 {
                if entry[first] <= best_t {
                    current = node.child[first];
                    continue 'visit;
                }
            } else {
                // Several inner children: all onto the stack, nearest on top.
                // SAFETY: the caller guarantees `B`'s instructions.
                unsafe { B::push_nearest_last(node, &entry, inner | (1 << first), &mut stack) };
            }
        }
        // Next on the stack, skipping children entered only beyond the best hit.
        loop {
            let Some(Entered { child, distance }) = stack.pop() else {
                return best;
            };
            if distance <= best_t {
                current = child;
                continue 'visit;
            }
        }
    }
}

/// Some primitive (BVH order) hit before `tmax`: the first found, not the nearest.
///
/// # Safety
/// The CPU must have `B`'s instructions.
#[inline(always)]
pub(crate) unsafe fn any<B: BoxTest>(
    bvh: &WideBvh,
    prims: &[RtTriangle],
    q: &Query,
) -> Option<u32> {
    if bvh.nodes.is_empty() {
        return None;
    }
    let mut stack = Stack::<u32>::new();
    let mut entry = [0f32; 8];
    let mut current = 0u32;
    loop {
        let node = &bvh.nodes[current as usize];
        // SAFETY: the caller guarantees `B`'s instructions.
        let hit = unsafe { B::hits(node, q, q.ray.tmax, &mut entry) };
        let mut leaves = hit & node.leaves;
        while leaves != 0 {
            let slot = leaves.trailing_zeros() as usize;
            leaves &= leaves - 1;
            if let Some(prim) = leaf_any(prims, node.child[slot], &q.ray) {
                return Some(prim);
            }
        }
        let mut inner = hit & !node.leaves;
        while inner != 0 {
            stack.push(node.child[inner.trailing_zeros() as usize]);
            inner &= inner - 1;
        }
        current = stack.pop()?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{stream, uniform2};
    use crate::vector_level::VectorLevel;

    /// The children a push left on `stack`, nearest first, with their distances.
    fn popped(stack: &mut Stack<Entered>) -> Vec<(u32, f32)> {
        std::iter::from_fn(|| stack.pop().map(|e| (e.child, e.distance))).collect()
    }

    #[test]
    fn children_are_stacked_nearest_on_top_by_both_sorts() {
        let mut rng = stream(3, 0);
        let node = WideNode {
            bounds: [[0.0; 8]; 6],
            child: [10, 11, 12, 13, 14, 15, 16, 17],
            leaves: 0,
        };
        for _ in 0..2000 {
            let [a, b] = uniform2(&mut rng);
            let slots = (a * 256.0) as u32 & 0xff;
            if slots.count_ones() < 2 {
                continue;
            }
            // Distinct distances, some of them 0 (a ray starting inside the box).
            let entry: [f32; 8] =
                std::array::from_fn(|k| ((k as f32 * 7.0 + b * 50.0) % 13.0).floor() * 1.5);
            let mut expected: Vec<(u32, f32)> = (0..8)
                .filter(|&k| slots & (1 << k) != 0)
                .map(|k| (node.child[k], entry[k]))
                .collect();
            expected.sort_by(|x, y| x.1.total_cmp(&y.1));
            let mut stack = Stack::new();
            stack.push(Entered::new(99, 1e9));
            // SAFETY: the baseline sort needs no instruction beyond x86-64.
            unsafe { Sse::push_nearest_last(&node, &entry, slots, &mut stack) };
            let by_insertion = popped(&mut stack);
            assert_eq!(by_insertion[..expected.len()], expected[..], "{slots:b}");
            assert_eq!(
                by_insertion[expected.len()],
                (99, 1e9),
                "the entry below kept"
            );
            if !VectorLevel::V3.available() {
                continue;
            }
            stack.push(Entered::new(99, 1e9));
            // SAFETY: the CPU has AVX2 (checked above).
            unsafe { Avx2::push_nearest_last(&node, &entry, slots, &mut stack) };
            let by_network = popped(&mut stack);
            assert_eq!(by_network.len(), expected.len() + 1);
            for ((child, got), (want_child, want)) in by_network.iter().zip(&expected) {
                assert_eq!(child, want_child, "{slots:b} {entry:?}");
                // The slot bits cleared from the distance: never above the true one.
                assert!(*got <= *want && *got >= want * (1.0 - 1e-6), "{got} {want}");
            }
        }
    }
}
