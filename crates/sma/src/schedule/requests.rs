//! Shade requests (DESIGN.md §3 step 5): the prioritised queue of samples wanted (`need`), the
//! keys in flight, and batching. The queue is re-planned from the visible sets whenever they change, so
//! priorities follow the camera; a key already in flight at a quality at least as good is never
//! asked twice.

use std::collections::{HashMap, HashSet, VecDeque};

use glam::Vec3;
use protocol::renderer_link::{Quality, SampleKey, ShadeBatch, ShadePoint};

use super::need::{Need, Urgency, awaited, queue_order};
use crate::cache::ShadingCache;
use crate::mesh::fast_hash::FastHash;

/// A batch taken from the queue, and the kind of its needs (`kind_of`).
struct Taken {
    kind: Urgency,
    batch: ShadeBatch,
}

/// The kinds a batch never mixes: awaited needs (as `Urgency::Missing`), top-ups, and more
/// paths (as `Urgency::Paths`, polish included).
fn kind_of(urgency: Urgency) -> Urgency {
    match urgency {
        u if awaited(u) => Urgency::Missing,
        Urgency::TopUp => Urgency::TopUp,
        _ => Urgency::Paths,
    }
}

/// How far down the queue, in batches of needs, a batch looks for needs of its own quality.
const BATCH_WINDOW: usize = 8;

/// How much one batch may carry (`ScheduleConfig::batch_points`, `batch_paths`). The paths bound
/// keeps a batch's time at the renderer short at every rung of the quality ladder: a renderer
/// finishes the batches it holds before it starts the next, so an awaited sample (a picture or a
/// refinement step waits for it) queues behind at most a few of them, and a batch of 128 points
/// at 1024 paths each takes a tenth of a second on Sponza.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchLimit {
    pub points: usize,
    pub paths: u64,
}

impl BatchLimit {
    /// The points of a batch that traces `quality`: at most `points`, and at most `paths` paths
    /// in all, but always one.
    fn points_at(self, quality: Quality) -> usize {
        let by_paths = self.paths / u64::from(quality.paths.max(1));
        self.points
            .min(usize::try_from(by_paths).unwrap_or(usize::MAX))
            .max(1)
    }
}

/// What a queue holds once: a key at a quality (`Quality::rank`).
type NeedId = (SampleKey, (u32, u32));

/// A need's place in the queue, smaller first: `queue_order`, then its index among the needs
/// planned (equals keep their order).
type QueuePlace = (u64, u32);

#[derive(Clone, Copy, Debug)]
struct InFlight {
    best: (u32, u32),
    count: u32,
}

/// Each batch taken shrinks the paths counted before it by this factor, so the share of
/// `TopUpShare` is held over the last few dozen batches, not since the start.
const SHARE_MEMORY: f64 = 0.95;

/// Paths traced recently for awaited needs and for top-ups taken beside them.
#[derive(Clone, Copy, Debug, Default)]
struct TopUpShare {
    awaited_paths: f64,
    top_up_paths: f64,
}

impl TopUpShare {
    /// Whether the next batch should be top-ups, to keep their share of the paths at `share`.
    fn owes_top_ups(&self, share: f64) -> bool {
        let total = self.awaited_paths + self.top_up_paths;
        self.top_up_paths < share * total || (total == 0.0 && share > 0.0)
    }

    fn count(&mut self, paths: f64, top_up: bool) {
        self.awaited_paths *= SHARE_MEMORY;
        self.top_up_paths *= SHARE_MEMORY;
        if top_up {
            self.top_up_paths += paths;
        } else {
            self.awaited_paths += paths;
        }
    }
}

#[derive(Default)]
pub struct Requests {
    /// Sorted by urgency, then priority; only ever popped at the front.
    queue: VecDeque<Need>,
    in_flight: HashMap<SampleKey, InFlight, FastHash>,
    batches_in_flight: usize,
    /// Batches in flight for awaited needs (above [`Urgency::TopUp`]), and their points: what
    /// refinement waits for (a batch holds needs of one kind only, see `next_batch`).
    awaited_batches: HashMap<u64, usize, FastHash>,
    /// Top-up batches taken beside awaited ones: they go out with them, ahead of more paths.
    shared_batches: HashSet<u64, FastHash>,
    /// The share of the paths that top-ups get while awaited needs are queued.
    top_up_share: f64,
    recent: TopUpShare,
    next_batch_id: u64,
    seed: u64,
}

