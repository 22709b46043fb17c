//! The viewer (DESIGN.md §2, §8, §9; thesis §2.3, §4.1): a thin wgpu client that holds the SMA's
//! visible triangles, draws them with Gouraud-interpolated vertex illumination times each pixel's
//! albedo (textures included) and tone mapping, and
//! sends the camera back. It has no scene of its own: it learns the scene from `SceneInfo`.
//!
//! - [`table`]: triangle table, O(1) insert/remove/recolour; [`vertex_buffer`]: its GPU copy,
//!   patched with partial uploads and a compute scatter;
//! - [`update`]: changes held back until the `Epoch` that closes them;
//! - [`direct_image`]: the resting camera's per-pixel direct tiles; [`direct_texture`]: their GPU
//!   copy, which the drawing pass shows in place of the vertices' direct part;
//! - [`looks`]: the scene's materials and decoded textures, each pixel's albedo; [`looks_texture`]:
//!   their GPU copy, a material table and a mipmapped texture array;
//! - [`link`]: the SMA connection with reconnect and backoff; [`view_state`] follows its events;
//! - [`draw`] (with `draw.wgsl`): the pass with tone mapping (`conventions::tone_map`, held to
//!   the shader by a test); [`offscreen`]: the same pass into textures, read back;
//! - [`progress`]: the one-line progress a parent process shows (`--progress`);
//! - [`panel`] (egui, drawn by `overlay`): what the system does, the keys, buttons for them;
//! - [`window`] (winit) and [`headless`] (snapshots: copied at their instant, drawn later by
//!   [`snapshot_painter`] on [`snapshot_files`]' idle writer thread; `--draw-frames` also draws
//!   and times the window's frames, [`live_frames`]) front ends, with
//!   [`walk_camera`], [`camera_path`], [`camera_sender`] and [`session`];
//! - [`gpu`]: device setup and the `WALKTHROUGH_REQUIRE_GPU` rule;
//! - [`config`]: the viewer's configuration, plain values;
//! - [`cli`]: the command line, embedded by the launcher as `walkthrough viewer`, the only module
//!   that parses arguments.

pub(crate) mod camera_path;
pub(crate) mod camera_sender;
pub mod cli;
pub(crate) mod config;
pub mod direct_image;
pub mod direct_texture;
pub mod draw;
pub mod gpu;
pub(crate) mod headless;
pub mod link;
pub mod live_frames;
pub mod looks;
pub mod looks_texture;
pub mod offscreen;
pub(crate) mod overlay;
pub mod panel;
pub mod progress;
pub(crate) mod session;
pub(crate) mod snapshot_files;
pub(crate) mod snapshot_painter;
pub mod table;
pub mod update;
pub mod vertex_buffer;
pub mod view_state;
pub(crate) mod walk_camera;
pub mod window;

pub use conventions::ToneMap;
pub use draw::DrawSettings;
pub use offscreen::{
    Snapshot, render_offscreen_with, render_offscreen_with_direct, render_offscreen_with_looks,
};
