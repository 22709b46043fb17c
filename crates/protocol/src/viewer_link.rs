//! Messages between the SMA and a viewer (DESIGN.md §8). The viewer holds a table
//! `triangle id -> 3 positions + 3 radiances`; the SMA keeps it in step with the visible set.

use serde::{Deserialize, Serialize};

use crate::direct_tile::ViewerTile;
use crate::frame::WireMessage;
use crate::renderer_link::Quality;
use crate::texture::{MaterialLook, Texcoords, TextureImage, TextureInfo};

use crate::types::{Bounds, Fingerprint, Rgb, Vec3f, Viewpoint};

/// The id of a shown triangle: a leaf of the subdivision mesh and the side facing the eye
/// (the visible set is keyed by (leaf, side), DESIGN.md §5). The SMA packs it; the viewer treats it
/// as opaque.
pub type TriangleId = u64;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShownTriangle {
    pub id: TriangleId,
    pub positions: [Vec3f; 3],
    /// Index into `SceneInfo::materials`: whose albedo (`kd`, texture) multiplies the
    /// illumination, per pixel.
    pub material: u16,
    /// Per corner, the texture coordinates of the material's texture (zero without one).
    pub texcoords: Texcoords,
    pub shading: CornerShading,
}

/// What a shown triangle's corners are lit with (DESIGN.md §5, "Parts, and textures"): the
/// viewer displays `albedo(pixel) × illumination + view_dependent`, each interpolated.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CornerShading {
    /// Per vertex the displayed diffuse illumination, direct + indirect, without the albedo.
    pub illumination: [Rgb; 3],
    /// Per vertex the direct part's share of `illumination` ([`DirectShare`]): a viewer that
    /// draws per-pixel direct light (`direct_tile`) subtracts it there.
    pub direct_share: [DirectShare; 3],
    /// Per vertex the view-dependent radiance (glossy and mirror lobes, emission), added as it
    /// is; `None` where all three are zero, as for nearly every diffuse triangle.
    pub view_dependent: Option<[Rgb; 3]>,
}