impl Requests {
    /// `top_up_share`: the fraction of the paths traced that go to early-rung top-ups while
    /// needs a picture or a refinement step waits for are queued (0: only once none are).
    pub fn new(seed: u64, top_up_share: f64) -> Self {
        Requests {
            seed,
            top_up_share: top_up_share.clamp(0.0, 1.0),
            ..Default::default()
        }
    }

    /// Replaces the queue with `needs`, best first (by urgency, then priority; equals keep their
    /// order); one entry per (key, quality), the first in that order. A re-plan orders every
    /// visible sample's needs several times a second, and each vertex is met once per leaf
    /// around it: on Sponza a few hundred thousand needs for a fraction as many keys. So the
    /// best need per (key, quality) is found first, and only those are sorted, as (order, index)
    /// pairs rather than the needs themselves.
    pub fn replan(&mut self, needs: Vec<Need>) {
        let mut best: HashMap<NeedId, QueuePlace, FastHash> =
            HashMap::with_capacity_and_hasher(needs.len() / 2, FastHash::default());
        for (i, n) in needs.iter().enumerate() {
            let order = (queue_order(n), i as u32);
            best.entry((n.point.key, n.target.rank()))
                .and_modify(|kept| *kept = (*kept).min(order))
                .or_insert(order);
        }
        let mut order: Vec<QueuePlace> = best.into_values().collect();
        order.sort_unstable();
        self.queue = order.into_iter().map(|(_, i)| needs[i as usize]).collect();
    }

    /// Samples asked for and not answered, plus those queued.
    pub fn outstanding(&self) -> usize {
        self.queue.len() + self.in_flight_keys()
    }

    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// Samples queued or in flight that a picture or a refinement step waits for: all but
    /// top-ups and more paths for samples already shown.
    pub fn outstanding_before_paths(&self) -> usize {
        self.queue.partition_point(|n| awaited(n.urgency))
            + self.awaited_batches.values().sum::<usize>()
    }

    pub fn in_flight_keys(&self) -> usize {
        self.in_flight.len()
    }

    pub fn batches_in_flight(&self) -> usize {
        self.batches_in_flight
    }

    /// Whether a batch goes out ahead of more paths: it holds needs a picture or a refinement
    /// step waits for, or top-ups taken as their share beside those.
    pub fn is_urgent(&self, batch_id: u64) -> bool {
        self.awaited_batches.contains_key(&batch_id) || self.shared_batches.contains(&batch_id)
    }

    /// Whether `key` is being shaded at `quality` or better.
    pub fn in_flight_at(&self, key: SampleKey, quality: Quality) -> bool {
        self.in_flight
            .get(&key)
            .is_some_and(|f| f.best >= quality.rank())
    }

    /// The next batch: up to `limit`'s queued needs of the quality and kind (awaited,
    /// top-up, or more paths) of the first unsatisfied need, taken from the next `BATCH_WINDOW`
    /// batches' worth of the queue, skipping those a cached sample or one in flight already
    /// satisfies. Needs of other qualities keep their places. (Taking only a run of equal
    /// qualities from the head made batches of one to three points where rungs of the ladder
    /// alternate, and the renderers spent their time on per-batch overhead.) While awaited
    /// needs are queued, top-ups get their share of the paths (`TopUpShare`).
    pub fn next_batch(&mut self, limit: BatchLimit, cache: &ShadingCache) -> Option<ShadeBatch> {
        let top_ups = self.queue.partition_point(|n| awaited(n.urgency));
        let has_top_ups = self
            .queue
            .get(top_ups)
            .is_some_and(|n| n.urgency == Urgency::TopUp);
        let shared = top_ups > 0 && has_top_ups && self.recent.owes_top_ups(self.top_up_share);
        let batch = if shared {
            self.batch_from(top_ups, Some(Urgency::TopUp), limit, cache)
        } else {
            None
        };
        let batch = batch.or_else(|| self.batch_from(0, None, limit, cache))?;
        let Taken { kind, batch } = batch;
        let paths = batch.points.len() as f64 * f64::from(batch.quality.paths);
        let batch_id = batch.batch_id;
        if awaited(kind) {
            self.awaited_batches.insert(batch_id, batch.points.len());
            self.recent.count(paths, false);
        } else if kind == Urgency::TopUp && top_ups > 0 {
            self.shared_batches.insert(batch_id);
            self.recent.count(paths, true);
        }
        Some(batch)
    }

