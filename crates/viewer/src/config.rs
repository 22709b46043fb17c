//! The viewer's configuration as plain values (no argument parsing here: `cli` fills it from
//! flags).

use std::path::PathBuf;

use conventions::ToneMap;

/// What a viewer connects to and shows, and, headless, which snapshots it takes.
#[derive(Clone, Debug)]
pub struct ViewerConfig {
    /// The SMA's viewer address, host:port.
    pub connect: String,
    /// Named viewpoint of the scene to start at (default: the scene's first).
    pub view: Option<String>,
    pub width: u32,
    pub height: u32,
    /// Headless: a snapshot every this many seconds, from t = 0 (the first camera sent).
    pub snapshot_every: Option<f64>,
    /// Headless: a snapshot when the SMA's sample count first reaches each of these.
    pub snapshot_at_samples: Vec<u64>,
    /// Headless: a snapshot when the run's clock first reaches each of these seconds.
    pub snapshot_at: Vec<f64>,
    /// Headless: a snapshot the first time the SMA has no shading request outstanding for the
    /// current camera.
    pub snapshot_when_idle: bool,
    /// Headless: stop after this many seconds (otherwise when every requested snapshot is taken).
    pub seconds: Option<f64>,
    /// Headless: where snapshots and snapshots.csv go.
    pub out: PathBuf,
    /// Headless: draw and write the snapshots only after the run, or once their copies fill
    /// half their memory budget, so that drawing them takes nothing from the system measured
    /// (`snapshot_files`); otherwise each is drawn as it comes, at idle priority.
    pub hold_snapshots: bool,
    /// Headless: a scripted walk (see `camera_path` for the format); t = 0 at the first camera.
    pub camera_path: Option<PathBuf>,
    pub tone_map: ToneMap,
    /// Overlay the triangle edges (the refinement mesh).
    pub wireframe: bool,
    /// Refinement criterion to ask the SMA for at start, by its name.
    pub criterion: Option<String>,
    /// Ask the SMA not to refine (visible triangles are still shaded).
    pub no_refine: bool,
    /// Print the progress line (`crate::progress`) on stdout.
    pub progress: bool,
    /// Headless: draw the panel over the PNG snapshots.
    pub overlay: bool,
    /// Headless: also draw every frame as the window would, timed, into `out`/frames.csv
    /// (`live_frames`: the viewer's frame rate while the system works).
    pub draw_frames: bool,
}
