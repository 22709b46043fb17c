//! Figures of the SMA core for BENCHMARKS.md (DESIGN.md §10 costs): an NLD_OS call on 100k visible leaves,
//! splits per second with closure, bytes per leaf and per cached vertex; and the synthetic
//! convergence runs behind the criterion defaults.

use std::fmt::Write;
use std::time::Instant;

use protocol::renderer_link::{Quality, SampleKey};
use protocol::{PartEstimate, SampleParts, Side};
use rand::{RngExt, SeedableRng};

use sma::cache::{CachedSample, ShadingCache};
use sma::criteria::synthetic::{Shading, Synthetic};
use sma::criteria::{
    Criterion, CriterionInput, CriterionKind, CriterionSettings, Metric, NldOs, NldPx,
    make_criterion,
};
use sma::indirect_filter::{IndirectFilter, IndirectFilterSettings};
use sma::mesh::{MeshParams, NodeId, SubdivisionMesh, grid_mesh};
use sma::visible_set::{VisibleLeaf, VisibleSet};

use super::stats::median;

/// The Markdown section: performance figures, then the criterion experiments.
pub fn section(quick: bool) -> anyhow::Result<String> {
    let runs = if quick { 3 } else { 7 };
    let mut md = String::from("## SMA core (crates/sma: mesh, cache, criteria)\n\n");
    write_criterion_speed(&mut md, runs)?;
    write_split_speed_and_memory(&mut md, runs, if quick { 100_000 } else { 400_000 })?;
    md.push_str(&criteria_experiment(quick)?);
    Ok(md)
}

/// A sample of radiance `rgb`, a third of it indirect light with a 10 % standard error of the
/// mean (what the object-space filter reads).
fn sample(rgb: [f32; 3]) -> CachedSample {
    let paths = Quality::INTERACTIVE.paths as f32;
    let third = rgb.map(|c| c / 3.0);
    let error = 0.1 * conventions::luminance(third);
    CachedSample {
        parts: SampleParts {
            direct: PartEstimate {
                rgb: rgb.map(|c| c - c / 3.0),
                luminance_variance: 0.0,
            },
            indirect: PartEstimate {
                rgb: third,
                luminance_variance: error * error * paths,
            },
            view_dependent: PartEstimate::default(),
        },
        quality: Quality::INTERACTIVE,
        view_dependent: false,
        eye: None,
        last_seen: 0,
    }
}

/// A mesh of about `leaves` leaves, every vertex cached, every leaf visible at 10 pixels.
fn visible_grid(leaves: usize) -> (SubdivisionMesh, ShadingCache, VisibleSet) {
    let n = ((leaves / 2) as f64).sqrt().ceil() as u32;
    let mesh = SubdivisionMesh::new(&grid_mesh(n), MeshParams::default());
    let mut cache = ShadingCache::new(usize::MAX);
    for vertex in 0..mesh.vertex_count() as u32 {
        let p = mesh.vertex(vertex).position;
        let l = Shading::Smooth.luminance(p.truncate() * 0.05, n);
        cache.insert(
            SampleKey {
                vertex,
                side: Side::Front,
            },
            sample([l; 3]),
        );
    }
    let visible = VisibleSet {
        leaves: mesh
            .leaves()
            .map(|leaf| VisibleLeaf {
                leaf,
                side: Side::Front,
                pixels: 10,
            })
            .collect(),
        width: 1024,
        height: 1024,
    };
    (mesh, cache, visible)
}

