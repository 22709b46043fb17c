//! How much of the wall time the renderers had work in hand (DESIGN.md §3: rest time is meant for
//! shading). The dispatcher tells the meter, after each of its events, how many connected
//! renderers hold at least one batch sent and not yet answered; the meter integrates that share
//! over time. It is measured where the links are, not in the schedule: a reply counts the moment
//! it arrives, however long the schedule takes to use it, so a schedule too busy to send more
//! work shows as idle renderers. Only the time on the wire (loopback: well under a millisecond)
//! counts as busy without being so.

use std::time::Instant;

#[derive(Debug)]
pub struct BusyMeter {
    /// The level since `changed`: the share of renderers with a batch in hand.
    level: f64,
    changed: Instant,
    /// Busy renderer-seconds (divided by the renderers) since `window_start`.
    busy_s: f64,
    window_start: Instant,
}

impl BusyMeter {
    pub fn new(now: Instant) -> BusyMeter {
        BusyMeter {
            level: 0.0,
            changed: now,
            busy_s: 0.0,
            window_start: now,
        }
    }

    /// The dispatcher's counts after an event; the level holds until the next call.
    pub fn observe(&mut self, now: Instant, holding: usize, renderers: usize) {
        self.accumulate(now);
        self.level = if renderers == 0 {
            0.0
        } else {
            holding.min(renderers) as f64 / renderers as f64
        };
    }

    /// The busy share since the previous call (0..1), and a new window from `now`.
    pub fn take(&mut self, now: Instant) -> f32 {
        self.accumulate(now);
        let wall = now.duration_since(self.window_start).as_secs_f64();
        let share = if wall > 0.0 { self.busy_s / wall } else { 0.0 };
        (self.busy_s, self.window_start) = (0.0, now);
        share.clamp(0.0, 1.0) as f32
    }

    fn accumulate(&mut self, now: Instant) {
        self.busy_s += self.level * now.duration_since(self.changed).as_secs_f64();
        self.changed = now;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn the_share_is_the_time_weighted_level_over_the_window() {
        let t0 = Instant::now();
        let at = |ms| t0 + Duration::from_millis(ms);
        let mut meter = BusyMeter::new(t0);
        meter.observe(at(0), 2, 2); // both renderers busy for 500 ms
        meter.observe(at(500), 1, 2); // one of two for 250 ms
        meter.observe(at(750), 0, 2); // none for 250 ms
        let share = meter.take(at(1000));
        assert!((share - 0.625).abs() < 1e-6, "{share}");
        // The level carries into the next window.
        meter.observe(at(1000), 2, 2);
        assert!((meter.take(at(2000)) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn no_renderer_is_never_busy() {
        let t0 = Instant::now();
        let mut meter = BusyMeter::new(t0);
        meter.observe(t0, 5, 0);
        assert_eq!(meter.take(t0 + Duration::from_secs(1)), 0.0);
    }
}
