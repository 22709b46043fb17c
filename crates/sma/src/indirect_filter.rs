//! The object-space filter of the indirect part (DESIGN.md §5, "Parts, and textures"): indirect
//! light is smooth, so a vertex's shown indirect estimate borrows from the samples of its
//! neighbours: path-space filtering (Keller et al. 2016), with the neighbours found by a spatial
//! hash over vertex positions (Binder et al. 2019). The direct part, which holds the sharp
//! shadows, is never filtered.
//!
//! A neighbour counts when it lies within a world-space radius of the vertex, on a surface facing
//! the same way (its shown normal within [`IndirectFilterSettings::min_normal_cos`]), at the same
//! bounce depth, and only where the difference of the two indirect estimates is explained by
//! their noise: the criteria's own test (`nld::NOISE_Z` combined standard errors), here in
//! radiance units, where it is the displayed test with the display slope cancelled. Each counted
//! sample (the vertex's own among them) is weighted by its paths, as if its paths had been traced
//! at the vertex: the pooled mean is unbiased whatever the samples' noise. Weighting by the
//! inverse of each sample's *estimated* variance would be the minimum-variance combination only
//! if the variances were known; estimated from the same paths as the means, they are smallest
//! where the few paths missed the rare bright ones, so such weights favour the dark estimates
//! and darken indirect light (measured on Sponza, where most light is indirect and carried by
//! few paths: FLIP at 5 s rose by 20–55 % with them). The shown variance is that of the pooled
//! mean, `Σ nᵢ sᵢ² / (Σ nᵢ)²` (taking the neighbours' noise as independent, which it is: each
//! vertex has its own paths).
//!
//! The radius shrinks as the vertex's paths accumulate, as n^(-1/4) (the progressive photon
//! mapping rate of Hachisuka et al.: the bias falls with the radius while the neighbours, ∝ r²,
//! fall slower than the paths grow, so the shown variance still falls as n^(-1/2)): the filtered
//! estimate converges to the vertex's own. View-dependent samples (their indirect part is a
//! reflection, not smooth), samples of fewer than two paths (no variance yet) and samples whose
//! neighbours all differ are shown as they are.
//!
//! The samples filtered, and the neighbours they borrow from, are those of the viewers' visible
//! leaves (one gather per run, not a scan of the whole cache): a sample's shown value can change
//! when another view brings its neighbours in, and reaches a viewer at its next sync.
//!
//! What the filter leaves is the cache's shown indirect part (`ShadingCache::set_shown_indirect`),
//! which every reader of a sample (viewer inserts, criteria, L_white, the stopping rule) reads:
//! they judge the filtered estimate and its reduced uncertainty.
//!
//! A run has three parts: [`IndirectFilter::start`] gathers the candidates from the mesh and the
//! cache, [`FilterJob::filter`] (the part that grows with the neighbours searched) needs neither
//! and runs on another thread ([`FilterWorker`]), and [`IndirectFilter::finish`] sets the results
//! on every sample that did not change in between.

mod job;
mod worker;

use std::time::Instant;

use glam::Vec3;
use protocol::renderer_link::SampleKey;
use protocol::{PartEstimate, Side};

use crate::cache::ShadingCache;
use crate::mesh::SubdivisionMesh;
use crate::sample::{Depth, Estimate};
use crate::visible_set::VisibleSet;
use conventions::luminance;
pub use job::{FilterJob, Filtered};
pub use worker::FilterWorker;

/// The filter's settings, plain values (`cli` fills them from flags).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndirectFilterSettings {
    /// Off: every sample is shown as the renderers answered it (the thesis's, and the control
    /// to measure the filter against).
    pub enabled: bool,
    /// The radius at [`REFERENCE_PATHS`] paths, as a fraction of the scene's bounding-box
    /// diagonal.
    pub radius: f32,
    /// When above 0, the radius at [`REFERENCE_PATHS`] paths is also at most this many times
    /// the longest edge of the finest visible leaf at the vertex: the mesh is refined where
    /// shading varies, so the radius follows it (a hundredth of a town's diagonal is metres,
    /// of a courtyard's decimetres).
    pub leaf_radius: f32,
    /// Least cosine between two samples' shown normals for one to borrow from the other.
    pub min_normal_cos: f32,
}

impl Default for IndirectFilterSettings {
    fn default() -> Self {
        IndirectFilterSettings {
            // On: with neighbours pooled by paths, mean FLIP at 5 s on Sponza S1, S2, S3
            // (512×384, nld-px, one run each, `walkthrough-bench convergence
            // --sma-flags=--indirect-filter,on|off`) fell from 0.080, 0.095, 0.122 to 0.069,
            // 0.065, 0.085, and at 1 s by a quarter to a third; bracara VT, lit mostly by the
            // sun, rose from 0.046 to 0.049.
            enabled: true,
            // A hundredth of the scene: about a metre of bracara, a few leaves of a refined
            // wall, well within the range over which its indirect light is smooth. Not a
            // measured optimum: the noise test keeps a larger one from blurring.
            radius: 0.01,
            leaf_radius: 0.0,
            // Within about 18°: a crease or a corner is not filtered across.
            min_normal_cos: 0.95,
        }
    }
}

