//! Command line: `renderer serve …` and `renderer reference …` (the launcher embeds [`Cli`] as
//! `walkthrough renderer …`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Parser, Subcommand};
use protocol::admission::PortLimits;
use protocol::frame::DEFAULT_MAX_FRAME;
use tokio::net::TcpListener;

use crate::bvh::Traversal;
use crate::estimator::Estimator;
use crate::reference::{ReferenceSettings, render_to_files};
use crate::service::{DEFAULT_MAX_BATCHES, Service, default_liveness};
use crate::vector_level::{self, VectorLevel};
use crate::world::World;

#[derive(Parser, Debug, Clone)]
#[command(
    name = "renderer",
    about = "Path-tracing service for object-space shading requests, and reference images",
    after_help = "Renderer, SMA and viewers on several machines: see \"Running on three machines \
                  of a LAN\" in the README."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug, Clone)]
pub enum Command {
    /// Answer shade batches from SMAs over TCP until Ctrl-C.
    Serve {
        /// Scene file (TOML) or built-in name ("bracara", "bracara-textured", "cornell").
        #[arg(long, default_value = "bracara")]
        scene: String,
        /// Address to listen on; port 0 picks a free port (the line "listening on ADDR" on
        /// stdout tells which).
        #[arg(long, default_value = "127.0.0.1:7201")]
        listen: String,
        /// Worker threads (0 = one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Largest frame accepted or sent, bytes.
        #[arg(long, default_value_t = DEFAULT_MAX_FRAME)]
        max_frame: usize,
        /// SMAs served at once; one past this is refused (DESIGN.md §8).
        #[arg(long, default_value_t = PortLimits::default().max_connections)]
        max_connections: usize,
        /// An SMA that has not completed its handshake within this many milliseconds is closed.
        #[arg(long, default_value_t = PortLimits::default().handshake_deadline.as_millis() as u64)]
        handshake_deadline_ms: u64,
        /// Also join the SMA whose renderer port is at `host:port` (its `--renderer-listen`),
        /// again and again while it runs; repeat for several SMAs.
        #[arg(long = "join")]
        join: Vec<String>,
        /// Batches one SMA connection may hold at once; one more is refused with a reason.
        #[arg(long, default_value_t = DEFAULT_MAX_BATCHES)]
        max_batches: usize,
        /// A frame begun must be complete within this many milliseconds, or the link is closed.
        #[arg(long, default_value_t = default_liveness().frame_timeout.as_millis() as u64)]
        frame_timeout_ms: u64,
        /// How paths are scheduled: "wavefront" (ray streams) or "path" (one path at a time);
        /// the answers are the same in distribution (DESIGN.md §7).
        #[arg(long, default_value = Estimator::default().name())]
        estimator: EstimatorChoice,
        /// BVH traversal: "wide" (the renderer's own, on x86-64) or "compressed" (obvhs's); the
        /// same tree and triangle test, so the same answers (DESIGN.md §7).
        #[arg(long, default_value = Traversal::Wide.name())]
        traversal: TraversalChoice,
    },
    /// Render a named viewpoint per pixel with the same estimator: linear EXR plus a PNG beside it.
    Reference {
        /// Scene file (TOML) or built-in name ("bracara", "bracara-textured", "cornell").
        #[arg(long, default_value = "bracara")]
        scene: String,
        /// Viewpoint name from the scene.
        #[arg(long)]
        view: String,
        /// Image width in pixels.
        #[arg(long, default_value_t = 1024)]
        width: u32,
        /// Image height in pixels.
        #[arg(long, default_value_t = 768)]
        height: u32,
        /// Paths per pixel.
        #[arg(long, default_value_t = 256)]
        spp: u32,
        /// Bounce depth: a number (0 = direct light only) or "unbounded" (Russian roulette).
        #[arg(long, default_value = "2")]
        bounces: BounceDepth,
        /// Output EXR path; the PNG is written beside it.
        #[arg(long)]
        out: PathBuf,
        /// Seed of the random stream (the same seed gives the same image).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Tone-mapping white for the PNG (default: the largest luminance among pixels that see
        /// geometry).
        #[arg(long)]
        l_white: Option<f32>,
        /// Worker threads (0 = one per core).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Also write the albedo and normal of the first hit, box-filtered like the colour, as
        /// `<out>-albedo.exr` and `<out>-normal.exr` (a denoiser's feature images).
        #[arg(long)]
        features: bool,
        /// How paths are scheduled: "wavefront" (ray streams) or "path" (one path at a time);
        /// the answers are the same in distribution (DESIGN.md §7).
        #[arg(long, default_value = Estimator::default().name())]
        estimator: EstimatorChoice,
        /// BVH traversal: "wide" (the renderer's own, on x86-64) or "compressed" (obvhs's); the
        /// same tree and triangle test, so the same answers (DESIGN.md §7).
        #[arg(long, default_value = Traversal::Wide.name())]
        traversal: TraversalChoice,
    },
}