fn write_criterion_speed(md: &mut String, runs: usize) -> anyhow::Result<()> {
    let (mesh, cache, visible) = visible_grid(100_000);
    let input = CriterionInput {
        mesh: &mesh,
        cache: &cache,
        visible: &visible,
        l_white: cache.l_white(&mesh, &visible),
        image: None,
    };
    let n = visible.leaves.len() as f64;
    // S_ref above every leaf's S: the call scans the whole set once and returns nothing.
    let full_scan = CriterionSettings {
        s_ref_start: 1.0,
        s_min: 1.0,
        display_error: 1.0,
        large_triangle_fraction: 1.0,
        ..Default::default()
    };
    let time = |make: &dyn Fn() -> Box<dyn Criterion>| {
        median(
            (0..runs)
                .map(|_| {
                    let mut c = make();
                    let t = Instant::now();
                    let picked = c.select(&input, 64);
                    std::hint::black_box(picked);
                    t.elapsed().as_secs_f64()
                })
                .collect(),
        )
    };
    let scan = time(&|| Box::new(NldOs::new(&full_scan, Metric::NoiseAware)));
    let px = time(&|| Box::new(NldPx::new(&CriterionSettings::default())));
    let (filter, borrowed) = filter_cost(&mesh, &cache, &visible, runs);
    writeln!(
        md,
        "### Criterion cost ({} visible leaves, all samples cached, median of {runs})\n",
        visible.leaves.len()
    )?;
    writeln!(md, "| call | ms per call | leaves/s |\n|---|---:|---:|")?;
    writeln!(
        md,
        "| `nld-os`, full pass, no leaf above S_ref | {:.2} | {:.1} M |",
        scan * 1e3,
        n / scan / 1e6
    )?;
    writeln!(
        md,
        "| `nld-px`, ranks all, R = 64 out | {:.2} | {:.1} M |",
        px * 1e3,
        n / px / 1e6
    )?;
    writeln!(
        md,
        "| object-space filter of the indirect part, one run ({borrowed:.0} neighbours a \
         sample) | {:.2} | {:.1} M |",
        filter.whole * 1e3,
        n / filter.whole / 1e6
    )?;
    writeln!(
        md,
        "| of it on the schedule's thread (gathering, setting; the rest on its worker) | {:.2} \
         | {:.1} M |\n",
        filter.schedule_thread * 1e3,
        n / filter.schedule_thread / 1e6
    )?;
    Ok(())
}

/// The median times of one run of the indirect filter (default settings, turned on) over every
/// visible sample, whole and of its parts on the schedule's thread (gathering the candidates,
/// setting the results; the filtering between runs on a worker), and the mean number of
/// neighbours a sample borrows from.
fn filter_cost(
    mesh: &SubdivisionMesh,
    cache: &ShadingCache,
    visible: &VisibleSet,
    runs: usize,
) -> (FilterCost, f64) {
    let settings = IndirectFilterSettings {
        enabled: true,
        ..IndirectFilterSettings::default()
    };
    let mut borrowed = 0.0;
    let timed: Vec<FilterCost> = (0..runs)
        .map(|_| {
            let mut cache = cache.clone();
            let mut filter = IndirectFilter::new(settings, mesh);
            let t = Instant::now();
            let job = filter
                .start(mesh, [visible], &cache)
                .expect("the filter is on");
            let gathered = t.elapsed().as_secs_f64();
            let filtered = job.filter();
            let before_setting = Instant::now();
            let run = filter.finish(filtered, mesh, &mut cache);
            let set = before_setting.elapsed().as_secs_f64();
            borrowed = run.neighbours as f64 / run.filtered.max(1) as f64;
            FilterCost {
                whole: t.elapsed().as_secs_f64(),
                schedule_thread: gathered + set,
            }
        })
        .collect();
    let cost = FilterCost {
        whole: median(timed.iter().map(|c| c.whole).collect()),
        schedule_thread: median(timed.iter().map(|c| c.schedule_thread).collect()),
    };
    (cost, borrowed)
}

/// One run of the indirect filter, in seconds.
struct FilterCost {
    whole: f64,
    /// Of it, on the schedule's thread (`IndirectFilter::start` and `finish`).
    schedule_thread: f64,
}

