//! Answers from the renderer pool (DESIGN.md §3 step 5, §5, §8): each answered point becomes a
//! cached sample, unless its answer is not a valid estimate; such a point is neither cached nor
//! shown, stays missing so that it is asked for again, and after [`MAX_REJECTIONS`] bad answers
//! the cache gives up on it (bad input loses nothing else). What the answers change beyond the
//! cache (the counts, the criteria's input, the viewers' sync) the schedule carries out.

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use protocol::renderer_link::{Quality, Radiance, SampleKey, ShadeBatch, point_flags};

use crate::cache::{CachedSample, ShadingCache};
use crate::mesh::VertexId;
use crate::mesh::fast_hash::FastHash;

/// Rejected answers for one key before the schedule stops asking for it.
const MAX_REJECTIONS: u8 = 3;

/// What one batch's answers brought.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Answered {
    /// Points answered, valid or not.
    pub points: u64,
    /// Paths traced for them.
    pub paths: u64,
    /// Points whose answer was not a valid estimate.
    pub rejected: u64,
}

/// Bad answers per key not yet given up on.
#[derive(Debug, Default)]
pub struct Answers {
    rejections: HashMap<SampleKey, u8>,
}

impl Answers {
    /// Caches a batch's answers, seen at `frame`, evicting what was seen least recently when
    /// over budget. A point is view-dependent when its base triangle's material is
    /// (`view_dependent`) or its renderer says so.
    pub fn shaded(
        &mut self,
        batch: &ShadeBatch,
        radiance: &Radiance,
        view_dependent: &[bool],
        frame: u64,
        cache: &mut ShadingCache,
    ) -> Answered {
        let mut rejected = 0;
        for (i, point) in batch.points.iter().enumerate() {
            let base = point.base_triangle as usize;
            let view_dependent = view_dependent.get(base).copied().unwrap_or(false)
                || radiance.flags[i] & point_flags::VIEW_DEPENDENT != 0;
            let sample = CachedSample {
                parts: radiance.parts[i],
                quality: Quality {
                    paths: radiance.paths[i],
                    bounces: radiance.quality.bounces,
                },
                view_dependent,
                eye: point.eye.map(Vec3::from),
                last_seen: frame,
            };
            if sample.estimate().is_valid() {
                cache.insert(point.key, sample);
            } else {
                rejected += 1;
                self.reject(point.key, &sample, cache);
            }
        }
        // Within its share of the memory budget between passes too: a pass may be seconds
        // away while renderers answer thousands of points (what was seen at `frame` stays).
        cache.evict(frame, &|_| false);
        Answered {
            points: batch.points.len() as u64,
            paths: radiance.paths.iter().map(|&p| u64::from(p)).sum(),
            rejected,
        }
    }

    /// Forgets the rejections of `vertices`, freed by the mesh for reuse.
    pub fn forget_vertices(&mut self, vertices: &HashSet<VertexId, FastHash>) {
        self.rejections
            .retain(|key, _| !vertices.contains(&key.vertex));
    }

    /// A point whose answer is not a valid estimate (NaN, infinite or negative radiance or
    /// variance, no paths) is neither cached nor shown; it stays missing, so it is asked for
    /// again, up to [`MAX_REJECTIONS`] times, after which the cache gives up on it.
    fn reject(&mut self, key: SampleKey, sample: &CachedSample, cache: &mut ShadingCache) {
        let count = self.rejections.entry(key).or_insert(0);
        *count += 1;
        if *count >= MAX_REJECTIONS {
            tracing::warn!(
                ?key,
                parts = ?sample.parts,

                paths = sample.quality.paths,
                "renderers answered this sample badly {MAX_REJECTIONS} times: it is shown with \
                 the mean of its triangles' other vertices"
            );
            self.rejections.remove(&key);
            cache.mark_failed(key);
        }
    }
}

#[cfg(test)]
mod tests {
    use protocol::Side;
    use protocol::renderer_link::ShadePoint;

    use super::*;
    use protocol::SampleParts;

    fn key(vertex: u32) -> SampleKey {
        SampleKey {
            vertex,
            side: Side::Front,
        }
    }

    /// A batch of two points at the scene's quality, the second answered with `bad` radiance.
    fn answer(bad: f32) -> (ShadeBatch, Radiance) {
        let point = |vertex| ShadePoint {
            key: key(vertex),
            base_triangle: 0,
            bary: [0.0; 2],
            side: Side::Front,
            eye: None,
        };
        let batch = ShadeBatch {
            batch_id: 1,
            quality: Quality::INTERACTIVE,
            seed: 0,
            points: vec![point(0), point(1)],
        };
        let radiance = Radiance {
            batch_id: 1,
            quality: Quality::INTERACTIVE,
            parts: vec![
                SampleParts::direct_only([0.5; 3], 0.1),
                SampleParts::direct_only([bad; 3], 0.1),
            ],
            paths: vec![Quality::INTERACTIVE.paths; 2],
            flags: vec![0; 2],
            micros: 0,
        };
        (batch, radiance)
    }

    #[test]
    fn a_bad_point_costs_only_itself_and_is_given_up_after_its_rejections() {
        let mut cache = ShadingCache::new(1 << 20);
        let mut answers = Answers::default();
        let (batch, radiance) = answer(f32::NAN);
        for round in 1..=MAX_REJECTIONS {
            let answered = answers.shaded(&batch, &radiance, &[false], 0, &mut cache);
            assert_eq!(
                answered,
                Answered {
                    points: 2,
                    paths: 2 * u64::from(Quality::INTERACTIVE.paths),
                    rejected: 1,
                }
            );
            assert!(cache.get(key(0)).is_some() && cache.get(key(1)).is_none());
            assert_eq!(cache.is_failed(key(1)), round == MAX_REJECTIONS, "{round}");
        }
    }
}
