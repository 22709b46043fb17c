//! The pool's tile lane (DESIGN.md §3 step 8): passes over tiles of a resting viewer's camera
//! (`protocol::direct_tile`), sent to a renderer with room only while the batch backlog is
//! empty, so a new view's missing samples always go first. A tile is answered at most once, by
//! the connection that holds it; a lost renderer's tiles are dropped (the schedule asks again),
//! not re-issued: by then the camera may have moved.

use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};

use protocol::direct_tile::{TileAnswer, TileRequest};
use protocol::renderer_link::ToRenderer;

use super::{Dispatcher, PoolHandle, lock};

/// Tiles waiting for a renderer with room, in the order the schedule handed them over.
#[derive(Debug, Default)]
pub struct TileQueue {
    waiting: VecDeque<TileRequest>,
}

/// What the pool tells the schedule of a tile.
#[derive(Debug)]
pub enum TileNews {
    /// An answer that passed its `check` against the camera it was asked for.
    Answered(TileAnswer),
    /// Refused by the renderer, answered badly, or lost with its renderer: not answered.
    Dropped { tile_id: u64, reason: String },
}

/// A tile a renderer holds.
struct HeldTile {
    index: usize,
    generation: u64,
    /// The size of the image the tile lies in.
    image: (u32, u32),
}

/// The dispatcher's side of the lane.
pub struct TileLane {
    queue: Arc<Mutex<TileQueue>>,
    held: HashMap<u64, HeldTile>,
}

impl TileLane {
    pub fn new(queue: Arc<Mutex<TileQueue>>) -> TileLane {
        TileLane {
            queue,
            held: HashMap::new(),
        }
    }
}

impl PoolHandle {
    /// Queues one pass over one tile; it goes out once no batch waits and a renderer has room.
    pub fn submit_tile(&self, request: TileRequest) {
        lock(&self.tiles).waiting.push_back(request);
        self.submitted.notify_one();
    }

    /// Takes back the waiting tiles among `tile_ids` (their camera moved); those a renderer
    /// holds are answered, and their answers found stale.
    pub fn withdraw_tiles(&self, tile_ids: &[u64]) {
        lock(&self.tiles)
            .waiting
            .retain(|t| !tile_ids.contains(&t.tile_id));
    }
}

impl Dispatcher {
    /// Sends waiting tiles to renderers with room, only while the batch backlog is empty.
    pub(super) fn dispatch_tiles(&mut self) {
        loop {
            if lock(&self.backlog).len() > 0 {
                return;
            }
            let depth = self.config.depth.max(1);
            let Some((&index, _)) = self
                .links
                .iter()
                .filter(|(_, s)| s.outstanding < depth)
                .min_by_key(|(_, s)| s.outstanding)
            else {
                return;
            };
            let Some(request) = lock(&self.tiles.queue).waiting.pop_front() else {
                return;
            };
            let slot = self.links.get_mut(&index).expect("chosen among the links");
            let held = HeldTile {
                index,
                generation: slot.generation,
                image: (request.camera.width, request.camera.height),
            };
            let tile_id = request.tile_id;
            if slot
                .batches
                .try_send(ToRenderer::DirectTile(request))
                .is_err()
            {
                let generation = slot.generation;
                self.lose(index, generation, "its link task ended");
                self.tile_dropped(tile_id, "its renderer's link ended".into());
                continue;
            }
            slot.outstanding += 1;
            self.tiles.held.insert(tile_id, held);
        }
    }

    /// A renderer's answer to a tile, or its refusal; only the connection holding it may answer.
    pub(super) fn on_tile_reply(
        &mut self,
        index: usize,
        generation: u64,
        tile_id: u64,
        answer: Result<TileAnswer, String>,
    ) {
        let owned = self
            .tiles
            .held
            .get(&tile_id)
            .is_some_and(|h| h.index == index && h.generation == generation);
        if !owned {
            tracing::warn!(
                renderer = index,
                tile_id,
                "renderer answered a tile it does not hold"
            );
            return;
        }
        let held = self.tiles.held.remove(&tile_id).expect("checked above");
        if let Some(slot) = self.links.get_mut(&index) {
            slot.outstanding = slot.outstanding.saturating_sub(1);
        }
        let (width, height) = held.image;
        match answer.and_then(|a| a.check(width, height).map(|()| a)) {
            Ok(answer) => self
                .news
                .push_back(super::PoolEvent::Tile(TileNews::Answered(answer))),
            Err(reason) => {
                tracing::warn!(renderer = index, tile_id, %reason, "tile answer refused");
                self.tile_dropped(tile_id, reason);
            }
        }
    }

    /// Drops the tiles a lost connection held.
    pub(super) fn drop_tiles_of(&mut self, index: usize, generation: u64) {
        let lost: Vec<u64> = (self.tiles.held.iter())
            .filter(|(_, h)| h.index == index && h.generation == generation)
            .map(|(id, _)| *id)
            .collect();
        for tile_id in lost {
            self.tiles.held.remove(&tile_id);
            self.tile_dropped(tile_id, "its renderer was lost".into());
        }
    }

    fn tile_dropped(&mut self, tile_id: u64, reason: String) {
        let news = TileNews::Dropped { tile_id, reason };
        self.news.push_back(super::PoolEvent::Tile(news));
    }
}
