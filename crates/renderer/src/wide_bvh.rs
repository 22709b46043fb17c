//! An eight-wide BVH laid out for the CPU's vector units (DESIGN.md §7). obvhs builds a compressed
//! wide BVH (CWBVH, `scene::bvh`): eight children per node with their boxes quantised to bytes,
//! a layout made for GPUs, whose traversal must dequantise every box and visits children in a
//! fixed octant order. Here the same tree is decoded once into full-precision boxes stored axis
//! by axis (one AVX2 instruction compares a ray with eight children's planes, SSE with four); a
//! leaf child names its range (one to three) of the BVH-ordered triangles. The traversal is
//! `wide_traversal`.
//!
//! Same tree, same leaves, same triangle test: the answers are those of the CWBVH traversal;
//! only the order of visits (nearest child first, so a closest hit prunes more) and the cost
//! change.

use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::node::CwBvhNode;

/// A child reference with this bit set is a leaf: its triangle count (1 to 3) in the two bits
/// below ([`LEAF_COUNT_SHIFT`]) and its first BVH primitive in the rest. Otherwise a node index.
pub(crate) const LEAF: u32 = 1 << 31;
pub(crate) const LEAF_COUNT_SHIFT: u32 = 29;
pub(crate) const LEAF_FIRST: u32 = (1 << LEAF_COUNT_SHIFT) - 1;

/// Entries of a traversal's stack. A node visit leaves at most seven of its children there, so a
/// tree up to [`MAX_DEPTH`] levels deep never fills it.
pub(crate) const STACK: usize = 256;

/// The deepest tree the fixed stack serves: 7 × 36 = 252 < [`STACK`]. obvhs's own traversal
/// keeps 32 levels; a deeper tree (degenerate geometry) keeps the CWBVH traversal.
pub(crate) const MAX_DEPTH: usize = crate::bvh::WIDE_MAX_DEPTH;

/// The BVH primitives of a leaf reference.
#[inline(always)]
pub(crate) fn leaf_range(child: u32) -> std::ops::Range<usize> {
    let first = (child & LEAF_FIRST) as usize;
    let count = ((child & !LEAF) >> LEAF_COUNT_SHIFT) as usize;
    first..first + count
}

/// One node: the boxes of its eight children, plane by plane, and what each child is.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(crate) struct WideNode {
    /// `bounds[2 * axis]` holds the children's lower planes on that axis, `bounds[2 * axis + 1]`
    /// their upper planes. An empty slot has lower +∞ and upper −∞, so no ray enters it.
    pub(crate) bounds: [[f32; 8]; 6],
    /// Node index, or [`LEAF`] | leaf index; meaningless for an empty slot.
    pub(crate) child: [u32; 8],
    /// A bit per slot whose child is a leaf, so a visit splits the children it enters into
    /// leaves (tested at once) and inner nodes (stacked) with one mask.
    pub(crate) leaves: u32,
}

/// The decoded tree. Node 0 is the root; no nodes means an empty scene. Leaves name ranges of
/// the BVH's primitives, which `SceneBvh` keeps in BVH order.
#[derive(Debug)]
pub(crate) struct WideBvh {
    pub(crate) nodes: Vec<WideNode>,
}

impl WideBvh {
    /// Decodes `cwbvh`, whose primitives are `prims` (in BVH primitive order). None when the tree
    /// is deeper than [`MAX_DEPTH`].
    pub(crate) fn from_cwbvh(cwbvh: &CwBvh) -> Option<WideBvh> {
        if depth(cwbvh) > MAX_DEPTH || cwbvh.primitive_indices.len() > LEAF_FIRST as usize {
            return None;
        }
        let nodes = cwbvh.nodes.iter().map(decode).collect();
        Some(WideBvh { nodes })
    }
}

/// Levels of inner nodes on the longest path from the root.
fn depth(cwbvh: &CwBvh) -> usize {
    if cwbvh.nodes.is_empty() {
        return 0;
    }
    let mut deepest = 0;
    let mut pending = vec![(0u32, 1usize)];
    while let Some((index, level)) = pending.pop() {
        deepest = deepest.max(level);
        if level > MAX_DEPTH {
            break;
        }
        let node = &cwbvh.nodes[index as usize];
        for inner in 0..node.imask.count_ones() {
            pending.push((node.child_base_idx + inner, level + 1));
        }
    }
    deepest
}

