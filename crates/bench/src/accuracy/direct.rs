//! The competitor of `bench accuracy` (DESIGN.md §10): a direct per-pixel render of a view at the
//! interactive preset, its wall time and its own error against the ground truth. Each measurement
//! is kept in `direct.csv` beside `bench convergence`'s CSVs, so a view whose ground truth (an
//! ignored cache of a quarter of an hour a view) is not on this machine keeps its stored figures
//! when the others are measured again; a view whose ground truth is here is always rendered anew.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::Context;

use super::AccuracyConfig;
use crate::convergence::manifest::ViewRecord;
use crate::convergence::{GROUND_TRUTH_SEED, INTERACTIVE_BOUNCES};
use crate::metrics::Reference;

const FILE: &str = "direct.csv";
const HEADER: &str = "stem,width,height,spp,seconds,flip,measured";

/// The competitor on one view.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Direct {
    pub seconds: f64,
    pub flip: f64,
    /// `machine::measured_stamp` of the render.
    pub measured: String,
    /// Read from `direct.csv`, not rendered by this run.
    pub recalled: bool,
}

impl Direct {
    /// Where the figures come from, for the report.
    pub fn provenance(&self) -> String {
        if self.recalled {
            format!(
                "stored, measured {}: the ground truth was not on this machine",
                self.measured
            )
        } else {
            format!("measured {}", self.measured)
        }
    }
}

/// One line of `direct.csv`: the view and terms a direct render was measured on.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct DirectRecord {
    stem: String,
    width: u32,
    height: u32,
    spp: u32,
    direct: Direct,
}

impl DirectRecord {
    fn matches(&self, r: &ViewRecord, spp: u32) -> bool {
        self.describes(r) && self.spp == spp
    }

    /// Whether this is a render of `r`'s view at its size, at any paths per pixel.
    pub(crate) fn describes(&self, r: &ViewRecord) -> bool {
        self.stem == r.view_stem() && self.width == r.width && self.height == r.height
    }

    /// The render's wall time, scene load included.
    pub(crate) fn seconds(&self) -> f64 {
        self.direct.seconds
    }

    /// The render's mean FLIP against the view's ground truth.
    pub(crate) fn flip(&self) -> f64 {
        self.direct.flip
    }

    fn line(&self) -> String {
        let d = &self.direct;
        format!(
            "{},{},{},{},{},{},{}",
            self.stem, self.width, self.height, self.spp, d.seconds, d.flip, d.measured
        )
    }

    fn parse(line: &str) -> anyhow::Result<DirectRecord> {
        let f: Vec<&str> = line.split(',').collect();
        anyhow::ensure!(f.len() == 7, "expected 7 fields ({HEADER})");
        Ok(DirectRecord {
            stem: f[0].into(),
            width: f[1].parse()?,
            height: f[2].parse()?,
            spp: f[3].parse()?,
            direct: Direct {
                seconds: f[4].parse()?,
                flip: f[5].parse()?,
                measured: f[6].into(),
                recalled: true,
            },
        })
    }
}

/// The stored direct renders; none when the file is not there yet.
pub(crate) fn read_records(dir: &Path) -> anyhow::Result<Vec<DirectRecord>> {
    let path = dir.join(FILE);
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(Vec::new());
    };
    text.lines()
        .skip(1)
        .filter(|l| !l.is_empty())
        .map(|l| DirectRecord::parse(l).with_context(|| format!("{}: {l:?}", path.display())))
        .collect()
}

pub(crate) fn write_records(dir: &Path, records: &[DirectRecord]) -> anyhow::Result<()> {
    let lines: Vec<String> = std::iter::once(HEADER.to_string())
        .chain(records.iter().map(DirectRecord::line))
        .collect();
    std::fs::write(dir.join(FILE), lines.join("\n") + "\n")?;
    Ok(())
}

/// The view's direct render: measured when its ground truth is on this machine (and stored in
/// `records`, replacing an older one), else the stored figures of the same terms.
pub(crate) fn measure_or_recall(
    exe: &Path,
    record: &ViewRecord,
    args: &AccuracyConfig,
    records: &mut Vec<DirectRecord>,
) -> anyhow::Result<Direct> {
    let stored = records.iter().position(|d| d.matches(record, args.spp));
    // The same view under another profile was rendered by this run already: one render a view.
    if let Some(i) = stored
        && !records[i].direct.recalled
    {
        return Ok(records[i].direct.clone());
    }
    if !Path::new(&record.ground_truth).is_file() {
        let stored = stored.with_context(|| {
            format!(
                "the ground truth {} of {} is not on this machine and {FILE} holds no direct render \
                 of it at {} paths per pixel: render it with `bench convergence --ground-truths-only`",
                record.ground_truth,
                record.stem(),
                args.spp
            )
        })?;
        eprintln!(
            "accuracy: {}: no ground truth here, the stored direct render is kept",
            record.stem()
        );
        return Ok(records[stored].direct.clone());
    }
    eprintln!(
        "accuracy: direct render of {} {} at {} paths per pixel…",
        record.label, record.view, args.spp
    );
    let direct = direct_render(exe, record, args)?;
    let line = DirectRecord {
        stem: record.view_stem(),
        width: record.width,
        height: record.height,
        spp: args.spp,
        direct: direct.clone(),
    };
    match stored {
        Some(i) => records[i] = line,
        None => records.push(line),
    }
    Ok(direct)
}

