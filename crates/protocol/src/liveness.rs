//! How long each side of a link waits for the other (DESIGN.md §2, §8): a peer that hangs —
//! stopped, partitioned, or stalled halfway through a frame — is told apart from a slow one by
//! heartbeats, so its work can go elsewhere and its connection can close.

use std::time::Duration;

/// The liveness rule of one side of a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Liveness {
    /// How often the side that pings sends a heartbeat.
    pub heartbeat: Duration,
    /// A peer that has sent nothing for this long, heartbeat answers included, is lost.
    pub silence: Duration,
    /// A frame begun must be complete within this long after its first byte.
    pub frame_timeout: Duration,
}

impl Default for Liveness {
    /// Heartbeats every 500 ms and 1.5 s of silence: a renderer's pong comes from its network
    /// task, not its busy workers, in milliseconds even with every core tracing (the farm tests
    /// run at 1 s on a loaded 2-core machine), so three missed heartbeats mean a hung peer, not
    /// a busy one. The silence is the whole detection delay of a hung renderer, and a view at
    /// the scene's preset takes about as long on one renderer (BENCHMARKS.md, "Renderer farm"):
    /// at 3 s a hung renderer more than doubled it. 30 s for a frame: the 64 MiB maximum over a
    /// 100 Mbit/s LAN takes about 5 s.
    fn default() -> Self {
        Liveness {
            heartbeat: Duration::from_millis(500),
            silence: Duration::from_millis(1500),
            frame_timeout: Duration::from_secs(30),
        }
    }
}