/// One CWBVH node as a [`WideNode`].
fn decode(node: &CwBvhNode) -> WideNode {
    let mut wide = WideNode {
        bounds: [
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
            [f32::INFINITY; 8],
            [f32::NEG_INFINITY; 8],
        ],
        child: [0; 8],
        leaves: 0,
    };
    // The quantisation grid: child planes are `p + 2^e · q` for byte q (a power of two times a
    // byte is exact; the sum is rounded once, and moved one step outward to stay conservative).
    let origin = [node.p.x, node.p.y, node.p.z];
    let scale = node.e.map(|e| f32::from_bits(u32::from(e) << 23));
    let planes = [
        (&node.child_min_x, &node.child_max_x),
        (&node.child_min_y, &node.child_max_y),
        (&node.child_min_z, &node.child_max_z),
    ];
    for slot in 0..8 {
        let meta = node.child_meta[slot];
        if meta == 0 {
            continue;
        }
        for (axis, (lo, hi)) in planes.iter().enumerate() {
            let plane = |q: u8| origin[axis] + scale[axis] * f32::from(q);
            wide.bounds[2 * axis][slot] = plane(lo[slot]).next_down();
            wide.bounds[2 * axis + 1][slot] = plane(hi[slot]).next_up();
        }
        wide.child[slot] = if node.imask & (1 << slot) != 0 {
            // Inner children are stored in slot order from `child_base_idx`.
            node.child_base_idx + (u32::from(node.imask) & ((1 << slot) - 1)).count_ones()
        } else {
            // Low five bits: offset of the first primitive; high three: the count, in unary.
            let first = node.primitive_base_idx + u32::from(meta & 0x1f);
            let count = (meta >> 5).count_ones();
            wide.leaves |= 1 << slot;
            LEAF | (count << LEAF_COUNT_SHIFT) | first
        };
    }
    wide
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::triangle::Triangle;
    use scene::bvh::{BuildPreset, build_cwbvh};

    fn grid_triangles(n: usize) -> Vec<Triangle> {
        let mut tris = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (x, z) = (i as f32, j as f32);
                let y = ((i * 7 + j * 3) % 5) as f32 * 0.1;
                tris.push(Triangle {
                    v0: [x, y, z].into(),
                    v1: [x + 1.0, y, z].into(),
                    v2: [x, y + 0.5, z + 1.0].into(),
                });
            }
        }
        tris
    }

    #[test]
    fn every_primitive_lands_in_a_leaf_inside_its_box() {
        let tris = grid_triangles(20);
        let cwbvh = build_cwbvh(&tris, BuildPreset::Medium);
        let wide = WideBvh::from_cwbvh(&cwbvh).expect("a shallow tree");
        let mut seen = vec![false; cwbvh.primitive_indices.len()];
        for node in &wide.nodes {
            for slot in 0..8 {
                let lo = [0, 2, 4].map(|a| node.bounds[a][slot]);
                let hi = [1, 3, 5].map(|a| node.bounds[a][slot]);
                let is_leaf = node.child[slot] & LEAF != 0;
                if lo[0] <= hi[0] {
                    assert_eq!(node.leaves & (1 << slot) != 0, is_leaf, "the leaf mask");
                }
                if lo[0] > hi[0] || !is_leaf {
                    continue;
                }
                for prim in leaf_range(node.child[slot]) {
                    seen[prim] = true;
                    let tri = &tris[cwbvh.primitive_indices[prim] as usize];
                    for v in [tri.v0, tri.v1, tri.v2] {
                        for axis in 0..3 {
                            let inside = lo[axis] <= v[axis] && v[axis] <= hi[axis];
                            assert!(inside, "a vertex outside its box");
                        }
                    }
                }
            }
        }
        assert!(seen.iter().all(|&s| s), "every primitive is in some leaf");
    }

    #[test]
    fn no_triangles_give_no_nodes() {
        let wide = WideBvh::from_cwbvh(&CwBvh::default()).unwrap();
        assert!(wide.nodes.is_empty());
    }
}