/// Paths at which the radius is [`IndirectFilterSettings::radius`]: the interactive preset's.
pub const REFERENCE_PATHS: f32 = 64.0;

/// The radius for a sample of `paths` paths, in scene units (`diagonal`: the scene's bounding-box
/// diagonal; `leaf_edge`: the longest edge of the finest visible leaf at the vertex): shrinking
/// as paths^(-1/4).
pub fn radius_at(
    settings: &IndirectFilterSettings,
    diagonal: f32,
    leaf_edge: f32,
    paths: u32,
) -> f32 {
    let paths = (paths.max(1)) as f32;
    let mut reach = settings.radius * diagonal;
    if settings.leaf_radius > 0.0 {
        reach = reach.min(settings.leaf_radius * leaf_edge);
    }
    reach * (REFERENCE_PATHS / paths).powf(0.25)
}

/// A sample the filter reads: where it is, which way it faces, its indirect part.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    key: SampleKey,
    position: Vec3,
    normal: Vec3,
    indirect: PartEstimate,
    /// The indirect part's luminance.
    luminance: f32,
    /// The variance of the mean of its luminance.
    mean_variance: f32,
    paths: u32,
    depth: Depth,
    /// Its radius ([`radius_at`]).
    radius: f32,
}

/// The filter, with what it keeps from run to run: the scene's diagonal, its pace, and its
/// buffers.
#[derive(Debug, Default)]
pub struct IndirectFilter {
    settings: IndirectFilterSettings,
    diagonal: f32,
    /// The last run's job, kept for its buffers.
    spare: FilterJob,
    /// Which (vertex, side) slots `gather` has taken, by `2 vertex + side`.
    taken: Vec<bool>,
    /// By slot, the longest edge of the finest visible leaf there (with a leaf radius only).
    leaf_edge: Vec<f32>,
    /// When the next run may start ([`IndirectFilter::ready`]).
    next_run: Option<Instant>,
}

/// A run of the filter is followed by this many times its own duration without one: it takes
/// at most a fifth of a core. Run at every sync, its cost (tens of milliseconds at 50k visible
/// samples) slowed refinement: on bracara MC, VR and VT at 512×384 the views had a quarter fewer
/// leaves at 5 s than without the filter. Between runs a sample that got paths is shown
/// unfiltered.
const SPACING: u32 = 4;

/// What one run of the filter did, for its tests and the benchmark.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FilterRun {
    /// Samples whose shown indirect part was set.
    pub filtered: usize,
    /// Of them, those that borrowed from at least one neighbour.
    pub borrowed: usize,
    /// Neighbours borrowed from, summed over the samples.
    pub neighbours: usize,
}

impl IndirectFilter {
    pub fn new(settings: IndirectFilterSettings, mesh: &SubdivisionMesh) -> IndirectFilter {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for v in 0..mesh.vertex_count() as u32 {
            let p = mesh.vertex(v).position;
            lo = lo.min(p);
            hi = hi.max(p);
        }
        IndirectFilter {
            settings,
            diagonal: if lo.x <= hi.x { lo.distance(hi) } else { 0.0 },
            ..IndirectFilter::default()
        }
    }

    pub fn settings(&self) -> &IndirectFilterSettings {
        &self.settings
    }

    /// Whether a run may start at `now`: spaced by its own cost ([`SPACING`]).
    pub fn ready(&self, now: Instant) -> bool {
        self.next_run.is_none_or(|next| now >= next)
    }