impl CornerShading {
    /// Per vertex the radiance shown at a point of albedo `albedo[k]`.
    pub fn radiance(&self, albedo: [Rgb; 3]) -> [Rgb; 3] {
        std::array::from_fn(|k| {
            let view_dependent = self.view_dependent.map_or([0.0; 3], |v| v[k]);
            std::array::from_fn(|c| albedo[k][c] * self.illumination[k][c] + view_dependent[c])
        })
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Recolour {
    pub id: TriangleId,
    pub shading: CornerShading,
}

/// The share of a vertex's displayed illumination that is its direct part, by luminance, in
/// 255ths: one byte on the wire (DESIGN.md §3 step 8). The direct part is taken to have the
/// illumination's colour; a viewer drawing a tile's per-pixel direct light in its place keeps
/// `illumination × (1 − share)` of the vertex's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DirectShare(pub u8);

impl DirectShare {
    /// `direct` of `total` (RGB): 0 where the total is black, at most the whole.
    pub fn of(direct: Rgb, total: Rgb) -> DirectShare {
        let (d, t) = (
            conventions::luminance(direct),
            conventions::luminance(total),
        );
        let share = if t > 0.0 && d.is_finite() && t.is_finite() {
            (d / t).clamp(0.0, 1.0)
        } else {
            0.0
        };
        DirectShare((share * 255.0).round() as u8)
    }

    /// The share as a fraction, 0..=1.
    pub fn fraction(self) -> f32 {
        f32::from(self.0) / 255.0
    }
}

/// A viewer sends at most one camera per this interval (DESIGN.md §3 step 1: every camera
/// restarts the SMA's visibility passes). Two cameras that reach the SMA closer together were
/// read in one turn of its loop, not taken that close.
pub const CAMERA_INTERVAL: std::time::Duration = std::time::Duration::from_millis(50);

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Increases with every camera change of this viewer.
    pub seq: u64,
    pub eye: Vec3f,
    /// Unit quaternion `[x, y, z, w]` rotating the camera frame (looking down -Z, Y up) into the world.
    pub orientation: [f32; 4],
    /// Vertical field of view, degrees.
    pub fov_y_deg: f32,
    pub width: u32,
    pub height: u32,
}

/// The SMA's counters at the close of one consistent update.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Epoch {
    /// The camera this update answers.
    pub camera_seq: u64,
    /// Triangles the viewer holds after this update.
    pub shown: u64,
    /// Visible leaves (with side) for this camera, shaded or not.
    pub visible_leaves: u64,
    /// Triangles inserted and removed since the previous epoch (Δins, Δrem).
    pub inserted: u64,
    pub removed: u64,
    /// Samples computed so far (all viewers).
    pub samples: u64,
    /// Paths traced for those samples so far: the cost of the picture, as samples of different
    /// rungs of the quality ladder cost different numbers of paths (DESIGN.md §5, §10).
    pub paths: u64,
    /// What keeps this picture from being final: shade requests not yet answered, visible
    /// leaves not shown yet for lack of samples, and triangles a walking viewer still holds
    /// from earlier views; zero when the picture is complete.
    pub outstanding: u64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    pub samples_per_sec: f32,
    pub paths_per_sec: f32,
    /// Share of the last interval during which the renderers had a batch in hand (the mean over
    /// the connected renderers, 0..1): how much of the rest time went to shading (DESIGN.md §3).
    pub renderer_busy: f32,
    pub leaves: u64,
    pub cached_samples: u64,
    pub renderers: u32,
    /// Every viewer's view is at its stated end (DESIGN.md §5): each visible sample's displayed
    /// standard error is below the threshold or at the ladder's cap, and the criterion finds
    /// nothing to subdivide. Nothing more is computed until a camera moves.
    pub converged: bool,
    /// Renderer answers rejected so far (NaN, infinite or negative radiance or variance, no
    /// paths): never cached nor shown, asked for again.
    pub rejected_points: u64,
    /// What the SMA's own structures hold, by part.
    pub memory: SmaMemory,
    /// How the subdivision mesh is shaped and what reshaped it.
    pub mesh: MeshShape,
}

/// The SMA's memory by part, counted by capacity (what is allocated, not what is used), against
/// its budget (`--memory-mib`), with the process's resident memory beside it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SmaMemory {
    /// The subdivision mesh's nodes, with the base triangles' adjacency.
    pub nodes_bytes: u64,
    /// The mesh's vertices and their welded points.
    pub vertices_bytes: u64,
    /// The mesh's tables of split edges and seam midpoints.
    pub edge_tables_bytes: u64,
    /// The shading cache.
    pub cache_bytes: u64,
    /// Per-viewer state: views, shown sets, targets, and what waits in each outbox.
    pub viewers_bytes: u64,
    /// What the parts above may hold together.
    pub budget_bytes: u64,
    /// The SMA process's resident memory (`/proc/self/statm`), where the system says it.
    pub rss_bytes: Option<u64>,
    /// The current views alone need more than the budget: refinement has stopped.
    pub memory_bound: bool,
}

impl SmaMemory {
    /// The subdivision mesh: nodes, vertices, edge and midpoint tables.
    pub fn mesh_bytes(&self) -> u64 {
        self.nodes_bytes + self.vertices_bytes + self.edge_tables_bytes
    }

    /// Every accounted part: what the budget bounds.
    pub fn accounted_bytes(&self) -> u64 {
        self.mesh_bytes() + self.cache_bytes + self.viewers_bytes
    }
}

