//! Batches handed to the pool and not yet sent to a renderer (DESIGN.md §3: rest time goes to
//! shading). The schedule's turns block for tens to hundreds of milliseconds (a visibility
//! pass, a refinement round over every visible leaf, a re-plan); a renderer that holds only what
//! the schedule sent before such a turn runs dry during it. The backlog is the work the
//! dispatcher sends on its own while the schedule is busy, sized by the schedule in seconds of
//! the renderers' measured capacity.
//!
//! It is shared between the schedule's handle and the dispatcher, behind one mutex held only to
//! push or pop. Two lanes: batches a picture or a refinement step waits for go out before more
//! paths, whatever order they were handed over in, so a deep backlog of more paths never holds
//! refinement back. Nothing here has been sent: the schedule may withdraw all of it when its
//! plan changes (a camera move), so a stale backlog never delays the new view.

use std::collections::VecDeque;

use protocol::renderer_link::ShadeBatch;

use super::rate;

/// A batch waiting, with the times a renderer has failed it.
pub struct Queued {
    pub batch: ShadeBatch,
    pub attempts: u32,
}

/// Which lane a batch waits in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lane {
    /// Needed for a picture or a refinement step.
    Urgent,
    /// More paths for samples already shown: fills the renderers' spare time.
    Background,
}

#[derive(Default)]
pub struct Backlog {
    urgent: VecDeque<Queued>,
    background: VecDeque<Queued>,
    /// Units (`rate::units`) of every waiting batch.
    units: f64,
    /// The answering renderers' measured capacity, units per second (None until measured).
    capacity: Option<f64>,
}

impl Backlog {
    pub fn len(&self) -> usize {
        self.urgent.len() + self.background.len()
    }

    /// Appends a batch handed over by the schedule.
    pub fn push_back(&mut self, batch: ShadeBatch, lane: Lane) {
        self.units += rate::units(&batch);
        let queued = Queued { batch, attempts: 0 };
        match lane {
            Lane::Urgent => self.urgent.push_back(queued),
            Lane::Background => self.background.push_back(queued),
        }
    }

    /// Puts back a batch a renderer lost or failed: it goes out first.
    pub fn push_front(&mut self, queued: Queued) {
        self.units += rate::units(&queued.batch);
        self.urgent.push_front(queued);
    }

    /// The next batch to send: urgent ones first.
    pub fn pop_front(&mut self) -> Option<Queued> {
        let queued = self
            .urgent
            .pop_front()
            .or_else(|| self.background.pop_front())?;
        self.units = (self.units - rate::units(&queued.batch)).max(0.0);
        Some(queued)
    }

    /// Every waiting batch, taken back by the schedule; none of them was sent.
    pub fn withdraw(&mut self) -> Vec<ShadeBatch> {
        self.units = 0.0;
        self.urgent
            .drain(..)
            .chain(self.background.drain(..))
            .map(|q| q.batch)
            .collect()
    }

    pub fn set_capacity(&mut self, units_per_sec: Option<f64>) {
        self.capacity = units_per_sec.filter(|c| c.is_finite() && *c > 0.0);
    }

    /// How long the answering renderers take to work through what waits here, at their
    /// measured capacity; None before any rate is measured.
    pub fn seconds(&self) -> Option<f64> {
        self.capacity.map(|c| self.units / c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::renderer_link::Quality;

    fn batch(id: u64, points: usize) -> ShadeBatch {
        let point = protocol::renderer_link::ShadePoint {
            key: protocol::renderer_link::SampleKey {
                vertex: 0,
                side: protocol::Side::Front,
            },
            base_triangle: 0,
            bary: [0.0; 2],
            side: protocol::Side::Front,
            eye: None,
        };
        ShadeBatch {
            batch_id: id,
            quality: Quality {
                paths: 10,
                bounces: Some(1),
            },
            seed: 0,
            points: vec![point; points],
        }
    }

    #[test]
    fn urgent_batches_overtake_more_paths_and_lost_ones_go_first() {
        let mut backlog = Backlog::default();
        backlog.push_back(batch(1, 1), Lane::Background);
        backlog.push_back(batch(2, 1), Lane::Background);
        backlog.push_back(batch(3, 1), Lane::Urgent);
        backlog.push_front(Queued {
            batch: batch(4, 1),
            attempts: 1,
        });
        let order: Vec<u64> = std::iter::from_fn(|| backlog.pop_front())
            .map(|q| q.batch.batch_id)
            .collect();
        assert_eq!(order, vec![4, 3, 1, 2]);
        assert_eq!(backlog.len(), 0);
    }

    #[test]
    fn the_backlog_is_counted_in_seconds_of_measured_capacity_and_withdrawn_whole() {
        let mut backlog = Backlog::default();
        // 5 points × 10 paths × (1 + 1 bounce) = 100 units each.
        backlog.push_back(batch(1, 5), Lane::Background);
        backlog.push_back(batch(2, 5), Lane::Urgent);
        assert_eq!(backlog.seconds(), None, "no rate measured yet");
        backlog.set_capacity(Some(400.0));
        assert_eq!(backlog.seconds(), Some(0.5));
        backlog.pop_front();
        assert_eq!(backlog.seconds(), Some(0.25));
        let withdrawn = backlog.withdraw();
        assert_eq!(withdrawn.len(), 1);
        assert_eq!(backlog.seconds(), Some(0.0));
        assert!(backlog.pop_front().is_none());
    }
}
