//! Red–green refinement with closure (module documentation of [`super`]; thesis §4.2).

use glam::Vec3;

use super::neighbour_rule::Cascade;
use super::step::StepRecorder;
use super::{
    EdgeSplit, MeshVertex, Node, NodeId, NodeKind, RefinementStep, SEAM_VERTEX, Split,
    SubdivisionMesh, VertexId, min_angle, pair_key, push_lean,
};

/// Children of a red split of (a, b, c) with midpoints m0 on ab, m1 on bc, m2 on ca: the corners
/// at a, b, c, then the middle one; all counter-clockwise like the parent. The layout is what
/// `adjacency` relies on.
fn red_children([a, b, c]: [VertexId; 3], [m0, m1, m2]: [VertexId; 3]) -> [[VertexId; 3]; 4] {
    [[a, m0, m2], [m0, b, m1], [m2, m1, c], [m0, m1, m2]]
}

/// Children of a green bisection of edge `s` at `m`: (v_s, m, o) and (m, v_s+1, o).
fn green_children(v: [VertexId; 3], s: usize, m: VertexId) -> [[VertexId; 3]; 2] {
    let (a, b, o) = (v[s], v[(s + 1) % 3], v[(s + 2) % 3]);
    [[a, m, o], [m, b, o]]
}

/// Barycentric weights of `p` on triangle `t` for its vertices 1 and 2: `p`'s components along
/// the edges, from cross products with the triangle's normal, in f64. The Gram determinant
/// (|e1|²|e2|² - (e1·e2)²) of the textbook form cancels to nothing in f32 for a needle (a sine of
/// its smallest angle below ~3e-4), placing its midpoints at a corner; a cross product keeps
/// the sine itself, and f64 keeps it to needles of sine 1e-7, the thinnest the scene keeps.
pub(super) fn barycentric(t: [Vec3; 3], p: Vec3) -> [f32; 2] {
    let [a, b, c] = t.map(Vec3::as_dvec3);
    let (e1, e2, d) = (b - a, c - a, p.as_dvec3() - a);
    let n = e1.cross(e2);
    let nn = n.length_squared();
    if nn <= 0.0 {
        return [0.0; 2];
    }
    [
        (d.cross(e2).dot(n) / nn) as f32,
        (e1.cross(d).dot(n) / nn) as f32,
    ]
}

impl SubdivisionMesh {
    /// Refines the selected leaves, each with its whole closure, one step per leaf actually
    /// split. A selected green leaf has its parent split red instead. Skipped: leaves no longer
    /// leaves (split by an earlier closure of the same call), leaves `too_small` vetoes (the
    /// caller's projected-size limit), and those whose red children would have edges below
    /// `MeshParams::min_edge_length`.
    pub fn refine(
        &mut self,
        selected: &[NodeId],
        too_small: &dyn Fn(NodeId) -> bool,
    ) -> Vec<RefinementStep> {
        let mut steps = Vec::new();
        let mut queue = Vec::new();
        for &leaf in selected {
            if !self.is_leaf(leaf) || self.is_degenerate(leaf) || too_small(leaf) {
                continue;
            }
            let node = self.node(leaf);
            let target = match (node.kind(), node.parent()) {
                (NodeKind::Green, Some(parent)) => parent,
                _ => leaf,
            };
            if self.longest_edge(target) < self.min_split_edge {
                continue;
            }
            let mut step = StepRecorder::default();
            self.red_split(target, &mut step, &mut queue);
            self.close(&mut step, &mut queue);
            steps.push(step.finish(self));
        }
        steps
    }

    /// Splits every node of `targets` red (a leaf, or a green-split node whose greens go), then
    /// closes the mesh once, as one step: the cache file's replay of a whole level of stored
    /// splits (DESIGN.md §5). Split one call at a time, each closure would green the neighbours
    /// the same level then splits red, and the steps would cost more than the splits. Skipped
    /// like [`Self::refine`]'s: red already, dead, degenerate, too short.
    pub fn split_red_all(&mut self, targets: &[NodeId]) -> RefinementStep {
        let (mut step, mut queue) = (StepRecorder::bulk(), Vec::new());
        for &id in targets {
            let node = self.node(id);
            if !node.is_alive()
                || matches!(node.split(), Split::Red { .. })
                || self.is_degenerate(id)
                || self.longest_edge(id) < self.min_split_edge
            {
                continue;
            }
            self.red_split(id, &mut step, &mut queue);
        }
        self.close(&mut step, &mut queue);
        step.finish(self)
    }

