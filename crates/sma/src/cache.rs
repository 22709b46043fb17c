//! The object-space vertex shading cache (DESIGN.md §5): per (vertex, side) RGB radiance, the
//! sample's quality and when it was last seen; which leaves have all their samples; a memory
//! budget with eviction of what has long been out of view.
//!
//! Storage is dense: a slot per (vertex, side) indexing a packed sample array, so the per-leaf
//! lookups of NLD_OS are two array reads, not hashing (issue 4 asks 10 M leaves/s).

use glam::Vec3;
use protocol::Side;
use protocol::renderer_link::{Quality, SampleKey};

use crate::mesh::{NodeId, SubdivisionMesh};
use crate::nld::luminance;
use crate::visible::VisibleSet;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CachedSample {
    pub rgb: [f32; 3],
    pub quality: Quality,
    /// Glossy or mirror: valid for `eye` only; ages as the eye moves (DESIGN.md §5).
    pub view_dependent: bool,
    pub eye: Option<Vec3>,
    /// Frame or epoch counter of the caller when the sample was last visible.
    pub last_seen: u64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheInsert {
    New,
    /// Replaced a worse sample, or a view-dependent one taken from another eye.
    Upgraded,
    /// Not better than what is cached, or not finite.
    Ignored,
}

const NO_SLOT: u32 = u32::MAX;

/// After eviction the cache holds at most this fraction of the budget, so a cache at its budget
/// does not evict (and sort) again on every call.
const EVICT_TO_FRACTION: f64 = 0.9;

#[derive(Clone, Debug)]
pub struct ShadingCache {
    budget_bytes: usize,
    /// `slots[2 vertex + side]`: index into `samples`, or `NO_SLOT`.
    slots: Vec<u32>,
    samples: Vec<CachedSample>,
    /// The slot of each sample, to re-point it when a removal moves the sample: four bytes
    /// rather than a stored `SampleKey`'s eight (issue 4: <= 100 bytes per leaf all included).
    owners: Vec<u32>,
}

fn slot_index(key: SampleKey) -> usize {
    2 * key.vertex as usize + usize::from(key.side == Side::Back)
}

fn slot_key(slot: u32) -> SampleKey {
    SampleKey {
        vertex: slot / 2,
        side: if slot % 2 == 1 {
            Side::Back
        } else {
            Side::Front
        },
    }
}

impl ShadingCache {
    pub fn new(budget_bytes: usize) -> Self {
        ShadingCache {
            budget_bytes,
            slots: Vec::new(),
            samples: Vec::new(),
            owners: Vec::new(),
        }
    }

    pub fn get(&self, key: SampleKey) -> Option<&CachedSample> {
        match self.slots.get(slot_index(key)) {
            Some(&s) if s != NO_SLOT => Some(&self.samples[s as usize]),
            _ => None,
        }
    }

    /// Stores a sample unless a cached one is at least as good (`Quality::rank`); a
    /// view-dependent sample from another eye always replaces the cached one.
    pub fn insert(&mut self, key: SampleKey, sample: CachedSample) -> CacheInsert {
        if !sample.rgb.iter().all(|c| c.is_finite()) {
            return CacheInsert::Ignored;
        }
        let index = slot_index(key);
        if index >= self.slots.len() {
            self.slots.resize(index + 1, NO_SLOT);
        }
        match self.slots[index] {
            NO_SLOT => {
                self.slots[index] = self.samples.len() as u32;
                self.samples.push(sample);
                self.owners.push(index as u32);
                CacheInsert::New
            }
            s => {
                let old = &mut self.samples[s as usize];
                let new_eye = sample.view_dependent && sample.eye != old.eye;
                if sample.quality.rank() <= old.quality.rank() && !new_eye {
                    return CacheInsert::Ignored;
                }
                let last_seen = old.last_seen.max(sample.last_seen);
                *old = CachedSample {
                    last_seen,
                    ..sample
                };
                CacheInsert::Upgraded
            }
        }
    }

    /// The radiance of a leaf's three vertices on `side`, if all are cached.
    pub fn leaf_radiance(
        &self,
        mesh: &SubdivisionMesh,
        leaf: NodeId,
        side: Side,
    ) -> Option<[[f32; 3]; 3]> {
        let [a, b, c] = mesh
            .node(leaf)
            .vertices
            .map(|vertex| self.get(SampleKey { vertex, side }));
        Some([a?.rgb, b?.rgb, c?.rgb])
    }

    /// The keys of a leaf on `side` that have no sample yet.
    pub fn missing_keys<'a>(
        &'a self,
        mesh: &'a SubdivisionMesh,
        leaf: NodeId,
        side: Side,
    ) -> impl Iterator<Item = SampleKey> + 'a {
        mesh.node(leaf)
            .vertices
            .into_iter()
            .map(move |vertex| SampleKey { vertex, side })
            .filter(|&key| self.get(key).is_none())
    }

    pub fn touch(&mut self, key: SampleKey, now: u64) {
        if let Some(&s) = self.slots.get(slot_index(key))
            && s != NO_SLOT
        {
            let seen = &mut self.samples[s as usize].last_seen;
            *seen = (*seen).max(now);
        }
    }

    /// Marks every sample of the visible leaves as seen at `now`.
    pub fn touch_visible(&mut self, mesh: &SubdivisionMesh, visible: &VisibleSet, now: u64) {
        for v in &visible.leaves {
            for vertex in mesh.node(v.leaf).vertices {
                self.touch(
                    SampleKey {
                        vertex,
                        side: v.side,
                    },
                    now,
                );
            }
        }
    }

    /// When over budget, removes samples not seen longest first, down to 90 % of the budget;
    /// `keep` and samples seen at `now` are spared. Returns how many were removed.
    pub fn evict(&mut self, now: u64, keep: &dyn Fn(SampleKey) -> bool) -> usize {
        if self.bytes() <= self.budget_bytes {
            return 0;
        }
        let target = (self.budget_bytes as f64 * EVICT_TO_FRACTION) as usize;
        let mut candidates: Vec<(u64, SampleKey)> = self
            .samples
            .iter()
            .zip(self.owners.iter().map(|&slot| slot_key(slot)))
            .filter(|&(s, key)| s.last_seen < now && !keep(key))
            .map(|(s, key)| (s.last_seen, key))
            .collect();
        candidates.sort_unstable_by_key(|&(seen, key)| (seen, slot_index(key)));
        let mut removed = 0;
        for (_, key) in candidates {
            if self.bytes() <= target {
                break;
            }
            self.remove(key);
            removed += 1;
        }
        removed
    }

    fn remove(&mut self, key: SampleKey) {
        let s = std::mem::replace(&mut self.slots[slot_index(key)], NO_SLOT) as usize;
        self.samples.swap_remove(s);
        self.owners.swap_remove(s);
        if let Some(&moved) = self.owners.get(s) {
            self.slots[moved as usize] = s as u32;
        }
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Bytes charged against the budget: the slot table plus the packed samples.
    pub fn bytes(&self) -> usize {
        self.slots.len() * size_of::<u32>()
            + self.samples.len() * (size_of::<CachedSample>() + size_of::<u32>())
    }

    pub fn budget_bytes(&self) -> usize {
        self.budget_bytes
    }

    /// Largest luminance of any cached sample.
    pub fn max_luminance(&self) -> f32 {
        self.samples
            .iter()
            .map(|s| luminance(s.rgb))
            .fold(0.0, f32::max)
    }

    /// L_white of DESIGN.md §6 (thesis appendix A): the largest luminance among the cached
    /// samples of the visible leaves on their visible sides, vertices off-screen included.
    pub fn l_white(&self, mesh: &SubdivisionMesh, visible: &VisibleSet) -> f32 {
        visible
            .leaves
            .iter()
            .flat_map(|v| {
                mesh.node(v.leaf).vertices.map(|vertex| SampleKey {
                    vertex,
                    side: v.side,
                })
            })
            .filter_map(|key| self.get(key))
            .map(|s| luminance(s.rgb))
            .fold(0.0, f32::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::renderer_link::Quality;
    use rand::{RngExt, SeedableRng};

    fn sample(l: f32, quality: Quality, seen: u64) -> CachedSample {
        CachedSample {
            rgb: [l; 3],
            quality,
            view_dependent: false,
            eye: None,
            last_seen: seen,
        }
    }

    fn key(vertex: u32) -> SampleKey {
        SampleKey {
            vertex,
            side: Side::Front,
        }
    }

    #[test]
    fn only_better_or_new_eye_samples_replace() {
        let mut cache = ShadingCache::new(1 << 20);
        assert_eq!(
            cache.insert(key(3), sample(1.0, Quality::INTERACTIVE, 0)),
            CacheInsert::New
        );
        assert_eq!(
            cache.insert(key(3), sample(2.0, Quality::DIRECT, 0)),
            CacheInsert::Ignored
        );
        assert_eq!(
            cache.insert(key(3), sample(2.0, Quality::INTERACTIVE, 0)),
            CacheInsert::Ignored
        );
        assert_eq!(
            cache.insert(key(3), sample(f32::NAN, Quality::INTERACTIVE, 0)),
            CacheInsert::Ignored
        );
        let better = Quality {
            paths: 256,
            bounces: Some(2),
        };
        assert_eq!(
            cache.insert(key(3), sample(2.0, better, 0)),
            CacheInsert::Upgraded
        );
        assert_eq!(cache.get(key(3)).unwrap().rgb, [2.0; 3]);
        let glossy = |eye| CachedSample {
            view_dependent: true,
            eye: Some(eye),
            ..sample(1.0, better, 0)
        };
        assert_eq!(cache.insert(key(3), glossy(Vec3::X)), CacheInsert::Upgraded);
        assert_eq!(cache.insert(key(3), glossy(Vec3::Y)), CacheInsert::Upgraded);
        assert!(
            cache
                .get(SampleKey {
                    vertex: 3,
                    side: Side::Back
                })
                .is_none()
        );
    }

    #[test]
    fn leaf_radiance_needs_all_three_vertices_of_the_side() {
        let mesh = SubdivisionMesh::new(&crate::mesh::test_meshes::square(), Default::default());
        let mut cache = ShadingCache::new(1 << 20);
        for v in [0, 1] {
            cache.insert(key(v), sample(v as f32, Quality::DIRECT, 0));
        }
        assert_eq!(cache.leaf_radiance(&mesh, 0, Side::Front), None);
        assert_eq!(
            cache
                .missing_keys(&mesh, 0, Side::Front)
                .collect::<Vec<_>>(),
            vec![key(2)]
        );
        cache.insert(key(2), sample(4.0, Quality::DIRECT, 0));
        assert_eq!(
            cache.leaf_radiance(&mesh, 0, Side::Front),
            Some([[0.0; 3], [1.0; 3], [4.0; 3]])
        );
        assert_eq!(cache.leaf_radiance(&mesh, 0, Side::Back), None);
        let visible = VisibleSet {
            leaves: vec![crate::visible::VisibleLeaf {
                leaf: 0,
                side: Side::Front,
                pixels: 9,
            }],
            width: 4,
            height: 4,
        };
        assert!((cache.l_white(&mesh, &visible) - 4.0).abs() < 1e-6);
    }

    /// A long random walk of visible sets: after each eviction the cache is within budget
    /// unless everything left is visible now, and nothing visible now is evicted.
    #[test]
    fn eviction_keeps_memory_under_budget_over_a_long_walk() {
        // The slot table of 20,000 vertices takes 160 kB of it.
        let budget = 512 * 1024;
        let mut cache = ShadingCache::new(budget);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let vertices = 20_000u32;
        for now in 1..400u64 {
            let start = rng.random_range(0..vertices - 300);
            let visible: Vec<SampleKey> = (start..start + 300).map(key).collect();
            for &k in &visible {
                cache.insert(k, sample(k.vertex as f32, Quality::DIRECT, now));
                cache.touch(k, now);
            }
            cache.evict(now, &|_| false);
            assert!(
                cache.bytes() <= budget,
                "{} bytes at step {now}",
                cache.bytes()
            );
            assert!(
                visible
                    .iter()
                    .all(|&k| cache.get(k).is_some_and(|s| s.rgb[0] == k.vertex as f32)),
                "a visible sample was evicted or moved to another key"
            );
        }
        assert!(cache.len() > 300);
    }
}
