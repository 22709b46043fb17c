//! Rebuilding the mesh and the cache from records (DESIGN.md §5), those of the base triangles
//! that just became visible. The splits are replayed level by level across the records, a
//! level at a time (`SubdivisionMesh::split_red_all`): a record's red splits are asked of the
//! mesh, whose closure makes the green ones (and any red ones a neighbour needs, loaded or not),
//! so the mesh is conforming after every level whatever records were saved or loaded together.
//! Then every record's shape is matched against the mesh that came out, node by node from its
//! base triangle, and each matched vertex the cache has no sample of gets its stored one (a
//! sample traced in this run is as new as any stored); where two records hold a vertex (an edge
//! or corner two base triangles share), the deeper estimate with more paths wins.

use protocol::Side;
use protocol::renderer_link::SampleKey;

use super::record::{
    BadShape, BaseRecord, GREEN_ALONG, LEAF, RED, StoredSample, synthetic_corners, vertex_map,
};
use crate::cache::ShadingCache;
use crate::mesh::{NodeId, RefinementStep, Split, SubdivisionMesh, VertexId};

/// A record checked and parsed, ready to replay.
pub struct Parsed {
    pub base: u32,
    record: BaseRecord,
    corners: Vec<[u32; 3]>,
    vertex_count: u32,
    /// Per shape node, the size of its subtree (itself included): its children follow it.
    sizes: Vec<u32>,
}

/// A record that cannot be this mesh's.
#[derive(Debug, thiserror::Error)]
pub enum BadRecord {
    #[error("base triangle {0} is not in this scene's mesh")]
    NoSuchBase(u32),
    #[error("base triangle {base}: {shape}")]
    Shape { base: u32, shape: BadShape },
    #[error("base triangle {0}: its samples do not match its subtree's vertices")]
    Samples(u32),
}

fn arity(code: u8) -> usize {
    match code {
        RED => 4,
        LEAF => 0,
        _ => 2,
    }
}

/// Subtree sizes of a well-formed pre-order shape, by a pass from its end.
fn subtree_sizes(shape: &[u8]) -> Vec<u32> {
    let mut sizes = vec![0; shape.len()];
    let mut done: Vec<u32> = Vec::new();
    for (i, &code) in shape.iter().enumerate().rev() {
        let n = arity(code);
        let size = 1 + done.drain(done.len() - n..).sum::<u32>();
        sizes[i] = size;
        done.push(size);
    }
    sizes
}

impl Parsed {
    pub fn new(base: u32, record: BaseRecord, base_count: usize) -> Result<Parsed, BadRecord> {
        if base as usize >= base_count {
            return Err(BadRecord::NoSuchBase(base));
        }
        let (corners, vertex_count) =
            synthetic_corners(&record.shape).map_err(|shape| BadRecord::Shape { base, shape })?;
        if record.samples.len() != vertex_count as usize {
            return Err(BadRecord::Samples(base));
        }
        let sizes = subtree_sizes(&record.shape);
        Ok(Parsed {
            base,
            record,
            corners,
            vertex_count,
            sizes,
        })
    }

    /// The shape indices of node `i`'s children.
    fn children(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        let mut next = i + 1;
        (0..arity(self.record.shape[i])).map(move |_| {
            let child = next;
            next += self.sizes[child] as usize;
            child
        })
    }
}

/// What a restore brought back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Restored {
    pub bases: usize,
    pub samples: usize,
    /// Stored vertices whose node the rebuilt mesh does not have (its splits came out otherwise):
    /// their samples are left out.
    pub unmatched_vertices: usize,
    /// Time opening the file (integrity check included) and listing its records.
    pub open: std::time::Duration,
    /// Time reading, decoding and checking the records.
    pub read: std::time::Duration,
    /// Time replaying the splits, and putting the samples into the cache.
    pub replay: std::time::Duration,
    pub samples_time: std::time::Duration,
    /// The whole load: the open and every load since.
    pub total: std::time::Duration,
}

impl Restored {
    /// Adds a later load's counts and times.
    pub fn add(&mut self, load: Restored) {
        self.bases += load.bases;
        self.samples += load.samples;
        self.unmatched_vertices += load.unmatched_vertices;
        self.read += load.read;
        self.replay += load.replay;
        self.samples_time += load.samples_time;
        self.total += load.total;
    }
}

/// What one restore changed: the steps that take the viewers from the leaves before it to
/// those after, and per matched mesh vertex a base triangle whose record holds it.
pub struct Replayed {
    pub restored: Restored,
    pub steps: Vec<RefinementStep>,
    pub owners: Vec<(VertexId, u32)>,
}