    /// Splits leaves with hanging vertices until none is left: one hanging edge gets a green
    /// bisection (or, by the thesis's rule, a red split: `neighbour_rule`), two or three a red
    /// split; a green leaf with any has its parent split red.
    fn close(&mut self, step: &mut StepRecorder, queue: &mut Vec<NodeId>) {
        let mut cascade = Cascade::default();
        while let Some(id) = queue.pop() {
            if !self.is_leaf(id) || self.is_degenerate(id) {
                continue;
            }
            let mut hanging = (0..3).filter(|&k| self.splits_of(self.edge_key(id, k)) > 0);
            let Some(first) = hanging.next() else {
                continue;
            };
            let more = hanging.next().is_some();
            let node = self.node(id);
            match (node.kind(), node.parent()) {
                (NodeKind::Green, Some(parent)) => self.red_split(parent, step, queue),
                _ if more => self.red_split(id, step, queue),
                _ if self.splits_neighbour_whole(id, first, &mut cascade) => {
                    self.red_split(id, step, queue)
                }
                _ => self.green_split(id, first, step, queue),
            }
        }
        cascade.finish(&mut self.neighbour_stats);
    }

    /// Red split of a leaf or of a green-split node (whose greens are removed first). Queues the
    /// leaves across its edges and its corner children, which may now have hanging vertices.
    pub(super) fn red_split(
        &mut self,
        id: NodeId,
        step: &mut StepRecorder,
        queue: &mut Vec<NodeId>,
    ) {
        if matches!(self.node(id).split(), Split::Green { .. }) {
            self.remove_children(id, step);
        }
        let mids = [0, 1, 2].map(|k| self.split_edge(id, k, step));
        let first = self.push_children(
            id,
            NodeKind::Red,
            &red_children(self.node(id).vertices, mids),
            step,
        );
        self.nodes[id as usize].set_split(Split::Red { first_child: first });
        for k in 0..3 {
            self.leaves_across(id, k, queue);
        }
        queue.extend(first..first + 3);
    }

    /// Green bisection of edge `s` of a leaf; queues the two halves.
    pub(super) fn green_split(
        &mut self,
        id: NodeId,
        s: usize,
        step: &mut StepRecorder,
        queue: &mut Vec<NodeId>,
    ) {
        let m = self.split_edge(id, s, step);
        let first = self.push_children(
            id,
            NodeKind::Green,
            &green_children(self.node(id).vertices, s, m),
            step,
        );
        self.nodes[id as usize].set_split(Split::Green {
            first_child: first,
            edge: s as u8,
        });
        queue.extend([first, first + 1]);
    }

    /// Removes the children (all leaves) of `id`, which becomes a leaf again.
    pub(super) fn remove_children(&mut self, id: NodeId, step: &mut StepRecorder) {
        let node = *self.node(id);
        self.changed.mark(self.base_of(id));
        step.before_change(self, id);
        for child in node.children() {
            debug_assert!(self.is_leaf(child), "only leaves are removed");
            step.before_change(self, child);
            self.nodes[child as usize].kill();
        }
        let children = node.children();
        self.free_nodes.retire(children.start, children.len());
        let cut: &[usize] = match node.split() {
            Split::Green { edge, .. } => &[edge as usize],
            _ => &[0, 1, 2],
        };
        for &k in cut {
            let key = self.edge_key(id, k);
            if let Some(e) = self.edge_splits.get_mut(&key) {
                e.splits -= 1;
            }
        }
        self.leaf_count = self.leaf_count + 1 - node.children().len();
        self.nodes[id as usize].set_split(Split::None);
    }

    fn push_children(
        &mut self,
        parent: NodeId,
        kind: NodeKind,
        children: &[[VertexId; 3]],
        step: &mut StepRecorder,
    ) -> NodeId {
        step.before_change(self, parent);
        self.changed.mark(self.base_of(parent));
        // A recycled block is dead, so the step sees its ids as new leaves, like pushed ones.
        let reused = self.free_nodes.take(children.len());
        let first = reused.unwrap_or(self.nodes.len() as NodeId);
        for (i, &vertices) in children.iter().enumerate() {
            let id = first + i as NodeId;
            step.before_change(self, id);
            let node = Node::new(vertices, Some(parent), kind);
            match reused {
                Some(_) => self.nodes[id as usize] = node,
                None => push_lean(&mut self.nodes, node),
            }
        }
        self.leaf_count += children.len() - 1;
        self.splits += 1;
        let base_angle = min_angle(self.leaf_positions(self.base_of(parent)));
        for child in first..first + children.len() as NodeId {
            self.split_shapes
                .observe(self.leaf_positions(child), base_angle);
        }
        first
    }

    /// Marks edge `k` of `id` as split and returns its midpoint vertex for this side of any seam,
    /// making the point and the vertex the first time.
    fn split_edge(&mut self, id: NodeId, k: usize, step: &mut StepRecorder) -> VertexId {
        let (va, vb) = self.edge_vertices(id, k);
        // A freed midpoint vertex is reused first (`memory::free_unused_midpoints`).
        let next_vertex =
            (self.free_vertices.last().copied()).unwrap_or(self.vertices.len() as VertexId);
        let split = self
            .edge_splits
            .entry(pair_key(self.point_of(va), self.point_of(vb)))
            .or_insert(EdgeSplit {
                mid_vertex: next_vertex,
                splits: 0,
            });
        split.splits += 1;
        let first = split.mid_vertex;
        let seam = self.is_seam(va) || self.is_seam(vb);
        let (point, position) = if first == next_vertex {
            self.point_count += 1;
            let [a, b] = [va, vb].map(|v| self.vertex(v).position);
            (self.point_count - 1, 0.5 * (a + b))
        } else if !seam {
            // Neither end shares its point, so this edge is the only vertex pair on the points.
            return first;
        } else if let Some(&v) = self.seam_midpoints.get(&pair_key(va, vb)) {
            return v;
        } else {
            (self.point_of(first), self.vertex(first).position)
        };
        let vertex = self.midpoint_vertex(id, va, vb, position);
        let point = if seam { point | SEAM_VERTEX } else { point };
        if self.free_vertices.pop().is_some() {
            self.vertices[next_vertex as usize] = vertex;
            self.vertex_point[next_vertex as usize] = point;
        } else {
            push_lean(&mut self.vertices, vertex);
            push_lean(&mut self.vertex_point, point);
        }
        if seam {
            self.seam_midpoints.insert(pair_key(va, vb), next_vertex);
        }
        step.new_vertices.push(next_vertex);
        next_vertex
    }

