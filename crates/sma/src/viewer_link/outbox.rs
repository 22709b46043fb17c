//! What waits for one viewer (DESIGN.md §8): not a queue of messages but the change from what the
//! viewer was last sent to what it should hold now. A viewer that reads slowly gets the latest
//! state of each triangle, not every step it went through: an insert then an update is one insert,
//! an insert then a remove is nothing, epochs keep only the newest, statistics the last few. So the bytes
//! waiting for a viewer are bounded by the triangles it could hold, whatever the SMA computes
//! meanwhile; the schedule never waits for a viewer, and other viewers and the renderers go on.
//!
//! The writer takes everything waiting at once and sends it in an order the viewer can apply:
//! notes (refinement state, errors, heartbeats), `Remove`, `Insert`, `Update`, `ToneMap`, then
//! the `Epoch` that closes them, then `Stats`. Changes after the last epoch wait for the next one,
//! so each epoch a viewer gets still closes a consistent state (its `shown` is the table's size).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use indexmap::IndexMap;
use protocol::direct_tile::ViewerTile;
use protocol::viewer_link::{
    CornerShading, Epoch, Recolour, ShownTriangle, SmaToViewer, Stats, TriangleId,
};
use tokio::sync::Notify;

/// Inserts and updates are split so no frame nears the protocol's maximum.
const MAX_TRIANGLES_PER_MESSAGE: usize = 100_000;

/// Encoded sizes, at most, of what a change sends (postcard: a varint id, f32 triples, a byte of
/// direct share per vertex, an optional view-dependent part, a material varint and 14 bytes of
/// texture coordinates).
const ID_BYTES: usize = 10;
const SHADING_BYTES: usize = 2 * 9 * 4 + 3 + 1;
const TRIANGLE_BYTES: usize = ID_BYTES + 9 * 4 + 3 + 14 + SHADING_BYTES;
const RECOLOUR_BYTES: usize = ID_BYTES + SHADING_BYTES;
const NOTE_BYTES: usize = 256;
/// A `ViewerTile`'s bytes besides its pixels', at most, and each pixel's (four halves).
const TILE_BYTES: usize = 48;
const TILE_PIXEL_BYTES: usize = 8;

/// What one triangle's messages since the last write add up to.
#[derive(Clone, Debug, PartialEq)]
enum Change {
    /// New to the viewer.
    Insert(ShownTriangle),
    /// The viewer holds an older triangle under this id: remove it, then insert this one.
    Replace(ShownTriangle),
    Remove,
    /// What the corners are lit with.
    Update(CornerShading),
}

impl Change {
    fn bytes(&self) -> usize {
        match self {
            Change::Insert(_) => TRIANGLE_BYTES,
            Change::Replace(_) => TRIANGLE_BYTES + ID_BYTES,
            Change::Remove => ID_BYTES,
            Change::Update(..) => RECOLOUR_BYTES,
        }
    }

    /// `self` followed by `next`; `None` when they cancel (inserted, then removed).
    fn then(self, next: Change) -> Option<Change> {
        use Change::*;
        Some(match (self, next) {
            (Insert(mut t), Update(shading)) => {
                t.shading = shading;
                Insert(t)
            }
            (Replace(mut t), Update(shading)) => {
                t.shading = shading;
                Replace(t)
            }
            (Insert(_), Remove) => return None,
            (Replace(_) | Update(..) | Remove, Remove) => Remove,
            (Insert(_), Insert(t)) => Insert(t),
            (Replace(_) | Remove | Update(..), Insert(t) | Replace(t)) => Replace(t),
            (Insert(_), Replace(t)) => Insert(t),
            // Nothing shown under the id to update.
            (Remove, Update(..)) => Remove,
            (Update(..), Update(shading)) => Update(shading),
        })
    }
}

/// Triangle changes and a tone map, folded per triangle.
#[derive(Debug, Default)]
struct Changes {
    triangles: IndexMap<TriangleId, Change>,
    tone_map: Option<f32>,
    bytes: usize,
}

impl Changes {
    fn fold(&mut self, id: TriangleId, change: Change) {
        let next = match self.triangles.swap_remove(&id) {
            Some(old) => {
                self.bytes -= old.bytes();
                old.then(change)
            }
            None => Some(change),
        };
        if let Some(next) = next {
            self.bytes += next.bytes();
            self.triangles.insert(id, next);
        }
    }