/// A bounce depth on the command line: a number, or "unbounded" (`None`, Russian roulette).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BounceDepth(pub Option<u32>);

impl std::str::FromStr for BounceDepth {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "unbounded" | "inf" | "none" => Ok(BounceDepth(None)),
            _ => s
                .parse::<u32>()
                .map(|b| BounceDepth(Some(b)))
                .map_err(|e| format!("{e} (a number or \"unbounded\")")),
        }
    }
}

/// An estimator on the command line, by its name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EstimatorChoice(pub Estimator);

impl std::str::FromStr for EstimatorChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        by_name(&Estimator::ALL, Estimator::name, s).map(EstimatorChoice)
    }
}

/// A BVH traversal on the command line, by its name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TraversalChoice(pub Traversal);

impl std::str::FromStr for TraversalChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        by_name(&Traversal::ALL, Traversal::name, s).map(TraversalChoice)
    }
}

/// The one of `all` called `s`, or an error that lists the names.
fn by_name<T: Copy>(all: &[T], name: fn(T) -> &'static str, s: &str) -> Result<T, String> {
    all.iter().copied().find(|&t| name(t) == s).ok_or_else(|| {
        let names: Vec<String> = all.iter().map(|&t| format!("{:?}", name(t))).collect();
        format!("{s:?}: expected one of {}", names.join(", "))
    })
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    conventions::logging::init();
    // A malformed or unavailable forced level is a plain error here, not the panic of the first
    // BVH built.
    VectorLevel::choose(std::env::var(vector_level::VAR).ok().as_deref())
        .map_err(anyhow::Error::msg)?;
    match cli.command {
        Command::Serve {
            scene,
            listen,
            threads,
            max_frame,
            max_connections,
            handshake_deadline_ms,
            join,
            max_batches,
            frame_timeout_ms,
            estimator,
            traversal,
        } => {
            let world = Arc::new(load_world(&scene, estimator.0, traversal.0)?);
            let mut service = Service::new(world, threads, max_frame)?;
            service.port = PortLimits {
                max_connections,
                handshake_deadline: Duration::from_millis(handshake_deadline_ms),
            };
            service.join = join;
            service.max_batches = max_batches.max(1);
            service.liveness.frame_timeout = Duration::from_millis(frame_timeout_ms.max(1));
            serve(service, &listen)
        }
        Command::Reference {
            scene,
            view,
            width,
            height,
            spp,
            bounces,
            out,
            seed,
            l_white,
            threads,
            features,
            estimator,
            traversal,
        } => {
            let settings = ReferenceSettings {
                width,
                height,
                spp,
                bounces: bounces.0,
                seed,
            };
            let world = load_world(&scene, estimator.0, traversal.0)?;
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()?;
            pool.install(|| {
                reference(&world, &view, &settings, &out, l_white)?;
                if features {
                    write_features(&world, &view, &settings, &out)?;
                }
                anyhow::Ok(())
            })
        }
    }
}

