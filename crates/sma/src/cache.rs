//! The object-space vertex shading cache (DESIGN.md §5): per (vertex, side) an estimate of the
//! radiance in parts with its uncertainty (`sample::Estimate`), when it was last seen; which
//! leaves have all their samples; a memory budget with eviction of what has long been out of view.
//!
//! What is read back is the *shown* estimate: the sample with its indirect part as the
//! object-space filter last left it (`indirect_filter`; the raw part until the filter has run),
//! and its illumination multiplied by the mean albedo over the leaves around its vertex
//! (`albedo`, `sample::display_radiance`). The criteria, L_white and the stopping rule read that one, so
//! they judge about what the person sees (a viewer multiplies the albedo in per pixel, and is
//! sent the shown estimate's illumination: `leaf_shading`); the raw estimate, illumination, is
//! what further paths merge with, what the filter smooths and what the cache file keeps.
//!
//! Storage is dense: a slot per (vertex, side) indexing a packed sample array, so the per-leaf
//! lookups of NLD_OS are two array reads, not hashing. A sample is packed into 32 bytes: per part
//! mean RGB and luminance variance, the shown indirect part (quantised: `cache::quantised`), paths, the time it was last seen,
//! its bounce depth and whether it is view-dependent; the eye, which only view-dependent samples
//! need, lives in a side table. A
//! view-dependent sample keeps a few eyes there, each with its own estimate: viewers looking at
//! one mirror from different places each read the one nearest their eye, instead of retaking
//! each other's forever (several viewers: thesis §2.2).

use std::collections::HashMap;

use glam::Vec3;
use protocol::renderer_link::SampleKey;
use protocol::{PartEstimate, Side};

use crate::mesh::fast_hash::FastHash;
use crate::mesh::{NodeId, SubdivisionMesh, push_lean, set_bytes, table_bytes};
use crate::sample::{Estimate, Merge, display_radiance};
use crate::visible_set::VisibleSet;
use conventions::luminance;

/// One eye's estimate of a view-dependent sample.
#[derive(Clone, Copy, Debug)]
struct EyeVariant {
    eye: Vec3,
    estimate: Estimate,
}

/// Eyes kept per view-dependent sample: one per viewer looking at the surface, for a few
/// viewers. A new eye beyond them replaces the nearest kept one, most likely the same viewer's
/// previous position.
const MAX_EYES: usize = 4;

