//! One run of the filter apart from the mesh and the cache: the candidates `gather` took, hashed
//! by position and filtered (the part of a run that grows with the neighbours searched, so the
//! part a worker takes, `worker`).

use std::collections::HashMap;
use std::time::{Duration, Instant};

use glam::{IVec3, Vec3};
use protocol::PartEstimate;

use super::Candidate;
use crate::mesh::fast_hash::FastHash;
use crate::nld::NOISE_Z;

/// The candidates of one run, and the hash over them.
#[derive(Debug, Default)]
pub struct FilterJob {
    /// Least cosine between two samples' shown normals (`IndirectFilterSettings`).
    pub(super) min_normal_cos: f32,
    pub(super) candidates: Vec<Candidate>,
    /// The hash's cell size, the median radius in use (`cell_size`).
    pub(super) cell_size: f32,
    /// Candidate indices sorted by cell, and each cell's range in it.
    sorted: Vec<u32>,
    cells: HashMap<u64, (u32, u32), FastHash>,
    /// What its gather took on the schedule's thread.
    pub(super) gathered_in: Duration,
}

/// A job filtered: each candidate's shown indirect part and the neighbours it borrowed from,
/// in the candidates' order.
#[derive(Debug)]
pub struct Filtered {
    pub(super) job: FilterJob,
    pub(super) shown: Vec<(PartEstimate, usize)>,
    /// What the filtering took, wherever it ran.
    pub(super) filtered_in: Duration,
}

impl FilterJob {
    /// Every candidate's shown indirect part.
    pub fn filter(mut self) -> Filtered {
        let start = Instant::now();
        self.hash();
        let shown = (0..self.candidates.len())
            .map(|i| self.filtered(i))
            .collect();
        Filtered {
            job: self,
            shown,
            filtered_in: start.elapsed(),
        }
    }

    /// Empties it for another run, keeping its buffers.
    pub(super) fn clear(&mut self) {
        self.candidates.clear();
        self.sorted.clear();
        self.cells.clear();
    }

    /// The median radius in use. Cells of the largest radius, as at first, made one sample of
    /// few paths (a radius up to five times that of a sample of 1024, `radius_at`) widen
    /// every sample's search a hundredfold in volume: on a walk's 500 k leaves a run took 0.6 s.
    fn cell_size(&self) -> f32 {
        let mut radii: Vec<f32> = self.candidates.iter().map(|c| c.radius).collect();
        if radii.is_empty() {
            return f32::MIN_POSITIVE;
        }
        let middle = radii.len() / 2;
        let (_, median, _) = radii.select_nth_unstable_by(middle, f32::total_cmp);
        median.max(f32::MIN_POSITIVE)
    }

    fn cell_of(p: Vec3, size: f32) -> IVec3 {
        (p / size).floor().as_ivec3()
    }

    /// A cell as one hash key, 21 bits an axis. A scene is far fewer cells across (a radius is
    /// over a ten-thousandth of its diagonal at any path count a `u32` holds); were
    /// two cells to share a key, they would only be searched together: the distance test still
    /// decides.
    fn cell_key(c: IVec3) -> u64 {
        let axis = |v: i32| u64::from(v as u32 & 0x1F_FFFF);
        axis(c.x) | axis(c.y) << 21 | axis(c.z) << 42
    }

    /// Sorts the candidates by cell, so that every neighbour of one lies within as many cells
    /// of its own as its radius spans (`filtered`).
    pub(super) fn hash(&mut self) {
        let size = self.cell_size();
        self.cell_size = size;
        let key: Vec<u64> = self
            .candidates
            .iter()
            .map(|c| Self::cell_key(Self::cell_of(c.position, size)))
            .collect();
        self.sorted.clear();
        self.sorted.extend(0..self.candidates.len() as u32);
        self.sorted.sort_unstable_by_key(|&i| key[i as usize]);
        self.cells.clear();
        let mut start = 0;
        while start < self.sorted.len() {
            let k = key[self.sorted[start] as usize];
            let end = start
                + self.sorted[start..]
                    .iter()
                    .take_while(|&&i| key[i as usize] == k)
                    .count();
            self.cells.insert(k, (start as u32, end as u32));
            start = end;
        }
    }

    /// Candidate `i`'s shown indirect part, and how many neighbours it borrowed from.
    pub(super) fn filtered(&self, i: usize) -> (PartEstimate, usize) {
        let me = &self.candidates[i];
        let radius = me.radius;
        let mut sum = WeightedSum::default();
        sum.add(me);
        let mut neighbours = 0;
        self.for_each_near(me, |j| {
            let other = &self.candidates[j as usize];
            if j as usize != i && self.agrees(me, other, radius) {
                sum.add(other);
                neighbours += 1;
            }
        });
        if neighbours == 0 {
            return (me.indirect, 0);
        }
        (sum.estimate(me.paths), neighbours)
    }

    /// Visits the candidates in the cells within `me`'s radius of its own; where those cells
    /// would outnumber the candidates (a radius far above the median), every candidate.
    fn for_each_near(&self, me: &Candidate, mut visit: impl FnMut(u32)) {
        let reach = (me.radius / self.cell_size).ceil().max(1.0);
        if (2.0 * reach + 1.0).powi(3) > self.candidates.len() as f32 {
            (0..self.candidates.len() as u32).for_each(visit);
            return;
        }
        let (reach, centre) = (reach as i32, Self::cell_of(me.position, self.cell_size));
        for z in -reach..=reach {
            for y in -reach..=reach {
                for x in -reach..=reach {
                    let cell = Self::cell_key(centre + IVec3::new(x, y, z));
                    if let Some(&(a, b)) = self.cells.get(&cell) {
                        self.sorted[a as usize..b as usize]
                            .iter()
                            .for_each(|&j| visit(j));
                    }
                }
            }
        }
    }

    /// Whether `me` may borrow from `other`: near, facing the same way, at the same depth, and
    /// different by no more than their noise explains.
    pub(super) fn agrees(&self, me: &Candidate, other: &Candidate, radius: f32) -> bool {
        me.position.distance_squared(other.position) <= radius * radius
            && me.normal.dot(other.normal) >= self.min_normal_cos
            && me.depth == other.depth
            && (me.luminance - other.luminance).abs()
                <= NOISE_Z * (me.mean_variance + other.mean_variance).sqrt()
    }
}

/// The paths-weighted sum of indirect parts: their pooled mean and its variance.
#[derive(Default)]
struct WeightedSum {
    rgb: [f64; 3],
    paths: f64,
    /// Σ nᵢ sᵢ²: each sample's per-path luminance variance times its paths.
    spread: f64,
}

impl WeightedSum {
    fn add(&mut self, c: &Candidate) {
        let n = f64::from(c.paths);
        for (sum, &v) in self.rgb.iter_mut().zip(&c.indirect.rgb) {
            *sum += n * f64::from(v);
        }
        self.paths += n;
        self.spread += n * f64::from(c.indirect.luminance_variance);
    }

    /// The pooled mean, with its variance in per-path units for a sample of `paths` paths
    /// (the cache's convention: the standard error is sqrt(variance / paths)).
    fn estimate(&self, paths: u32) -> PartEstimate {
        let mean_variance = self.spread / (self.paths * self.paths);
        PartEstimate {
            rgb: self.rgb.map(|s| (s / self.paths) as f32),
            luminance_variance: (f64::from(paths) * mean_variance) as f32,
        }
    }
}
