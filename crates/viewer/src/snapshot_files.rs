//! Snapshots on disk: `snapshot_NNN.png` (tone-mapped sRGB), `snapshot_NNN.exr` (linear radiance)
//! and one line per snapshot in `snapshots.csv`, the raw material of the convergence measurements
//! (DESIGN.md §10).

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;

use crate::offscreen::Snapshot;

pub const CSV_NAME: &str = "snapshots.csv";
/// `inserted`/`removed` are summed over the epochs since the previous snapshot (Δins, Δrem);
/// `camera_seq`, `shown`, `samples`, `paths` and `outstanding` are the latest epoch's;
/// `renderer_busy` and `converged` the latest `Stats`' (one interval of the SMA's, about a second).
pub const CSV_HEADER: &str = "index,time_s,camera_seq,shown,inserted,removed,samples,paths,\
                              outstanding,renderer_busy,converged,png,exr";

/// One CSV row.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotRecord {
    pub index: u32,
    pub time_s: f64,
    pub camera_seq: u64,
    pub shown: u64,
    pub inserted: u64,
    pub removed: u64,
    pub samples: u64,
    pub paths: u64,
    pub outstanding: u64,
    pub renderer_busy: f32,
    pub converged: bool,
}

pub struct SnapshotWriter {
    dir: PathBuf,
    csv: std::fs::File,
}

impl SnapshotWriter {
    /// Creates `dir` and a fresh CSV with its header.
    pub fn create(dir: &Path) -> anyhow::Result<SnapshotWriter> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join(CSV_NAME);
        let mut csv =
            std::fs::File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        writeln!(csv, "{CSV_HEADER}")?;
        Ok(SnapshotWriter {
            dir: dir.to_path_buf(),
            csv,
        })
    }

    pub fn write(&mut self, record: &SnapshotRecord, snapshot: &Snapshot) -> anyhow::Result<()> {
        let stem = format!("snapshot_{:03}", record.index);
        let (png, exr) = (format!("{stem}.png"), format!("{stem}.exr"));
        write_png(&self.dir.join(&png), snapshot)?;
        write_exr(&self.dir.join(&exr), snapshot)?;
        let r = record;
        writeln!(
            self.csv,
            "{},{:.3},{},{},{},{},{},{},{},{:.3},{},{png},{exr}",
            r.index,
            r.time_s,
            r.camera_seq,
            r.shown,
            r.inserted,
            r.removed,
            r.samples,
            r.paths,
            r.outstanding,
            r.renderer_busy,
            u8::from(r.converged)
        )?;
        self.csv.flush()?;
        Ok(())
    }
}

pub fn write_png(path: &Path, snapshot: &Snapshot) -> anyhow::Result<()> {
    let rgb = image::DynamicImage::ImageRgba8(snapshot.display.clone()).into_rgb8();
    rgb.save(path)
        .with_context(|| format!("writing {}", path.display()))
}

/// Linear radiance with the coverage as alpha (1: sees geometry, 0: sky), as the ground truth
/// carries it.
pub fn write_exr(path: &Path, snapshot: &Snapshot) -> anyhow::Result<()> {
    let width = snapshot.width as usize;
    exr::prelude::write_rgba_file(path, width, snapshot.height as usize, |x, y| {
        let i = y * width + x;
        let [r, g, b] = snapshot.linear[i];
        (r, g, b, f32::from(u8::from(snapshot.covered[i])))
    })
    .with_context(|| format!("writing {}", path.display()))
}
