//! `walkthrough-bench walk`: a person walks a scene, stops, looks, walks on, and walks the same
//! route again (DESIGN.md §3 work while walking, §10). Per scene a scripted path kept in the repo
//! (`route`, `crates/bench/walks/<scene>.path`) is followed by a headless viewer of a fresh system
//! on loopback (renderer, SMA, viewer as separate processes, empty cache), with snapshots at each
//! stop (at set delays after stopping) and at moments along the walk, each judged against the
//! ground truth of its camera (`truths`). Then the per-pixel competitor (`viewport`) follows the
//! same path in real time on the same cores and is judged at the same instants. The section
//! `docs/bench/walk.md`, a CSV and a plot per scene go into the output folders.

mod frames;
pub(crate) mod measure;
pub(crate) mod route;
mod section;
pub(crate) mod sites;
pub(crate) mod truths;
pub(crate) mod viewport;

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;

use crate::convergence::{BEST_NOISE_AWARE, START_ALLOWANCE};
use measure::{Ask, SceneResult};
use route::{Route, WalkPlan};
use testkit::loopback::{System, SystemConfig, ViewerConfig};
use truths::{Scene, Truths};

pub const SECTION: &str = "docs/bench/walk.md";

/// Where the committed paths are, relative to this package.
pub const PATHS_DIR: &str = "walks";

/// What `bench walk` measures and where it writes.
#[derive(Debug, Clone)]
pub struct WalkConfig {
    /// One scene (a built-in name or a TOML file of a scene that has a route: bracara, Sponza).
    /// Default: bracara, and Sponza when ../shared/scenes is there.
    pub scene: Option<String>,
    /// A short walk at a small size with low-sample ground truths (a smoke run, and the test's).
    pub quick: bool,
    pub width: u32,
    pub height: u32,
    /// Paths per pixel of the stops' ground truths.
    pub stop_spp: u32,
    /// Paths per pixel of the moments' ground truths.
    pub moment_spp: u32,
    /// Moments judged per pass.
    pub moments: usize,
    /// CSVs and plots (committed: keep it small).
    pub out: PathBuf,
    /// Raw snapshots and process logs (an ignored folder).
    pub runs: PathBuf,
    /// Ground truth EXRs (an ignored folder).
    pub gt_cache: PathBuf,
    pub seed: u64,
    /// Only the route's first stops (a shorter reproduction of them); None: the whole route.
    pub stops: Option<usize>,
    /// Flags passed on to `walkthrough sma`, e.g. `--work-while-walking,off`.
    pub sma_flags: Vec<String>,
    /// Do not write docs/bench/walk.md nor BENCHMARKS.md.
    pub no_report: bool,
    /// Write the scenes' path files into `crates/bench/walks` and measure nothing.
    pub write_paths: bool,
    /// Runs of each side of the viewer's frame rate with work while walking on and off
    /// (`frames`); 0: not measured.
    pub frame_runs: usize,
}

impl WalkConfig {
    /// The full measurement's settings (`quick`: the smoke run's), writing into `out`, `runs`
    /// and `gt_cache`.
    pub fn new(quick: bool, out: PathBuf, runs: PathBuf, gt_cache: PathBuf) -> WalkConfig {
        let (width, height, stop_spp, moment_spp, moments, frame_runs) = if quick {
            (96, 72, 16, 8, 2, 1)
        } else {
            (512, 384, 1024, 256, 30, 3)
        };
        WalkConfig {
            scene: None,
            quick,
            width,
            height,
            stop_spp,
            moment_spp,
            moments,
            out,
            runs,
            gt_cache,
            seed: 1,
            stops: None,
            sma_flags: Vec::new(),
            no_report: false,
            write_paths: false,
            frame_runs,
        }
    }

    /// A fresh system for `walkable`: one renderer, the SMA with the best noise-aware criterion,
    /// its statistics every half second, `sma_flags` and then `more_flags`.
    fn system(&self, exe: &Path, walkable: &Walkable, more_flags: &[String]) -> SystemConfig {
        let stats = STATS_EVERY.map(String::from);
        SystemConfig {
            exe: exe.to_path_buf(),
            scene: walkable.spec.clone(),
            criterion: BEST_NOISE_AWARE.to_string(),
            refine: true,
            seed: self.seed,
            renderers: 1,
            sma_flags: [stats.as_slice(), &self.sma_flags, more_flags].concat(),
        }
    }