    /// A batch whose first need is the first unsatisfied one at or after `start` in the queue
    /// (of kind `only`, if given: none when the queue holds no more of it there). The needs
    /// before `start` are set aside and put back, so the queue is worked at its front, where a
    /// `VecDeque` takes and gives back needs at no cost: on Sponza it holds a few hundred
    /// thousand.
    fn batch_from(
        &mut self,
        start: usize,
        only: Option<Urgency>,
        limit: BatchLimit,
        cache: &ShadingCache,
    ) -> Option<Taken> {
        let before: Vec<Need> = self.queue.drain(..start.min(self.queue.len())).collect();
        let taken = self.batch_at_front(only, limit, cache);
        for need in before.into_iter().rev() {
            self.queue.push_front(need);
        }
        taken
    }

    /// A batch whose first need is the queue's first unsatisfied one (see `batch_from`).
    fn batch_at_front(
        &mut self,
        only: Option<Urgency>,
        limit: BatchLimit,
        cache: &ShadingCache,
    ) -> Option<Taken> {
        let head = loop {
            let next = self.queue.front()?;
            if only.is_some_and(|kind| kind_of(next.urgency) != kind) {
                return None;
            }
            let need = self.queue.pop_front()?;
            if !self.satisfied(&need, cache) {
                break need;
            }
        };
        let (quality, kind) = (head.quality, kind_of(head.urgency));
        let max_points = limit.points_at(quality);
        let window = self
            .queue
            .len()
            .min(limit.points.saturating_mul(BATCH_WINDOW));
        let mut kept = Vec::new();
        let mut points = Vec::new();
        self.take(&head, &mut points);
        for need in self.queue.drain(..window).collect::<Vec<_>>() {
            let same_kind = need.quality == quality && kind_of(need.urgency) == kind;
            if points.len() >= max_points || !same_kind {
                kept.push(need);
            } else if !self.satisfied(&need, cache) {
                self.take(&need, &mut points);
            }
        }
        for need in kept.into_iter().rev() {
            self.queue.push_front(need);
        }
        self.next_batch_id += 1;
        self.batches_in_flight += 1;
        let batch_id = self.next_batch_id;
        let seed = self.seed ^ batch_id.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        Some(Taken {
            kind,
            batch: ShadeBatch {
                batch_id,
                quality,
                seed,
                points,
            },
        })
    }

    /// Puts `need` in flight, in a batch being filled.
    fn take(&mut self, need: &Need, points: &mut Vec<ShadePoint>) {
        let entry = self.in_flight.entry(need.point.key).or_insert(InFlight {
            best: (0, 0),
            count: 0,
        });
        entry.best = entry.best.max(need.target.rank());
        entry.count += 1;
        points.push(need.point);
    }

    fn satisfied(&self, need: &Need, cache: &ShadingCache) -> bool {
        let eye = need.point.eye.map(Vec3::from);
        let cached = cache.get_seen_from(need.point.key, eye).is_some_and(|s| {
            s.quality.rank() >= need.target.rank() && (!need.new_eye || s.eye == eye)
        });
        cached || self.in_flight_at(need.point.key, need.target)
    }

