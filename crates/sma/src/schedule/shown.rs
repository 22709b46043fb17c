//! The triangles one viewer is shown, and the diff that keeps them in step (DESIGN.md §3 step 4,
//! §5, §8): `Remove` for what left, `Insert` for what came in with all three samples cached,
//! `Update` for a shown triangle whose samples got better. The caller closes the batch with an
//! `Epoch`.
//!
//! A walking viewer keeps, for a while, what left its view (DESIGN.md §3 step 9). Its view is
//! the SMA's last pass, drawn from a camera some steps behind the one the viewer draws with, so
//! a leaf the pass did not see may be in the viewer's picture: at the image's edge the head
//! turns into, and wherever leaves are about a pixel wide, which a step moves across pixel
//! centres. Sent only what the last pass saw, a walk through a refined site showed the
//! background through both (bracara's walk: black bands at the edges, its refined columns and
//! steps speckled black, FLIP 0.24 where the same camera's first pass had 0.11). Kept, they fill
//! what was seen a moment ago; the depth test hides those now behind something.

use std::collections::{HashMap, VecDeque};
use std::hash::Hasher;
use std::time::{Duration, Instant};

use glam::Vec3;
use protocol::Side;
use protocol::viewer_link::{CornerShading, Recolour, ShownTriangle, SmaToViewer, TriangleId};

use crate::cache::{LeafShading, ShadingCache};
use crate::mesh::fast_hash::{FastHash, IdHasher};
use crate::mesh::{NodeId, SubdivisionMesh, VertexId, table_bytes};
use crate::visible_set::{shown_id, split_shown_id};

/// Shown triangles a table keeps room for however few it holds: shrinking below is not worth
/// its rehash.
const SHOWN_KEPT: usize = 1024;

/// What one viewer is shown, as this process last sent it.
#[derive(Debug, Default)]
pub struct ShownSet {
    /// Shown triangles, by their [`TriangleId`] (below 2^30: node ids fit 29 bits, `mesh`),
    /// with what was last sent for each and the sync that last wanted it (ids made by this
    /// process: the fast hasher; a sync walks every visible leaf several times a second). One
    /// entry per visible leaf, so it is kept lean: at 100,000 shown triangles it was the
    /// largest part of the SMA's memory.
    shown: HashMap<u32, Entry, FastHash>,
    /// Syncs so far: what a sync does not stamp with its own count has left the view.
    syncs: u32,
    /// Δins and Δrem since the last epoch.
    pub inserted: u64,
    pub removed: u64,
    /// Wanted triangles not shown yet for lack of samples, after the last sync.
    pub unshown: usize,
    /// Shown triangles the last sync did not want, kept while the viewer walks.
    pub kept: usize,
    /// When the recent syncs ran, oldest first, as far back as a walking viewer keeps what
    /// left its view.
    recent: VecDeque<(u32, Instant)>,
}

/// How a sync treats what left the view: dropped at once (a camera at rest: the same camera as
/// the last sync's), or kept while it was wanted within `for_` and is still a leaf of the mesh
/// (a walking camera: the sync answers a new one).
#[derive(Clone, Copy, Debug)]
pub struct Keeping {
    pub now: Instant,
    pub walking: bool,
    pub for_: Duration,
}

/// One shown triangle.
#[derive(Clone, Copy, Debug)]
struct Entry {
    /// A hash of the shading last sent (illumination, direct share and view-dependent part at
    /// each corner): a sync sends an `Update` when the cache's differs; two alike in their
    /// 64-bit hash are taken as one.
    sent: [u32; 2],
    /// The luminance of the radiance last sent (with the mean albedo around each vertex), per corner:
    /// what `nld-is` reads.
    luminance: [f32; 3],
    /// Its corners when sent: the mesh reuses removed nodes' ids (`mesh::free_nodes`), so an id
    /// may come back as another triangle; a shown triangle's vertices are never reused
    /// (`SubdivisionMesh::free_unused_midpoints` keeps them), so they tell.
    vertices: [VertexId; 3],
    /// The sync that last wanted it (wrapping: only equality with the current one is read).
    wanted_at: u32,
}

/// A table slot is this, and a control byte: 41 bytes a shown triangle (73 with the colours kept
/// whole and a 64-bit key).
const _: () = assert!(size_of::<(u32, Entry)>() == 40);

/// Whether shown triangle `key`, sent with `vertices`, is still a leaf of `mesh`: refinement,
/// coarsening and compaction (which renames nodes) may all have replaced it.
fn still_a_leaf(mesh: &SubdivisionMesh, key: u32, vertices: [VertexId; 3]) -> bool {
    let node = split_shown_id(u64::from(key)).0;
    (node as usize) < mesh.node_count()
        && mesh.is_leaf(node)
        && mesh.node(node).vertices == vertices
}

