//! Shade requests (DESIGN.md §3 step 5): the prioritised queue of samples wanted (`need`), the
//! keys in flight, and batching. The queue is re-planned from the visible sets whenever they change, so
//! priorities follow the camera; a key already in flight at a quality at least as good is never
//! asked twice.

use std::collections::{HashMap, HashSet, VecDeque};

use glam::Vec3;
use protocol::renderer_link::{Quality, SampleKey, ShadeBatch, ShadePoint};

use super::need::{Need, Urgency, awaited, queue_order};
use crate::cache::ShadingCache;
use crate::mesh::VertexId;
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
    /// What went out since the last `take_handed_out`, per kind of batch.
    handed_out: HandedOut,
}

/// Points and paths batched since the last look, per kind of batch (awaited, top-ups, more
/// paths): what the renderers were given to do, for the debug statistics.
#[derive(Clone, Copy, Debug, Default)]
pub struct HandedOut {
    pub awaited: (u64, u64),
    pub top_up: (u64, u64),
    pub paths: (u64, u64),
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
    /// The vertices of every queued and in-flight sample: their ids must not be reused while
    /// an answer may come (`SubdivisionMesh::free_unused_midpoints`).
    pub fn vertices(&self) -> impl Iterator<Item = VertexId> + '_ {
        let queued = self.queue.iter().map(|need| need.point.key.vertex);
        queued.chain(self.in_flight.keys().map(|key| key.vertex))
    }

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

    /// The queue's needs per urgency (`Urgency` order), for the debug statistics.
    pub fn queued_by_urgency(&self) -> [usize; 6] {
        let mut counts = [0; 6];
        for need in &self.queue {
            counts[need.urgency as usize] += 1;
        }
        counts
    }

    /// What was batched since the last call.
    pub fn take_handed_out(&mut self) -> HandedOut {
        std::mem::take(&mut self.handed_out)
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
    /// needs are queued, none of them missing from a picture, top-ups get their share of the
    /// paths (`TopUpShare`).
    pub fn next_batch(&mut self, limit: BatchLimit, cache: &ShadingCache) -> Option<ShadeBatch> {
        let top_ups = self.queue.partition_point(|n| awaited(n.urgency));
        let has_top_ups = self
            .queue
            .get(top_ups)
            .is_some_and(|n| n.urgency == Urgency::TopUp);
        // Never beside a picture's missing samples: a new view's come before any upgrade of
        // what is already shown (DESIGN.md §3 step 9); the share is refinement's to give.
        let picture_waits = self
            .queue
            .front()
            .is_some_and(|n| n.urgency == Urgency::Missing);
        let shared = top_ups > 0
            && has_top_ups
            && !picture_waits
            && self.recent.owes_top_ups(self.top_up_share);
        let batch = if shared {
            self.batch_from(top_ups, Some(Urgency::TopUp), limit, cache)
        } else {
            None
        };
        let batch = batch.or_else(|| self.batch_from(0, None, limit, cache))?;
        let Taken { kind, batch } = batch;
        let paths = batch.points.len() as f64 * f64::from(batch.quality.paths);
        let batch_id = batch.batch_id;
        let handed = match kind {
            k if awaited(k) => &mut self.handed_out.awaited,
            Urgency::TopUp => &mut self.handed_out.top_up,
            _ => &mut self.handed_out.paths,
        };
        handed.0 += batch.points.len() as u64;
        handed.1 += paths as u64;
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
mod tests;
