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
    about = "Thin viewer: shows the SMA's triangles with Gouraud shading, in a window or headless"
)]
pub struct Cli {
    /// The SMA's viewer address, host:port.
    #[arg(long)]
    pub connect: String,
    /// Draw offscreen and write snapshots instead of opening a window.
    #[arg(long)]
    pub headless: bool,
    /// Named viewpoint of the scene to start at (default: the scene's first).
    #[arg(long)]
    pub view: Option<String>,
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Headless: a snapshot every this many seconds, from t = 0 (the first camera sent).
    #[arg(long, conflicts_with = "snapshot_at_samples")]
    pub snapshot_every: Option<f64>,
    /// Headless: a snapshot when the SMA's sample count first reaches each of these.
    #[arg(long, value_delimiter = ',')]
    pub snapshot_at_samples: Vec<u64>,
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
    /// Headless: a scripted walk (see `camera_path` for the format); t = 0 at the first camera.
    #[arg(long)]
    pub camera_path: Option<PathBuf>,
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
}

/// Runs the viewer until the window closes or the headless run ends.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .try_init();
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
    pub fn config(self) -> ViewerConfig {
        ViewerConfig {
            connect: self.connect,
            view: self.view,
            width: self.width,
            height: self.height,
            snapshot_every: self.snapshot_every,
            snapshot_at_samples: self.snapshot_at_samples,
            snapshot_when_idle: self.snapshot_when_idle,
            seconds: self.seconds,
            out: self.out,
            camera_path: self.camera_path,
            tone_map: self.tonemap.into(),
            wireframe: self.wireframe,
            criterion: self.criterion,
            no_refine: self.no_refine,
        }
    }
}