/// What [`Entry::sent`] holds of a triangle's shading.
fn shading_hash(shading: &CornerShading) -> [u32; 2] {
    let mut hasher = IdHasher::default();
    for c in shading.illumination.as_flattened() {
        hasher.write_u32(c.to_bits());
    }
    for d in &shading.direct_share {
        hasher.write_u8(d.0);
    }
    match &shading.view_dependent {
        None => hasher.write_u8(0),
        Some(v) => {
            hasher.write_u8(1);
            for c in v.as_flattened() {
                hasher.write_u32(c.to_bits());
            }
        }
    }
    let h = hasher.finish();
    [h as u32, (h >> 32) as u32]
}

impl ShownSet {
    /// Triangles shown.
    pub fn len(&self) -> usize {
        self.shown.len()
    }

    /// Brings the viewer to `targets` (each node with the side it is seen from), as far as the
    /// cache allows, view-dependent samples as seen from `eye`. A shown triangle whose samples
    /// were evicted stays as it is. An id shown as another triangle (a reused node) is removed
    /// and, once its samples are cached, inserted again, in that order, in the same epoch. What
    /// left the view goes or stays as `keeping` says.
    pub fn sync(
        &mut self,
        targets: &[(NodeId, Side)],
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
        eye: Vec3,
        keeping: Keeping,
    ) -> Vec<SmaToViewer> {
        self.syncs = self.syncs.wrapping_add(1);
        let sync = self.syncs;
        let oldest_kept = self.oldest_kept(keeping);
        let (mut inserts, mut updates) = (Vec::new(), Vec::new());
        self.unshown = 0;
        let mut removed = Vec::new();
        for &(node, side) in targets {
            let id = shown_id(node, side);
            let key = id as u32;
            let colours = cache.leaf_shading_from(mesh, node, side, eye);
            let vertices = mesh.node(node).vertices;
            if self.shown.get(&key).is_some_and(|s| s.vertices != vertices) {
                self.shown.remove(&key);
                removed.push(id);
            }
            match (self.shown.get_mut(&key), colours) {
                (Some(shown), colours) => {
                    shown.wanted_at = sync;
                    let changed = colours.map(|c| {
                        let sent = shading_hash(&c.shading);
                        (c, sent)
                    });
                    if let Some((LeafShading { radiance, shading }, sent)) =
                        changed.filter(|&(_, sent)| sent != shown.sent)
                    {
                        shown.sent = sent;
                        shown.luminance = radiance.map(conventions::luminance);
                        updates.push(Recolour { id, shading });
                    }
                }
                (None, Some(LeafShading { radiance, shading })) => {
                    let (material, texcoords) = cache.leaf_surface(mesh, node);
                    let sent = shading_hash(&shading);
                    inserts.push(ShownTriangle {
                        id,
                        positions: mesh.leaf_positions(node).map(|p| p.to_array()),
                        material,
                        texcoords,
                        shading,
                    });
                    self.shown.insert(
                        key,
                        Entry {
                            sent,
                            luminance: radiance.map(conventions::luminance),
                            vertices,
                            wanted_at: sync,
                        },
                    );
                }
                (None, None) => self.unshown += 1,
            }
        }
        self.kept = 0;
        let kept_syncs = sync.wrapping_sub(oldest_kept);
        self.shown.retain(|&key, shown| {
            let age = sync.wrapping_sub(shown.wanted_at);
            if age == 0 {
                return true;
            }
            let kept = age <= kept_syncs && still_a_leaf(mesh, key, shown.vertices);
            if kept {
                self.kept += 1;
            } else {
                removed.push(TriangleId::from(key));
            }
            kept
        });
        // A table keeps its peak capacity: once the view shrank (a coarsened mesh, a turn to a
        // plainer wall) to a quarter of it, half is given back to the memory budget.
        if self.shown.capacity() > 4 * self.shown.len().max(SHOWN_KEPT) {
            self.shown.shrink_to(2 * self.shown.len());
        }
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

    /// Notes the sync about to run and returns the oldest one whose wanted triangles it keeps:
    /// itself unless the viewer walks, else the oldest within `keeping.for_`.
    fn oldest_kept(&mut self, keeping: Keeping) -> u32 {
        let now = keeping.now;
        self.recent.push_back((self.syncs, now));
        while self
            .recent
            .front()
            .is_some_and(|&(_, at)| now.saturating_duration_since(at) > keeping.for_)
        {
            self.recent.pop_front();
        }
        match self.recent.front() {
            Some(&(oldest, _)) if keeping.walking => oldest,
            _ => self.syncs,
        }
    }

    /// The shown triangles as (corners, luminance of the radiance sent), for the luminance image
    /// of `nld-is`: the corners as sent, whatever their node's id names now.
    pub fn shown_triangles(&self) -> impl Iterator<Item = ([VertexId; 3], [f32; 3])> + '_ {
        self.shown
            .values()
            .map(|shown| (shown.vertices, shown.luminance))
    }

