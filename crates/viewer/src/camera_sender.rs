//! Cameras go to the SMA on change, rate-limited (DESIGN.md §3 step 1): every camera restarts the
//! SMA's visibility passes and interrupts refinement, so sending one per frame while walking would
//! keep it from ever finishing a pass. Each camera sent gets the next sequence number, which the
//! SMA's epochs echo back.

use std::time::{Duration, Instant};

use protocol::viewer_link::{CAMERA_INTERVAL, Camera};

/// At most 20 cameras a second, the most the SMA expects.
pub const DEFAULT_INTERVAL: Duration = CAMERA_INTERVAL;

pub struct CameraSender {
    interval: Duration,
    seq: u64,
    last: Option<(Camera, Instant)>,
}

impl CameraSender {
    pub fn new(interval: Duration) -> Self {
        CameraSender {
            interval,
            seq: 0,
            last: None,
        }
    }

    /// The sequence number of the last camera sent (0 before any).
    pub fn seq(&self) -> u64 {
        self.seq
    }

    /// The camera to send now, if it differs from the last one sent and the interval has passed.
    /// A change held back is offered again on the next call.
    pub fn offer(&mut self, camera: &Camera, now: Instant) -> Option<Camera> {
        match &self.last {
            Some((last, _)) if same_view(last, camera) => None,
            Some((_, at)) if now.duration_since(*at) < self.interval => None,
            _ => Some(self.stamp(camera, now)),
        }
    }

    /// The camera to send now, whatever was sent before (a new session knows nothing).
    pub fn force(&mut self, camera: &Camera, now: Instant) -> Camera {
        self.stamp(camera, now)
    }

    fn stamp(&mut self, camera: &Camera, now: Instant) -> Camera {
        self.seq += 1;
        let sent = Camera {
            seq: self.seq,
            ..camera.clone()
        };
        self.last = Some((sent.clone(), now));
        sent
    }
}

/// Whether two cameras see the same image (their sequence numbers aside).
pub(crate) fn same_view(a: &Camera, b: &Camera) -> bool {
    a.eye == b.eye
        && a.orientation == b.orientation
        && a.fov_y_deg == b.fov_y_deg
        && (a.width, a.height) == (b.width, b.height)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(x: f32) -> Camera {
        Camera {
            seq: 0,
            eye: [x, 0.0, 0.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            fov_y_deg: 60.0,
            width: 64,
            height: 48,
        }
    }

    #[test]
    fn sends_changes_only_and_no_faster_than_the_interval() {
        let mut s = CameraSender::new(Duration::from_millis(50));
        let t0 = Instant::now();
        assert_eq!(s.offer(&camera(0.0), t0).map(|c| c.seq), Some(1));
        assert_eq!(s.offer(&camera(0.0), t0 + Duration::from_secs(1)), None);
        assert_eq!(s.offer(&camera(1.0), t0 + Duration::from_millis(10)), None);
        let sent = s
            .offer(&camera(1.0), t0 + Duration::from_millis(60))
            .unwrap();
        assert_eq!((sent.seq, sent.eye[0]), (2, 1.0));
        assert_eq!(s.force(&camera(1.0), t0 + Duration::from_millis(61)).seq, 3);
        assert_eq!(s.seq(), 3);
    }
}