/// Times `walkthrough renderer reference` at the interactive preset as a user would run it (scene
/// load and BVH build included, as in the thesis's Radiance times), and measures its image.
fn direct_render(exe: &Path, r: &ViewRecord, args: &AccuracyConfig) -> anyhow::Result<Direct> {
    std::fs::create_dir_all(&args.direct)?;
    let out = args.direct.join(format!(
        "{}-{}x{}-{}spp.exr",
        r.view_stem(),
        r.width,
        r.height,
        args.spp
    ));
    let seconds = timed_reference(exe, r, args.spp, &out, false)?;
    let reference = Reference::read_exr(Path::new(&r.ground_truth))?;
    let flip = reference
        .error_of(&crate::metrics::LinearImage::read_exr(&out)?)?
        .flip;
    Ok(Direct {
        seconds,
        flip,
        measured: crate::machine::measured_stamp(),
        recalled: false,
    })
}

/// Runs `walkthrough renderer reference` of `r`'s view at `spp` paths per pixel into `out` (with
/// the albedo and normal images beside it when `features`), and returns its wall time.
pub(crate) fn timed_reference(
    exe: &Path,
    r: &ViewRecord,
    spp: u32,
    out: &Path,
    features: bool,
) -> anyhow::Result<f64> {
    let started = Instant::now();
    let status = Command::new(exe)
        .args([
            "renderer",
            "reference",
            "--scene",
            &r.scene,
            "--view",
            &r.view,
        ])
        .args([
            "--width",
            &r.width.to_string(),
            "--height",
            &r.height.to_string(),
        ])
        .args([
            "--spp",
            &spp.to_string(),
            "--bounces",
            &INTERACTIVE_BOUNCES.to_string(),
        ])
        // Sharing the ground truth's per-pixel streams would replay its first paths and flatter
        // the per-pixel render's error.
        .args(["--seed", &(GROUND_TRUTH_SEED + 1).to_string()])
        .args(features.then_some("--features"))
        .arg("--out")
        .arg(out)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .status()
        .context("starting the per-pixel render")?;
    let seconds = started.elapsed().as_secs_f64();
    anyhow::ensure!(
        status.success(),
        "the per-pixel render of {} at {spp} spp failed ({status})",
        r.stem()
    );
    Ok(seconds)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(ground_truth: &str) -> ViewRecord {
        ViewRecord {
            label: "bracara".into(),
            scene: "bracara".into(),
            view: "VT".into(),
            width: 64,
            height: 48,
            gt_spp: 1024,
            seconds: 60.0,
            sample_counts: vec![1000],
            ground_truth: ground_truth.into(),
            measured: String::new(),
            profile: sma::config::Profile::Today,
        }
    }

    fn config(dir: &Path) -> AccuracyConfig {
        AccuracyConfig {
            convergence: dir.into(),
            levels: vec![0.1],
            spp: 64,
            direct: dir.join("direct"),
            per_pixel_spp: vec![],
            per_pixel_max_seconds: 1.0,
            denoise: false,
            no_report: true,
            textured: false,
        }
    }

    #[test]
    fn a_view_without_its_ground_truth_keeps_its_stored_render_and_says_so() {
        let dir = tempfile::tempdir().unwrap();
        let stored = DirectRecord {
            stem: "bracara-VT".into(),
            width: 64,
            height: 48,
            spp: 64,
            direct: Direct {
                seconds: 13.25,
                flip: 0.0231,
                measured: "2026-12-03 at 24a570b".into(),
                recalled: false,
            },
        };
        write_records(dir.path(), std::slice::from_ref(&stored)).unwrap();
        let mut records = read_records(dir.path()).unwrap();
        let missing = dir.path().join("no-such-gt.exr");
        let direct = measure_or_recall(
            Path::new("/nonexistent/walkthrough"),
            &view(&missing.to_string_lossy()),
            &config(dir.path()),
            &mut records,
        )
        .unwrap();
        assert_eq!((direct.seconds, direct.flip), (13.25, 0.0231));
        assert!(direct.recalled);
        assert!(
            direct
                .provenance()
                .contains("stored, measured 2026-12-03 at 24a570b")
        );
    }

    #[test]
    fn a_view_with_neither_ground_truth_nor_stored_render_is_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut records = Vec::new();
        let err = measure_or_recall(
            Path::new("/nonexistent/walkthrough"),
            &view("no-such-gt.exr"),
            &config(dir.path()),
            &mut records,
        )
        .unwrap_err();
        assert!(err.to_string().contains("--ground-truths-only"), "{err}");
    }
}
