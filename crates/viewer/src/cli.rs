//! Command line of the viewer (also `walkthrough viewer …`, which embeds [`Cli`]): the only module
//! of the library that knows clap; it turns flags into a [`ViewerConfig`].

use std::path::PathBuf;

use conventions::ToneMap;

use crate::config::ViewerConfig;

/// `--tonemap`: the operators of `conventions::tone_map`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToneMapFlag {
    /// Drago's logarithmic mapping, eq. 4.2.
    Drago,
    /// Reinhard's global operator, eq. 4.1.
    Reinhard,
}

impl From<ToneMapFlag> for ToneMap {
    fn from(flag: ToneMapFlag) -> ToneMap {
        match flag {
            ToneMapFlag::Drago => ToneMap::Drago,
            ToneMapFlag::Reinhard => ToneMap::Reinhard,
        }
    }
}

#[derive(clap::Parser, Clone, Debug)]
#[command(
    name = "viewer",
    about = "Thin viewer: shows the SMA's triangles with Gouraud shading, in a window or headless",
    long_about = "Thin viewer: shows the triangles the Shading Management Agent (SMA) sends, with \
                  Gouraud shading and tone mapping under the scene's sky, in a window (with a \
                  panel of what the system is doing; H hides it) or headless, writing snapshots.",
    after_help = "Renderer, SMA and viewers on several machines: see \"Running on three machines \
                  of a LAN\" in the README."
)]
pub struct Cli {
    /// The SMA's viewer address, host:port (the SMA prints it as `listening on`).
    #[arg(long)]
    pub connect: String,
    /// Draw offscreen and write snapshots instead of opening a window.
    #[arg(long)]
    pub headless: bool,
    /// Named viewpoint of the scene to start at (default: the scene's first).
    #[arg(long)]
    pub view: Option<String>,
    /// Image width in pixels (the window's, or the snapshots').
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Headless: a snapshot every this many seconds, from t = 0 (the first camera sent); with
    /// `--snapshot-at-samples` as well, both kinds in one run.
    #[arg(long)]
    pub snapshot_every: Option<f64>,
    /// Headless: a snapshot when the SMA's sample count first reaches each of these.
    #[arg(long, value_delimiter = ',')]
    pub snapshot_at_samples: Vec<u64>,
    /// Headless: a snapshot when the run's clock (t = 0 at the first camera) first reaches each
    /// of these seconds, e.g. the stops of a `--camera-path`.
    #[arg(long, value_delimiter = ',')]
    pub snapshot_at: Vec<f64>,
    /// Headless: a snapshot the first time the SMA has no shading request outstanding for the
    /// current camera.
    #[arg(long)]
    pub snapshot_when_idle: bool,
    /// Headless: stop after this many seconds (otherwise when every requested snapshot is taken).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Headless: where snapshots and snapshots.csv go.
    #[arg(long, default_value = "snapshots")]
    pub out: PathBuf,
    /// Headless: draw and write the snapshots only after the run (or once their copies fill
    /// 512 MiB), so that drawing them takes nothing from the system measured; otherwise each is
    /// drawn as it comes, at idle priority.
    #[arg(long)]
    pub hold_snapshots: bool,
    /// Headless: a scripted walk (see `camera_path` for the format); t = 0 at the first camera.
    #[arg(long)]
    pub camera_path: Option<PathBuf>,
    /// Tone-mapping operator at start (T switches it in the window).
    #[arg(long, value_enum, default_value_t = ToneMapFlag::Drago)]
    pub tonemap: ToneMapFlag,
    /// Overlay the triangle edges (the refinement mesh).
    #[arg(long)]
    pub wireframe: bool,
    /// Refinement criterion to ask the SMA for at start.
    #[arg(long)]
    pub criterion: Option<String>,
    /// Ask the SMA not to refine (visible triangles are still shaded).
    #[arg(long)]
    pub no_refine: bool,
    /// Print a `progress samples=… samples_per_sec=… shown=… state=…` line on stdout twice a
    /// second, for a parent process that shows it (the launcher's progress bar).
    #[arg(long)]
    pub progress: bool,
    /// Headless: draw the window's panel over the PNG snapshots (they are clean otherwise).
    #[arg(long, requires = "headless")]
    pub overlay: bool,
    /// Headless: also draw every frame at the current camera as the window would (at most 60 a
    /// second), timed, into frames.csv beside the snapshots: the frame rate while the system
    /// works.
    #[arg(long, requires = "headless")]
    pub draw_frames: bool,
}

/// Runs the viewer until the window closes or the headless run ends.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    conventions::logging::init();
    anyhow::ensure!(
        cli.width > 0 && cli.height > 0,
        "--width and --height must be positive"
    );
    let headless = cli.headless;
    let config = cli.config();
    if headless {
        crate::headless::run(&config)
    } else {
        crate::window::run(&config)
    }
}

impl Cli {
    /// The configuration these flags ask for.
    pub(crate) fn config(self) -> ViewerConfig {
        ViewerConfig {
            connect: self.connect,
            view: self.view,
            width: self.width,
            height: self.height,
            snapshot_every: self.snapshot_every,
            snapshot_at_samples: self.snapshot_at_samples,
            snapshot_at: self.snapshot_at,
            snapshot_when_idle: self.snapshot_when_idle,
            hold_snapshots: self.hold_snapshots,
            seconds: self.seconds,
            out: self.out,
            camera_path: self.camera_path,
            tone_map: self.tonemap.into(),
            wireframe: self.wireframe,
            criterion: self.criterion,
            no_refine: self.no_refine,
            progress: self.progress,
            overlay: self.overlay,
            draw_frames: self.draw_frames,
        }
    }
}