/// Replays the records' splits into `mesh` and puts their samples into `cache` where it has
/// none.
pub fn restore(
    records: &[Parsed],
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> Replayed {
    let start = std::time::Instant::now();
    let steps = replay_splits(records, mesh);
    let replay = start.elapsed();
    // The replay made midpoint vertices no answer has covered yet: until their mean albedos are
    // taken (over the restored leaves around them, finer than when a walk made them: on a
    // texture far finer than the leaves the two means agree), every reader of a sample (the
    // criteria, L_white, the stopping rule) would judge them at albedo one beside corners at
    // their material's, a variation the first visit never saw, and split the restored leaves
    // again (DESIGN.md §5, "Parts, and textures"; "Persistence": a site walked yesterday
    // appears at once today).
    cache.cover_albedos(mesh);
    // The best stored sample per slot `2 * vertex + side`: a table by slot, as the cache's own
    // is (zeroed pages cost nothing until touched), and the slots filled, in order.
    let mut best: Vec<Option<&StoredSample>> = vec![None; 2 * mesh.vertex_count()];
    let stored_samples: usize = records.iter().map(|p| p.record.samples.len()).sum();
    let mut filled = Vec::with_capacity(2 * stored_samples);
    let mut owners = Vec::new();
    let mut unmatched_vertices = 0;
    for parsed in records {
        let node_of = matched_nodes(parsed, mesh);
        let map = vertex_map(mesh, &parsed.corners, parsed.vertex_count, |i| node_of[i]);
        for (stored, vertex) in parsed.record.samples.iter().zip(map) {
            let Some(vertex) = vertex else {
                unmatched_vertices += 1;
                continue;
            };
            owners.push((vertex, parsed.base));
            for (side, sample) in stored.iter().enumerate() {
                let Some(sample) = sample.as_ref().filter(|s| s.cached().estimate().is_valid())
                else {
                    continue;
                };
                let slot = 2 * vertex as usize + side;
                match best[slot] {
                    None => {
                        best[slot] = Some(sample);
                        filled.push(slot);
                    }
                    Some(kept) if rank(sample) > rank(kept) => best[slot] = Some(sample),
                    Some(_) => {}
                }
            }
        }
    }
    let mut samples = 0;
    for slot in filled {
        let Some(sample) = best[slot] else { continue };
        let side = if slot % 2 == 0 {
            Side::Front
        } else {
            Side::Back
        };
        let key = SampleKey {
            vertex: (slot / 2) as VertexId,
            side,
        };
        if cache.get(key).is_none() {
            cache.insert(key, sample.cached());
            samples += 1;
        }
    }
    let restored = Restored {
        bases: records.len(),
        samples,
        unmatched_vertices,
        replay,
        samples_time: start.elapsed() - replay,
        ..Restored::default()
    };
    Replayed {
        restored,
        steps,
        owners,
    }
}

/// Of two stored samples of one vertex and side (an edge or corner two base triangles share),
/// the deeper estimate with more paths wins: unlimited bounces first, then paths.
fn rank(sample: &StoredSample) -> (u32, u32) {
    (sample.bounces.unwrap_or(u32::MAX), sample.paths)
}

/// Asks the mesh for every record's red splits, shallowest first, a level at a time; one step
/// per level that split anything.
fn replay_splits(records: &[Parsed], mesh: &mut SubdivisionMesh) -> Vec<RefinementStep> {
    let mut steps = Vec::new();
    let mut level: Vec<(usize, usize, NodeId)> = records
        .iter()
        .enumerate()
        .filter(|(_, p)| p.record.shape[0] == RED)
        .map(|(r, p)| (r, 0, p.base))
        .collect();
    let mut targets = Vec::new();
    while !level.is_empty() {
        targets.clear();
        targets.extend(level.iter().map(|&(_, _, id)| id));
        let step = mesh.split_red_all(&targets);
        if !step.new_leaves.is_empty() {
            steps.push(step);
        }
        let mut next = Vec::new();
        for (r, i, id) in level {
            let Split::Red { first_child } = mesh.node(id).split() else {
                continue;
            };
            let children = records[r].children(i).zip(first_child..);
            next.extend(
                children
                    .filter(|&(child, _)| records[r].record.shape[child] == RED)
                    .map(|(child, node)| (r, child, node)),
            );
        }
        level = next;
    }
    steps
}

/// Per node of the record's shape, the mesh node that has the same place in the base
/// triangle's subtree and the same split above it; None where the mesh came out otherwise.
fn matched_nodes(parsed: &Parsed, mesh: &SubdivisionMesh) -> Vec<Option<NodeId>> {
    let mut node_of = vec![None; parsed.record.shape.len()];
    let mut stack = vec![(0usize, parsed.base)];
    while let Some((i, id)) = stack.pop() {
        node_of[i] = Some(id);
        let code = parsed.record.shape[i];
        let first = match mesh.node(id).split() {
            Split::Red { first_child } if code == RED => first_child,
            Split::Green { first_child, edge } if code == GREEN_ALONG + edge => first_child,
            _ => continue,
        };
        stack.extend(parsed.children(i).zip(first..));
    }
    node_of
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subtree_sizes_count_each_node_and_its_descendants() {
        let shape = [
            RED,
            GREEN_ALONG,
            LEAF,
            LEAF,
            LEAF,
            RED,
            LEAF,
            LEAF,
            LEAF,
            LEAF,
            LEAF,
        ];
        let sizes = subtree_sizes(&shape);
        assert_eq!(sizes[0], 11);
        assert_eq!(sizes[1], 3);
        assert_eq!(sizes[5], 5);
    }
}
