//! Each renderer's measured rate (DESIGN.md §2): what a batch costs it, so batches go where they
//! finish first and each batch has a deadline scaled by its expected time there.

use std::time::{Duration, Instant};

use protocol::renderer_link::ShadeBatch;

/// Weight of the newest measurement in the running mean: a few batches follow a host that
/// slows down (another job on it) without one odd batch swinging it.
const SMOOTHING: f64 = 0.3;
/// Bounces counted for a path ended only by Russian roulette.
const UNBOUNDED_BOUNCES: u32 = 8;

/// A batch's expected cost in units of one path segment: points × paths × (1 + bounces).
pub fn units(batch: &ShadeBatch) -> f64 {
    let bounces = batch.quality.bounces.unwrap_or(UNBOUNDED_BOUNCES).min(64);
    batch.points.len() as f64 * f64::from(batch.quality.paths) * f64::from(1 + bounces)
}

/// Seconds per unit on one renderer, from how fast its answers come while it is busy.
///
/// The mean is a ratio of running means, seconds over units, not a running mean of each
/// batch's seconds per unit: a batch also costs a fixed overhead (its round trip, the
/// renderer's set-up), which makes a cheap batch (direct light, a few points) look many times
/// slower per unit than a batch of more paths. Weighted by units, cheap batches barely move
/// the rate, and the renderers' capacity is not underestimated when they are mixed.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rate {
    /// Running means of an answer's service time and units, once one is measured.
    means: Option<(f64, f64)>,
    last_answer: Option<Instant>,
}

impl Rate {
    /// An answer of `units` came at `now` for a batch sent at `sent`. Its service time is
    /// counted from the later of its sending and the previous answer: a renderer works on
    /// several batches at once, so the gap between answers, not a batch's round trip, is the
    /// time one batch's worth of its work takes.
    pub fn answered(&mut self, units: f64, sent: Instant, now: Instant) {
        let from = self.last_answer.map_or(sent, |last| last.max(sent));
        self.last_answer = Some(now);
        if units <= 0.0 {
            return;
        }
        let seconds = now.duration_since(from).as_secs_f64();
        self.means = Some(match self.means {
            Some((mean_s, mean_u)) => (
                mean_s + SMOOTHING * (seconds - mean_s),
                mean_u + SMOOTHING * (units - mean_u),
            ),
            None => (seconds, units),
        });
    }

    fn secs_per_unit(&self) -> Option<f64> {
        self.means.map(|(s, u)| s / u)
    }

    /// Units of work done per second, if measured.
    pub fn units_per_sec(&self) -> Option<f64> {
        self.secs_per_unit().filter(|s| *s > 0.0).map(|s| 1.0 / s)
    }

    /// The time `units` of work take here, if measured.
    pub fn expected(&self, units: f64) -> Option<Duration> {
        self.secs_per_unit()
            .map(|s| Duration::from_secs_f64((s * units).clamp(0.0, 3600.0)))
    }
}

/// When a batch sent now counts as lost: `factor` times the expected time of the work ahead of
/// it and its own on that renderer, plus `grace` for a round trip and scheduling noise; before
/// the renderer's rate is measured, `first` (its heartbeats still tell a hung one at once).
pub fn deadline(
    rate: &Rate,
    units_ahead_and_own: f64,
    factor: f64,
    grace: Duration,
    first: Duration,
) -> Duration {
    match rate.expected(units_ahead_and_own) {
        Some(expected) => expected.mul_f64(factor.max(1.0)) + grace,
        None => first,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_counts_the_gaps_between_answers_of_a_busy_renderer() {
        let t0 = Instant::now();
        let mut rate = Rate::default();
        assert_eq!(rate.expected(10.0), None);
        // Two batches of 100 units sent together, answered 1 s and 2 s later: 1 s per batch.
        rate.answered(100.0, t0, t0 + Duration::from_secs(1));
        rate.answered(100.0, t0, t0 + Duration::from_secs(2));
        let per_batch = rate.expected(100.0).unwrap().as_secs_f64();
        assert!((per_batch - 1.0).abs() < 1e-6, "{per_batch}");
        let first = Duration::from_secs(30);
        let grace = Duration::from_secs(1);
        let due = deadline(&rate, 300.0, 4.0, grace, first).as_secs_f64();
        assert!((due - 13.0).abs() < 1e-6, "{due}");
        assert_eq!(deadline(&Rate::default(), 300.0, 4.0, grace, first), first);
    }

    #[test]
    fn cheap_batches_with_a_fixed_overhead_barely_lower_the_capacity() {
        // 1 ms of overhead per batch, 1 µs per unit: a batch of 100,000 units takes 101 ms,
        // one of 100 units 1.1 ms (1,000 times slower per unit).
        let service = |units: f64| Duration::from_secs_f64(1e-3 + 1e-6 * units);
        let t0 = Instant::now();
        let mut rate = Rate::default();
        let mut now = t0;
        for i in 0..40 {
            let units = if i % 2 == 0 { 100_000.0 } else { 100.0 };
            let sent = now;
            now += service(units);
            rate.answered(units, sent, now);
        }
        let capacity = rate.units_per_sec().unwrap();
        assert!(
            capacity > 0.9e6 && capacity < 1.0e6,
            "{capacity} units/s, against 1e6 without overhead"
        );
    }
}