    /// The walk measured: the route (or its first `stops`), with its moments.
    fn plan(&self, route: &Route) -> WalkPlan {
        self.plan_of(route, self.stops, self.moments)
    }

    /// The stretch the viewer's frame rate is measured on (`frames`): the route's first stops.
    fn frames_plan(&self, route: &Route) -> WalkPlan {
        let stops = self.stops.unwrap_or(usize::MAX).min(frames::FRAME_STOPS);
        self.plan_of(route, Some(stops), 0)
    }

    fn plan_of(&self, route: &Route, stops: Option<usize>, moments: usize) -> WalkPlan {
        let route = match stops {
            Some(n) => route.first_stops(n),
            None => route.clone(),
        };
        let route = if self.quick {
            route.quick(QUICK_METRES, QUICK_STOP_S)
        } else {
            route
        };
        route::generate(&route, moments)
    }
}

/// The quick walk: this far along the first stretch, with stops of this long.
const QUICK_METRES: f32 = 2.5;
const QUICK_STOP_S: f32 = 1.5;

/// The SMA's stats (busy share, leaves, cached samples) twice a second, so that a snapshot's are
/// at most half a second old.
const STATS_EVERY: [&str; 2] = ["--stats-secs", "0.5"];

/// Time the held snapshots may take to draw once the walk is over (a few hundred at most).
const DRAWING_ALLOWANCE: Duration = Duration::from_secs(600);

/// A scene to walk: how to load it and its route.
struct Walkable {
    spec: String,
    route: Route,
}

impl Walkable {
    /// The scene's first viewpoint: the viewer starts there (the path then sets every camera).
    fn first_view(&self) -> anyhow::Result<String> {
        scene::load(&self.spec)?
            .settings
            .viewpoints
            .first()
            .map(|v| v.name.clone())
            .context("the scene has no viewpoint")
    }
}

pub fn run(config: WalkConfig) -> anyhow::Result<()> {
    if config.write_paths {
        return write_paths(&Path::new(env!("CARGO_MANIFEST_DIR")).join(PATHS_DIR));
    }
    let exe = crate::product::walkthrough_exe()?;
    std::fs::create_dir_all(&config.out)?;
    let mut results = Vec::new();
    let mut md = String::new();
    for walkable in scenes(config.scene.as_deref())? {
        eprintln!("walk: {}", walkable.route.scene);
        results.push(walk_scene(&config, &exe, &walkable)?);
        // After each scene: a long run stopped later keeps what it measured.
        md = section::write(&config, &results)?;
        if !config.no_report {
            std::fs::create_dir_all(Path::new(SECTION).parent().expect("a folder"))?;
            std::fs::write(SECTION, &md)?;
            crate::report::assemble(Path::new("BENCHMARKS.md"))?;
        }
    }
    print!("{md}");
    Ok(())
}

/// Every route's path file, as the viewer reads it.
pub fn path_files() -> Vec<(String, String)> {
    [sites::bracara(), sites::sponza()]
        .iter()
        .map(|r| {
            (
                format!("{}.path", r.scene),
                route::generate(r, 0).path_text(),
            )
        })
        .collect()
}

fn write_paths(dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    for (name, text) in path_files() {
        std::fs::write(dir.join(&name), text)?;
        println!("wrote {}", dir.join(name).display());
    }
    Ok(())
}

/// The scenes to walk: `scene`, or bracara and, when the shared scenes are there, Sponza.
fn scenes(scene: Option<&str>) -> anyhow::Result<Vec<Walkable>> {
    let walkable = |spec: &str| -> anyhow::Result<Walkable> {
        let name = scene::load(spec)
            .with_context(|| format!("loading {spec}"))?
            .name;
        let route = match name.as_str() {
            "bracara" => sites::bracara(),
            "sponza" => sites::sponza(),
            other => anyhow::bail!("no walk is scripted for scene {other} (bracara, sponza)"),
        };
        Ok(Walkable {
            spec: spec.to_string(),
            route,
        })
    };
    match scene {
        Some(spec) => Ok(vec![walkable(spec)?]),
        None => {
            let mut all = vec![walkable("bracara")?];
            if crate::convergence::sponza_is_here() {
                all.push(walkable(crate::convergence::SPONZA)?);
            }
            Ok(all)
        }
    }
}

