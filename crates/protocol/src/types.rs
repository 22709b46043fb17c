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
/// parts"). The diffuse parts are **illumination**: the paths leave out the first vertex's
/// albedo, which multiplies them where they are displayed (the albedo at the shading point, a
/// texel or `Kd`); what the point's glossy or mirror lobe reflects, and its own emission, stay
/// radiance and are added on top ([`SampleParts::radiance`]). The parts are named rather than
/// indexed so that a later part is a new field that every reader must place.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SampleParts {
    /// Illumination arriving at the first vertex straight from the sun, the sky and emitters
    /// (next-event estimation, and the first diffuse continuation ray where it escapes to the
    /// sky): sharp, never filtered.
    pub direct: PartEstimate,
    /// Illumination that reached the first vertex over at least one more surface. Smooth, so
    /// the SMA may filter it over neighbouring vertices (DESIGN.md §5).
    pub indirect: PartEstimate,
    /// Radiance toward the eye that depends on where the eye is (the first vertex's glossy or
    /// mirror lobe, whatever it reflects), plus the point's own emission: never multiplied by
    /// an albedo, never filtered.
    pub view_dependent: PartEstimate,
}

impl SampleParts {
    /// The parts in order, for what is done to each alike.
    pub fn each(&self) -> [&PartEstimate; 3] {
        [&self.direct, &self.indirect, &self.view_dependent]
    }

    /// The radiance the parts stand for at a point of diffuse albedo `albedo` (linear RGB):
    /// `albedo × (direct + indirect) + view_dependent`.
    pub fn radiance(&self, albedo: Rgb) -> Rgb {
        std::array::from_fn(|i| {
            albedo[i] * (self.direct.rgb[i] + self.indirect.rgb[i]) + self.view_dependent.rgb[i]
        })
    }

    pub fn is_valid(&self) -> bool {
        self.each().iter().all(|p| p.is_valid())
    }

    /// A sample whose whole value is direct illumination (tests, synthetic fixtures).
    pub fn direct_only(rgb: Rgb, luminance_variance: f32) -> SampleParts {
        SampleParts {
            direct: PartEstimate {
                rgb,
                luminance_variance,
            },
            ..SampleParts::default()
        }
    }

    /// A sample whose whole value is radiance, shown as it is whatever the albedo (emitters, a
    /// fake renderer's answers).
    pub fn radiance_only(rgb: Rgb, luminance_variance: f32) -> SampleParts {
        SampleParts {
            view_dependent: PartEstimate {
                rgb,
                luminance_variance,
            },
            ..SampleParts::default()
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