    /// Sets the shown indirect part of every sample of `views`' leaves (all of them, on their
    /// seen sides), in one go: [`Self::start`], [`FilterJob::filter`], [`Self::finish`]. Off, it
    /// does nothing: the shown part stays the answered one.
    pub fn run<'a>(
        &mut self,
        mesh: &SubdivisionMesh,
        views: impl IntoIterator<Item = &'a VisibleSet>,
        cache: &mut ShadingCache,
    ) -> FilterRun {
        match self.start(mesh, views, cache) {
            Some(job) => self.finish(job.filter(), mesh, cache),
            None => FilterRun::default(),
        }
    }

    /// A run's first part: the samples of `views`' leaves to filter, to be filtered anywhere
    /// (`FilterJob::filter`) and set by [`Self::finish`]. None when the filter is off.
    pub fn start<'a>(
        &mut self,
        mesh: &SubdivisionMesh,
        views: impl IntoIterator<Item = &'a VisibleSet>,
        cache: &ShadingCache,
    ) -> Option<FilterJob> {
        if !self.settings.enabled || self.diagonal <= 0.0 {
            return None;
        }
        let start = Instant::now();
        let mut job = std::mem::take(&mut self.spare);
        job.clear();
        job.min_normal_cos = self.settings.min_normal_cos;
        self.gather(mesh, views, cache, &mut job.candidates);
        job.gathered_in = start.elapsed();
        Some(job)
    }

    /// A run's last part: sets each filtered sample's shown indirect part, unless the sample
    /// changed since [`Self::start`] took it (its own shown part then holds until the next run).
    /// The next run is spaced by this one's gather, filtering and setting.
    pub fn finish(
        &mut self,
        filtered: Filtered,
        mesh: &SubdivisionMesh,
        cache: &mut ShadingCache,
    ) -> FilterRun {
        let start = Instant::now();
        let Filtered {
            job,
            shown,
            filtered_in,
        } = filtered;
        let mut run = FilterRun::default();
        for (c, &(part, neighbours)) in job.candidates.iter().zip(&shown) {
            if !unchanged(mesh, cache, c) {
                continue;
            }
            cache.set_shown_indirect(c.key, part);
            run.filtered += 1;
            run.borrowed += usize::from(neighbours > 0);
            run.neighbours += neighbours;
        }
        let spent = job.gathered_in + filtered_in + start.elapsed();
        self.next_run = Some(Instant::now() + spent * SPACING);
        self.spare = job;
        run
    }

    /// The samples to filter, once each: diffuse, of at least two paths.
    fn gather<'a>(
        &mut self,
        mesh: &SubdivisionMesh,
        views: impl IntoIterator<Item = &'a VisibleSet>,
        cache: &ShadingCache,
        candidates: &mut Vec<Candidate>,
    ) {
        self.taken.clear();
        self.taken.resize(2 * mesh.vertex_count(), false);
        let by_leaf = self.settings.leaf_radius > 0.0;
        self.leaf_edge.clear();
        if by_leaf {
            self.leaf_edge
                .resize(2 * mesh.vertex_count(), f32::INFINITY);
        }
        for view in views {
            for v in &view.leaves {
                let corners = mesh.node(v.leaf).vertices;
                let edge = if by_leaf {
                    longest_edge(mesh, corners)
                } else {
                    0.0
                };
                for vertex in corners {
                    let key = SampleKey {
                        vertex,
                        side: v.side,
                    };
                    let slot = slot_of(key);
                    if by_leaf {
                        self.leaf_edge[slot] = self.leaf_edge[slot].min(edge);
                    }
                    if std::mem::replace(&mut self.taken[slot], true) {
                        continue;
                    }
                    if let Some(c) = candidate(mesh, cache, key) {
                        candidates.push(c);
                    }
                }
            }
        }
        for c in candidates {
            let edge = self.leaf_edge.get(slot_of(c.key)).copied().unwrap_or(0.0);
            c.radius = radius_at(&self.settings, self.diagonal, edge, c.paths);
        }
    }
}

/// Whether `c`'s sample is still the one gathered: the same paths, at a vertex in the same place
/// (the mesh reuses a removed vertex's id, `mesh::free_nodes`).
fn unchanged(mesh: &SubdivisionMesh, cache: &ShadingCache, c: &Candidate) -> bool {
    (c.key.vertex as usize) < mesh.vertex_count()
        && mesh.vertex(c.key.vertex).position == c.position
        && cache
            .answered(c.key)
            .is_some_and(|(estimate, _)| estimate.paths == c.paths)
}

/// A (vertex, side) slot's index in the filter's per-slot tables.
fn slot_of(key: SampleKey) -> usize {
    2 * key.vertex as usize + usize::from(key.side == Side::Back)
}

/// The longest edge of the triangle of `corners`.
fn longest_edge(mesh: &SubdivisionMesh, corners: [u32; 3]) -> f32 {
    let p = corners.map(|v| mesh.vertex(v).position);
    p[0].distance(p[1])
        .max(p[1].distance(p[2]))
        .max(p[2].distance(p[0]))
}

/// The filter's view of one cached sample, if it is one to filter; its radius is set later.
fn candidate(mesh: &SubdivisionMesh, cache: &ShadingCache, key: SampleKey) -> Option<Candidate> {
    let (estimate, view_dependent): (Estimate, bool) = cache.answered(key)?;
    if view_dependent || estimate.paths < 2 {
        return None;
    }
    let vertex = mesh.vertex(key.vertex);
    let indirect = estimate.parts.indirect;
    Some(Candidate {
        key,
        position: vertex.position,
        normal: vertex.normal * key.side.sign(),
        indirect,
        luminance: luminance(indirect.rgb),
        mean_variance: indirect.luminance_variance / estimate.paths as f32,
        paths: estimate.paths,
        depth: estimate.depth,
        radius: 0.0,
    })
}

#[cfg(test)]
mod tests;