    /// Heap bytes of the table, by capacity.
    pub fn heap_bytes(&self) -> usize {
        table_bytes(&self.shown) + self.recent.capacity() * size_of::<(u32, Instant)>()
    }
}

#[cfg(test)]
mod tests {
    use protocol::renderer_link::SampleKey;

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
                CachedSample::diffuse(SampleParts::direct_only([value; 3], 0.0)),
            );
        }
    }

    fn resting() -> Keeping {
        Keeping {
            now: Instant::now(),
            walking: false,
            for_: Duration::from_secs(2),
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
        let none = shown.sync(&front(&[0, 1, 2]), &mesh, &cache, eye, resting());
        assert!(none.is_empty() && shown.unshown == 3, "nothing cached yet");
        cache_all(&mesh, &mut cache, 0.5);
        let first = shown.sync(&front(&[0, 1, 2]), &mesh, &cache, eye, resting());
        assert_eq!(kinds(&first), [("insert", 3)]);
        assert_eq!((shown.len(), shown.unshown), (3, 0));
        assert!(
            shown
                .sync(&front(&[0, 1, 2]), &mesh, &cache, eye, resting())
                .is_empty()
        );
        let moved = shown.sync(&front(&[1, 2, 3, 4]), &mesh, &cache, eye, resting());
        assert_eq!(kinds(&moved), [("remove", 1), ("insert", 2)]);
        let mut brighter = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut brighter, 0.9);
        let changed = shown.sync(&front(&[1, 2, 3, 4]), &mesh, &brighter, eye, resting());
        assert_eq!(kinds(&changed), [("update", 4)]);
        assert_eq!((shown.inserted, shown.removed), (5, 1));
    }

    #[test]
    fn a_walking_viewer_keeps_what_left_its_view_for_a_while_and_drops_it_at_rest() {
        let mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let mut cache = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut cache, 0.5);
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let start = Instant::now();
        let walking = |s: f64| Keeping {
            now: start + Duration::from_secs_f64(s),
            walking: true,
            for_: Duration::from_secs(2),
        };
        let front = |nodes: &[NodeId]| -> Vec<(NodeId, Side)> {
            nodes.iter().map(|&n| (n, Side::Front)).collect()
        };
        let mut shown = ShownSet::default();
        shown.sync(&front(&[0, 1, 2]), &mesh, &cache, eye, walking(0.0));
        let moved = shown.sync(&front(&[1, 2, 3]), &mesh, &cache, eye, walking(0.5));
        assert_eq!(kinds(&moved), [("insert", 1)], "0 left the view, and stays");
        assert_eq!((shown.len(), shown.kept), (4, 1));
        shown.sync(&front(&[3]), &mesh, &cache, eye, walking(1.0));
        assert_eq!((shown.len(), shown.kept), (4, 3));
        let later = shown.sync(&front(&[3]), &mesh, &cache, eye, walking(2.2));
        assert_eq!(kinds(&later), [("remove", 1)], "0, last wanted 2.2 s ago");
        assert_eq!((shown.len(), shown.kept), (3, 2));
        let rested = shown.sync(&front(&[3]), &mesh, &cache, eye, resting());
        assert_eq!(
            kinds(&rested),
            [("remove", 2)],
            "at rest only the view is shown"
        );
        assert_eq!((shown.len(), shown.kept), (1, 0));
    }

    #[test]
    fn a_kept_triangle_that_is_no_longer_a_leaf_goes_at_once() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(2), Default::default());
        let mut cache = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut cache, 0.5);
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let walking = Keeping {
            now: Instant::now(),
            walking: true,
            for_: Duration::from_secs(2),
        };
        let far = mesh.base_count() as NodeId - 1;
        let mut shown = ShownSet::default();
        let both = [(0, Side::Front), (far, Side::Front)];
        shown.sync(&both, &mesh, &cache, eye, walking);
        shown.sync(&both[1..], &mesh, &cache, eye, walking);
        assert_eq!(shown.kept, 1);
        mesh.refine(&[0], &|_| false);
        assert!(!mesh.is_leaf(0) && mesh.is_leaf(far));
        let refined = shown.sync(&both[1..], &mesh, &cache, eye, walking);
        assert_eq!(kinds(&refined), [("remove", 1)]);
        assert_eq!((shown.len(), shown.kept), (1, 0));
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
            kinds(&shown.sync(&front, &mesh, &cache, eye, resting())),
            [("insert", 4)]
        );
        mesh.coarsen(0).expect("allowed");
        assert!(mesh.recycle_removed());
        // The far corner's split takes the recycled block: the same ids, other triangles.
        let far = mesh.base_count() as NodeId - 1;
        mesh.refine(&[far], &|_| false);
        assert_eq!(mesh.node(far).children().collect::<Vec<_>>(), red);
        cache_all(&mesh, &mut cache, 0.5);
        let messages = shown.sync(&front, &mesh, &cache, eye, resting());
        assert_eq!(kinds(&messages), [("remove", 4), ("insert", 4)]);
        let SmaToViewer::Insert { triangles } = &messages[1] else {
            unreachable!()
        };
        for t in triangles {
            let node = crate::visible_set::split_shown_id(t.id).0;
            assert_eq!(t.positions, mesh.leaf_positions(node).map(|p| p.to_array()));
        }
        assert!(
            shown.sync(&front, &mesh, &cache, eye, resting()).is_empty(),
            "in step again"
        );
        assert_eq!((shown.inserted, shown.removed), (8, 4));
    }

    #[test]
    fn nodes_moved_by_a_compaction_reach_the_viewer_as_remove_then_insert_of_the_same_triangles() {
        let mut mesh = SubdivisionMesh::new(&grid_mesh(4), Default::default());
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let (near, far) = (0, mesh.base_count() as NodeId - 1);
        mesh.refine(&[near], &|_| false);
        mesh.refine(&[far], &|_| false);
        let far_leaves = |mesh: &SubdivisionMesh| -> Vec<(NodeId, Side)> {
            mesh.leaves_of_base(far)
                .into_iter()
                .map(|n| (n, Side::Front))
                .collect()
        };
        let mut cache = ShadingCache::new(1 << 20);
        cache_all(&mesh, &mut cache, 0.5);
        let mut shown = ShownSet::default();
        let before = far_leaves(&mesh);
        let first = shown.sync(&before, &mesh, &cache, eye, resting());
        assert_eq!(kinds(&first), [("insert", before.len())]);
        // The near corner's blocks go; the far one's, the array's end, move into them.
        assert!(!mesh.coarsen_many(&[near]).is_empty());
        assert!(mesh.recycle_removed());
        let after = far_leaves(&mesh);
        assert_ne!(after, before, "the far leaves were renamed");
        let messages = shown.sync(&after, &mesh, &cache, eye, resting());
        let moved = after.iter().filter(|t| !before.contains(t)).count();
        assert_eq!(kinds(&messages), [("remove", moved), ("insert", moved)]);
        let positions = |first: &[SmaToViewer]| -> Vec<[[f32; 3]; 3]> {
            let mut p: Vec<_> = first
                .iter()
                .flat_map(|m| match m {
                    SmaToViewer::Insert { triangles } => triangles.clone(),
                    _ => Vec::new(),
                })
                .map(|t| t.positions)
                .collect();
            p.sort_by(|a, b| a.partial_cmp(b).unwrap());
            p
        };
        let mut kept = positions(&first);
        kept.retain(|p| positions(&messages).contains(p));
        assert_eq!(kept, positions(&messages), "moved, not changed");
        assert!(shown.sync(&after, &mesh, &cache, eye, resting()).is_empty());
    }

    #[test]
    fn a_table_that_shrank_gives_its_capacity_back() {
        let mesh = SubdivisionMesh::new(&grid_mesh(64), Default::default());
        let eye = Vec3::new(1.0, 1.0, 3.0);
        let mut cache = ShadingCache::new(1 << 24);
        cache_all(&mesh, &mut cache, 0.5);
        let all: Vec<(NodeId, Side)> = mesh.leaves().map(|n| (n, Side::Front)).collect();
        let mut shown = ShownSet::default();
        shown.sync(&all, &mesh, &cache, eye, resting());
        let full = shown.heap_bytes();
        shown.sync(&all[..10], &mesh, &cache, eye, resting());
        assert_eq!(shown.len(), 10);
        assert!(
            shown.heap_bytes() < full / 4,
            "{} of {full}",
            shown.heap_bytes()
        );
    }
}
