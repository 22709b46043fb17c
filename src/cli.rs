//! The command line of the launcher, the only module of this package that knows clap: each flag
//! set is turned into the plain configuration its module takes. Each process crate's own command
//! line is embedded whole, so `walkthrough renderer …` is exactly `renderer …`, and tests start
//! real separate processes from one binary.

use std::path::PathBuf;

use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use sma::config::Profile;

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
    /// The Shading Management Agent (boxed: its flags outweigh the other commands' many times).
    Sma(Box<sma::cli::Cli>),
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
            crate::launch::run(cli.launch.config()?)
        }
        Some(Command::Renderer(c)) => renderer::cli::run(c),
        Some(Command::Sma(c)) => sma::cli::run(*c),
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
    #[arg(long, default_value = "bracara-textured")]
    pub scene: String,
    /// Viewpoint to start at (default: the scene's first).
    #[arg(long)]
    pub view: Option<String>,
    /// Refinement criterion (rnd, nld-is, nld-os, nld-px, …) [default: nld-px, the best
    /// measured; nld-os-thesis under --profile thesis].
    #[arg(long)]
    pub criterion: Option<String>,
    /// Which system the SMA runs: today's, or the thesis's as published (2006; see `walkthrough
    /// sma --help`). Under it nld-os and nld-is run as their -thesis forms, and nld-px is refused.
    #[arg(long, default_value_t = Profile::Today, value_parser = profile_parser())]
    pub profile: Profile,
    /// The SMA's object-space filter of the indirect light (on|off), passed on as
    /// `--indirect-filter` [default: on, off under `--profile thesis`].
    #[arg(long, value_parser = on_off())]
    pub indirect_filter: Option<bool>,
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
    /// Start from an empty cache and keep nothing: without it the SMA keeps the mesh and the
    /// samples in one file per scene under the user's cache directory
    /// (`$XDG_CACHE_HOME/walkthrough/` or `~/.cache/walkthrough/`; delete it to start afresh).
    #[arg(long)]
    pub no_cache_file: bool,
}

/// `--profile`: one of the SMA's profiles, by name.
fn profile_parser() -> impl TypedValueParser<Value = Profile> {
    let names: Vec<&str> = Profile::ALL.iter().map(|p| p.name()).collect();
    PossibleValuesParser::new(names)
        .map(|name| Profile::from_name(&name).expect("a possible value"))
}

/// `on` or `off`.
fn on_off() -> impl TypedValueParser<Value = bool> {
    PossibleValuesParser::new(["on", "off"]).map(|value| value == "on")
}

impl LaunchArgs {
    /// Refused here, before any process starts: a criterion the profile does not run.
    fn config(self) -> anyhow::Result<LaunchConfig> {
        let criterion = match self.criterion {
            Some(name) => self.profile.criterion_named(&name)?,
            None => self.profile.default_criterion(),
        };
        Ok(LaunchConfig {
            scene: self.scene,
            view: self.view,
            criterion: criterion.name().to_string(),
            profile: self.profile,
            indirect_filter: self.indirect_filter,
            renderers: self.renderers,
            width: self.width,
            height: self.height,
            seconds: self.seconds,
            headless: self.headless,
            out: self.out,
            cache_dir: if self.no_cache_file {
                None
            } else {
                crate::launch::user_cache_dir()
            },
        })
    }
}

#[derive(Subcommand, Debug)]
pub enum SceneCommand {
    /// Triangles, vertices, materials, bounds, dropped triangles, effects, fingerprint, and the
    /// visible base triangles per viewpoint.
    Info {
        /// A scene TOML file or a built-in name (bracara, bracara-textured, cornell).
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

#[cfg(test)]
mod tests {
    use super::*;

    fn launch(args: &[&str]) -> anyhow::Result<LaunchConfig> {
        let args = std::iter::once("walkthrough").chain(args.iter().copied());
        Cli::try_parse_from(args)?.launch.config()
    }

    #[test]
    fn the_profile_goes_to_the_sma_and_refuses_what_it_does_not_run() {
        let today = launch(&[]).unwrap();
        assert_eq!(
            (today.profile, today.criterion.as_str()),
            (Profile::Today, "nld-px")
        );
        let thesis = launch(&["--profile", "thesis", "--criterion", "nld-os"]).unwrap();
        assert_eq!(
            (thesis.profile, thesis.criterion.as_str()),
            (Profile::Thesis, "nld-os-thesis")
        );
        let thesis_default = launch(&["--profile", "thesis"]).unwrap();
        assert_eq!(thesis_default.criterion, "nld-os-thesis");
        assert!(launch(&["--profile", "thesis", "--criterion", "nld-px"]).is_err());
        assert!(launch(&["--criterion", "nld-px"]).is_ok());
        assert!(launch(&["--criterion", "nope"]).is_err());
        assert!(launch(&["--profile", "2006"]).is_err());
    }

    #[test]
    fn the_indirect_filter_flag_is_passed_on_only_when_given() {
        assert_eq!(launch(&[]).unwrap().indirect_filter, None);
        let off = launch(&["--indirect-filter", "off"]).unwrap();
        assert_eq!(off.indirect_filter, Some(false));
        assert_eq!(
            crate::launch::indirect_filter_args(&off),
            ["--indirect-filter", "off"]
        );
        assert!(crate::launch::indirect_filter_args(&launch(&[]).unwrap()).is_empty());
        assert!(launch(&["--indirect-filter", "yes"]).is_err());
    }
}