    /// `later` follows these changes.
    fn absorb(&mut self, later: Changes) {
        for (id, change) in later.triangles {
            self.fold(id, change);
        }
        self.tone_map = later.tone_map.or(self.tone_map);
    }

    /// `Remove`, `Insert`, `Update` in frames of a safe size, then `ToneMap`.
    fn write_into(self, messages: &mut Vec<SmaToViewer>) {
        let (mut removed, mut inserts, mut updates) = (Vec::new(), Vec::new(), Vec::new());
        for (id, change) in self.triangles {
            match change {
                Change::Insert(t) => inserts.push(t),
                Change::Replace(t) => {
                    removed.push(id);
                    inserts.push(t);
                }
                Change::Remove => removed.push(id),
                Change::Update(shading) => updates.push(Recolour { id, shading }),
            }
        }
        if !removed.is_empty() {
            messages.push(SmaToViewer::Remove { ids: removed });
        }
        for chunk in inserts.chunks(MAX_TRIANGLES_PER_MESSAGE) {
            messages.push(SmaToViewer::Insert {
                triangles: chunk.to_vec(),
            });
        }
        for chunk in updates.chunks(MAX_TRIANGLES_PER_MESSAGE) {
            messages.push(SmaToViewer::Update {
                triangles: chunk.to_vec(),
            });
        }
        messages.extend(
            self.tone_map
                .map(|l_white| SmaToViewer::ToneMap { l_white }),
        );
    }
}

/// Everything waiting for one viewer. Changes an epoch has closed go out with it; those after
/// the last epoch wait for theirs, so every epoch the viewer gets closes a consistent state.
#[derive(Debug, Default)]
struct Pending {
    notes: Vec<SmaToViewer>,
    closed: Changes,
    epoch: Option<Epoch>,
    open: Changes,
    /// The newest statistics, oldest first: a viewer that keeps up sees every interval, one
    /// that lags the last `STATS_KEPT`.
    stats: VecDeque<Stats>,
    /// The latest accumulation of each direct-light tile of one camera, by its top-left pixel
    /// (`direct_tiles`): a newer one replaces the one waiting, a newer camera drops them all.
    tiles: IndexMap<(u32, u32), ViewerTile>,
}

fn tile_bytes(tile: &ViewerTile) -> usize {
    TILE_BYTES + tile.pixels.len() * TILE_PIXEL_BYTES
}

/// Statistics kept for a viewer that lags.
const STATS_KEPT: usize = 64;

impl Pending {
    fn add(&mut self, message: SmaToViewer) {
        match message {
            SmaToViewer::Insert { triangles } => {
                for t in triangles {
                    self.open.fold(t.id, Change::Insert(t));
                }
            }
            SmaToViewer::Remove { ids } => {
                for id in ids {
                    self.open.fold(id, Change::Remove);
                }
            }
            SmaToViewer::Update { triangles } => {
                for t in triangles {
                    self.open.fold(t.id, Change::Update(t.shading));
                }
            }
            SmaToViewer::ToneMap { l_white } => self.open.tone_map = Some(l_white),
            SmaToViewer::Epoch(epoch) => {
                self.closed.absorb(std::mem::take(&mut self.open));
                self.epoch = Some(merged(self.epoch, epoch));
            }
            SmaToViewer::Stats(stats) => {
                if self.stats.len() == STATS_KEPT {
                    self.stats.pop_front();
                }
                self.stats.push_back(stats);
            }
            SmaToViewer::DirectTile(tile) => {
                let older = |t: &ViewerTile| t.camera_seq < tile.camera_seq;
                if self.tiles.values().next().is_some_and(older) {
                    self.tiles.clear();
                }
                self.tiles.insert((tile.rect.x, tile.rect.y), tile);
            }
            note => self.notes.push(note),
        }
    }

    /// Bytes waiting, at most.
    fn bytes(&self) -> usize {
        (self.notes.len() + self.stats.len()) * NOTE_BYTES
            + self.closed.bytes
            + self.open.bytes
            + self.tiles.values().map(tile_bytes).sum::<usize>()
    }