/// Bytes charged per entry of the eye side table beyond its variants: key and list header,
/// one control byte, and as much again for the hash table's free buckets (it is at most 7/8
/// full and grows by doubling). Charged per entry rather than by capacity, so that evicting
/// samples lowers the charge.
const EYE_ENTRY_BYTES: usize = 2 * (size_of::<(u32, Vec<EyeVariant>)>() + 1);

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheInsert {
    New,
    /// Changed what a viewer sees: further paths added at the same depth, a deeper sample in
    /// place of a shallower one, or a view-dependent one taken from another eye.
    Upgraded,
    /// Shallower than what is cached, or not a valid estimate (`Estimate::is_valid`).
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
    samples: Vec<PackedSample>,
    /// The slot of each sample, to re-point it when a removal moves the sample: four bytes
    /// rather than a stored `SampleKey`'s eight (<= 110 bytes per leaf all included).
    owners: Vec<u32>,
    /// The eyes of each view-dependent sample that has one, by slot, latest last: slots stay
    /// put when a removal moves samples, so the table is never re-keyed.
    eyes: HashMap<u32, Vec<EyeVariant>, FastHash>,
    /// Variants in `eyes`, for `bytes`.
    eye_variants: usize,
    /// Slots whose renderer answers were rejected too often (`mark_failed`): never asked again,
    /// shown with the mean of their leaves' other vertices.
    failed: std::collections::HashSet<u32, FastHash>,
    /// The fraction of the brightest visible samples [`ShadingCache::l_white`] leaves above it.
    l_white_outliers: f64,
    /// The mean albedo around each vertex, which multiplies its samples' illumination when read.
    albedos: VertexAlbedos,
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
            eyes: HashMap::default(),
            eye_variants: 0,
            failed: Default::default(),
            l_white_outliers: L_WHITE_OUTLIERS,
            albedos: VertexAlbedos::default(),
        }
    }

    /// The same cache taking the mean albedo around its vertices from `scene`'s materials and
    /// textures (without, every vertex's albedo is one: the samples are shown as stored).
    pub fn with_albedos_of(mut self, scene: std::sync::Arc<scene::Scene>) -> Self {
        self.albedos = VertexAlbedos::of(scene);
        self
    }

    /// Takes the mean albedo around every vertex of `mesh` not yet covered (`albedo`): called
    /// before samples of new vertices arrive (answers, a restored cache file).
    pub fn cover_albedos(&mut self, mesh: &SubdivisionMesh) {
        self.albedos.cover(mesh);
    }

    /// A stored estimate of `slot` as displayed: the mean albedo around its vertex multiplies
    /// its illumination (`sample::display_radiance`).
    fn displayed(&self, slot: usize, e: &Estimate) -> Estimate {
        display_radiance(e, self.albedos.at((slot / 2) as u32))
    }

    /// The shown estimate of `slot`, displayed.
    fn shown(&self, slot: usize) -> Option<Estimate> {
        self.packed(slot)
            .map(|p| self.displayed(slot, &p.estimate()))
    }

    /// The same cache with `fraction` (0..1) of the brightest visible samples left above
    /// L_white; 0: L_white is their maximum, as the thesis has it (§2.3, appendix A).
    pub fn with_l_white_outliers(mut self, fraction: f64) -> Self {
        self.l_white_outliers = if fraction.is_finite() {
            fraction.clamp(0.0, 1.0)
        } else {
            0.0
        };
        self
    }

    pub fn get(&self, key: SampleKey) -> Option<CachedSample> {
        let slot = slot_index(key);
        self.packed(slot).map(|p| self.unpack(slot, p))
    }

    /// The stored sample of a slot: what the per-leaf hot paths read, without unpacking.
    fn packed(&self, slot: usize) -> Option<&PackedSample> {
        match self.slots.get(slot) {
            Some(&s) if s != NO_SLOT => Some(&self.samples[s as usize]),
            _ => None,
        }
    }

    fn unpack(&self, slot: usize, p: &PackedSample) -> CachedSample {
        // Diffuse samples, nearly all of them, skip the hash lookup.
        let eye = p
            .view_dependent()
            .then(|| self.eyes.get(&(slot as u32))?.last().map(|v| v.eye))
            .flatten();
        sample_of(
            &self.displayed(slot, &p.estimate()),
            p.view_dependent(),
            eye,
            p.last_seen,
        )
    }

    /// The sample as seen from `eye`: for a view-dependent one, the kept eye nearest to it;
    /// otherwise (or without an eye) what [`Self::get`] returns.
    pub fn get_seen_from(&self, key: SampleKey, eye: Option<Vec3>) -> Option<CachedSample> {
        let slot = slot_index(key);
        let p = self.packed(slot)?;
        let nearest = eye
            .filter(|_| p.view_dependent())
            .and_then(|eye| self.nearest_eye(slot, eye));
        Some(match nearest {
            Some(v) => sample_of(
                &self.displayed(slot, &v.estimate),
                true,
                Some(v.eye),
                p.last_seen,
            ),
            None => self.unpack(slot, p),
        })
    }

    fn nearest_eye(&self, slot: usize, eye: Vec3) -> Option<&EyeVariant> {
        self.eyes.get(&(slot as u32))?.iter().min_by(|a, b| {
            a.eye
                .distance_squared(eye)
                .total_cmp(&b.eye.distance_squared(eye))
        })
    }

    /// Adds an eye's variant to a slot, as its latest; beyond [`MAX_EYES`] the kept eye nearest
    /// the new one goes.
    fn add_eye(&mut self, slot: usize, variant: EyeVariant) {
        let variants = self.eyes.entry(slot as u32).or_default();
        variants.push(variant);
        self.eye_variants += 1;
        if variants.len() > MAX_EYES {
            let last = variants.len() - 1;
            let nearest = (0..last)
                .min_by(|&a, &b| {
                    let d = |i: usize| variants[i].eye.distance_squared(variant.eye);
                    d(a).total_cmp(&d(b))
                })
                .expect("more than one variant");
            variants.remove(nearest);
            self.eye_variants -= 1;
        }
    }

    fn drop_eyes(&mut self, slot: usize) {
        if let Some(variants) = self.eyes.remove(&(slot as u32)) {
            self.eye_variants -= variants.len();
        }
    }

    /// Merges a renderer's answer into the cache (`sample::Estimate::accumulate`): paths at the
    /// cached depth are added to the estimate, a deeper answer replaces it, a shallower one is
    /// ignored. A view-dependent sample is kept per eye: an answer from a new eye is added beside
    /// the others (retaken), one from a kept eye merges with that eye's estimate.
    pub fn insert(&mut self, key: SampleKey, sample: CachedSample) -> CacheInsert {
        let new = sample.estimate();
        if !new.is_valid() {
            return CacheInsert::Ignored;
        }
        let slot = slot_index(key);
        if slot >= self.slots.len() {
            let more = (slot + 1 - self.slots.len()).max(self.slots.len() / 4 + 16);
            if slot >= self.slots.capacity() {
                self.slots.reserve_exact(more);
            }
            self.slots.resize(slot + 1, NO_SLOT);
        }
        self.failed.remove(&(slot as u32));
        let eye = sample.eye.filter(|_| sample.view_dependent);
        let s = self.slots[slot];
        if s == NO_SLOT {
            self.slots[slot] = self.samples.len() as u32;
            let seen = stamp(sample.last_seen);
            // Grown by a quarter, as the mesh's arrays: capacity is what the memory budget counts.
            push_lean(
                &mut self.samples,
                PackedSample::new(&new, sample.view_dependent, seen),
            );
            push_lean(&mut self.owners, slot as u32);
            self.set_eye(slot, eye, new);
            return CacheInsert::New;
        }
        let s = s as usize;
        self.samples[s].set_view_dependent(sample.view_dependent);
        let Some(eye) = eye else {
            let mut kept = self.samples[s].raw();
            if kept.accumulate(&new) == Merge::Kept {
                return CacheInsert::Ignored;
            }
            self.samples[s].set(&kept);
            self.drop_eyes(slot);
            return CacheInsert::Upgraded;
        };
        let mut merged = new;
        if let Some(variants) = self.eyes.get_mut(&(slot as u32))
            && let Some(i) = variants.iter().position(|v| v.eye == eye)
        {
            let mut kept = variants[i].estimate;
            if kept.accumulate(&new) == Merge::Kept {
                return CacheInsert::Ignored;
            }
            merged = kept;
            variants.remove(i);
            self.eye_variants -= 1;
        }
        self.samples[s].set(&merged);
        self.set_eye(slot, Some(eye), merged);
        CacheInsert::Upgraded
    }

    /// Records the eye of a slot's latest estimate (view-dependent samples only).
    fn set_eye(&mut self, slot: usize, eye: Option<Vec3>, estimate: Estimate) {
        match eye {
            Some(eye) => self.add_eye(slot, EyeVariant { eye, estimate }),
            None => self.drop_eyes(slot),
        }
    }

    /// The estimate of a key as seen from `eye` (see [`Self::get_seen_from`]).
    pub fn estimate(&self, key: SampleKey, eye: Option<Vec3>) -> Option<Estimate> {
        self.stored_seen_from(key, eye)
            .map(|(slot, stored)| self.displayed(slot, &stored))
    }

    /// A sample as the renderers answered it (no filter), and whether it is view-dependent: what
    /// the object-space filter reads (`indirect_filter`).
    pub(crate) fn answered(&self, key: SampleKey) -> Option<(Estimate, bool)> {
        self.packed(slot_index(key))
            .map(|p| (p.raw(), p.view_dependent()))
    }

    /// Sets the indirect part a sample is shown with (`indirect_filter`); it holds until the
    /// sample changes.
    pub(crate) fn set_shown_indirect(&mut self, key: SampleKey, shown: PartEstimate) {
        if let Some(&s) = self.slots.get(slot_index(key))
            && s != NO_SLOT
        {
            self.samples[s as usize].set_shown_indirect(&shown);
        }
    }

    /// The estimates of a leaf's three vertices on `side`, if all are cached, displayed.
    pub fn leaf_estimates(
        &self,
        mesh: &SubdivisionMesh,
        leaf: NodeId,
        side: Side,
    ) -> Option<[Estimate; 3]> {
        let [a, b, c] = mesh
            .node(leaf)
            .vertices
            .map(|vertex| self.shown(slot_index(SampleKey { vertex, side })));
        Some([a?, b?, c?])
    }

    /// Gives up on a key whose answers were rejected too often: it counts as known from now on
    /// (never asked again), and leaves show it with the mean of their other vertices, never black
    /// (DESIGN.md §8: bad input loses nothing else). A later valid answer clears the mark.
    pub fn mark_failed(&mut self, key: SampleKey) {
        self.failed.insert(slot_index(key) as u32);
    }

    pub fn is_failed(&self, key: SampleKey) -> bool {
        self.failed.contains(&(slot_index(key) as u32))
    }

    /// The radiance of a leaf's three vertices on `side`, if all are cached (a failed vertex
    /// takes the mean of the others).
    pub fn leaf_radiance(
        &self,
        mesh: &SubdivisionMesh,
        leaf: NodeId,
        side: Side,
    ) -> Option<[[f32; 3]; 3]> {
        self.leaf_radiance_with(mesh, leaf, side, |key| {
            self.shown(slot_index(key)).map(|e| e.rgb())
        })
    }

    /// A leaf's vertices as `value_of` gives them, if all are cached (a failed vertex takes the
    /// mean of the others).
    pub(super) fn leaf_radiance_with<const N: usize>(
        &self,
        mesh: &SubdivisionMesh,
        leaf: NodeId,
        side: Side,
        rgb_of: impl Fn(SampleKey) -> Option<[f32; N]>,
    ) -> Option<[[f32; N]; 3]> {
        let keys = mesh
            .node(leaf)
            .vertices
            .map(|vertex| SampleKey { vertex, side });
        let rgb = keys.map(&rgb_of);
        if rgb.iter().all(Option::is_some) {
            return Some(rgb.map(|c| c.expect("all cached")));
        }
        if keys
            .iter()
            .zip(&rgb)
            .any(|(&k, c)| c.is_none() && !self.is_failed(k))
        {
            return None;
        }
        let known: Vec<[f32; N]> = rgb.iter().flatten().copied().collect();
        if known.is_empty() {
            return None;
        }
        let n = known.len() as f32;
        let mean = std::array::from_fn(|i| known.iter().map(|c| c[i]).sum::<f32>() / n);
        Some(rgb.map(|c| c.unwrap_or(mean)))
    }

    /// The keys of a leaf on `side` that have no sample yet (and have not failed).
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
            .filter(|&key| self.packed(slot_index(key)).is_none() && !self.is_failed(key))
    }

    pub fn touch(&mut self, key: SampleKey, now: u64) {
        if let Some(&s) = self.slots.get(slot_index(key))
            && s != NO_SLOT
        {
            let seen = &mut self.samples[s as usize].last_seen;
            *seen = (*seen).max(stamp(now));
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

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Bytes charged against the budget: the slot table, the packed samples and their owners,
    /// the eye side table and the vertices' albedos.
    pub fn bytes(&self) -> usize {
        self.slots.len() * size_of::<u32>()
            + self.albedos.bytes()
            + self.samples.len() * (size_of::<PackedSample>() + size_of::<u32>())
            + self.eyes.len() * EYE_ENTRY_BYTES
            + self.eye_variants * size_of::<EyeVariant>()
    }

    pub fn budget_bytes(&self) -> usize {
        self.budget_bytes
    }

    /// A new budget for [`Self::evict`]: the SMA's memory budget leaves the cache what the mesh
    /// and the viewers do not hold (`schedule::memory`).
    pub fn set_budget_bytes(&mut self, budget_bytes: usize) {
        self.budget_bytes = budget_bytes;
    }

    /// Heap bytes by capacity, as the SMA's memory budget counts them: the arrays as allocated,
    /// the eye and failure tables by their buckets, the vertices' albedos.
    pub fn capacity_bytes(&self) -> usize {
        self.slots.capacity() * size_of::<u32>()
            + self.samples.capacity() * size_of::<PackedSample>()
            + self.owners.capacity() * size_of::<u32>()
            + table_bytes(&self.eyes)
            + self.eye_variants * size_of::<EyeVariant>()
            + set_bytes(&self.failed)
            + self.albedos.bytes()
    }

    /// Largest displayed luminance of any cached sample.
    pub fn max_luminance(&self) -> f32 {
        self.owners
            .iter()
            .filter_map(|&slot| self.shown(slot as usize))
            .map(|e| luminance(e.rgb()))
            .fold(0.0, f32::max)
    }

    /// L_white of DESIGN.md §6 (thesis appendix A), over the cached samples of the visible leaves
    /// on their visible sides, vertices off-screen included: the largest luminance but for the
    /// top fraction of them set by [`ShadingCache::with_l_white_outliers`] (by default
    /// [`L_WHITE_OUTLIERS`]; the thesis profile sets 0, the maximum). The plain maximum lets one
    /// sample decide for the whole view: a vertex of bracara's pool that happened to mirror the
    /// sun set L_white so high that the picture went dark and every S fell below S_min, and
    /// NLD_OS stopped refining for good (a 20-s convergence run stuck at 6.6k samples). The few
    /// samples above L_white show white.
    pub fn l_white(&self, mesh: &SubdivisionMesh, visible: &VisibleSet) -> f32 {
        let mut lum: Vec<f32> = visible
            .leaves
            .iter()
            // Guard leaves (`visibility::guards`) are sent but not seen: what lies hidden beside
            // the view does not set its white.
            .filter(|v| v.pixels > 0)
            .flat_map(|v| {
                mesh.node(v.leaf).vertices.map(|vertex| SampleKey {
                    vertex,
                    side: v.side,
                })
            })
            .filter_map(|key| self.shown(slot_index(key)))
            .map(|e| luminance(e.rgb()))
            .collect();
        let skipped = (lum.len() as f64 * self.l_white_outliers) as usize;
        let Some(rank) = lum.len().checked_sub(1 + skipped) else {
            return 0.0;
        };
        *lum.select_nth_unstable_by(rank, f32::total_cmp).1
    }
}

/// The fraction of the brightest visible samples [`ShadingCache::l_white`] leaves above it by
/// default (`ScheduleConfig::l_white_outliers`).
pub const L_WHITE_OUTLIERS: f64 = 0.001;

mod albedo;
mod leaf_shading;
mod leaving;
mod packed;
mod quantised;
use albedo::VertexAlbedos;
pub use leaf_shading::LeafShading;
pub use packed::CachedSample;
use packed::{PackedSample, sample_of, stamp};

#[cfg(test)]
mod tests;
