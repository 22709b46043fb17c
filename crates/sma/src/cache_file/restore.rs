//! Rebuilding the mesh and the cache from the records (DESIGN.md §5). The splits are replayed
//! level by level across all base triangles: a record's red splits are asked of the mesh, whose
//! closure makes the green ones (and any red ones a neighbour's record needs), so the mesh is
//! conforming after every split whatever records were saved together. Then every record's shape
//! is matched against the mesh that came out, node by node from its base triangle, and each
//! matched vertex gets its stored samples; where two records hold a vertex (an edge or corner
//! two base triangles share), the deeper estimate with more paths wins.

use std::collections::HashMap;

use protocol::Side;
use protocol::renderer_link::SampleKey;

use super::record::{BadShape, BaseRecord, GREEN_ALONG, LEAF, RED, synthetic_corners, vertex_map};
use crate::cache::{CachedSample, ShadingCache};
use crate::mesh::{NodeId, Split, SubdivisionMesh, VertexId};

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
    /// Time opening the file (integrity check included), reading and checking the records.
    pub read: std::time::Duration,
    /// Time replaying the splits, and putting the samples into the cache.
    pub replay: std::time::Duration,
    pub samples_time: std::time::Duration,
    /// The whole load.
    pub total: std::time::Duration,
}

/// Replays every record's splits into `mesh` and puts their samples into `cache`; returns what
/// came back and, per matched mesh vertex, a base triangle whose record holds it.
pub fn restore(
    records: &[Parsed],
    mesh: &mut SubdivisionMesh,
    cache: &mut ShadingCache,
) -> (Restored, Vec<(VertexId, u32)>) {
    let start = std::time::Instant::now();
    replay_splits(records, mesh);
    let replay = start.elapsed();
    let mut best: HashMap<SampleKey, CachedSample> = HashMap::new();
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
            for (sample, side) in stored.iter().zip([Side::Front, Side::Back]) {
                let Some(sample) = sample else { continue };
                let sample = sample.cached();
                if !sample.estimate().is_valid() {
                    continue;
                }
                best.entry(SampleKey { vertex, side })
                    .and_modify(|kept| {
                        if (
                            sample.quality.bounces.map_or(u32::MAX, |b| b),
                            sample.quality.paths,
                        ) > (
                            kept.quality.bounces.map_or(u32::MAX, |b| b),
                            kept.quality.paths,
                        ) {
                            *kept = sample;
                        }
                    })
                    .or_insert(sample);
            }
        }
    }
    let samples = best.len();
    for (key, sample) in best {
        cache.insert(key, sample);
    }
    let restored = Restored {
        bases: records.len(),
        samples,
        unmatched_vertices,
        replay,
        samples_time: start.elapsed() - replay,
        ..Restored::default()
    };
    (restored, owners)
}

/// Asks the mesh for every record's red splits, shallowest first.
fn replay_splits(records: &[Parsed], mesh: &mut SubdivisionMesh) {
    let mut level: Vec<(usize, usize, NodeId)> = records
        .iter()
        .enumerate()
        .map(|(r, p)| (r, 0, p.base))
        .collect();
    while !level.is_empty() {
        let mut next = Vec::new();
        for (r, i, id) in level {
            if records[r].record.shape[i] != RED || !mesh.node(id).is_alive() {
                continue;
            }
            split_red(mesh, id);
            if let Split::Red { first_child } = mesh.node(id).split() {
                let children = records[r].children(i).zip(first_child..);
                next.extend(children.map(|(child, node)| (r, child, node)));
            }
        }
        level = next;
    }
}

/// Splits `id` red unless it is: a leaf is split, a green-split node has its parent rule
/// applied by selecting one of its green children (`SubdivisionMesh::refine`).
fn split_red(mesh: &mut SubdivisionMesh, id: NodeId) {
    let select = match mesh.node(id).split() {
        Split::Red { .. } => return,
        Split::Green { first_child, .. } => first_child,
        Split::None => id,
    };
    mesh.refine(&[select], &|_| false);
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
