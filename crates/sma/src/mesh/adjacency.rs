//! Who lies across an edge. Base triangles meet along point-pair edges (any number of faces per
//! edge); inside a base triangle the fixed child layout of red and green splits tells which
//! child edge lies on which parent edge. A neighbour query climbs from a node to where its edge
//! is either interior to an ancestor (the neighbour is a sibling subtree) or on a base edge (the
//! neighbours are in the adjacent base triangles), then descends there along the same segment.
//! Segments are tracked as dyadic intervals of the ancestor's edge, exact in f64.

use super::{Node, NodeId, Split, SubdivisionMesh, pair_key};

/// Part of an edge, as parameters from its start vertex (0) to its end vertex (1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Interval {
    lo: f64,
    hi: f64,
}

impl Interval {
    const WHOLE: Interval = Interval { lo: 0.0, hi: 1.0 };

    /// The same segment seen from an edge running the other way.
    fn reversed(self) -> Interval {
        Interval {
            lo: 1.0 - self.hi,
            hi: 1.0 - self.lo,
        }
    }

    /// This interval of `[from, to]` expressed in the parent's parameters.
    fn into_range(self, from: f64, to: f64) -> Interval {
        let w = to - from;
        Interval {
            lo: from + self.lo * w,
            hi: from + self.hi * w,
        }
    }

    /// The part over `[from, to]`, expressed in that sub-edge's parameters, if they overlap.
    fn within(self, from: f64, to: f64) -> Option<Interval> {
        (self.hi.min(to) > self.lo.max(from)).then(|| {
            let w = to - from;
            Interval {
                lo: (self.lo - from) / w,
                hi: (self.hi - from) / w,
            }
        })
    }
}

/// Where a child's edge lies in its parent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ParentEdge {
    /// The whole of parent edge `k`.
    Whole(usize),
    /// The first (`false`) or second (`true`) half of parent edge `k`.
    Half(usize, bool),
    /// Inside the parent, shared with edge `edge` of sibling `child` (running the other way).
    Interior { child: usize, edge: usize },
}

/// Red layout: corner children 0, 1, 2 at the parent's vertices, middle child 3 (see
/// `refine::red_children`).
fn red_parent_edge(child: usize, edge: usize) -> ParentEdge {
    if child == 3 {
        ParentEdge::Interior {
            child: (edge + 1) % 3,
            edge: (edge + 2) % 3,
        }
    } else if edge == child {
        ParentEdge::Half(child, false)
    } else if edge == (child + 2) % 3 {
        ParentEdge::Half(edge, true)
    } else {
        ParentEdge::Interior {
            child: 3,
            edge: (child + 2) % 3,
        }
    }
}

/// Green layout on split edge `s`: child 0 = (v_s, m, o), child 1 = (m, v_s+1, o).
fn green_parent_edge(s: usize, child: usize, edge: usize) -> ParentEdge {
    match (child, edge) {
        (0, 0) => ParentEdge::Half(s, false),
        (0, 1) => ParentEdge::Interior { child: 1, edge: 2 },
        (0, _) => ParentEdge::Whole((s + 2) % 3),
        (_, 0) => ParentEdge::Half(s, true),
        (_, 1) => ParentEdge::Whole((s + 1) % 3),
        (_, _) => ParentEdge::Interior { child: 0, edge: 1 },
    }
}

/// The children lying along parent edge `k`: (child index, its edge, part of the parent edge);
/// one or two of them, the second `None` when one child holds the whole edge.
type AlongEdge = [Option<(usize, usize, f64, f64)>; 2];

fn children_along(split: Split, k: usize) -> AlongEdge {
    match split {
        Split::None => [None, None],
        Split::Red { .. } => [Some((k, k, 0.0, 0.5)), Some(((k + 1) % 3, k, 0.5, 1.0))],
        Split::Green { edge, .. } => {
            let s = edge as usize;
            if k == s {
                [Some((0, 0, 0.0, 0.5)), Some((1, 0, 0.5, 1.0))]
            } else if k == (s + 1) % 3 {
                [Some((1, 1, 0.0, 1.0)), None]
            } else {
                [Some((0, 2, 0.0, 1.0)), None]
            }
        }
    }
}