fn load_world(spec: &str, estimator: Estimator, traversal: Traversal) -> anyhow::Result<World> {
    let start = Instant::now();
    let scene = scene::load(spec).with_context(|| format!("loading scene {spec:?}"))?;
    let mut world = World::new(scene);
    world.estimator = estimator;
    if traversal != world.bvh.traversal() {
        anyhow::ensure!(
            world.bvh.wide_available() || traversal == Traversal::Compressed,
            "the wide traversal is not available here (x86-64 only, and a tree at most {} levels deep)",
            crate::bvh::WIDE_MAX_DEPTH
        );
        world.bvh.set_traversal(traversal);
    }
    tracing::debug!(
        scene = %world.scene.name,
        triangles = world.triangle_count(),
        bvh_ms = world.bvh.build_time().as_secs_f64() * 1e3,
        bvh_preset = ?world.bvh.preset(),
        total_ms = start.elapsed().as_secs_f64() * 1e3,
        effects = ?world.effects(),
        vector_level = world.bvh.vector_level().name(),
        estimator = world.estimator.name(),
        traversal = world.bvh.traversal().name(),
        "scene ready"
    );
    Ok(world)
}

fn serve(service: Service, listen: &str) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    runtime.block_on(async move {
        let listener = TcpListener::bind(listen)
            .await
            .with_context(|| format!("binding {listen}"))?;
        let addr = listener.local_addr()?;
        // The launcher and tests read this line to learn the port when `--listen` asks for port 0.
        conventions::listening::announce("renderer", addr)?;
        tracing::debug!(%addr, "renderer serving");
        service
            .serve(listener, async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
    })
}

fn reference(
    world: &World,
    view: &str,
    s: &ReferenceSettings,
    out: &std::path::Path,
    l_white: Option<f32>,
) -> anyhow::Result<()> {
    let start = Instant::now();
    let (_, counts) = render_to_files(world, view, s, out, l_white)?;
    let secs = start.elapsed().as_secs_f64();
    tracing::info!(
        seconds = secs,
        rays = counts.total(),
        mrays_per_s = counts.total() as f64 / secs / 1e6,
        "reference written to {}",
        out.display()
    );
    Ok(())
}

/// The feature images beside `out`: `<stem>-albedo.exr`, `<stem>-normal.exr`.
fn write_features(
    world: &World,
    view: &str,
    s: &ReferenceSettings,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    let camera = crate::reference::camera_for(world, view, s.width, s.height)?;
    let f = crate::features::render_features(world, &camera, s.width, s.height, s.seed);
    for (name, pixels) in [("albedo", &f.albedo), ("normal", &f.normal)] {
        let path = crate::features::beside(out, name);
        crate::image_files::write_exr(&path, s.width, s.height, pixels)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_both_subcommands() {
        let cli = Cli::try_parse_from([
            "renderer",
            "serve",
            "--scene",
            "cornell",
            "--listen",
            "127.0.0.1:0",
            "--threads",
            "2",
            "--join",
            "sma:7300",
        ])
        .unwrap();
        assert!(
            matches!(cli.command, Command::Serve { ref scene, threads: 2, ref join, .. }
                if scene == "cornell" && join == &["sma:7300"])
        );
        let cli = Cli::try_parse_from([
            "renderer",
            "reference",
            "--scene",
            "cornell",
            "--view",
            "main",
            "--width",
            "64",
            "--height",
            "48",
            "--spp",
            "4",
            "--bounces",
            "unbounded",
            "--out",
            "x.exr",
            "--estimator",
            "path",
        ])
        .unwrap();
        assert!(matches!(
            cli.command,
            Command::Reference {
                bounces: BounceDepth(None),
                width: 64,
                estimator: EstimatorChoice(Estimator::Path),
                ..
            }
        ));
        for name in ["wavefront", "path"] {
            let e: EstimatorChoice = name.parse().unwrap();
            assert_eq!(e.0.name(), name);
        }
        assert!("streams".parse::<EstimatorChoice>().is_err());
        for name in ["wide", "compressed"] {
            let t: TraversalChoice = name.parse().unwrap();
            assert_eq!(t.0.name(), name);
        }
        let refused = "cwbvh".parse::<TraversalChoice>().unwrap_err();
        assert!(refused.contains("\"wide\", \"compressed\""), "{refused}");
        assert!(
            Cli::try_parse_from([
                "renderer",
                "reference",
                "--view",
                "v",
                "--out",
                "o.exr",
                "--bounces",
                "x"
            ])
            .is_err()
        );
    }
}
