//! Where the machine's time went in each run (DESIGN.md §10: rest time is meant for the renderer),
//! kept as `<scene>-<view>-cpu.csv` beside the snapshots' CSV: CPU seconds of the renderer(s),
//! the SMA and the viewer over the viewer's run, and the wall time.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use testkit::loopback::CpuShares;

const HEADER: &str = "run,wall_s,renderers_cpu_s,sma_cpu_s,viewer_cpu_s";

pub fn write_csv(path: &Path, runs: &[(String, CpuShares)]) -> anyhow::Result<()> {
    let mut text = format!("{HEADER}\n");
    for (run, c) in runs {
        let _ = writeln!(
            text,
            "{run},{:.2},{:.2},{:.2},{:.2}",
            c.wall_s, c.renderers_s, c.sma_s, c.viewer_s
        );
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// The runs of a view's CSV; none when it was measured before this file existed.
pub fn read_csv(path: &Path) -> anyhow::Result<Vec<(String, CpuShares)>> {
    let Ok(text) = std::fs::read_to_string(path) else {
        return Ok(Vec::new());
    };
    text.lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            anyhow::ensure!(
                f.len() == 5,
                "{}: {line:?} has not 5 fields",
                path.display()
            );
            let num = |i: usize| f[i].parse::<f64>().with_context(|| format!("{:?}", f[i]));
            Ok((
                f[0].to_string(),
                CpuShares {
                    wall_s: num(1)?,
                    renderers_s: num(2)?,
                    sma_s: num(3)?,
                    viewer_s: num(4)?,
                },
            ))
        })
        .collect()
}

/// Each process's CPU time as a share of the machine's cores over the run (the SMA's includes the
/// threads of Mesa's llvmpipe, which draws its visibility passes); the rest went to other processes
/// or was idle.
pub fn table(runs: &[(String, CpuShares)]) -> String {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as f64;
    let mut md = String::from(
        "| run | wall (s) | renderer | SMA | viewer | other or idle |\n|---|---:|---:|---:|---:|---:|\n",
    );
    for (run, c) in runs {
        let share = |s: f64| s / (c.wall_s * cores).max(1e-9);
        let idle = 1.0 - share(c.renderers_s + c.sma_s + c.viewer_s);
        let _ = writeln!(
            md,
            "| {run} | {:.1} | {:.0} % | {:.0} % | {:.0} % | {:.0} % |",
            c.wall_s,
            100.0 * share(c.renderers_s),
            100.0 * share(c.sma_s),
            100.0 * share(c.viewer_s),
            100.0 * idle.max(0.0)
        );
    }
    md
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_shares() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v-cpu.csv");
        let runs = vec![(
            "nld-px".to_string(),
            CpuShares {
                wall_s: 10.0,
                renderers_s: 15.0,
                sma_s: 2.5,
                viewer_s: 0.5,
            },
        )];
        write_csv(&path, &runs).unwrap();
        assert_eq!(read_csv(&path).unwrap(), runs);
        assert!(read_csv(&dir.path().join("none.csv")).unwrap().is_empty());
        let cores = std::thread::available_parallelism().unwrap().get() as f64;
        let md = table(&runs);
        let renderer = format!("{:.0} %", 150.0 / cores);
        assert!(
            md.contains(&format!("| nld-px | 10.0 | {renderer} |")),
            "{md}"
        );
    }
}
