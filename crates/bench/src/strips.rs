//! Image strips like the thesis's appendix B (figures B.1–B.3): the first row without refinement,
//! then one row per criterion with its images at 1, 2, 3, 4 and 5 s, and the ground truth last.
//! Every image is tone-mapped like the error measure sees it (DESIGN.md §10) and shrunk, so the
//! strips stay small enough to commit.

use std::path::Path;

use anyhow::Context;
use image::{RgbImage, imageops};

use crate::convergence::record::{Measurement, at_time, run_rows};
use crate::metrics::{LinearImage, Reference};

/// The instants of appendix B.
const STRIP_SECONDS: [f64; 5] = [1.0, 2.0, 3.0, 4.0, 5.0];
const THUMB_WIDTH: u32 = 192;
const GAP: u32 = 4;
/// A cell with no snapshot (the run ended earlier).
const EMPTY: image::Rgb<u8> = image::Rgb([200, 200, 200]);

/// `no_refinement`: the run without refinement's last snapshot; `criteria`: the rows, in order.
pub fn write_strip(
    path: &Path,
    reference: &Reference,
    rows: &[Measurement],
    no_refinement: Option<&Measurement>,
    criteria: &[String],
) -> anyhow::Result<()> {
    let (w, h) = (reference.image.width, reference.image.height);
    let thumb_height = (THUMB_WIDTH * h / w.max(1)).max(1);
    let mut grid: Vec<Vec<Option<RgbImage>>> = vec![vec![
        no_refinement
            .map(|m| thumb(reference, m, thumb_height))
            .transpose()?,
    ]];
    for criterion in criteria {
        let run = run_rows(rows, criterion);
        grid.push(
            STRIP_SECONDS
                .iter()
                .map(|t| {
                    at_time(&run, *t)
                        .map(|m| thumb(reference, m, thumb_height))
                        .transpose()
                })
                .collect::<anyhow::Result<_>>()?,
        );
    }
    let gt = RgbImage::from_raw(w, h, reference.tone_mapped(&reference.image))
        .context("ground truth size")?;
    grid.push(vec![Some(imageops::thumbnail(
        &gt,
        THUMB_WIDTH,
        thumb_height,
    ))]);

    let columns = STRIP_SECONDS.len() as u32;
    let canvas_w = columns * THUMB_WIDTH + (columns - 1) * GAP;
    let canvas_h = grid.len() as u32 * (thumb_height + GAP) - GAP;
    let mut canvas = RgbImage::from_pixel(canvas_w, canvas_h, image::Rgb([255, 255, 255]));
    for (r, row) in grid.iter().enumerate() {
        for (c, cell) in row.iter().enumerate() {
            let (x, y) = (
                c as u32 * (THUMB_WIDTH + GAP),
                r as u32 * (thumb_height + GAP),
            );
            match cell {
                Some(image) => imageops::replace(&mut canvas, image, x.into(), y.into()),
                None => imageops::replace(
                    &mut canvas,
                    &RgbImage::from_pixel(THUMB_WIDTH, thumb_height, EMPTY),
                    x.into(),
                    y.into(),
                ),
            }
        }
    }
    canvas
        .save(path)
        .with_context(|| format!("writing {}", path.display()))
}

fn thumb(reference: &Reference, m: &Measurement, thumb_height: u32) -> anyhow::Result<RgbImage> {
    let exr = m.exr.as_ref().context("a measurement without its image")?;
    let image = LinearImage::read_exr(exr)?;
    let full = RgbImage::from_raw(image.width, image.height, reference.tone_mapped(&image))
        .context("image size")?;
    Ok(imageops::thumbnail(&full, THUMB_WIDTH, thumb_height))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convergence::record::test_measurement;

    #[test]
    fn lays_out_appendix_b_rows() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (384usize, 288usize);
        let exr = dir.path().join("s.exr");
        let grey = vec![glam::Vec3::splat(0.5); w * h];
        renderer::image_files::write_exr(&exr, w as u32, h as u32, &grey).unwrap();
        let reference = Reference::new(LinearImage {
            width: w as u32,
            height: h as u32,
            rgb: vec![[1.0; 3]; w * h],
            alpha: None,
        });
        let m = |t: f64| Measurement {
            exr: Some(exr.clone()),
            ..test_measurement("nld-os", t, 1, 0.1)
        };
        let rows = [m(1.0), m(2.0)];
        let path = dir.path().join("strip.png");
        write_strip(
            &path,
            &reference,
            &rows,
            Some(&m(9.0)),
            &["nld-os".into(), "rnd".into()],
        )
        .unwrap();
        let strip = image::open(&path).unwrap().into_rgb8();
        // Rows: no refinement, nld-os, rnd, ground truth; 144-pixel thumbnails of a 4:3 image.
        assert_eq!(strip.dimensions(), (5 * 192 + 4 * 4, 4 * 144 + 3 * 4));
        // nld-os at 3 s was never taken: that cell is empty; at 1 s it shows the grey image.
        assert_eq!(*strip.get_pixel(2 * 196 + 10, 148 + 10), EMPTY);
        assert_ne!(*strip.get_pixel(10, 148 + 10), EMPTY);
    }
}
