//! What one viewer holds, and the diff that keeps it in step (DESIGN.md §3 step 4, §5, §8):
//! `Remove` for what left, `Insert` for what came in with all three samples cached, `Update` for
//! a shown triangle whose samples got better. The caller closes the batch with an `Epoch`.

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use protocol::Side;
use protocol::viewer_link::{Recolour, ShownTriangle, SmaToViewer, TriangleId};

use crate::cache::ShadingCache;
use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh};
use crate::visible_set::shown_id;

#[derive(Debug, Default)]
pub struct Display {
    /// Shown triangles and the radiance last sent for each (ids made by this process: the fast
    /// hasher; a sync walks every visible leaf several times a second).
    shown: HashMap<TriangleId, [[f32; 3]; 3], FastHash>,
    /// Δins and Δrem since the last epoch.
    pub inserted: u64,
    pub removed: u64,
    /// Wanted triangles not shown yet for lack of samples, after the last sync.
    pub unshown: usize,
}

impl Display {
    pub fn shown(&self) -> usize {
        self.shown.len()
    }

    /// Brings the viewer to `targets` (each node with the side it is seen from), as far as the
    /// cache allows, view-dependent samples as seen from `eye`. A shown triangle whose samples
    /// were evicted stays as it is.
    pub fn sync(
        &mut self,
        targets: &[(NodeId, Side)],
        mesh: &SubdivisionMesh,
        cache: &ShadingCache,
        eye: Vec3,
    ) -> Vec<SmaToViewer> {
        let wanted: HashSet<TriangleId, FastHash> =
            targets.iter().map(|&(n, s)| shown_id(n, s)).collect();
        let removed: Vec<TriangleId> = self
            .shown
            .keys()
            .filter(|id| !wanted.contains(id))
            .copied()
            .collect();
        for id in &removed {
            self.shown.remove(id);
        }
        let (mut inserts, mut updates) = (Vec::new(), Vec::new());
        self.unshown = 0;
        for &(node, side) in targets {
            let id = shown_id(node, side);
            let Some(radiance) = cache.leaf_radiance_from(mesh, node, side, eye) else {
                self.unshown += usize::from(!self.shown.contains_key(&id));
                continue;
            };
            match self.shown.insert(id, radiance) {
                None => inserts.push(ShownTriangle {
                    id,
                    positions: mesh.leaf_positions(node).map(|p| p.to_array()),
                    radiance,
                }),
                Some(old) if old != radiance => updates.push(Recolour { id, radiance }),
                Some(_) => {}
            }
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

    /// The shown triangles as (node, side, radiance), for the luminance image of `nld-is`.
    pub fn shown_triangles(&self) -> impl Iterator<Item = (NodeId, [[f32; 3]; 3])> + '_ {
        self.shown
            .iter()
            .map(|(&id, &rgb)| (crate::visible_set::split_shown_id(id).0, rgb))
    }
}
