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
    /// The SMA's mesh leaves and cached samples, as its latest `Stats` says (0 in a record
    /// written before the viewer recorded them).
    pub leaves: u64,
    pub cached_samples: u64,
    /// The linear image.
    pub exr: PathBuf,
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
    // Columns a record written by an older viewer lacks.
    let leaves = header.get("leaves").copied();
    let cached_samples = header.get("cached_samples").copied();
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
                leaves: leaves.map_or(Ok(0), int)?,
                cached_samples: cached_samples.map_or(Ok(0), int)?,
                exr: dir.join(fields[exr]),
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
        assert_eq!(run[2].leaves, 0, "an older record has no leaves column");
    }

    #[test]
    fn reads_the_memory_the_stats_report() {
        let csv = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,outstanding,\
                   renderer_busy,converged,leaves,cached_samples,png,exr\n\
                   0,0.500,1,7,7,0,10,640,0,0.500,0,1200,3400,snapshot_000.png,snapshot_000.exr\n";
        let run = parse(csv, Path::new("/r")).unwrap();
        assert_eq!((run[0].leaves, run[0].cached_samples), (1200, 3400));
    }

    #[test]
    fn a_missing_column_is_an_error() {
        assert!(parse("index,time_s\n0,0.0\n", Path::new(".")).is_err());
    }
}