    /// What may go out now, in sending order; the changes no epoch has closed yet stay.
    fn take_closed(&mut self) -> Vec<SmaToViewer> {
        let mut messages = std::mem::take(&mut self.notes);
        let tiles = std::mem::take(&mut self.tiles).into_values();
        messages.extend(tiles.map(SmaToViewer::DirectTile));
        if let Some(epoch) = self.epoch.take() {
            std::mem::take(&mut self.closed).write_into(&mut messages);
            messages.push(SmaToViewer::Epoch(epoch));
        }
        messages.extend(self.stats.drain(..).map(SmaToViewer::Stats));
        messages
    }
}

/// An epoch that replaces one never sent: Δins and Δrem count every change since the last epoch
/// the viewer saw.
fn merged(older: Option<Epoch>, mut newer: Epoch) -> Epoch {
    if let Some(older) = older {
        newer.inserted += older.inserted;
        newer.removed += older.removed;
    }
    newer
}

/// The state one viewer's schedule side and writing task share.
#[derive(Debug)]
struct Shared {
    pending: Mutex<Pending>,
    /// Something was added since the writer last took.
    ready: Notify,
    /// Bytes that may wait; past them the viewer is cut off.
    limit: usize,
    cut: AtomicBool,
    overflow: Notify,
    /// When the writer last wrote a `Ping`, and its nonce.
    ping_written: Mutex<Option<(u64, Instant)>>,
}

impl Shared {
    fn pending(&self) -> MutexGuard<'_, Pending> {
        // A panic while holding the lock leaves a consistent `Pending` (each change is whole).
        self.pending.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The schedule's side of one viewer's link. Sending never blocks and never fails: a viewer
/// whose waiting changes pass the byte bound is cut off, and later messages are dropped.
#[derive(Clone, Debug)]
pub struct Outbox {
    shared: Arc<Shared>,
}

/// The writing task's side of the same link.
#[derive(Debug)]
pub(crate) struct Outgoing {
    shared: Arc<Shared>,
}

/// A new outbox holding at most `limit` bytes of waiting changes, and its writer's side.
pub(crate) fn outbox(limit: usize) -> (Outbox, Outgoing) {
    let shared = Arc::new(Shared {
        pending: Mutex::new(Pending::default()),
        ready: Notify::new(),
        limit,
        cut: AtomicBool::new(false),
        overflow: Notify::new(),
        ping_written: Mutex::new(None),
    });
    (
        Outbox {
            shared: Arc::clone(&shared),
        },
        Outgoing { shared },
    )
}

impl Outbox {
    pub fn send(&self, message: SmaToViewer) {
        if self.shared.cut.load(Ordering::Relaxed) {
            return;
        }
        let over = {
            let mut pending = self.shared.pending();
            pending.add(message);
            pending.bytes() > self.shared.limit
        };
        if over {
            self.shared.cut.store(true, Ordering::Relaxed);
            self.shared.overflow.notify_one();
        } else {
            self.shared.ready.notify_one();
        }
    }

    /// Bytes waiting for the viewer, at most (what the SMA's memory budget counts of it).
    pub fn waiting_bytes(&self) -> usize {
        self.shared.pending().bytes()
    }

    /// Drops the direct-light tiles waiting: the viewer's camera moved.
    pub fn drop_tiles(&self) {
        self.shared.pending().tiles.clear();
    }

    /// Resolves once the waiting changes have passed the bound.
    pub(crate) async fn overflowed(&self) {
        self.shared.overflow.notified().await;
    }

    /// When the writer wrote the `Ping` with this nonce, if it has.
    pub(crate) fn ping_written(&self, nonce: u64) -> Option<Instant> {
        let written = *self
            .shared
            .ping_written
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        written.and_then(|(n, at)| (n == nonce).then_some(at))
    }
}

impl Outgoing {
    /// Waits until something is waiting, then takes all of it as messages in sending order.
    pub(crate) async fn next(&self) -> Vec<SmaToViewer> {
        loop {
            self.shared.ready.notified().await;
            let messages = self.shared.pending().take_closed();
            if !messages.is_empty() {
                return messages;
            }
        }
    }

    /// Records that `message` has just been written, for the heartbeat's clock.
    pub(crate) fn written(&self, message: &SmaToViewer) {
        if let SmaToViewer::Ping { nonce } = message {
            *self
                .shared
                .ping_written
                .lock()
                .unwrap_or_else(|e| e.into_inner()) = Some((*nonce, Instant::now()));
        }
    }
}

#[cfg(test)]
mod tests;