    /// A batch came back (answered or failed): its keys are no longer in flight for it.
    pub fn finished(&mut self, batch: &ShadeBatch) {
        self.batches_in_flight = self.batches_in_flight.saturating_sub(1);
        self.awaited_batches.remove(&batch.batch_id);
        self.shared_batches.remove(&batch.batch_id);
        for point in &batch.points {
            if let Some(f) = self.in_flight.get_mut(&point.key) {
                f.count -= 1;
                if f.count == 0 {
                    self.in_flight.remove(&point.key);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::CachedSample;
    use protocol::Side;

    fn need(vertex: u32, quality: Quality, urgency: Urgency, priority: f32) -> Need {
        let key = SampleKey {
            vertex,
            side: Side::Front,
        };
        let point = ShadePoint {
            key,
            base_triangle: 0,
            bary: [0.0; 2],
            side: Side::Front,
            eye: None,
        };
        Need {
            point,
            quality,
            target: quality,
            urgency,
            priority,
            new_eye: false,
        }
    }

    /// At most `n` points, whatever their paths.
    fn points(n: usize) -> BatchLimit {
        BatchLimit {
            points: n,
            paths: u64::MAX,
        }
    }

    #[test]
    fn a_batch_of_many_paths_per_point_carries_fewer_points() {
        let cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        let rung = Quality {
            paths: 256,
            ..Quality::INTERACTIVE
        };
        r.replan(
            (0..10)
                .map(|v| need(v, rung, Urgency::Paths, 1.0))
                .chain((10..20).map(|v| need(v, Quality::DIRECT, Urgency::Paths, 0.5)))
                .collect(),
        );
        let limit = BatchLimit {
            points: 8,
            paths: 1000,
        };
        let sizes = |r: &mut Requests, limit| {
            let b: ShadeBatch = r.next_batch(limit, &cache).unwrap();
            (b.quality.paths, b.points.len())
        };
        assert_eq!(sizes(&mut r, limit), (256, 3), "1000 / 256 paths");
        assert_eq!(sizes(&mut r, limit), (256, 3));
        let tight = BatchLimit { paths: 1, ..limit };
        assert_eq!(sizes(&mut r, tight), (256, 1), "never empty");
        assert_eq!(sizes(&mut r, limit), (256, 3));
        assert_eq!(sizes(&mut r, limit), (16, 8), "points bound cheap ones");
    }

    #[test]
    fn batches_follow_urgency_then_priority_and_never_repeat_a_key_in_flight() {
        let cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        r.replan(vec![
            need(1, Quality::INTERACTIVE, Urgency::Better, 100.0),
            need(2, Quality::DIRECT, Urgency::Missing, 1.0),
            need(3, Quality::DIRECT, Urgency::Missing, 50.0),
            need(3, Quality::DIRECT, Urgency::Missing, 10.0),
        ]);
        assert_eq!(r.outstanding(), 3);
        let b = r.next_batch(points(8), &cache).unwrap();
        assert_eq!(b.quality, Quality::DIRECT);
        assert_eq!(
            b.points.iter().map(|p| p.key.vertex).collect::<Vec<_>>(),
            vec![3, 2]
        );
        // Re-planning the same needs while they fly asks nothing twice.
        r.replan(vec![need(3, Quality::DIRECT, Urgency::Missing, 50.0)]);
        assert!(r.next_batch(points(8), &cache).is_none());
        r.finished(&b);
        assert_eq!(r.in_flight_keys(), 0);
        assert_eq!(r.batches_in_flight(), 0);
    }

    #[test]
    fn the_queue_orders_by_urgency_then_larger_priority_and_keeps_equals_in_order() {
        let cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        let priorities = [
            0.5,
            -3.0,
            f32::INFINITY,
            0.0,
            -0.0,
            7.25,
            1e-30,
            -1e-30,
            7.25,
        ];
        let mut needs: Vec<Need> = priorities
            .iter()
            .enumerate()
            .map(|(i, &p)| need(i as u32, Quality::DIRECT, Urgency::Better, p))
            .collect();
        needs.push(need(100, Quality::DIRECT, Urgency::Missing, -1e9));
        r.replan(needs);
        let batch = r.next_batch(points(16), &cache).unwrap();
        let order: Vec<u32> = batch.points.iter().map(|p| p.key.vertex).collect();
        // Missing before Better whatever the priority; then descending `total_cmp` (0.0 above
        // -0.0), the two 7.25 in the order given.
        assert_eq!(order, vec![100, 2, 5, 8, 0, 6, 3, 4, 7, 1]);
    }

    #[test]
    fn alternating_rungs_of_the_ladder_still_fill_whole_batches_in_order() {
        let cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        let rung = |i: u32| Quality {
            paths: if i.is_multiple_of(2) { 192 } else { 768 },
            bounces: Some(2),
        };
        r.replan(
            (0..40)
                .map(|i| need(i, rung(i), Urgency::Paths, 100.0 - i as f32))
                .collect(),
        );
        let first = r.next_batch(points(8), &cache).unwrap();
        assert_eq!(first.quality.paths, 192);
        let vertices: Vec<u32> = first.points.iter().map(|p| p.key.vertex).collect();
        assert_eq!(vertices, vec![0, 2, 4, 6, 8, 10, 12, 14]);
        let second = r.next_batch(points(8), &cache).unwrap();
        assert_eq!(
            second.quality.paths, 768,
            "the skipped needs kept their place"
        );
        assert_eq!(second.points[0].key.vertex, 1);
        assert_eq!(second.points.len(), 8);
    }

    #[test]
    fn more_paths_fill_their_own_batches_and_never_hold_refinement_back() {
        let cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        r.replan(vec![
            need(1, Quality::INTERACTIVE, Urgency::Paths, 9.0),
            need(2, Quality::INTERACTIVE, Urgency::Paths, 8.0),
            need(3, Quality::INTERACTIVE, Urgency::Refinement, 1.0),
        ]);
        assert_eq!((r.outstanding(), r.outstanding_before_paths()), (3, 1));
        let refinement = r.next_batch(points(8), &cache).unwrap();
        assert_eq!(refinement.points.len(), 1, "a batch holds one kind of need");
        assert_eq!(r.outstanding_before_paths(), 1, "in flight, still awaited");
        let paths = r.next_batch(points(8), &cache).unwrap();
        assert_eq!(paths.points.len(), 2);
        r.finished(&refinement);
        assert_eq!((r.outstanding(), r.outstanding_before_paths()), (2, 0));
        r.finished(&paths);
        assert_eq!(r.outstanding(), 0);
    }

    #[test]
    fn top_ups_get_their_share_of_the_paths_while_refinement_waits_and_are_not_awaited() {
        let cache = ShadingCache::new(1 << 20);
        let early = Quality {
            paths: 16,
            bounces: Some(2),
        };
        let top_up = Quality {
            paths: 48,
            bounces: Some(2),
        };
        let queue = || {
            let refinement = (0..64).map(|i| need(i, early, Urgency::Refinement, 1.0));
            let top_ups = (100..164).map(|i| need(i, top_up, Urgency::TopUp, 1.0));
            refinement.chain(top_ups).collect::<Vec<_>>()
        };
        // Share 0: refinement's eight batches first, then the top-ups.
        let mut r = Requests::new(7, 0.0);
        r.replan(queue());
        let kinds: Vec<u32> = (0..16)
            .map(|_| r.next_batch(points(8), &cache).unwrap().quality.paths)
            .collect();
        assert_eq!(kinds, [[16; 8], [48; 8]].concat());
        // Share 1/2: top-up batches cost three times the paths, so about one in four batches.
        let mut r = Requests::new(7, 0.5);
        r.replan(queue());
        let mut taken = Vec::new();
        while r.queue.front().is_some_and(|n| awaited(n.urgency)) {
            let batch = r.next_batch(points(8), &cache).unwrap();
            assert!(
                r.is_urgent(batch.batch_id),
                "top-ups go out with refinement"
            );
            taken.push(batch);
        }
        let paths = |q: u32| -> u32 {
            let of = taken.iter().filter(|b| b.quality.paths == q);
            of.map(|b| b.points.len() as u32 * q).sum()
        };
        let share = f64::from(paths(48)) / f64::from(paths(16) + paths(48));
        assert!((0.4..=0.6).contains(&share), "top-ups took {share:.2}");
        // Top-ups in flight hold no refinement back.
        let refinement: usize = taken.iter().filter(|b| b.quality.paths == 16).count();
        assert_eq!(refinement, 8);
        for b in taken.iter().filter(|b| b.quality.paths == 16) {
            r.finished(b);
        }
        assert_eq!(r.outstanding_before_paths(), 0);
    }

    #[test]
    fn needs_satisfied_while_queued_leave_nothing_outstanding_once_submission_passes() {
        // The schedule counts `outstanding` after submitting: a queue whose needs were all
        // answered meanwhile must drain to zero then, or an epoch would never report completion.
        let mut cache = ShadingCache::new(1 << 20);
        let mut r = Requests::new(7, 0.0);
        r.replan(vec![
            need(1, Quality::DIRECT, Urgency::Missing, 1.0),
            need(2, Quality::DIRECT, Urgency::Missing, 1.0),
        ]);
        for vertex in [1, 2] {
            let key = SampleKey {
                vertex,
                side: Side::Front,
            };
            let sample = CachedSample {
                rgb: [1.0; 3],
                luminance_variance: 0.0,
                quality: Quality::INTERACTIVE,
                view_dependent: false,
                eye: None,
                last_seen: 0,
            };
            cache.insert(key, sample);
        }
        assert_eq!(r.outstanding(), 2);
        assert!(r.next_batch(points(8), &cache).is_none());
        assert_eq!(r.outstanding(), 0);
    }
}