fn write_split_speed_and_memory(
    md: &mut String,
    runs: usize,
    target_leaves: usize,
) -> anyhow::Result<()> {
    let mut rates = Vec::new();
    let mut per_leaf = Vec::new();
    let mut per_sample = Vec::new();
    let mut mesh_per_leaf = Vec::new();
    let mut split_rates = Vec::new();
    let mut last = (0, 0);
    for run in 0..runs {
        let mut mesh = SubdivisionMesh::new(
            &grid_mesh(32),
            MeshParams {
                min_edge_length: 0.0,
                ..Default::default()
            },
        );
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(run as u64);
        let (mut steps, mut elapsed) = (0usize, 0.0);
        while mesh.leaf_count() < target_leaves {
            let leaves: Vec<NodeId> = mesh.leaves().collect();
            let picks: Vec<NodeId> = (0..1000)
                .map(|_| leaves[rng.random_range(0..leaves.len())])
                .collect();
            let t = Instant::now();
            steps += mesh.refine(&picks, &|_| false).len();
            elapsed += t.elapsed().as_secs_f64();
        }
        rates.push(steps as f64 / elapsed);
        split_rates.push(mesh.split_count() as f64 / elapsed);
        let mut cache = ShadingCache::new(usize::MAX);
        for vertex in 0..mesh.vertex_count() as u32 {
            cache.insert(
                SampleKey {
                    vertex,
                    side: Side::Front,
                },
                sample([1.0; 3]),
            );
        }
        per_leaf.push((mesh.heap_bytes() + cache.bytes()) as f64 / mesh.leaf_count() as f64);
        mesh_per_leaf.push(mesh.heap_bytes() as f64 / mesh.leaf_count() as f64);
        per_sample.push(cache.bytes() as f64 / cache.len() as f64);
        last = (mesh.leaf_count(), mesh.vertex_count());
    }
    writeln!(
        md,
        "### Subdivision and memory (random selections of 1,000 leaves from a 32×32 grid to {} leaves, {} vertices; median of {runs})\n",
        last.0, last.1
    )?;
    writeln!(md, "| figure | value |\n|---|---:|")?;
    writeln!(
        md,
        "| splits per second (a split: one triangle replaced by its children, red or green, selected or made by closure) | {:.2} M |",
        median(split_rates) / 1e6
    )?;
    writeln!(
        md,
        "| refinement steps per second (a selected leaf's red split and its whole closure) | {:.2} M |",
        median(rates) / 1e6
    )?;
    writeln!(
        md,
        "| bytes per leaf, mesh + cache (one side per vertex) | {:.0} |",
        median(per_leaf)
    )?;
    writeln!(
        md,
        "| of which mesh (nodes incl. dead ones, vertices, edge tables; Vec and table capacity) | {:.0} |",
        median(mesh_per_leaf)
    )?;
    writeln!(
        md,
        "| bytes per cached vertex sample (slot table included) | {:.0} |\n",
        median(per_sample)
    )?;
    Ok(())
}

/// Mean absolute luminance error after each of `budgets` samples (ascending), refining R = 16
/// leaves per call. A call adds a varying number of samples, so the error at a budget is
/// interpolated between the calls around it: criteria are compared at exactly equal samples. A
/// run that stops refining earlier keeps its final error for the larger budgets.
pub fn error_curve(
    shading: Shading,
    criterion: CriterionKind,
    settings: &CriterionSettings,
    budgets: &[usize],
) -> Vec<f64> {
    let mut scene = Synthetic::new(8, 128, shading);
    let mut c = make_criterion(criterion, settings, 1);
    let mut errors = Vec::with_capacity(budgets.len());
    let mut before = (scene.samples(), scene.error());
    let mut idle = 0;
    while errors.len() < budgets.len() && idle < 3 {
        let picked = c.select(&scene.input(), 16);
        idle = if picked.is_empty() { idle + 1 } else { 0 };
        scene.refine_and_shade(&picked);
        let after = (scene.samples(), scene.error());
        while let Some(&budget) = budgets.get(errors.len())
            && after.0 >= budget
        {
            let t = (budget.saturating_sub(before.0)) as f64 / (after.0 - before.0).max(1) as f64;
            errors.push(before.1 + t.min(1.0) * (after.1 - before.1));
        }
        before = after;
    }
    errors.resize(budgets.len(), before.1);
    errors
}

const SHADINGS: [Shading; 3] = [Shading::ShadowEdge, Shading::Blob, Shading::Smooth];

/// The error curves of a criterion on each of [`SHADINGS`].
fn curves(
    criterion: CriterionKind,
    settings: &CriterionSettings,
    budgets: &[usize],
) -> Vec<Vec<f64>> {
    SHADINGS
        .iter()
        .map(|&s| error_curve(s, criterion, settings, budgets))
        .collect()
}

/// The curves averaged budget by budget.
fn mean_of(curves: &[Vec<f64>]) -> Vec<f64> {
    (0..curves[0].len())
        .map(|i| curves.iter().map(|c| c[i]).sum::<f64>() / curves.len() as f64)
        .collect()
}

