//! The scene file (TOML): what an OBJ cannot say (DESIGN.md §7).
//!
//! ```toml
//! name = "sponza"
//! obj = "../../shared/scenes/sponza/sponza.obj"   # relative to this file
//! units = "m"
//! crease_angle_deg = 45.0
//!
//! [sun]
//! direction = [0.3, 1.0, 0.2]      # toward the sun
//! radiance = [1.6e5, 1.5e5, 1.3e5] # per channel; irradiance = radiance x solid angle
//! angular_diameter_deg = 0.53
//!
//! [sky]
//! kind = "uniform"                 # "none" | "uniform"
//! radiance = [0.6, 0.7, 1.0]
//!
//! [quality]
//! paths = 64
//! bounces = 2
//!
//! [textures]
//! enabled = false                  # the default; see `TextureSettings`
//! albedo = "kd_times_texture"      # "kd_times_texture" | "texture"
//!
//! [[viewpoint]]
//! name = "S1"
//! eye = [...]; target = [...]; up = [0, 1, 0]; fov_y_deg = 60
//! ```

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSettings {
    pub name: String,
    /// OBJ path, relative to the scene file. Empty for built-in scenes (generated in code).
    #[serde(default)]
    pub obj: String,
    #[serde(default = "default_units")]
    pub units: String,
    /// Faces meeting at more than this angle do not share a vertex (DESIGN.md §4).
    #[serde(default = "default_crease")]
    pub crease_angle_deg: f32,
    #[serde(default)]
    pub sun: Option<Sun>,
    #[serde(default)]
    pub sky: Sky,
    #[serde(default)]
    pub quality: QualitySetting,
    #[serde(default, rename = "viewpoint")]
    pub viewpoints: Vec<ViewpointSetting>,
    #[serde(default)]
    pub textures: TextureSettings,
}

/// Diffuse textures (MTL `map_Kd`, DESIGN.md §5). Part of the scene's identity: the renderer,
/// the SMA and the viewer must agree on them (the fingerprint and the handshake carry them).
///
/// Off unless a scene file turns them on, so a file written before textures keeps the figures
/// measured with it. Off, `map_Kd` is checked but not read, and every material's albedo is its
/// `Kd`; on, the cache holds illumination and the viewer multiplies the texture in per pixel.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TextureSettings {
    #[serde(default)]
    pub enabled: bool,
    #[serde(default)]
    pub albedo: AlbedoRule,
}

/// How a textured material's albedo follows from its `Kd` and its texel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlbedoRule {
    /// `Kd` × texel, as the MTL specification says.
    #[default]
    KdTimesTexture,
    /// The texel alone: for files whose exporter wrote the texture's mean colour into `Kd`,
    /// where the product would count that colour twice and come out far too dark.
    Texture,
}

impl AlbedoRule {
    /// The name a scene file gives it.
    pub fn name(self) -> &'static str {
        match self {
            AlbedoRule::KdTimesTexture => "kd_times_texture",
            AlbedoRule::Texture => "texture",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sun {
    /// Direction toward the sun (need not be unit length).
    pub direction: [f32; 3],
    /// Radiance of the sun's disc, linear RGB.
    pub radiance: [f32; 3],
    pub angular_diameter_deg: f32,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum Sky {
    #[default]
    None,
    /// Constant radiance over the upper hemisphere (+Y up); black below the horizon.
    Uniform { radiance: [f32; 3] },
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QualitySetting {
    pub paths: u32,
    /// Omitted = unbounded with Russian roulette.
    #[serde(default)]
    pub bounces: Option<u32>,
}

impl Default for QualitySetting {
    fn default() -> Self {
        QualitySetting {
            paths: 64,
            bounces: Some(2),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewpointSetting {
    pub name: String,
    pub eye: [f32; 3],
    pub target: [f32; 3],
    #[serde(default = "default_up")]
    pub up: [f32; 3],
    #[serde(default = "default_fov")]
    pub fov_y_deg: f32,
}

impl SceneSettings {
    /// Checks what serde cannot: finite numbers, a usable sun and usable viewpoints.
    pub fn validate(&self) -> Result<(), String> {
        if !(0.0..=180.0).contains(&self.crease_angle_deg) {
            return Err(format!(
                "crease_angle_deg {} is not within 0..=180",
                self.crease_angle_deg
            ));
        }
        if let Some(sun) = &self.sun {
            sun.validate()?;
        }
        if let Sky::Uniform { radiance } = &self.sky {
            check_radiance("sky radiance", radiance)?;
        }
        if self.quality.paths == 0 {
            return Err("quality.paths must be at least 1".into());
        }
        self.viewpoints
            .iter()
            .try_for_each(ViewpointSetting::validate)
    }

    pub fn viewpoint(&self, name: &str) -> Option<&ViewpointSetting> {
        self.viewpoints.iter().find(|v| v.name == name)
    }
}

impl Sun {
    /// Whether some of the disc is above the horizon (y = 0; +Y is up, DESIGN.md §7). Like the
    /// sky, the sun gives no light from below the horizon: a sun wholly under it lights nothing,
    /// and one on it lights with the part above.
    pub fn is_above_horizon(&self) -> bool {
        let d = glam::Vec3::from(self.direction).normalize_or_zero();
        let half = (0.5 * self.angular_diameter_deg).to_radians();
        d.y > -half.sin()
    }

    fn validate(&self) -> Result<(), String> {
        let d = glam::Vec3::from(self.direction);
        if !d.is_finite() || d.length_squared() == 0.0 {
            return Err(format!(
                "sun direction {:?} is not a usable direction",
                self.direction
            ));
        }
        if !(self.angular_diameter_deg > 0.0 && self.angular_diameter_deg < 180.0) {
            return Err(format!(
                "sun angular_diameter_deg {} is not within (0, 180)",
                self.angular_diameter_deg
            ));
        }
        check_radiance("sun radiance", &self.radiance)
    }
}

impl ViewpointSetting {
    fn validate(&self) -> Result<(), String> {
        let [eye, target, up] = [self.eye, self.target, self.up].map(glam::Vec3::from);
        let forward = target - eye;
        if !(eye.is_finite() && forward.is_finite() && up.is_finite()) {
            return Err(format!(
                "viewpoint {}: non-finite eye, target or up",
                self.name
            ));
        }
        if forward.length_squared() == 0.0 || forward.cross(up).length_squared() == 0.0 {
            return Err(format!(
                "viewpoint {}: eye equals target, or up is parallel to the view",
                self.name
            ));
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return Err(format!(
                "viewpoint {}: fov_y_deg {} is not within (0, 180)",
                self.name, self.fov_y_deg
            ));
        }
        Ok(())
    }
}

fn check_radiance(what: &str, rgb: &[f32; 3]) -> Result<(), String> {
    if rgb.iter().all(|c| c.is_finite() && *c >= 0.0) {
        Ok(())
    } else {
        Err(format!("{what} {rgb:?} must be finite and non-negative"))
    }
}

fn default_units() -> String {
    "m".into()
}
fn default_crease() -> f32 {
    45.0
}
fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f32 {
    60.0
}