fn walk_scene(config: &WalkConfig, exe: &Path, walkable: &Walkable) -> anyhow::Result<SceneResult> {
    let plan = config.plan(&walkable.route);
    let dir = config.runs.join(plan.scene);
    if dir.exists() {
        std::fs::remove_dir_all(&dir)?;
    }
    std::fs::create_dir_all(&dir)?;
    let path_file = dir.join("walk.path");
    std::fs::write(&path_file, plan.path_text())?;
    let scene = Scene::load(&walkable.spec, plan.fov_y_deg)?;
    let truths = Truths {
        scene: &scene,
        cache: config.gt_cache.clone(),
        width: config.width,
        height: config.height,
    };
    let asks = measure::asks(&plan);
    let references = measure::ground_truths(&truths, &plan, config)?;
    eprintln!("  the system along the walk…");
    let system = run_system(config, exe, walkable, &plan, &path_file, &asks, &dir)?;
    eprintln!("  the per-pixel viewport along the walk…");
    let times: Vec<f64> = asks.iter().map(Ask::time_s).collect();
    let viewport = viewport::follow(&scene, &plan, &times, config.width, config.height);
    let mut result = measure::judge(plan, asks, &references, system, viewport)?;
    if config.frame_runs > 0 {
        eprintln!("  the viewer's frames with work while walking on and off…");
        let plan = config.frames_plan(&walkable.route);
        result.frame_rates =
            frames::measure(config, exe, walkable, &plan, config.frame_runs, &dir)?;
    }
    Ok(result)
}

/// What the system's run left: its snapshots, the SMA's resident memory along the walk
/// ((walk seconds, bytes)), and where the CPU went.
pub(crate) struct SystemRun {
    pub snapshots: Vec<crate::convergence::snapshots::Snapshot>,
    pub sma_rss: Vec<(f64, u64)>,
    pub cpu: testkit::loopback::CpuShares,
}

fn run_system(
    config: &WalkConfig,
    exe: &Path,
    walkable: &Walkable,
    plan: &WalkPlan,
    path_file: &Path,
    asks: &[Ask],
    dir: &Path,
) -> anyhow::Result<SystemRun> {
    let system = config.system(exe, walkable, &[]);
    let viewer = ViewerConfig {
        view: walkable.first_view()?,
        width: config.width,
        height: config.height,
        seconds: Some(plan.seconds()),
        time_limit: Duration::from_secs_f64(plan.seconds()) + START_ALLOWANCE + DRAWING_ALLOWANCE,
        every_seconds: None,
        at_samples: vec![],
        when_idle: false,
    };
    let times: Vec<String> = asks.iter().map(|a| format!("{:.3}", a.time_s())).collect();
    let flags = vec![
        "--camera-path".to_string(),
        path_file.to_string_lossy().into_owned(),
        "--snapshot-at".to_string(),
        times.join(","),
    ];
    let snapshots_dir = dir.join("snapshots");
    let mut running = System::start(&system, dir)?;
    let cpu = running.run_viewer_with(&viewer, &flags, &snapshots_dir)?;
    // The run's wall time ends when the viewer's clock reached the walk's end: what came before
    // its clock started (the processes' start) is the offset of the memory samples.
    let offset = cpu.wall_s - plan.seconds();
    let sma_rss = running
        .sma_rss()
        .iter()
        .map(|&(t, bytes)| (t - offset, bytes))
        .filter(|(t, _)| (0.0..=plan.seconds()).contains(t))
        .collect();
    drop(running);
    let snapshots = crate::convergence::snapshots::read_run(&snapshots_dir)?;
    Ok(SystemRun {
        snapshots,
        sma_rss,
        cpu,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_paths_are_what_the_routes_generate() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join(PATHS_DIR);
        for (name, text) in path_files() {
            let committed = std::fs::read_to_string(dir.join(&name)).unwrap_or_else(|e| {
                panic!("{name}: {e}: run `walkthrough-bench walk --write-paths`")
            });
            assert!(
                committed == text,
                "{name} differs from its route: run `walkthrough-bench walk --write-paths`"
            );
        }
    }
}
