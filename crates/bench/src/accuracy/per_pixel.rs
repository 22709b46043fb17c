//! The per-pixel competitors of `bench accuracy` (DESIGN.md §10), what a person compares the
//! system with today: the project's renderer per pixel at 1, 2, 4, … paths per pixel, each a
//! timed run of `renderer reference` (wall time with the scene's load, a seed other than the
//! ground truth's), and each of those images denoised by Intel Open Image Denoise ("high"
//! quality, with the albedo and normal images `reference --features` writes beside it; the
//! denoiser's warm time is added to the render's). Kept in `per_pixel.csv` beside the
//! convergence CSVs, like `direct.csv`, so a view whose ground truth is not on this machine keeps
//! its stored figures.

use std::path::Path;

use anyhow::Context;

use super::AccuracyConfig;
use super::denoise::Denoiser;
use super::direct::timed_reference;
use crate::convergence::manifest::ViewRecord;
use crate::metrics::{LinearImage, Reference};

const FILE: &str = "per_pixel.csv";
const HEADER: &str = "stem,width,height,spp,seconds,flip,denoised_seconds,denoised_flip,measured";

/// One per-pixel render of a view.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PerPixel {
    pub spp: u32,
    /// Wall time of the render, the scene's load included.
    pub seconds: f64,
    pub flip: f64,
    /// The same image denoised: the render's time plus the denoiser's, and its error.
    pub denoised: Option<(f64, f64)>,
    pub measured: String,
}

/// A line of `per_pixel.csv`.
#[derive(Clone, Debug, PartialEq)]
struct Stored {
    stem: String,
    width: u32,
    height: u32,
    render: PerPixel,
}

impl Stored {
    fn describes(&self, r: &ViewRecord) -> bool {
        self.stem == r.view_stem() && self.width == r.width && self.height == r.height
    }

    fn line(&self) -> String {
        let p = &self.render;
        let (ds, df) = p.denoised.map_or((String::new(), String::new()), |(s, f)| {
            (s.to_string(), f.to_string())
        });
        format!(
            "{},{},{},{},{},{},{ds},{df},{}",
            self.stem, self.width, self.height, p.spp, p.seconds, p.flip, p.measured
        )
    }

    fn parse(line: &str) -> anyhow::Result<Stored> {
        let f: Vec<&str> = line.split(',').collect();
        anyhow::ensure!(f.len() == 9, "expected 9 fields ({HEADER})");
        let denoised = match (f[6], f[7]) {
            ("", "") => None,
            (s, e) => Some((s.parse()?, e.parse()?)),
        };
        Ok(Stored {
            stem: f[0].into(),
            width: f[1].parse()?,
            height: f[2].parse()?,
            render: PerPixel {
                spp: f[3].parse()?,
                seconds: f[4].parse()?,
                flip: f[5].parse()?,
                denoised,
                measured: f[8].into(),
            },
        })
    }
}

/// The per-pixel competitors stored in `dir`, by view.
pub(crate) struct PerPixelRecords {
    stored: Vec<Stored>,
}

impl PerPixelRecords {
    pub(crate) fn read(dir: &Path) -> anyhow::Result<PerPixelRecords> {
        let path = dir.join(FILE);
        let Ok(text) = std::fs::read_to_string(&path) else {
            return Ok(PerPixelRecords { stored: vec![] });
        };
        let stored = text
            .lines()
            .skip(1)
            .filter(|l| !l.is_empty())
            .map(|l| Stored::parse(l).with_context(|| format!("{}: {l:?}", path.display())))
            .collect::<anyhow::Result<_>>()?;
        Ok(PerPixelRecords { stored })
    }

    pub(crate) fn write(&self, dir: &Path) -> anyhow::Result<()> {
        let lines: Vec<String> = std::iter::once(HEADER.to_string())
            .chain(self.stored.iter().map(Stored::line))
            .collect();
        Ok(std::fs::write(dir.join(FILE), lines.join("\n") + "\n")?)
    }

    fn of(&self, r: &ViewRecord) -> Vec<PerPixel> {
        self.stored
            .iter()
            .filter(|s| s.describes(r))
            .map(|s| s.render.clone())
            .collect()
    }

