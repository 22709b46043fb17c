//! The command line of the launcher, the only module of this package that knows clap: each flag
//! set is turned into the plain configuration its module takes. Each process crate's own command
//! line is embedded whole, so `walkthrough renderer …` is exactly `renderer …`, and tests start
//! real separate processes from one binary.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::launch::LaunchConfig;

#[derive(Parser, Debug)]
#[command(
    name = "walkthrough",
    version,
    about = "Interactive walkthroughs with progressive global illumination",
    long_about = "Interactive walkthroughs with progressive global illumination. Without a \
                  subcommand, runs a renderer, the SMA and a viewer on this machine: in a window \
                  when a display is there, else headless, writing snapshots.",
    after_help = "Renderer, SMA and viewers on several machines: see \"Running on three machines \
                  of a LAN\" in the README.",
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    /// With no subcommand: run renderer(s), SMA and viewer on loopback.
    #[command(flatten)]
    pub launch: LaunchArgs,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// The path-tracing renderer service (`serve`) and reference images (`reference`).
    Renderer(renderer::cli::Cli),
    /// The Shading Management Agent.
    Sma(sma::cli::Cli),
    /// The viewer, in a window or headless.
    Viewer(viewer::cli::Cli),
    /// Scene tools.
    #[command(subcommand)]
    Scene(SceneCommand),
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        None => {
            conventions::logging::init();
            crate::launch::run(cli.launch.config())
        }
        Some(Command::Renderer(c)) => renderer::cli::run(c),
        Some(Command::Sma(c)) => sma::cli::run(c),
        Some(Command::Viewer(c)) => viewer::cli::run(c),
        Some(Command::Scene(SceneCommand::Info {
            scene,
            width,
            height,
        })) => crate::scene_cmd::info(&scene, width, height),
        Some(Command::Scene(SceneCommand::Export { builtin, dir })) => {
            crate::scene_cmd::export(&builtin, &dir)
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct LaunchArgs {
    /// Scene: a TOML file or a built-in name.
    #[arg(long, default_value = "bracara")]
    pub scene: String,
    /// Viewpoint to start at (default: the scene's first).
    #[arg(long)]
    pub view: Option<String>,
    /// Refinement criterion (rnd, nld-is, nld-os, …).
    #[arg(long, default_value = "nld-os")]
    pub criterion: String,
    /// Number of renderer processes; the cores are shared among them.
    #[arg(long, default_value_t = 1)]
    pub renderers: usize,
    /// Image width in pixels (window or snapshots).
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Stop after this many seconds (headless default: 20; a window runs until closed).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Run headless even when a display is there.
    #[arg(long)]
    pub headless: bool,
    /// Where headless snapshots go (default: out/run-<unix time>).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl LaunchArgs {
    fn config(self) -> LaunchConfig {
        LaunchConfig {
            scene: self.scene,
            view: self.view,
            criterion: self.criterion,
            renderers: self.renderers,
            width: self.width,
            height: self.height,
            seconds: self.seconds,
            headless: self.headless,
            out: self.out,
        }
    }
}

#[derive(Subcommand, Debug)]
pub enum SceneCommand {
    /// Triangles, vertices, materials, bounds, dropped triangles, effects, fingerprint, and the
    /// visible base triangles per viewpoint.
    Info {
        /// A scene TOML file or a built-in name (bracara, cornell).
        scene: String,
        /// Image size for the per-viewpoint visibility estimate.
        #[arg(long, default_value_t = 1024)]
        width: u32,
        #[arg(long, default_value_t = 768)]
        height: u32,
    },
    /// Writes a built-in scene as OBJ + MTL + TOML.
    Export { builtin: String, dir: PathBuf },
}
