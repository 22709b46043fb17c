//! The command line of `walkthrough-bench`, the only module of this package that knows clap:
//! each flag set is turned into the plain configuration its benchmark takes.

use std::path::PathBuf;

use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use sma::config::Profile;

use crate::accuracy::{self, AccuracyConfig};
use crate::convergence::{self, ConvergenceConfig};

/// `walkthrough-bench <section>`: the benchmarks that regenerate BENCHMARKS.md (DESIGN.md §10).
/// They start the product processes from the `walkthrough` binary beside this one.
#[derive(Parser, Debug)]
#[command(
    name = "walkthrough-bench",
    version,
    about = "Benchmarks of the walkthrough system (BENCHMARKS.md)",
    after_help = "Build both binaries first: cargo build --release --workspace"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: BenchCommand,
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    run_bench(cli.command)
}

fn run_bench(cmd: BenchCommand) -> anyhow::Result<()> {
    match cmd {
        BenchCommand::Report { quick, out, only } => crate::report::write(&out, quick, &only),
        BenchCommand::Convergence(args) => convergence::run(args.config()),
        BenchCommand::Accuracy(args) => accuracy::run(args.config()),
        BenchCommand::Cost(args) => crate::cost::run(args.config()),
        BenchCommand::MeshOptions(args) => crate::mesh_options::run(args.config()),
        BenchCommand::CacheFile { quick, out } => {
            crate::report::write(&out, quick, &["cache-file".to_string()])
        }
        BenchCommand::Textures { quick, out } => {
            crate::report::write(&out, quick, &["textures".to_string()])
        }
        BenchCommand::CacheFileRevisit(args) => crate::cache_file::revisit::run(&args.config()),
        BenchCommand::CacheFileCrashChild { file, first_view } => {
            crate::cache_file::crash_child(&file, first_view)
        }
        BenchCommand::LoopbackSink { listen } => crate::protocol::loopback_sink(&listen),
        BenchCommand::Walk(args) => crate::walk::run(args.config()),
        BenchCommand::Reproduction { runs } => {
            crate::reproduction::run(crate::reproduction::ReproductionConfig { runs })
        }
    }
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Runs every benchmark section and writes BENCHMARKS.md.
    Report {
        /// A few seconds per section instead of the full measurement (a smoke run).
        #[arg(long)]
        quick: bool,
        #[arg(long, default_value = "BENCHMARKS.md")]
        out: PathBuf,
        /// Only the sections whose name contains one of these (protocol, scene, renderer, sma-core,
        /// sma-service, cache-file, viewer, textures, farm).
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
    },
    /// The SMA's cache file: saving and loading 1 M leaves, an incremental save, the schedule's
    /// pause (docs/bench/cache-file.md, then BENCHMARKS.md); `report --only cache-file`.
    CacheFile {
        /// A quarter of the leaves, one run.
        #[arg(long)]
        quick: bool,
        #[arg(long, default_value = "BENCHMARKS.md")]
        out: PathBuf,
    },
    /// Diffuse textures end to end: bytes per textured triangle on the wire, Sponza's textures
    /// reaching a viewer from a real SMA, the viewer's texture memory, a textured frame against
    /// an untextured one (docs/bench/textures.md, then BENCHMARKS.md); `report --only textures`.
    Textures {
        /// Fewer runs (a smoke run).
        #[arg(long)]
        quick: bool,
        #[arg(long, default_value = "BENCHMARKS.md")]
        out: PathBuf,
    },
    /// The cache file's revisit: a view converged, the SMA stopped cleanly and started again on
    /// its cache file; samples and FLIP of the revisit's first complete picture
    /// (docs/bench/cache-file-revisit.md, then BENCHMARKS.md).
    CacheFileRevisit(RevisitArgs),
    /// Convergence per viewpoint against the ground truth, per criterion (DESIGN.md §10).
    Convergence(ConvergenceArgs),
    /// Time to reach error levels against a direct per-pixel render (DESIGN.md §10).
    Accuracy(AccuracyArgs),
    /// Error after 10 s and 60 s per ladder cap × bounce depth × criterion (DESIGN.md §10).
    Cost(CostArgs),
    /// The thesis's neighbour rule and merging by uniformity against today's default mesh, on
    /// the same views at equal paths (thesis §4.2, §6; DESIGN.md §4).
    MeshOptions(MeshOptionsArgs),
    /// A person walks each scene's scripted path twice, stopping to look: both the system and a
    /// per-pixel progressive viewport judged at the stops and along the walk (DESIGN.md §3, §10).
    Walk(WalkArgs),
    /// The thesis's findings beside ours (thesis §5.2–5.3), from `convergence` runs on MC, VR and
    /// VT with rnd, nld-is and nld-os: one with `--profile thesis`, one with today's defaults.
    Reproduction {
        /// The `--out` folder of `convergence`, run with `--profile thesis` and with today's
        /// defaults (and of `accuracy --convergence` for the speed-ups).
        #[arg(long, default_value = "docs/reproduction")]
        runs: PathBuf,
    },
    /// The process the cache file's crash trials kill (started by `cache-file` as a child).
    #[command(hide = true)]
    CacheFileCrashChild {
        file: PathBuf,
        /// The first view of its walk.
        #[arg(long, default_value_t = 0)]
        first_view: u32,
    },
    /// The receiving end of the loopback protocol benchmark (started by `report` as a child).
    #[command(hide = true)]
    LoopbackSink {
        #[arg(long)]
        listen: String,
    },
}