    /// The view's renders: measured when its ground truth is on this machine (replacing the
    /// stored ones), else those stored. One measurement a view, whichever profile asks.
    pub(crate) fn measure_or_recall(
        &mut self,
        exe: &Path,
        r: &ViewRecord,
        args: &AccuracyConfig,
        denoiser: Option<&Denoiser>,
        measured_now: &mut Vec<String>,
    ) -> anyhow::Result<Vec<PerPixel>> {
        if measured_now.contains(&r.view_stem()) || !Path::new(&r.ground_truth).is_file() {
            return Ok(self.of(r));
        }
        let renders = measure(exe, r, args, denoiser)?;
        self.stored.retain(|s| !s.describes(r));
        self.stored.extend(renders.iter().map(|p| Stored {
            stem: r.view_stem(),
            width: r.width,
            height: r.height,
            render: p.clone(),
        }));
        measured_now.push(r.view_stem());
        Ok(renders)
    }
}

/// Renders at each of `args.per_pixel_spp` until one takes longer than
/// `args.per_pixel_max_seconds`.
fn measure(
    exe: &Path,
    r: &ViewRecord,
    args: &AccuracyConfig,
    denoiser: Option<&Denoiser>,
) -> anyhow::Result<Vec<PerPixel>> {
    let reference = Reference::read_exr(Path::new(&r.ground_truth))?;
    std::fs::create_dir_all(&args.direct)?;
    let mut renders = Vec::new();
    for &spp in &args.per_pixel_spp {
        eprintln!("accuracy: {} {} per pixel at {spp} spp…", r.label, r.view);
        let out = args.direct.join(format!(
            "{}-{}x{}-{spp}spp-features.exr",
            r.view_stem(),
            r.width,
            r.height
        ));
        let seconds = timed_reference(exe, r, spp, &out, denoiser.is_some())?;
        let color = LinearImage::read_exr(&out)?;
        let flip = reference.error_of(&color)?.flip;
        let denoised = match denoiser {
            None => None,
            Some(d) => {
                let feature = |name| LinearImage::read_exr(&renderer::features::beside(&out, name));
                let (image, denoise_seconds) =
                    d.denoise(&color, &feature("albedo")?, &feature("normal")?)?;
                Some((seconds + denoise_seconds, reference.error_of(&image)?.flip))
            }
        };
        renders.push(PerPixel {
            spp,
            seconds,
            flip,
            denoised,
            measured: crate::machine::measured_stamp(),
        });
        if seconds > args.per_pixel_max_seconds {
            break;
        }
    }
    Ok(renders)
}

/// The shortest time at which a competitor's render has a mean FLIP at or below `level`: the
/// plain renders', or with `denoised` the denoised ones'.
pub(crate) fn time_to_level(renders: &[PerPixel], level: f64, denoised: bool) -> Option<f64> {
    renders
        .iter()
        .filter_map(|p| {
            if denoised {
                p.denoised
            } else {
                Some((p.seconds, p.flip))
            }
        })
        .filter(|&(_, flip)| flip <= level)
        .map(|(seconds, _)| seconds)
        .min_by(f64::total_cmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn render(spp: u32, seconds: f64, flip: f64, denoised: Option<(f64, f64)>) -> PerPixel {
        PerPixel {
            spp,
            seconds,
            flip,
            denoised,
            measured: "today".into(),
        }
    }

    #[test]
    fn lines_round_trip_with_and_without_the_denoised_image() {
        for denoised in [None, Some((1.5, 0.04))] {
            let stored = Stored {
                stem: "bracara-VT".into(),
                width: 512,
                height: 384,
                render: render(4, 0.75, 0.125, denoised),
            };
            assert_eq!(Stored::parse(&stored.line()).unwrap(), stored);
        }
        assert!(Stored::parse("bracara-VT,512").is_err());
    }

    #[test]
    fn the_time_to_a_level_is_the_first_render_that_reaches_it() {
        let renders = [
            render(1, 0.3, 0.2, Some((1.3, 0.06))),
            render(2, 0.5, 0.12, Some((1.5, 0.04))),
            render(4, 0.9, 0.08, Some((1.9, 0.03))),
        ];
        assert_eq!(time_to_level(&renders, 0.1, false), Some(0.9));
        assert_eq!(time_to_level(&renders, 0.05, false), None);
        assert_eq!(time_to_level(&renders, 0.05, true), Some(1.5));
        assert_eq!(time_to_level(&renders, 0.1, true), Some(1.3));
    }
}
