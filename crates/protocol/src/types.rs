//! Plain types shared by both links. Kept as arrays so the wire format stays independent of any
//! maths library (postcard writes an `f32` as 4 little-endian bytes, integers as varints).

use serde::{Deserialize, Serialize};

/// A position or direction, `[x, y, z]`.
pub type Vec3f = [f32; 3];

/// Linear RGB radiance (W·sr⁻¹·m⁻², per channel).
pub type Rgb = [f32; 3];

/// A 256-bit scene fingerprint (BLAKE3 of scene file, geometry and materials, and with textures
/// on, of the textures and their coordinates).
pub type Fingerprint = [u8; 32];

/// Which scene a process has loaded, as the handshake compares it (DESIGN.md §8): its
/// fingerprint, and whether its textures are on (DESIGN.md §5). The fingerprint covers the
/// textures setting too; it travels beside it so that a refusal can say which one differs, and
/// renderer, SMA and viewer never disagree on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneIdentity {
    pub fingerprint: Fingerprint,
    pub textures: bool,
}

/// Which side of a surface, relative to its vertex's canonical normal (DESIGN.md §5): surfaces are
/// two-sided, so a vertex seen from both sides carries one sample per side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Side {
    Front,
    Back,
}

impl Side {
    /// The other side.
    pub fn flipped(self) -> Side {
        match self {
            Side::Front => Side::Back,
            Side::Back => Side::Front,
        }
    }

    /// +1 for the front, -1 for the back: the sign to apply to the canonical normal.
    pub fn sign(self) -> f32 {
        match self {
            Side::Front => 1.0,
            Side::Back => -1.0,
        }
    }
}

/// Axis-aligned bounds of a scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub min: Vec3f,
    pub max: Vec3f,
}

/// A named viewpoint of a scene (the thesis's MC, VR, VT…).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viewpoint {
    pub name: String,
    pub eye: Vec3f,
    pub target: Vec3f,
    pub up: Vec3f,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
}