#[derive(Args, Debug, Clone)]
pub struct ConvergenceArgs {
    /// One scene (a TOML file or a built-in name). Default: `bracara`, and Sponza when
    /// ../shared/scenes is there.
    #[arg(long)]
    pub scene: Option<String>,
    /// Views to measure. Default: MC, VR, VT of bracara and S1, S2, S3 of Sponza; with --scene, all
    /// of that scene's views.
    #[arg(long, value_delimiter = ',')]
    pub views: Vec<String>,
    /// Criteria to compare. Default: rnd, nld-is-thesis, nld-os-thesis and the best noise-aware
    /// criterion (nld-px), or under --profile thesis the first three; a run without refinement
    /// is always added.
    #[arg(long, value_delimiter = ',')]
    pub criteria: Vec<String>,
    /// Which system every SMA runs: today's, or the thesis's as published (`walkthrough sma
    /// --profile`). Tables, plots and CSVs say "today" or "thesis (2006)", and a view measured
    /// under the thesis's profile has files of its own (`<scene>-<view>-thesis.*`).
    #[arg(long, default_value_t = Profile::Today, value_parser = profile_parser())]
    pub profile: Profile,
    /// Length of each run; snapshots every second.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Fixed sample counts at which snapshots are also taken; by default quarter steps of a
    /// doubling up to 8000 samples, sixteenth steps up to 128000, quarter steps up to 256000.
    #[arg(long, value_delimiter = ',', default_values_t = snapshot_sample_grid())]
    pub at_samples: Vec<u64>,
    #[command(flatten)]
    pub images: ImageArgs,
    /// Tables, plots, strips and CSVs (committed: keep it small).
    #[arg(long, default_value = "docs/convergence")]
    pub out: PathBuf,
    /// Raw snapshots and process logs of every run (big: an ignored folder).
    #[arg(long, default_value = "out/convergence")]
    pub runs: PathBuf,
    /// Renderer processes per run (the cores are shared among them).
    #[arg(long, default_value_t = 1)]
    pub renderers: usize,
    /// Seed of the SMA's criteria and renderers.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Flags passed on to every `walkthrough sma` (to measure a setting against its default),
    /// e.g. `--sma-flags=--max-selections,256`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub sma_flags: Vec<String>,
    /// Runs of the best noise-aware criterion per view: the end-to-end targets take medians
    /// over them (DESIGN.md §10: medians of three).
    #[arg(long, default_value_t = 3)]
    pub repetitions: usize,
    /// Keep the runs already in --out's CSVs and measure only those missing (e.g. repetitions
    /// added to an earlier measurement).
    #[arg(long)]
    pub add_repetitions: bool,
    /// Do not write docs/bench/convergence.md nor BENCHMARKS.md.
    #[arg(long, conflicts_with = "report_only")]
    pub no_report: bool,
    /// Measure nothing: redraw the plots, the section and BENCHMARKS.md from the CSVs in --out.
    #[arg(long)]
    pub report_only: bool,
    /// Render the views' missing ground truths (into --gt-cache) and stop: they may render while
    /// the machine does other work, the timed runs may not.
    #[arg(long, conflicts_with = "report_only")]
    pub ground_truths_only: bool,
}