/// Errors as "a / b / c", one per budget.
fn slashed(errors: &[f64]) -> String {
    let cells: Vec<String> = errors.iter().map(|e| format!("{e:.4}")).collect();
    cells.join(" / ")
}

/// The synthetic runs behind the defaults of `CriterionSettings`.
pub fn criteria_experiment(quick: bool) -> anyhow::Result<String> {
    let budgets: &[usize] = if quick {
        &[300, 600]
    } else {
        &[300, 600, 1200]
    };
    let shown: Vec<String> = budgets.iter().map(usize::to_string).collect();
    let shown = shown.join(" / ");
    let d = CriterionSettings::default();
    let mut md = format!(
        "### Criterion defaults: synthetic convergence\n\nAn 8×8 grid (128 triangles) seen from above at 128×128, shaded by a hard shadow line, a small shadow disc inside one square (fig. 4.10) and a smooth ripple; R = 16 per call; mean absolute luminance error of the Gouraud image against the exact shading after {shown} samples (81 to start with; interpolated between calls, so at exactly equal samples). Lower is better. The shadow line and the disc converge (no leaf of 6 pixels or more left to split) near 1,100 samples, so the early budgets tell the criteria apart.\n\n"
    );
    writeln!(
        md,
        "| criterion (defaults) | shadow line | disc | smooth | mean |\n|---|---:|---:|---:|---:|"
    )?;
    for name in CriterionKind::ALL {
        let curves = curves(name, &d, budgets);
        writeln!(
            md,
            "| `{name}` | {} | {} | {} | {} |",
            slashed(&curves[0]),
            slashed(&curves[1]),
            slashed(&curves[2]),
            slashed(&mean_of(&curves))
        )?;
    }
    type Sweep = (
        CriterionKind,
        &'static str,
        fn(f32) -> CriterionSettings,
        &'static [f32],
    );
    let sweeps: [Sweep; 6] = [
        (
            CriterionKind::NldOs,
            "s_ref_start",
            |x| CriterionSettings {
                s_ref_start: x,
                ..Default::default()
            },
            &[0.3, 0.5, 0.8],
        ),
        (
            CriterionKind::NldOs,
            "s_ref_step",
            |x| CriterionSettings {
                s_ref_step: x,
                ..Default::default()
            },
            &[0.05, 0.1, 0.2],
        ),
        (
            // S_min is eq. 4.6's floor; the noise-aware NLD_OS stops at `display_error`.
            CriterionKind::NldOsThesis,
            "s_min",
            |x| CriterionSettings {
                s_min: x,
                ..Default::default()
            },
            &[0.005, 0.02, 0.05, 0.1],
        ),
        (
            CriterionKind::NldOs,
            "large_triangle_fraction",
            |x| CriterionSettings {
                large_triangle_fraction: x,
                ..Default::default()
            },
            &[0.002, 0.005, 0.02],
        ),
        (
            CriterionKind::NldPx,
            "nld_px_epsilon",
            |x| CriterionSettings {
                nld_px_epsilon: x,
                ..Default::default()
            },
            &[0.0, 0.05, 0.3],
        ),
        (
            CriterionKind::NldIs,
            "nld_is_fraction",
            |x| CriterionSettings {
                nld_is_fraction: x,
                ..Default::default()
            },
            &[0.02, 0.1, 0.3],
        ),
    ];
    writeln!(
        md,
        "\n| sweep (others at default) | values | mean error after {shown} samples |\n|---|---|---|"
    )?;
    for (criterion, setting, make, values) in sweeps {
        let errors: Vec<String> = values
            .iter()
            .map(|&x| {
                format!(
                    "{x}: {}",
                    slashed(&mean_of(&curves(criterion, &make(x), budgets)))
                )
            })
            .collect();
        writeln!(
            md,
            "| `{criterion}` {setting} | {values:?} | {} |",
            errors.join(", ")
        )?;
    }
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refining_lowers_the_synthetic_error() {
        let untouched = Synthetic::new(8, 128, Shading::ShadowEdge).error();
        let refined = error_curve(
            Shading::ShadowEdge,
            CriterionKind::NldOs,
            &CriterionSettings::default(),
            &[200, 400],
        );
        assert!(refined[1] < refined[0], "{refined:?}");
        assert!(refined[1] < 0.8 * untouched, "{refined:?} vs {untouched}");
    }
}
