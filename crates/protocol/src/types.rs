//! Plain types shared by both links. Kept as arrays so the wire format stays independent of any
//! maths library (postcard writes an `f32` as 4 little-endian bytes, integers as varints).

use serde::{Deserialize, Serialize};

/// A position or direction, `[x, y, z]`.
pub type Vec3f = [f32; 3];

/// Linear RGB radiance (W·sr⁻¹·m⁻², per channel).
pub type Rgb = [f32; 3];

/// One part of a point's answer (DESIGN.md §5, "a sample is an estimate with its uncertainty"):
/// the mean RGB of the part over the point's paths and the sample variance of its luminance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PartEstimate {
    pub rgb: Rgb,
    pub luminance_variance: f32,
}

impl PartEstimate {
    /// Finite, non-negative mean and variance: anything else is refused per point.
    pub fn is_valid(&self) -> bool {
        self.rgb.iter().all(|c| c.is_finite() && *c >= 0.0)
            && self.luminance_variance.is_finite()
            && self.luminance_variance >= 0.0
    }
}

/// A point's answer in parts, each estimated from the same paths (DESIGN.md §5, "samples in
/// parts"): what is displayed is their sum. The parts are named rather than indexed so that a
/// later part (an albedo-demodulated illumination, a view-dependent part) is a new field that
/// every reader must place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SampleParts {
    /// Light arriving at the first vertex straight from the sun, the sky and emitters (next-event
    /// estimation, and the first continuation ray where it escapes to the sky or, through a
    /// mirror, meets an emitter), plus the point's own emission: sharp, never filtered.
    pub direct: PartEstimate,
    /// Everything else: light that reached the first vertex over at least one more surface.
    /// Smooth, so the SMA may filter it over neighbouring vertices (DESIGN.md §5).
    pub indirect: PartEstimate,
}

impl SampleParts {
    /// Both parts in order, for what is done to each alike.
    pub fn each(&self) -> [&PartEstimate; 2] {
        [&self.direct, &self.indirect]
    }

    /// The displayed radiance: the sum of the parts.
    pub fn rgb(&self) -> Rgb {
        std::array::from_fn(|i| self.direct.rgb[i] + self.indirect.rgb[i])
    }

    /// The luminance variance of the sum, taking the parts as uncorrelated. Within a path the two
    /// are drawn from independent numbers but for the sky, where a first continuation ray that
    /// escapes gives direct light and one that hits gives indirect light: that covariance is
    /// negative, so the sum of the variances errs on the safe side.
    pub fn luminance_variance(&self) -> f32 {
        self.direct.luminance_variance + self.indirect.luminance_variance
    }

    pub fn is_valid(&self) -> bool {
        self.each().iter().all(|p| p.is_valid())
    }

    /// A sample whose whole radiance is direct light (emitters, tests, synthetic fixtures).
    pub fn direct_only(rgb: Rgb, luminance_variance: f32) -> SampleParts {
        SampleParts {
            direct: PartEstimate {
                rgb,
                luminance_variance,
            },
            indirect: PartEstimate::default(),
        }
    }
}

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