impl ConvergenceArgs {
    fn config(self) -> ConvergenceConfig {
        ConvergenceConfig {
            scene: self.scene,
            views: self.views,
            criteria: self.criteria,
            profile: self.profile,
            seconds: self.seconds,
            at_samples: self.at_samples,
            width: self.images.width,
            height: self.images.height,
            gt_spp: self.images.gt_spp,
            out: self.out,
            gt_cache: self.images.gt_cache,
            runs: self.runs,
            renderers: self.renderers,
            seed: self.seed,
            sma_flags: self.sma_flags,
            repetitions: self.repetitions.max(1),
            add_repetitions: self.add_repetitions,
            no_report: self.no_report,
            report_only: self.report_only,
            ground_truths_only: self.ground_truths_only,
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct AccuracyArgs {
    /// The output folder of `bench convergence`.
    #[arg(long, default_value = "docs/convergence")]
    pub convergence: PathBuf,
    /// Mean FLIP levels to reach.
    #[arg(long, value_delimiter = ',', default_value = "0.2,0.15,0.1,0.05")]
    pub levels: Vec<f64>,
    /// Paths per pixel of the direct render (the interactive preset: 64).
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// The direct renders' images (an ignored folder).
    #[arg(long, default_value = "out/direct")]
    pub direct: PathBuf,
    /// Paths per pixel of the per-pixel competitors (plain and denoised).
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16,32,64")]
    pub per_pixel_spp: Vec<u32>,
    /// No per-pixel render above the first that takes longer than this many seconds.
    #[arg(long, default_value_t = 30.0)]
    pub per_pixel_max_seconds: f64,
    /// Skip the denoised competitor (it needs `pip install pyoidn numpy`).
    #[arg(long)]
    pub no_denoise: bool,
    /// Do not write docs/bench/accuracy.md nor BENCHMARKS.md.
    #[arg(long)]
    pub no_report: bool,
    /// The textured views of `--convergence` beside their untextured twins, into
    /// docs/bench/textured.md (instead of the accuracy and headline sections); no per-pixel
    /// competitors.
    #[arg(long)]
    pub textured: bool,
}

#[derive(Args, Debug, Clone)]
pub struct WalkArgs {
    /// One scene: bracara or Sponza's TOML. Default: bracara, and Sponza when ../shared/scenes
    /// is there.
    #[arg(long)]
    pub scene: Option<String>,
    /// A short walk at 96×72 with low-sample ground truths (a smoke run).
    #[arg(long)]
    pub quick: bool,
    /// CSVs and plots (committed: keep it small).
    #[arg(long, default_value = "docs/walk")]
    pub out: PathBuf,
    /// Raw snapshots and process logs (big: an ignored folder).
    #[arg(long, default_value = "out/walk")]
    pub runs: PathBuf,
    /// Ground truth EXRs (big: an ignored folder).
    #[arg(long, default_value = "out/gt")]
    pub gt_cache: PathBuf,
    /// Moments judged per pass (default 30, quick 2; at most 30: the 60 a walk).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=30))]
    pub moments: Option<u16>,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Walk only the route's first N stops, twice (a shorter reproduction of them).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    pub stops: Option<u16>,
    /// Paths per pixel of the stops' ground truths (default 1024, quick 16).
    #[arg(long)]
    pub stop_spp: Option<u32>,
    /// Paths per pixel of the moments' ground truths (default 256, quick 8).
    #[arg(long)]
    pub moment_spp: Option<u32>,
    /// Flags passed on to `walkthrough sma`, e.g. `--sma-flags=--work-while-walking,off`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub sma_flags: Vec<String>,
    /// Do not write docs/bench/walk.md nor BENCHMARKS.md.
    #[arg(long)]
    pub no_report: bool,
    /// Write the scenes' path files (crates/bench/walks) from their routes and measure nothing.
    #[arg(long)]
    pub write_paths: bool,
    /// Runs of each side of the viewer's frame rate with work while walking on and off, on the
    /// route's first two stops (default 3, quick 1; 0: not measured).
    #[arg(long)]
    pub frame_runs: Option<usize>,
}

impl WalkArgs {
    fn config(self) -> crate::walk::WalkConfig {
        let defaults = crate::walk::WalkConfig::new(self.quick, self.out, self.runs, self.gt_cache);
        crate::walk::WalkConfig {
            moments: self.moments.map_or(defaults.moments, usize::from),
            scene: self.scene,
            seed: self.seed,
            stops: self.stops.map(usize::from),
            stop_spp: self.stop_spp.unwrap_or(defaults.stop_spp),
            moment_spp: self.moment_spp.unwrap_or(defaults.moment_spp),
            sma_flags: self.sma_flags,
            no_report: self.no_report,
            write_paths: self.write_paths,
            frame_runs: self.frame_runs.unwrap_or(defaults.frame_runs),
            ..defaults
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct RevisitArgs {
    /// A scene TOML file or a built-in name.
    #[arg(long, default_value = "bracara")]
    pub scene: String,
    #[arg(long, default_value = "MC")]
    pub view: String,
    #[arg(long, default_value_t = 512)]
    pub width: u32,
    #[arg(long, default_value_t = 384)]
    pub height: u32,
    /// Paths per pixel of the ground truth (rendered into --gt-cache when missing).
    #[arg(long, default_value_t = 256)]
    pub gt_spp: u32,
    #[arg(long, default_value = "out/gt")]
    pub gt_cache: PathBuf,
    /// Seconds each visit may run before it is taken as it stands, unconverged.
    #[arg(long, default_value_t = 900.0)]
    pub limit_s: f64,
    /// The control: once the restarted SMA converged, a look at this view and back (an empty
    /// value skips it).
    #[arg(long, default_value = "VR")]
    pub away_view: String,
    /// Runs, each with a fresh cache file (medians over them, targets judged on the worst).
    #[arg(long, default_value_t = 3)]
    pub runs: usize,
    /// Flags passed on to both `walkthrough sma` runs, e.g. `--sma-flags=--criterion,rnd`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub sma_flags: Vec<String>,
    #[arg(long, default_value = "BENCHMARKS.md")]
    pub out: PathBuf,
}

impl RevisitArgs {
    fn config(self) -> crate::cache_file::revisit::RevisitConfig {
        crate::cache_file::revisit::RevisitConfig {
            scene: self.scene,
            view: self.view,
            width: self.width,
            height: self.height,
            gt_spp: self.gt_spp,
            gt_cache: self.gt_cache,
            limit: std::time::Duration::from_secs_f64(self.limit_s.clamp(1.0, 86_400.0)),
            runs: self.runs,
            away: Some(self.away_view).filter(|v| !v.is_empty()),
            sma_flags: self.sma_flags,
            out: self.out,
        }
    }
}

/// The image size and ground truth shared by the end-to-end benchmarks.
#[derive(Args, Debug, Clone)]
pub struct ImageArgs {
    /// Image size of the runs, the ground truth and the direct render: DESIGN.md §10's 1024×768
    /// (a 1024-path ground truth then takes 4 to 12 minutes a view on 2 cores, once).
    #[arg(long, default_value_t = 1024)]
    pub width: u32,
    #[arg(long, default_value_t = 768)]
    pub height: u32,
    /// Paths per pixel of the ground truth (DESIGN.md §10: at least 256; 1024 so that its own
    /// noise does not set the error floor).
    #[arg(long, default_value_t = 1024)]
    pub gt_spp: u32,
    /// Ground truth EXRs (big: an ignored folder).
    #[arg(long, default_value = "out/gt")]
    pub gt_cache: PathBuf,
}

#[derive(Args, Debug, Clone)]
pub struct CostArgs {
    /// Views (of bracara and, when ../shared/scenes is there, Sponza).
    #[arg(long, value_delimiter = ',', default_value = "VT,S1")]
    pub views: Vec<String>,
    /// Ladder caps (the SMA's `--max-paths`).
    #[arg(long, value_delimiter = ',', default_value = "256,1024")]
    pub caps: Vec<u32>,
    /// Bounce depths (the SMA's `--bounces`), each with its own ground truth.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    pub depths: Vec<u32>,
    /// Criteria: the best noise-aware one and the thesis's object-space one.
    #[arg(long, value_delimiter = ',', default_value = "nld-px,nld-os-thesis")]
    pub criteria: Vec<String>,
    /// Length of each run.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Times at which the error is read.
    #[arg(long, value_delimiter = ',', default_value = "10,60")]
    pub at: Vec<f64>,
    #[command(flatten)]
    pub images: ImageArgs,
    /// Raw snapshots and process logs of every run (big: an ignored folder).
    #[arg(long, default_value = "out/cost")]
    pub runs: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Do not write docs/bench/cost.md nor BENCHMARKS.md.
    #[arg(long)]
    pub no_report: bool,
}

impl CostArgs {
    fn config(self) -> crate::cost::CostConfig {
        crate::cost::CostConfig {
            views: self.views,
            caps: self.caps,
            depths: self.depths,
            criteria: self.criteria,
            seconds: self.seconds,
            at: self.at,
            width: self.images.width,
            height: self.images.height,
            gt_spp: self.images.gt_spp,
            gt_cache: self.images.gt_cache,
            runs: self.runs,
            seed: self.seed,
            no_report: self.no_report,
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct MeshOptionsArgs {
    /// Views; default: MC, VR, VT of bracara and S1, S2, S3 of Sponza when ../shared/scenes is
    /// there.
    #[arg(long, value_delimiter = ',')]
    pub views: Vec<String>,
    /// Length of each run; snapshots every second and at the convergence grid's sample counts.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Runs of the default per view: the spread merging is judged against.
    #[arg(long, default_value_t = 3)]
    pub repetitions: usize,
    #[command(flatten)]
    pub images: ImageArgs,
    /// The readings' CSVs (committed: small).
    #[arg(long, default_value = "docs/mesh-options")]
    pub out: PathBuf,
    /// Raw snapshots and process logs of every run (big: an ignored folder).
    #[arg(long, default_value = "out/mesh-options")]
    pub runs: PathBuf,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Measure nothing: rewrite the section from the CSVs in --out.
    #[arg(long)]
    pub report_only: bool,
    /// Do not write docs/bench/mesh-options.md nor BENCHMARKS.md.
    #[arg(long)]
    pub no_report: bool,
}

impl MeshOptionsArgs {
    fn config(self) -> crate::mesh_options::MeshOptionsConfig {
        crate::mesh_options::MeshOptionsConfig {
            views: self.views,
            seconds: self.seconds,
            repetitions: self.repetitions.max(1),
            at_samples: snapshot_sample_grid(),
            width: self.images.width,
            height: self.images.height,
            gt_spp: self.images.gt_spp,
            gt_cache: self.images.gt_cache,
            out: self.out,
            runs: self.runs,
            seed: self.seed,
            report_only: self.report_only,
            no_report: self.no_report,
        }
    }
}

impl AccuracyArgs {
    fn config(self) -> AccuracyConfig {
        AccuracyConfig {
            convergence: self.convergence,
            levels: self.levels,
            spp: self.spp,
            direct: self.direct,
            // The textured section compares the system with itself and the direct render.
            per_pixel_spp: if self.textured {
                vec![]
            } else {
                self.per_pixel_spp
            },
            per_pixel_max_seconds: self.per_pixel_max_seconds,
            denoise: !self.no_denoise && !self.textured,
            no_report: self.no_report,
            textured: self.textured,
        }
    }
}

/// `--profile`: one of the SMA's profiles, by name.
fn profile_parser() -> impl TypedValueParser<Value = Profile> {
    let names: Vec<&str> = Profile::ALL.iter().map(|p| p.name()).collect();
    PossibleValuesParser::new(names)
        .map(|name| Profile::from_name(&name).expect("a possible value"))
}

/// The sample counts at which `bench convergence` takes snapshots besides one a second: quarter
/// steps of a doubling from 1 000 to 8 000, sixteenth steps to 128 000, quarter steps to 256 000.
/// A time to reach an error is read at the first snapshot at or below it, so the grid bounds how
/// finely it is read: the views cross mean FLIP 0.1 between 8 000 and 128 000 samples, in their
/// first seconds, when the error falls fastest. The harness's viewer holds its snapshots as
/// copies until the run ends (`--hold-snapshots`, `viewer::snapshot_files`), so a fine grid
/// costs the system measured next to nothing.
fn snapshot_sample_grid() -> Vec<u64> {
    let mut counts = Vec::new();
    for (from, to, steps) in [
        (1_000, 8_000, 4),
        (8_000, 128_000, 16),
        (128_000, 256_000, 4),
    ] {
        let mut doubling = from;
        while doubling < to {
            counts.extend((0..steps).map(|k| doubling + k * doubling / steps));
            doubling *= 2;
        }
    }
    counts.push(256_000);
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_snapshot_grid_rises_in_finer_steps_where_the_views_cross_flip_0_1() {
        let grid = snapshot_sample_grid();
        assert!(grid.windows(2).all(|w| w[0] < w[1]), "{grid:?}");
        assert_eq!((grid[0], grid[grid.len() - 1]), (1_000, 256_000));
        for (count, next) in [(1_750, 2_000), (8_000, 8_500), (124_000, 128_000)] {
            let at = grid.iter().position(|&c| c == count).unwrap();
            assert_eq!(grid[at + 1], next);
        }
        assert_eq!(grid.len(), 4 * 3 + 16 * 4 + 4 + 1);
    }
}
