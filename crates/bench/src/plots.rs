//! Convergence plots (DESIGN.md §10): the error against time and against paths traced, and the
//! renderers' busy share over time, one line per criterion and one for the run without
//! refinement; and panels of lines of any series (`bench walk`). SVG, because text in plotters' bitmap backend
//! needs system font libraries (DEPENDENCY-NOTES.md).

use std::path::Path;

use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::convergence::record::{Measurement, run_labels, run_rows};

type Metric = (&'static str, fn(&Measurement) -> f64);
type Axis = (&'static str, fn(&Measurement) -> f64);

const FLIP: Metric = ("mean LDR-FLIP", |m| m.error.flip);
const RMSE: Metric = ("RMSE (sRGB, 0..1)", |m| m.error.rmse);
const BUSY: Metric = ("renderer busy share", |m| m.renderer_busy);
const TIME: Axis = ("time (s)", |m| m.time_s);
const PATHS: Axis = ("paths traced", |m| m.paths as f64);
/// The panels, row by row.
const PANELS: [(Metric, Axis); 4] = [(FLIP, TIME), (FLIP, PATHS), (RMSE, TIME), (BUSY, TIME)];

/// A 2×2 SVG: FLIP against time and against paths traced; RMSE and the renderers' busy share
/// against time.
pub fn error_panels(path: &Path, title: &str, rows: &[Measurement]) -> anyhow::Result<()> {
    let root = SVGBackend::new(path, (1100, 760)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(plot_error)?;
    let panels = root.split_evenly((2, 2));
    for (panel, (metric, axis)) in panels.iter().zip(PANELS) {
        panel_chart(panel, rows, metric, axis)?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

/// One panel of [`line_panels`]: its title, axes' names and one line per named series.
pub struct Panel {
    pub title: String,
    pub x_name: &'static str,
    pub y_name: &'static str,
    pub series: Vec<(String, Vec<(f64, f64)>)>,
}

/// An SVG of panels two a row, each with linear axes from 0 (the walk's plots).
pub fn line_panels(path: &Path, title: &str, panels: &[Panel]) -> anyhow::Result<()> {
    let rows = panels.len().div_ceil(2).max(1);
    let root = SVGBackend::new(path, (1100, 380 * rows as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let root = root.titled(title, ("sans-serif", 22)).map_err(plot_error)?;
    let areas = root.split_evenly((rows, 2));
    for (area, panel) in areas.iter().zip(panels) {
        let points = panel.series.iter().flat_map(|(_, p)| p.iter());
        let x_max = points.clone().map(|p| p.0).fold(1.0, f64::max);
        let y_max = points.map(|p| p.1).fold(0.0, f64::max).max(1e-3) * 1.05;
        let chart = ChartBuilder::on(area)
            .caption(&panel.title, ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..x_max, 0.0..y_max)
            .map_err(plot_error)?;
        draw_chart(chart, (panel.x_name, panel.y_name), &panel.series)?;
    }
    root.present().map_err(plot_error)?;
    Ok(())
}

fn panel_chart(
    area: &DrawingArea<SVGBackend, Shift>,
    rows: &[Measurement],
    metric: Metric,
    axis: Axis,
) -> anyhow::Result<()> {
    let (y_name, y_of) = metric;
    let (x_name, x_of) = axis;
    // Paths span decades (0 at t = 0 is left out of the log axis).
    let log_x = x_name == PATHS.0;
    let series: Vec<(String, Vec<(f64, f64)>)> = run_labels(rows)
        .into_iter()
        .map(|label| {
            let points = run_rows(rows, &label)
                .into_iter()
                .map(|m| (x_of(m), y_of(m)))
                .filter(|(x, _)| !log_x || *x > 0.0)
                .collect();
            (label, points)
        })
        .collect();
    let all = series.iter().flat_map(|(_, p)| p.iter());
    let x_min = all.clone().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let x_max = all.clone().map(|p| p.0).fold(1.0, f64::max);
    let y_max = all.map(|p| p.1).fold(0.0, f64::max).max(1e-3) * 1.05;
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55);
    let names = (x_name, y_name);
    if log_x {
        let x_range = (x_min.min(x_max) * 0.8).max(1.0)..x_max * 1.25;
        let chart = builder.build_cartesian_2d(x_range.log_scale(), 0.0..y_max);
        draw_chart(chart.map_err(plot_error)?, names, &series)
    } else {
        let chart = builder.build_cartesian_2d(0.0..x_max, 0.0..y_max);
        draw_chart(chart.map_err(plot_error)?, names, &series)
    }
}

fn draw_chart<'a, X>(
    mut chart: ChartContext<'a, SVGBackend<'a>, Cartesian2d<X, RangedCoordf64>>,
    (x_name, y_name): (&str, &str),
    series: &[(String, Vec<(f64, f64)>)],
) -> anyhow::Result<()>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    // Only the labelled grid lines: the fine ones crowd the small panels.
    chart
        .configure_mesh()
        .light_line_style(TRANSPARENT)
        .x_labels(6)
        .x_label_formatter(&|x| format!("{x:.0}"))
        .x_desc(x_name)
        .y_desc(y_name)
        .draw()
        .map_err(plot_error)?;
    for (i, (label, points)) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                colour.stroke_width(2),
            ))
            .map_err(plot_error)?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.85))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(plot_error)?;
    Ok(())
}

/// plotters' errors borrow the backend; keep the message only.
fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("plotting: {e}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convergence::record::test_measurement;

    #[test]
    fn line_panels_name_every_panel_and_series() {
        let panel = |title: &str, series: &str| Panel {
            title: title.into(),
            x_name: "step",
            y_name: "FLIP",
            series: vec![(series.into(), vec![(0.0, 0.5), (10.0, 0.2)])],
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("w.svg");
        line_panels(
            &path,
            "walk",
            &[panel("along", "system"), panel("memory", "pass 2")],
        )
        .unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for word in ["walk", "along", "memory", "system", "pass 2"] {
            assert!(svg.contains(word), "{word}");
        }
    }

    #[test]
    fn writes_an_svg_with_every_run_in_the_legend() {
        let m = |run: &str, t: f64, flip: f64| test_measurement(run, t, (t * 1000.0) as u64, flip);
        let rows = [
            m("nld-os", 0.0, 0.9),
            m("nld-os", 1.0, 0.2),
            m("rnd", 0.0, 0.9),
            m("rnd", 1.0, 0.4),
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.svg");
        error_panels(&path, "bracara VT", &rows).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("nld-os") && svg.contains("rnd") && svg.contains("bracara VT"));
    }
}
