//! What a listening port allows a peer that has not yet said who it is (DESIGN.md §8: the server
//! keeps serving everyone else). Until its handshake is done a peer may send one small frame, and
//! must send it within a deadline; and a port serves a bounded number of connections at once, a
//! semaphore's permits as in tokio's mini-redis. Past the bound a peer is not left waiting in the
//! backlog: it is told `Refused` (a second, equal bound on those being told), and past that too
//! its connection is closed at once.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Largest frame a peer may send before its handshake is done: a `Hello` is under 64 bytes, so a
/// few KiB leave room for any later field while an unidentified peer cannot make the server
/// reserve the post-handshake maximum (64 MiB by default).
pub const HANDSHAKE_MAX_FRAME: usize = 4 * 1024;

/// How many peers one port serves at once, and how long a peer has to complete its handshake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PortLimits {
    pub max_connections: usize,
    pub handshake_deadline: Duration,
}

impl Default for PortLimits {
    /// 64 connections: a LAN walkthrough has a handful of viewers or renderers per port. 5 s: a
    /// handshake is one round trip, milliseconds even across a LAN.
    fn default() -> Self {
        PortLimits {
            max_connections: 64,
            handshake_deadline: Duration::from_secs(5),
        }
    }
}

/// What to do with a connection just accepted. The permit is held for as long as the
/// connection is being served or refused, and given back when it is dropped.
#[derive(Debug)]
pub enum Admission {
    Serve(OwnedSemaphorePermit),
    Refuse(OwnedSemaphorePermit),
    /// Both bounds are reached: close the connection without a word.
    Close,
}

/// The connection bound of one port.
#[derive(Clone, Debug)]
pub struct ConnectionLimit {
    max: usize,
    served: Arc<Semaphore>,
    refused: Arc<Semaphore>,
}

impl ConnectionLimit {
    pub fn new(max_connections: usize) -> ConnectionLimit {
        ConnectionLimit {
            max: max_connections,
            served: Arc::new(Semaphore::new(max_connections)),
            refused: Arc::new(Semaphore::new(max_connections)),
        }
    }

    /// Decides at once, never waiting for a permit.
    pub fn admit(&self) -> Admission {
        if let Ok(permit) = Arc::clone(&self.served).try_acquire_owned() {
            Admission::Serve(permit)
        } else if let Ok(permit) = Arc::clone(&self.refused).try_acquire_owned() {
            Admission::Refuse(permit)
        } else {
            Admission::Close
        }
    }

    /// The reason a refused peer is told.
    pub fn full_reason(&self) -> String {
        format!(
            "this port serves at most {} connections at once; try again later",
            self.max
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn admits_up_to_the_bound_then_refuses_then_closes() {
        let limit = ConnectionLimit::new(2);
        let served: Vec<_> = (0..2).map(|_| limit.admit()).collect();
        assert!(served.iter().all(|a| matches!(a, Admission::Serve(_))));
        let refused: Vec<_> = (0..2).map(|_| limit.admit()).collect();
        assert!(refused.iter().all(|a| matches!(a, Admission::Refuse(_))));
        assert!(matches!(limit.admit(), Admission::Close));
        drop(served);
        assert!(matches!(limit.admit(), Admission::Serve(_)));
    }
}
