//! Giving the node array's capacity back (DESIGN.md §4, §5's memory budget): reused free blocks
//! keep a long walk's nodes from growing, but the array stays at its high-water mark once a
//! coarsening has emptied it. Compaction moves the live child blocks nearest its end into free
//! blocks lower down, cuts off the free end and shrinks the allocation.
//!
//! Moving a block renames live nodes, so it runs only where recycling does (`free_nodes`):
//! nothing outside the mesh names a node then but the viewers' shown tables, which tell a moved
//! triangle by its corners and send it as a `Remove` and an `Insert` (`schedule::shown`).

use super::{GREEN_CHILD, NO_PARENT, NodeId, Split, SubdivisionMesh};

impl SubdivisionMesh {
    /// Moves live child blocks from the end of the node array into the free blocks below them
    /// (blocks of the same size), truncates the free end and gives back the capacity beyond
    /// it. Call only right after a recycle: every removed block is free, none retired.
    pub(super) fn compact_nodes(&mut self) {
        debug_assert_eq!(self.free_nodes.retired_slots(), 0);
        let mut free = self.free_nodes.take_free();
        free.sort_unstable();
        // Live child blocks, last first.
        let mut live: Vec<(NodeId, usize)> = self
            .nodes
            .iter()
            .filter(|n| n.is_alive())
            .map(|n| n.children())
            .filter(|c| !c.is_empty())
            .map(|c| (c.start, c.len()))
            .collect();
        live.sort_unstable_by(|a, b| b.cmp(a));
        let mut remap: Vec<NodeId> = (0..self.nodes.len() as NodeId).collect();
        let mut vacated = Vec::new();
        // The lowest free block of each size not yet taken.
        let mut lowest = [0usize; 2];
        for (first, len) in live {
            let class = usize::from(len == 4);
            let next = &mut lowest[class];
            while free.get(*next).is_some_and(|&(_, l)| l != len) {
                *next += 1;
            }
            let Some(&(to, _)) = free.get(*next).filter(|&&(to, _)| to < first) else {
                continue;
            };
            free[*next].1 = 0;
            *next += 1;
            for i in 0..len as NodeId {
                self.nodes[(to + i) as usize] = self.nodes[(first + i) as usize];
                self.nodes[(first + i) as usize].kill();
                remap[(first + i) as usize] = to + i;
            }
            vacated.push((first, len));
        }
        if !vacated.is_empty() {
            for node in self.nodes.iter_mut().filter(|n| n.is_alive()) {
                if node.parent != NO_PARENT {
                    let green = node.parent & GREEN_CHILD;
                    node.parent = remap[(node.parent & !GREEN_CHILD) as usize] | green;
                }
                match node.split() {
                    Split::None => {}
                    Split::Red { first_child } => node.set_split(Split::Red {
                        first_child: remap[first_child as usize],
                    }),
                    Split::Green { first_child, edge } => node.set_split(Split::Green {
                        first_child: remap[first_child as usize],
                        edge,
                    }),
                }
            }
        }
        let len = self
            .nodes
            .iter()
            .rposition(|n| n.is_alive())
            .map_or(0, |last| last + 1)
            .max(self.base_count);
        self.nodes.truncate(len);
        self.nodes.shrink_to_fit();
        let kept = free
            .into_iter()
            .filter(|&(_, l)| l > 0)
            .chain(vacated)
            .filter(|&(first, _)| (first as usize) < len)
            .collect();
        self.free_nodes.set_free(kept);
    }
}

#[cfg(test)]
mod tests {
    use crate::mesh::test_meshes::grid;
    use crate::mesh::{MeshParams, NodeId, SubdivisionMesh, invariants};

    fn coarsen_all(mesh: &mut SubdivisionMesh) {
        while !mesh
            .coarsen_many(&(0..mesh.node_count() as NodeId).collect::<Vec<_>>())
            .is_empty()
        {}
    }

    /// The leaves as their corners, in base order: what compaction must keep whatever the ids.
    fn leaf_corners(mesh: &SubdivisionMesh) -> Vec<[u32; 3]> {
        mesh.leaves().map(|l| mesh.node(l).vertices).collect()
    }

    #[test]
    fn a_refine_and_collapse_cycle_gives_the_node_capacity_back() {
        let scene = grid(4);
        let mut mesh = SubdivisionMesh::new(&scene, MeshParams::default());
        let base = mesh.memory();
        for _ in 0..3 {
            let leaves: Vec<NodeId> = mesh.leaves().collect();
            mesh.refine(&leaves, &|_| false);
        }
        assert!(mesh.memory().nodes > 4 * base.nodes);
        coarsen_all(&mut mesh);
        assert!(mesh.recycle_removed());
        assert_eq!(mesh.node_count(), mesh.base_count(), "every child was free");
        assert_eq!(
            mesh.memory().nodes,
            base.nodes,
            "the capacity is given back"
        );
        invariants::check(&mesh, &scene).unwrap();
    }

    #[test]
    fn live_blocks_move_down_into_free_ones_and_the_leaves_stay_the_same_triangles() {
        let scene = grid(4);
        let mut mesh = SubdivisionMesh::new(&scene, MeshParams::default());
        // Refine the first corner, then the far one on top of it, then two levels more there.
        let (near, far) = (0, mesh.base_count() as NodeId - 1);
        mesh.refine(&[near], &|_| false);
        mesh.refine(&[far], &|_| false);
        for _ in 0..2 {
            let deep: Vec<NodeId> = mesh.leaves().filter(|&l| mesh.base_of(l) == far).collect();
            mesh.refine(&deep, &|_| false);
        }
        // The near corner's blocks, the lowest ids, go: the far one's are the array's end.
        assert!(!mesh.coarsen_many(&[near]).is_empty());
        let corners = leaf_corners(&mesh);
        let (nodes, leaves) = (mesh.node_count(), mesh.leaf_count());
        assert!(mesh.recycle_removed());
        assert!(mesh.node_count() < nodes, "blocks moved down, the end cut");
        assert_eq!(mesh.leaf_count(), leaves);
        assert_eq!(leaf_corners(&mesh), corners, "the same triangles");
        invariants::check(&mesh, &scene).unwrap();
        // Ids stay consistent: refining and coarsening go on over the moved nodes.
        let deep: Vec<NodeId> = mesh
            .leaves()
            .filter(|&l| mesh.base_of(l) == far)
            .take(3)
            .collect();
        mesh.refine(&deep, &|_| false);
        invariants::check(&mesh, &scene).unwrap();
        coarsen_all(&mut mesh);
        assert_eq!(mesh.leaf_count(), mesh.base_count());
        assert!(mesh.recycle_removed());
        assert_eq!(mesh.node_count(), mesh.base_count());
        invariants::check(&mesh, &scene).unwrap();
    }
}