/// The subdivision mesh's shape (thesis §4.2; DESIGN.md §4), to compare neighbour rules and
/// merging by what they make.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshShape {
    /// The smallest interior angle of a leaf a split made, degrees; `None` before any split.
    pub smallest_split_angle_deg: Option<f32>,
    /// The smallest ratio of such a leaf's smallest angle to its base triangle's.
    pub smallest_split_angle_ratio: Option<f32>,
    /// Refinement steps whose thesis neighbour rule reached its bound on propagation (zero
    /// under red–green closure).
    pub neighbour_bound_hits: u64,
    /// Parents merged back because their children's shading was uniform, since the start.
    pub uniform_merges: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneInfo {
    pub name: String,
    pub fingerprint: Fingerprint,
    pub bounds: Bounds,
    pub viewpoints: Vec<Viewpoint>,
    /// Criteria the SMA offers, the active one first.
    pub criteria: Vec<String>,
    /// What a ray that meets no geometry sees, so the viewer draws it behind the triangles
    /// (DESIGN.md §7: the renderer's sky and sun).
    pub sky: SkyInfo,
    /// The quality the scene's samples aim at (paths per sample, bounce depth; DESIGN.md §7).
    pub quality: Quality,
    /// Whether the scene's textures are on (DESIGN.md §5): part of the scene's identity, which
    /// the SMA and its renderers have agreed on at their handshake.
    pub textures: bool,
    /// Each scene material's albedo, by the index a `ShownTriangle` names.
    pub materials: Vec<MaterialLook>,
    /// The textures the materials use (none with textures off), each sent next as a
    /// `SmaToViewer::Texture`.
    pub texture_table: Vec<TextureInfo>,
}

/// The scene's sky as the renderer lights with it: radiance over the upper hemisphere (+Y up,
/// black below the horizon) and an optional sun disc.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SkyInfo {
    /// Linear RGB radiance of the upper hemisphere; zero for a scene without a sky.
    pub radiance: Rgb,
    pub sun: Option<SunInfo>,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SunInfo {
    /// Unit direction toward the sun.
    pub direction: Vec3f,
    /// Linear RGB radiance of the disc.
    pub radiance: Rgb,
    /// Angular diameter of the disc, degrees.
    pub angular_diameter_deg: f32,
}

/// viewer -> SMA.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ViewerToSma {
    Camera(Camera),
    SetCriterion {
        name: String,
    },
    /// Stop refining (shading of what is visible goes on).
    Pause,
    Resume,
    Bye,
    /// The answer to `Ping`, sent by the viewer's link at once, whatever its front end is doing.
    Pong {
        nonce: u64,
    },
}

/// SMA -> viewer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum SmaToViewer {
    /// Boxed: it is by far the largest message, and every other one would take its size.
    SceneInfo(Box<SceneInfo>),
    Insert {
        #[serde(with = "crate::preallocated")]
        triangles: Vec<ShownTriangle>,
    },
    Remove {
        ids: Vec<TriangleId>,
    },
    /// Better radiance for triangles the viewer already shows (not counted in Δins/Δrem).
    Update {
        #[serde(with = "crate::preallocated")]
        triangles: Vec<Recolour>,
    },
    ToneMap {
        l_white: f32,
    },
    /// Closes one consistent update: the viewer draws only what an epoch closed.
    Epoch(Epoch),
    Stats(Stats),
    /// The active criterion and whether refinement is paused, after `SetCriterion`/`Pause`/`Resume`.
    Refinement {
        criterion: String,
        paused: bool,
    },
    Error {
        message: String,
    },
    /// A heartbeat (DESIGN.md §8): a viewer answers `Pong` with the same nonce; one that does not
    /// within the SMA's silence limit is lost. A viewer hears the SMA at least this often, so a
    /// silent SMA is lost too.
    Ping {
        nonce: u64,
    },
    /// The latest accumulation of one tile of the viewer's resting camera: its direct part per
    /// pixel, which the viewer shows instead of the vertices' where it is the better estimate
    /// (`direct_tile`, DESIGN.md §3 step 8). Tiles of an older camera are stale.
    DirectTile(ViewerTile),
    /// One texture of `SceneInfo::texture_table`, sent once per viewer right after `SceneInfo`
    /// (before any `Insert`).
    Texture(TextureImage),
}

impl WireMessage for ViewerToSma {}

impl WireMessage for SmaToViewer {}