/// For each base triangle and edge, the other base triangles on the same point pair.
#[derive(Clone, Debug)]
pub(super) struct BaseAdjacency {
    /// `offsets[3 t + k]..offsets[3 t + k + 1]` indexes `across` for edge `k` of base `t`.
    offsets: Vec<u32>,
    /// (base triangle, its edge, whether it runs the other way).
    across: Vec<(u32, u8, bool)>,
}

impl BaseAdjacency {
    pub(super) fn new(nodes: &[Node], vertex_point: &[u32], degenerate: &[bool]) -> Self {
        let points = |t: usize, k: usize| {
            let v = nodes[t].vertices;
            (
                vertex_point[v[k] as usize],
                vertex_point[v[(k + 1) % 3] as usize],
            )
        };
        let mut edges: Vec<(u64, u32, u8)> = (0..nodes.len())
            .filter(|&t| !degenerate[t])
            .flat_map(|t| (0..3).map(move |k| (t, k)))
            .map(|(t, k)| {
                let (a, b) = points(t, k);
                (pair_key(a, b), t as u32, k as u8)
            })
            .collect();
        edges.sort_unstable();
        let mut lists: Vec<Vec<(u32, u8, bool)>> = vec![Vec::new(); nodes.len() * 3];
        for group in edges.chunk_by(|x, y| x.0 == y.0) {
            for &(_, t, k) in group {
                let start = points(t as usize, k as usize).0;
                lists[t as usize * 3 + k as usize] = group
                    .iter()
                    .filter(|o| (o.1, o.2) != (t, k))
                    .map(|&(_, u, j)| (u, j, points(u as usize, j as usize).0 != start))
                    .collect();
            }
        }
        let mut offsets = vec![0u32];
        let mut across = Vec::new();
        for list in lists {
            across.extend(list);
            offsets.push(across.len() as u32);
        }
        // Kept for the mesh's life and counted by capacity (`mesh::memory`): no growth slack.
        offsets.shrink_to_fit();
        across.shrink_to_fit();
        BaseAdjacency { offsets, across }
    }

