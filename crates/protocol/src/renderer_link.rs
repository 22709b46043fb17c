//! Messages between the SMA and a renderer (DESIGN.md §8): batches of object-space shading points
//! out, radiance back.

use serde::{Deserialize, Serialize};

use crate::direct_tile::{TileAnswer, TileRequest};
use crate::frame::WireMessage;

use crate::types::{SampleParts, Side, Vec3f};

/// Key of a cached sample: a mesh vertex (after material and crease splits) and a side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct SampleKey {
    pub vertex: u32,
    pub side: Side,
}

/// How much work one sample gets: paths and bounce depth (DESIGN.md §7, "quality as a knob").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Quality {
    pub paths: u32,
    /// Number of indirect bounces after the first hit: 0 = direct light only; `None` = unbounded,
    /// ended by Russian roulette.
    pub bounces: Option<u32>,
}

impl Quality {
    /// The cheap first sample: direct light only, a few paths (DESIGN.md §7, progressive quality).
    pub const DIRECT: Quality = Quality {
        paths: 16,
        bounces: Some(0),
    };
    /// The "interactive" preset of DESIGN.md §10: 64 paths, 2 bounces.
    pub const INTERACTIVE: Quality = Quality {
        paths: 64,
        bounces: Some(2),
    };

    /// A total order of sample quality, used to decide whether a reply upgrades a cached sample.
    pub fn rank(&self) -> (u32, u32) {
        (self.bounces.unwrap_or(u32::MAX), self.paths)
    }
}

/// One object-space point to shade: a base triangle, barycentric coordinates on it, and a side.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShadePoint {
    pub key: SampleKey,
    pub base_triangle: u32,
    /// Barycentric weights of the base triangle's vertices 1 and 2 (vertex 0 gets `1 - u - v`).
    pub bary: [f32; 2],
    pub side: Side,
    /// The eye, for view-dependent (glossy, mirror) materials; `None` for diffuse ones.
    pub eye: Option<Vec3f>,
}

/// SMA -> renderer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToRenderer {
    ShadeBatch(ShadeBatch),
    /// Polite goodbye; the renderer finishes nothing more for this link.
    Bye,
    /// A heartbeat: the renderer answers `Pong` with the same nonce at once, however busy its
    /// workers are, so a renderer that stops answering is known to be lost (DESIGN.md §2).
    Ping {
        nonce: u64,
    },
    /// One pass over one tile of a resting viewer's camera: its direct part per pixel
    /// (`direct_tile`, DESIGN.md §3 step 8).
    DirectTile(TileRequest),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShadeBatch {
    pub batch_id: u64,
    pub quality: Quality,
    /// Seed of the batch's random streams, so a batch is reproducible.
    pub seed: u64,
    pub points: Vec<ShadePoint>,
}

/// Per-point flags of a reply.
pub mod point_flags {
    /// The point lay hidden inside geometry and was moved into the visible part of its faces
    /// (the thesis's black walls, §5.2.2).
    pub const MOVED_OFF_HIDDEN: u8 = 1;
    /// The point's base triangle or coordinates were invalid; the radiance is zero.
    pub const INVALID_POINT: u8 = 2;
    /// The estimator produced a non-finite value that was discarded.
    pub const NON_FINITE_DISCARDED: u8 = 4;
    /// The point sees a view-dependent material: its sample ages as the eye moves.
    pub const VIEW_DEPENDENT: u8 = 8;
}

/// renderer -> SMA.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum FromRenderer {
    Radiance(Radiance),
    /// The renderer could not take a batch (e.g. malformed, or more batches than it holds at
    /// once); the SMA re-issues it elsewhere.
    Rejected {
        batch_id: u64,
        reason: String,
    },
    Error {
        message: String,
    },
    /// The answer to `Ping`.
    Pong {
        nonce: u64,
    },
    /// The answer to `ToRenderer::DirectTile`.
    DirectTile(TileAnswer),
    /// A tile request the renderer would not take (outside its image, too many samples).
    TileRejected {
        tile_id: u64,
        reason: String,
    },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Radiance {
    pub batch_id: u64,
    pub quality: Quality,
    /// Each point's answer in parts (direct, indirect), one per point of the batch, in order:
    /// per part the mean radiance of the point's paths and the sample variance of their
    /// luminance (Rec. 709). With `paths`, each part is an estimate with its uncertainty
    /// (DESIGN.md §5); the point's radiance is the parts' sum.
    pub parts: Vec<SampleParts>,
    /// The paths each point's estimate averages (`quality.paths`, or 0 for a point that could
    /// not be shaded).
    pub paths: Vec<u32>,
    /// One `point_flags` byte per point.
    pub flags: Vec<u8>,
    /// Renderer-side time for the batch, microseconds (for the cost figures of §5.4).
    pub micros: u64,
}

impl WireMessage for ToRenderer {}

impl WireMessage for FromRenderer {}
