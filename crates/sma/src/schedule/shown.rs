//! The triangles one viewer is shown, and the diff that keeps them in step (DESIGN.md §3 step 4,
//! §5, §8): `Remove` for what left, `Insert` for what came in with all three samples cached,
//! `Update` for a shown triangle whose samples got better. The caller closes the batch with an
//! `Epoch`.

use std::collections::HashMap;

use glam::Vec3;
use protocol::Side;
use protocol::viewer_link::{CornerShading, Recolour, ShownTriangle, SmaToViewer, TriangleId};

use crate::cache::{LeafShading, ShadingCache};
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh, VertexId, table_bytes};
use crate::visible_set::shown_id;

/// What one viewer is shown, as this process last sent it.
#[derive(Debug, Default)]
pub struct ShownSet {
    /// Shown triangles, the radiance last sent for each, and the sync that last wanted it (ids
    /// made by this process: the fast hasher; a sync walks every visible leaf several times a
    /// second).
    shown: HashMap<TriangleId, Entry, FastHash>,
    /// Syncs so far: what a sync does not stamp with its own count has left the view.
    syncs: u64,
    /// Δins and Δrem since the last epoch.
    pub inserted: u64,
    pub removed: u64,
    /// Wanted triangles not shown yet for lack of samples, after the last sync.
    pub unshown: usize,
}

/// One shown triangle.
#[derive(Clone, Debug)]
struct Entry {
    /// Its radiance with the albedo at each vertex, for the luminance image of `nld-is`.
    radiance: [[f32; 3]; 3],
    /// What the viewer was last sent of it.
    shading: CornerShading,
    /// Its corners when sent: the mesh reuses removed nodes' ids (`mesh::free_nodes`), so an id
    /// may come back as another triangle; vertices are never reused, so they tell.
    vertices: [VertexId; 3],
    wanted_at: u64,
}

impl ShownSet {
    /// Triangles shown.
    pub fn len(&self) -> usize {
        self.shown.len()
    }

    /// Brings the viewer to `targets` (each node with the side it is seen from), as far as the
    /// cache allows, view-dependent samples as seen from `eye`. A shown triangle whose samples
    /// were evicted stays as it is. An id shown as another triangle (a reused node) is removed
    /// and, once its samples are cached, inserted again, in that order, in the same epoch.
    pub fn sync(
        &mut self,
        targets: &[(NodeId, Side)],
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
        eye: Vec3,
    ) -> Vec<SmaToViewer> {
        self.syncs += 1;
        let sync = self.syncs;
        let (mut inserts, mut updates) = (Vec::new(), Vec::new());
        self.unshown = 0;
        let mut removed = Vec::new();
        for &(node, side) in targets {
            let id = shown_id(node, side);
            let colours = cache.leaf_shading_from(mesh, node, side, eye);
            let vertices = mesh.node(node).vertices;
            if self.shown.get(&id).is_some_and(|s| s.vertices != vertices) {
                self.shown.remove(&id);
                removed.push(id);
            }
            match (self.shown.get_mut(&id), colours) {
                (Some(shown), colours) => {
                    shown.wanted_at = sync;
                    if let Some(LeafShading { radiance, shading }) =
                        colours.filter(|c| c.shading != shown.shading)
                    {
                        (shown.radiance, shown.shading) = (radiance, shading.clone());
                        updates.push(Recolour { id, shading });
                    }
                }
                (None, Some(LeafShading { radiance, shading })) => {
                    let (material, texcoords) = cache.leaf_surface(mesh, node);
                    inserts.push(ShownTriangle {
                        id,
                        positions: mesh.leaf_positions(node).map(|p| p.to_array()),
                        material,
                        texcoords,
                        shading: shading.clone(),
                    });
                    self.shown.insert(
                        id,
                        Entry {
                            radiance,
                            shading,
                            vertices,
                            wanted_at: sync,
                        },
                    );
                }
                (None, None) => self.unshown += 1,
            }
        }
        self.shown.retain(|&id, shown| {
            let wanted = shown.wanted_at == sync;
            if !wanted {
                removed.push(id);
            }
            wanted
        });
        self.inserted += inserts.len() as u64;
        self.removed += removed.len() as u64;
        let mut messages = Vec::new();
        if !removed.is_empty() {
            messages.push(SmaToViewer::Remove { ids: removed });
        }
        // The viewer's outbox splits them into frames of a safe size as it writes.
        if !inserts.is_empty() {
            messages.push(SmaToViewer::Insert { triangles: inserts });
        }
        if !updates.is_empty() {
            messages.push(SmaToViewer::Update { triangles: updates });
        }
        messages
    }

