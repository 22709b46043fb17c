//! The headless viewer's record of one run (`snapshots.csv` beside `snapshot_NNN.exr`), read back
//! with Δins and Δrem summed from t = 0 as in the thesis's tables 5.2–5.4 (the viewer writes them
//! per interval between snapshots).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};

#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// Seconds since the viewer's first camera (t = 0, DESIGN.md §10).
    pub time_s: f64,
    /// Triangles shown (Δvis).
    pub shown: u64,
    /// Triangles inserted and removed since t = 0 (Δins, Δrem).
    pub inserted: u64,
    pub removed: u64,
    /// Samples computed so far, and the paths traced for them.
    pub samples: u64,
    pub paths: u64,
    /// Shade requests outstanding at the latest epoch.
    pub outstanding: u64,
    /// The SMA's latest `Stats`: the renderers' busy share, and whether the view converged.
    pub renderer_busy: f64,
    pub converged: bool,
    /// The linear image.
    pub exr: PathBuf,
    /// The mesh and the SMA's memory as the latest `Stats` gave them; `None` in a record
    /// written before the viewer wrote them.
    pub mesh: Option<MeshColumns>,
    /// The SMA's memory against its budget as the latest `Stats` gave it; `None` in a record
    /// written before the viewer wrote it.
    pub budget: Option<BudgetColumns>,
}

/// The memory budget's columns of a snapshot (the viewer's `snapshot_files::CSV_HEADER`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BudgetColumns {
    /// Every part the budget bounds (`--memory-mib`), by capacity.
    pub accounted_bytes: u64,
    pub budget_bytes: u64,
    /// The current views alone needed more: refinement had stopped.
    pub memory_bound: bool,
}

const BUDGET_COLUMNS: [&str; 3] = ["accounted_bytes", "budget_bytes", "memory_bound"];

/// The mesh and memory columns of a snapshot (the viewer's `snapshot_files::CSV_HEADER`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshColumns {
    pub leaves: u64,
    pub cached_samples: u64,
    pub mesh_bytes: u64,
    pub cache_bytes: u64,
    /// The smallest angle of a leaf a split made, degrees, and its smallest ratio to its base
    /// triangle's (none before any split).
    pub smallest_split_angle_deg: Option<f64>,
    pub smallest_split_angle_ratio: Option<f64>,
    pub neighbour_bound_hits: u64,
    pub uniform_merges: u64,
}

const MESH_COLUMNS: [&str; 8] = [
    "leaves",
    "cached_samples",
    "mesh_bytes",
    "cache_bytes",
    "smallest_split_angle_deg",
    "smallest_split_angle_ratio",
    "neighbour_bound_hits",
    "uniform_merges",
];

/// The mesh columns of a row, given their indices in the header.
fn mesh_columns(fields: &[&str], at: [usize; 8]) -> anyhow::Result<MeshColumns> {
    let [leaves, cached, mesh, cache, angle, ratio, hits, merges] = at.map(|i| fields[i]);
    let int = |f: &str| f.parse::<u64>().with_context(|| format!("field {f:?}"));
    let optional = |f: &str| -> anyhow::Result<Option<f64>> {
        (!f.is_empty())
            .then(|| f.parse::<f64>().with_context(|| format!("field {f:?}")))
            .transpose()
    };
    Ok(MeshColumns {
        leaves: int(leaves)?,
        cached_samples: int(cached)?,
        mesh_bytes: int(mesh)?,
        cache_bytes: int(cache)?,
        smallest_split_angle_deg: optional(angle)?,
        smallest_split_angle_ratio: optional(ratio)?,
        neighbour_bound_hits: int(hits)?,
        uniform_merges: int(merges)?,
    })
}

/// All snapshots of a run directory, in the order taken.
pub fn read_run(dir: &Path) -> anyhow::Result<Vec<Snapshot>> {
    let path = dir.join("snapshots.csv");
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    parse(&text, dir).with_context(|| format!("parsing {}", path.display()))
}