    /// The midpoint vertex of edge (va, vb) of node `id`: shaded on the scene triangle of the
    /// node's base triangle, normal halfway between the ends' (the node's face normal, turned
    /// to `va`'s side, if those cancel).
    fn midpoint_vertex(
        &self,
        id: NodeId,
        va: VertexId,
        vb: VertexId,
        position: Vec3,
    ) -> MeshVertex {
        let (na, nb) = (self.vertex(va).normal, self.vertex(vb).normal);
        let normal = (na + nb).try_normalize().unwrap_or_else(|| {
            let [a, b, c] = self.leaf_positions(id);
            let face = (b - a).cross(c - a).normalize_or(na);
            if face.dot(na) < 0.0 { -face } else { face }
        });
        let (scene_triangle, corners) = self.scene_triangle_of(self.base_of(id));
        MeshVertex {
            position,
            normal,
            base_triangle: scene_triangle,
            bary: barycentric(corners, position),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshParams;
    use crate::mesh::test_meshes::square;

    #[test]
    fn red_split_of_one_triangle_bisects_its_neighbour_green() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        let steps = mesh.refine(&[0], &|_| false);
        assert_eq!(steps.len(), 1);
        let step = &steps[0];
        assert_eq!(step.replaced_leaves, vec![0, 1]);
        assert_eq!(step.new_leaves.len(), 4 + 2);
        assert_eq!(step.new_vertices.len(), 3);
        assert_eq!(mesh.leaf_count(), 6);
        assert!(matches!(mesh.node(1).split(), Split::Green { .. }));
        let mid = mesh.vertex(step.new_vertices[1]);
        assert_eq!(mid.position, Vec3::new(1.0, 0.5, 0.0));
    }

    #[test]
    fn selecting_a_green_splits_its_parent_red_and_undoes_the_greens() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        mesh.refine(&[0], &|_| false);
        let green = mesh.leaves_of_base(1)[0];
        let step = mesh.refine(&[green], &|_| false).remove(0);
        assert!(matches!(mesh.node(1).split(), Split::Red { .. }));
        assert_eq!(mesh.leaf_count(), 8);
        assert_eq!(step.replaced_leaves.len(), 2, "both greens go");
        assert_eq!(step.new_leaves.len(), 4);
        assert!(
            step.new_leaves
                .iter()
                .all(|&l| mesh.node(l).parent() == Some(1))
        );
    }

    #[test]
    fn neighbours_split_together_leave_no_greens_between_them() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        let step = mesh.split_red_all(&[0, 1]);
        assert!(matches!(mesh.node(0).split(), Split::Red { .. }));
        assert!(matches!(mesh.node(1).split(), Split::Red { .. }));
        assert_eq!(mesh.leaf_count(), 8);
        assert_eq!(step.replaced_leaves, vec![0, 1]);
        assert_eq!(step.new_leaves.len(), 8, "no green made and undone");
        assert_eq!(step.new_vertices.len(), 5);
        assert!(
            mesh.split_red_all(&[0]).new_leaves.is_empty(),
            "red already"
        );
    }

    #[test]
    fn vetoed_and_too_short_leaves_are_not_split() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        assert!(mesh.refine(&[0], &|id| id == 0).is_empty());
        let params = MeshParams {
            min_edge_length: 0.8,
            ..MeshParams::default()
        };
        let mut coarse = SubdivisionMesh::new(&square(), params);
        assert!(
            coarse.refine(&[0], &|_| false).is_empty(),
            "children would have edges < 0.8"
        );
        assert_eq!(coarse.leaf_count(), 2);
    }

    #[test]
    fn midpoint_barycentrics_place_it_on_its_base_triangle() {
        let mut mesh = SubdivisionMesh::new(&square(), MeshParams::default());
        let step = mesh.refine(&[1], &|_| false).remove(0);
        for v in step.new_vertices {
            let vertex = mesh.vertex(v);
            let t = mesh.leaf_positions(vertex.base_triangle);
            let [u, w] = vertex.bary;
            let p = (1.0 - u - w) * t[0] + u * t[1] + w * t[2];
            assert!(p.distance(vertex.position) < 1e-6);
        }
    }
}