    /// The shown triangles as (corners, radiance), for the luminance image of `nld-is`: the
    /// corners as sent, whatever their node's id names now.
    pub fn shown_triangles(&self) -> impl Iterator<Item = ([VertexId; 3], [[f32; 3]; 3])> + '_ {
        self.shown
            .values()
            .map(|shown| (shown.vertices, shown.radiance))
    }

    /// Heap bytes of the table, by capacity.
    pub fn heap_bytes(&self) -> usize {
        table_bytes(&self.shown)
    }
}

#[cfg(test)]
mod tests {
    use protocol::renderer_link::{Quality, SampleKey};

    use super::*;
    use crate::cache::CachedSample;
    use crate::mesh::grid_mesh;
    use protocol::SampleParts;

    fn cache_all(mesh: &SubdivisionMesh, cache: &mut ShadingCache, value: f32) {
        for vertex in 0..mesh.vertex_count() as u32 {
            cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                CachedSample {
                    parts: SampleParts::direct_only([value; 3], 0.0),
                    quality: Quality::INTERACTIVE,
                    view_dependent: false,
                    eye: None,
                    last_seen: 0,
                },
            );
        }
    }

    fn kinds(messages: &[SmaToViewer]) -> Vec<(&'static str, usize)> {
        messages
            .iter()
            .map(|m| match m {
                SmaToViewer::Remove { ids } => ("remove", ids.len()),
                SmaToViewer::Insert { triangles } => ("insert", triangles.len()),
                SmaToViewer::Update { triangles } => ("update", triangles.len()),
                _ => ("other", 0),
            })
            .collect()
    }

    #[test]
    fn a_sync_removes_what_left_inserts_what_came_and_updates_what_changed() {
        let mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let mut cache = ShadingCache::new(1 << 20);
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let mut shown = ShownSet::default();
        let front = |nodes: &[NodeId]| -> Vec<(NodeId, Side)> {
            nodes.iter().map(|&n| (n, Side::Front)).collect()
        };
        let none = shown.sync(&front(&[0, 1, 2]), &mesh, &cache, eye);
        assert!(none.is_empty() && shown.unshown == 3, "nothing cached yet");
        cache_all(&mesh, &mut cache, 0.5);
        let first = shown.sync(&front(&[0, 1, 2]), &mesh, &cache, eye);
        assert_eq!(kinds(&first), [("insert", 3)]);
        assert_eq!((shown.len(), shown.unshown), (3, 0));
        assert!(
            shown
                .sync(&front(&[0, 1, 2]), &mesh, &cache, eye)
                .is_empty()
        );
        let moved = shown.sync(&front(&[1, 2, 3, 4]), &mesh, &cache, eye);
        assert_eq!(kinds(&moved), [("remove", 1), ("insert", 2)]);
        let mut brighter = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut brighter, 0.9);
        let changed = shown.sync(&front(&[1, 2, 3, 4]), &mesh, &brighter, eye);
        assert_eq!(kinds(&changed), [("update", 4)]);
        assert_eq!((shown.inserted, shown.removed), (5, 1));
    }

    #[test]
    fn a_reused_node_id_reaches_the_viewer_as_remove_then_insert_in_one_sync() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let eye = Vec3::new(1.0, 1.0, 3.0);
        mesh.refine(&[0], &|_| false);
        let red: Vec<NodeId> = mesh.node(0).children().collect();
        let front: Vec<(NodeId, Side)> = red.iter().map(|&n| (n, Side::Front)).collect();
        let mut cache = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut cache, 0.5);
        let mut shown = ShownSet::default();
        assert_eq!(
            kinds(&shown.sync(&front, &mesh, &cache, eye)),
            [("insert", 4)]
        );
        mesh.coarsen(0).expect("allowed");
        assert!(mesh.recycle_removed());
        // The far corner's split takes the recycled block: the same ids, other triangles.
        let far = mesh.base_count() as NodeId - 1;
        mesh.refine(&[far], &|_| false);
        assert_eq!(mesh.node(far).children().collect::<Vec<_>>(), red);
        cache_all(&mesh, &mut cache, 0.5);
        let messages = shown.sync(&front, &mesh, &cache, eye);
        assert_eq!(kinds(&messages), [("remove", 4), ("insert", 4)]);
        let SmaToViewer::Insert { triangles } = &messages[1] else {
            unreachable!()
        };
        for t in triangles {
            let node = crate::visible_set::split_shown_id(t.id).0;
            assert_eq!(t.positions, mesh.leaf_positions(node).map(|p| p.to_array()));
        }
        assert!(
            shown.sync(&front, &mesh, &cache, eye).is_empty(),
            "in step again"
        );
        assert_eq!((shown.inserted, shown.removed), (8, 4));
    }
}
