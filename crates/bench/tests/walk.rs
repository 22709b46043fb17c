//! `walkthrough-bench walk --quick` end to end on the built-in scene: a short scripted walk with
//! two stops, walked twice by a real system on loopback (renderer, SMA and headless viewer as
//! separate processes) and by the per-pixel viewport. The CSV must judge every stop and moment
//! of both passes for both systems, with sane values, and the plot must be written; the viewer's
//! own frame rate, drawn as its window would, is measured with work while walking on and off.
//!
//! Needs a wgpu adapter (Mesa's llvmpipe without a GPU): without one the test says so and returns,
//! unless `WALKTHROUGH_REQUIRE_GPU` is set, where it fails.

use std::collections::HashMap;
use std::path::Path;

use bench::walk::WalkConfig;

/// One CSV row, by column name.
type Row = HashMap<String, String>;

fn read_csv(path: &Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).expect("the walk's CSV");
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    lines
        .map(|l| {
            header
                .iter()
                .cloned()
                .zip(l.split(',').map(String::from))
                .collect()
        })
        .collect()
}

fn number(row: &Row, column: &str) -> f64 {
    row[column]
        .parse()
        .unwrap_or_else(|e| panic!("{column} {:?}: {e}", row[column]))
}

#[test]
fn a_quick_walk_judges_every_stop_and_moment_of_both_systems() {
    match viewer::gpu::headless_or_skip("walk") {
        Ok(Some(_)) => {}
        Ok(None) => return,
        Err(e) => panic!("{e:#}"),
    }
    let work = tempfile::tempdir().expect("a temporary folder");
    let gt_cache = Path::new(env!("CARGO_TARGET_TMPDIR")).join("walk");
    let config = WalkConfig {
        scene: Some("bracara".into()),
        no_report: true,
        ..WalkConfig::new(
            true,
            work.path().join("out"),
            work.path().join("runs"),
            gt_cache,
        )
    };
    bench::walk::run(config).expect("the quick walk");

    let rows = read_csv(&work.path().join("out/bracara-walk.csv"));
    for system in ["system", "per-pixel"] {
        let of = |kind: &str, pass: &str, n: &str| {
            rows.iter()
                .filter(|r| r["system"] == system && r["kind"] == kind)
                .filter(|r| r["pass"] == pass && r["number"] == n)
                .collect::<Vec<_>>()
        };
        for pass in ["1", "2"] {
            for n in ["1", "2"] {
                let stop = of("stop", pass, n);
                assert!(
                    stop.len() >= 8,
                    "{system} stop {n} of pass {pass}: {}",
                    stop.len()
                );
                for r in &stop {
                    let since = number(r, "since_stop_s");
                    assert!(
                        (0.0..1.6).contains(&since),
                        "{system}: {since} s after stopping"
                    );
                }
                assert_eq!(
                    of("moment", pass, n).len(),
                    1,
                    "{system} moment {n} of pass {pass}"
                );
            }
        }
        for r in rows.iter().filter(|r| r["system"] == system) {
            let flip = number(r, "flip");
            assert!(flip > 0.0 && flip < 1.0, "{system}: FLIP {flip}");
        }
        // The walk starts with nothing shown: at the first stop's end both systems show far
        // better than at its start.
        let first = of("stop", "1", "1");
        let (start, end) = (
            number(first[0], "flip"),
            number(first[first.len() - 1], "flip"),
        );
        assert!(
            end < 0.7 * start,
            "{system}: FLIP {start} at the first stop's start, {end} at its end"
        );
    }
    let system: Vec<&Row> = rows.iter().filter(|r| r["system"] == "system").collect();
    let mut by_time = system.clone();
    by_time.sort_by(|a, b| number(a, "time_s").total_cmp(&number(b, "time_s")));
    assert!(
        by_time
            .windows(2)
            .all(|w| number(w[0], "samples") <= number(w[1], "samples")),
        "the SMA's sample count never falls"
    );
    let last = by_time.last().unwrap();
    assert!(number(last, "samples") > 0.0 && number(last, "leaves") > 0.0);
    assert!(
        number(last, "sma_accounted_mb") > 0.0,
        "the SMA's accounted memory is read from its Stats"
    );
    assert!(
        system.iter().all(|r| number(r, "sma_rss_mb") > 1.0),
        "the SMA's memory is sampled"
    );
    let svg = std::fs::read_to_string(work.path().join("out/bracara-walk.svg")).unwrap();
    assert!(svg.contains("pass 2") && svg.contains("per-pixel"));
    // The viewer's own frames, drawn as its window would, with work while walking on and off.
    let frames = read_csv(&work.path().join("out/bracara-walk-frames.csv"));
    for side in ["on", "off"] {
        let runs: Vec<&Row> = frames
            .iter()
            .filter(|r| r["work_while_walking"] == side)
            .collect();
        assert_eq!(
            runs.len(),
            1,
            "one quick run with work while walking {side}"
        );
        let fps = number(runs[0], "frames_per_s");
        assert!(
            fps > 1.0 && fps <= 61.0,
            "{fps} frames a second with work while walking {side}"
        );
    }
}