fn parse(text: &str, dir: &Path) -> anyhow::Result<Vec<Snapshot>> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: HashMap<&str, usize> = lines
        .next()
        .context("empty file")?
        .split(',')
        .enumerate()
        .map(|(i, h)| (h.trim(), i))
        .collect();
    let column = |name: &str| {
        header
            .get(name)
            .copied()
            .with_context(|| format!("no column {name:?}"))
    };
    let [
        time,
        shown,
        inserted,
        removed,
        samples,
        paths,
        outstanding,
        busy,
        converged,
        exr,
    ] = [
        "time_s",
        "shown",
        "inserted",
        "removed",
        "samples",
        "paths",
        "outstanding",
        "renderer_busy",
        "converged",
        "exr",
    ]
    .map(column);
    let (time, shown, inserted, removed, samples, paths, outstanding, busy, converged, exr) = (
        time?,
        shown?,
        inserted?,
        removed?,
        samples?,
        paths?,
        outstanding?,
        busy?,
        converged?,
        exr?,
    );
    let mesh_at: Option<[usize; 8]> = MESH_COLUMNS
        .iter()
        .map(|name| header.get(name).copied())
        .collect::<Option<Vec<_>>>()
        .map(|v| v.try_into().expect("eight columns"));
    let budget_at: Option<[usize; 3]> = BUDGET_COLUMNS
        .iter()
        .map(|name| header.get(name).copied())
        .collect::<Option<Vec<_>>>()
        .map(|v| v.try_into().expect("three columns"));
    let (mut total_inserted, mut total_removed) = (0, 0);
    lines
        .map(|line| {
            let fields: Vec<&str> = line.split(',').map(str::trim).collect();
            if fields.len() != header.len() {
                bail!(
                    "line {line:?} has {} fields, the header {}",
                    fields.len(),
                    header.len()
                );
            }
            let int = |i: usize| {
                fields[i]
                    .parse::<u64>()
                    .with_context(|| format!("field {:?}", fields[i]))
            };
            total_inserted += int(inserted)?;
            total_removed += int(removed)?;
            Ok(Snapshot {
                time_s: fields[time]
                    .parse()
                    .with_context(|| format!("time {:?}", fields[time]))?,
                shown: int(shown)?,
                inserted: total_inserted,
                removed: total_removed,
                samples: int(samples)?,
                paths: int(paths)?,
                outstanding: int(outstanding)?,
                renderer_busy: fields[busy]
                    .parse()
                    .with_context(|| format!("busy {:?}", fields[busy]))?,
                converged: fields[converged] == "1",
                exr: dir.join(fields[exr]),
                mesh: mesh_at.map(|at| mesh_columns(&fields, at)).transpose()?,
                budget: budget_at
                    .map(|[accounted, budget, bound]| {
                        anyhow::Ok(BudgetColumns {
                            accounted_bytes: int(accounted)?,
                            budget_bytes: int(budget)?,
                            memory_bound: fields[bound] == "1",
                        })
                    })
                    .transpose()?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_insertions_and_removals_from_the_start() {
        let csv = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,outstanding,\
                   renderer_busy,converged,png,exr\n\
                   0,0.000,1,0,0,0,0,0,12,0.000,0,snapshot_000.png,snapshot_000.exr\n\
                   1,1.002,1,700,737,37,1500,96000,0,0.950,0,snapshot_001.png,snapshot_001.exr\n\
                   2,2.001,1,900,300,100,3000,192000,4,1.000,1,snapshot_002.png,snapshot_002.exr\n";
        let run = parse(csv, Path::new("/r")).unwrap();
        assert_eq!(run.len(), 3);
        assert_eq!(
            (run[2].inserted, run[2].removed, run[2].shown),
            (1037, 137, 900)
        );
        assert_eq!(run[1].time_s, 1.002);
        assert_eq!((run[1].paths, run[1].renderer_busy), (96000, 0.95));
        assert!(run[2].converged && !run[1].converged);
        assert_eq!(run[2].exr, Path::new("/r/snapshot_002.exr"));
        assert_eq!(run[2].mesh, None);
    }

    #[test]
    fn reads_the_mesh_columns_where_the_viewer_wrote_them() {
        let csv = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,outstanding,\
                   renderer_busy,converged,leaves,cached_samples,mesh_bytes,cache_bytes,\
                   smallest_split_angle_deg,smallest_split_angle_ratio,neighbour_bound_hits,\
                   uniform_merges,png,exr\n\
                   0,1.0,1,700,737,37,1500,96000,0,0.950,0,900,800,4096,8192,,,0,0,a.png,a.exr\n\
                   1,2.0,1,700,0,0,1600,97000,0,0.950,0,1000,900,4096,8192,12.5000,0.5000,3,7,\
                   b.png,b.exr\n";
        let run = parse(csv, Path::new("/r")).unwrap();
        let first = run[0].mesh.clone().unwrap();
        assert_eq!((first.leaves, first.smallest_split_angle_deg), (900, None));
        let second = run[1].mesh.clone().unwrap();
        assert_eq!(
            (
                second.smallest_split_angle_deg,
                second.smallest_split_angle_ratio,
                second.neighbour_bound_hits,
                second.uniform_merges
            ),
            (Some(12.5), Some(0.5), 3, 7)
        );
        assert_eq!((second.mesh_bytes, second.cache_bytes), (4096, 8192));
    }

    #[test]
    fn a_missing_column_is_an_error() {
        assert!(parse("index,time_s\n0,0.0\n", Path::new(".")).is_err());
    }

    #[test]
    fn reads_the_memory_budget_columns_where_the_viewer_wrote_them() {
        let csv = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,outstanding,\
                   renderer_busy,converged,accounted_bytes,budget_bytes,rss_bytes,memory_bound,png,exr\n\
                   0,0.000,1,0,0,0,0,0,12,0.000,0,1000,4000,,0,snapshot_000.png,snapshot_000.exr\n\
                   1,1.002,1,700,737,37,1500,96000,0,0.950,0,3900,4000,9000,1,snapshot_001.png,snapshot_001.exr\n";
        let run = parse(csv, Path::new("/r")).unwrap();
        let budget = |i: usize| run[i].budget.unwrap();
        assert_eq!(
            (budget(0).accounted_bytes, budget(0).memory_bound),
            (1000, false)
        );
        assert_eq!(
            (budget(1).accounted_bytes, budget(1).budget_bytes),
            (3900, 4000)
        );
        assert!(budget(1).memory_bound);
    }
}