    fn across(&self, base: u32, edge: usize) -> &[(u32, u8, bool)] {
        let i = base as usize * 3 + edge;
        &self.across[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    pub(super) fn heap_bytes(&self) -> usize {
        self.offsets.capacity() * 4
            + self.across.capacity() * std::mem::size_of::<(u32, u8, bool)>()
    }
}

impl SubdivisionMesh {
    /// The leaves on the other side of edge `k` of node `id` (any node, leaf or not) that touch
    /// the edge along a segment: coarser, equal or finer ones alike.
    pub(crate) fn leaves_across(&self, id: NodeId, k: usize, out: &mut Vec<NodeId>) {
        let (mut node, mut edge, mut part) = (id, k, Interval::WHOLE);
        while let Some(parent) = self.node(node).parent() {
            let child = (node - self.node(parent).children().start) as usize;
            let place = match self.node(parent).split() {
                Split::Green { edge: s, .. } => green_parent_edge(s as usize, child, edge),
                _ => red_parent_edge(child, edge),
            };
            match place {
                ParentEdge::Whole(e) => edge = e,
                ParentEdge::Half(e, second) => {
                    edge = e;
                    part = if second {
                        part.into_range(0.5, 1.0)
                    } else {
                        part.into_range(0.0, 0.5)
                    };
                }
                ParentEdge::Interior { child, edge } => {
                    let sibling = self.node(parent).children().start + child as u32;
                    return self.leaves_along(sibling, edge, part.reversed(), out);
                }
            }
            node = parent;
        }
        for &(base, e, reversed) in self.adjacency.across(node, edge) {
            let seen = if reversed { part.reversed() } else { part };
            self.leaves_along(base, e as usize, seen, out);
        }
    }

    /// The base triangles that share an edge with base triangle `base` (none for a degenerate one).
    pub(crate) fn base_neighbours(&self, base: u32) -> impl Iterator<Item = u32> + '_ {
        (0..3).flat_map(move |k| self.adjacency.across(base, k).iter().map(|&(b, _, _)| b))
    }

    /// The leaves with a corner at the point of corner `corner` of leaf `id` (`id` included), in
    /// `out`: found by turning around the point across the edges that meet there. At most
    /// `limit` of them (a fan of hundreds of faces is a modelling accident, not a surface).
    pub(crate) fn leaves_around(
        &self,
        id: NodeId,
        corner: usize,
        limit: usize,
        out: &mut Vec<NodeId>,
    ) {
        let point = self.point_of(self.node(id).vertices[corner]);
        let corner_of =
            |n: NodeId| (0..3).find(|&c| self.point_of(self.node(n).vertices[c]) == point);
        let first = out.len();
        out.push(id);
        let mut next = first;
        let mut across = Vec::new();
        while next < out.len() && out.len() - first < limit {
            let n = out[next];
            next += 1;
            let Some(c) = corner_of(n) else { continue };
            // Edges c (from the corner) and c + 2 (to it) meet at the corner.
            for k in [c, (c + 2) % 3] {
                across.clear();
                self.leaves_across(n, k, &mut across);
                for &m in &across {
                    if corner_of(m).is_some() && !out[first..].contains(&m) {
                        out.push(m);
                    }
                }
            }
        }
        out.truncate(first + limit);
    }

    /// The leaves under `id` with an edge overlapping `part` of its edge `k`.
    fn leaves_along(&self, id: NodeId, k: usize, part: Interval, out: &mut Vec<NodeId>) {
        let node = self.node(id);
        if node.split() == Split::None {
            out.push(id);
            return;
        }
        let first = node.children().start;
        for (child, edge, from, to) in children_along(node.split(), k).into_iter().flatten() {
            if let Some(sub) = part.within(from, to) {
                self.leaves_along(first + child as u32, edge, sub, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Descending along a parent edge and climbing back give the same place, for every edge
    /// of every child of both layouts.
    #[test]
    fn child_tables_are_inverse() {
        for s in 0..3u8 {
            let splits = [
                Split::Red { first_child: 0 },
                Split::Green {
                    first_child: 0,
                    edge: s,
                },
            ];
            for split in splits {
                for k in 0..3 {
                    let along = children_along(split, k);
                    for (child, edge, from, _) in along.into_iter().flatten() {
                        let place = match split {
                            Split::Green { edge: s, .. } => {
                                green_parent_edge(s as usize, child, edge)
                            }
                            _ => red_parent_edge(child, edge),
                        };
                        let expected = match along[1] {
                            None => ParentEdge::Whole(k),
                            Some(_) => ParentEdge::Half(k, from > 0.0),
                        };
                        assert_eq!(place, expected, "{split:?} edge {k} child {child}");
                    }
                }
            }
        }
    }

    /// Around an inner point of a grid, then with one of its faces refined: every leaf with a
    /// corner there, and no other.
    #[test]
    fn leaves_around_a_point_are_the_whole_fan() {
        use crate::mesh::test_meshes::grid;
        use crate::mesh::{MeshParams, SubdivisionMesh};
        use glam::Vec3;

        let mut mesh = SubdivisionMesh::new(&grid(2), MeshParams::default());
        let centre = Vec3::new(1.0, 1.0, 0.0);
        let fan = |mesh: &SubdivisionMesh| {
            let mut all: Vec<NodeId> = mesh
                .leaves()
                .filter(|&l| mesh.leaf_positions(l).contains(&centre))
                .collect();
            all.sort_unstable();
            all
        };
        for round in 0..2 {
            let want = fan(&mesh);
            let (leaf, corner) = want
                .iter()
                .find_map(|&l| {
                    let c = mesh.leaf_positions(l).iter().position(|&p| p == centre)?;
                    Some((l, c))
                })
                .expect("a leaf at the centre");
            let mut got = Vec::new();
            mesh.leaves_around(leaf, corner, 64, &mut got);
            got.sort_unstable();
            assert_eq!(got, want, "round {round}");
            assert!(want.len() >= 6);
            mesh.refine(&[want[2]], &|_| false);
        }
    }

    #[test]
    fn interior_edges_pair_up_both_ways() {
        for child in 0..4 {
            for edge in 0..3 {
                if let ParentEdge::Interior { child: c, edge: e } = red_parent_edge(child, edge) {
                    assert_eq!(red_parent_edge(c, e), ParentEdge::Interior { child, edge });
                }
            }
        }
        assert_eq!(
            green_parent_edge(1, 0, 1),
            ParentEdge::Interior { child: 1, edge: 2 }
        );
        assert_eq!(
            green_parent_edge(1, 1, 2),
            ParentEdge::Interior { child: 0, edge: 1 }
        );
    }
}
