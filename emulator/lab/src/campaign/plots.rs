//! A campaign's figures: the touchdown footprint with its 3-sigma ellipse, histograms
//! of touchdown speed and propellant used, and every case's altitude-speed trace over
//! the nominal one. Drawn with plotters and the bundled font of [`crate::plot`].

use super::case::CaseResult;
use super::summary::Merged;
use crate::plot::{register_font, PlotError, FONT_FAMILY};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The files [`write_all`] writes.
pub const FIGURES: [&str; 4] = [
    "footprint.png",
    "touchdown-speed.png",
    "propellant.png",
    "altitude-speed.png",
];

const BLUE: RGBColor = RGBColor(31, 119, 180);
const RED: RGBColor = RGBColor(214, 39, 40);
const GREY: RGBColor = RGBColor(150, 150, 150);

fn backend_err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Backend {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

type Chart<'a> = ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Axes, labels and grid in the style of every oils figure.
fn mesh(chart: &mut Chart, x_desc: &str, y_desc: &str, path: &Path) -> Result<(), PlotError> {
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style((FONT_FAMILY, 15).into_font())
        .axis_desc_style((FONT_FAMILY, 16).into_font())
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(|e| backend_err(path)(&e))
}

/// The legend box.
fn legend(chart: &mut Chart, position: SeriesLabelPosition, path: &Path) -> Result<(), PlotError> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FONT_FAMILY, 15).into_font())
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| backend_err(path)(&e))
}

fn range(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (lo, hi) = values
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    if lo > hi {
        return None;
    }
    let span = (hi - lo).max(1e-9 * hi.abs().max(1.0));
    Some((lo - 0.05 * span, hi + 0.05 * span))
}

/// Writes the campaign's figures into `dir`; returns their paths.
pub fn write_all(merged: &Merged, dir: &Path) -> Result<Vec<PathBuf>, PlotError> {
    register_font()?;
    std::fs::create_dir_all(dir).map_err(|e| PlotError::Backend {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    let title = format!(
        "{}: {} cases, {}",
        merged.summary.name, merged.summary.merged, merged.summary.propulsion
    );
    let mut written = Vec::new();
    let path = dir.join(FIGURES[0]);
    footprint(merged, &path, &title)?;
    written.push(path);
    let td: Vec<&CaseResult> = merged
        .results
        .iter()
        .filter(|r| r.touchdown.is_some())
        .collect();
    let limits = &merged.nominal_limits;
    let path = dir.join(FIGURES[1]);
    histograms(
        &path,
        &format!("{title}: touchdown speed"),
        &[
            (
                "vertical speed at touchdown [m/s]",
                td.iter()
                    .filter_map(|r| r.touchdown.map(|t| t.vertical_speed_mps))
                    .collect(),
                Some(limits.0),
            ),
            (
                "horizontal speed at touchdown [m/s]",
                td.iter()
                    .filter_map(|r| r.touchdown.map(|t| t.horizontal_speed_mps))
                    .collect(),
                Some(limits.1),
            ),
        ],
    )?;
    written.push(path);
    let path = dir.join(FIGURES[2]);
    histograms(
        &path,
        &format!("{title}: propellant"),
        &[(
            "propellant used [kg]",
            merged
                .results
                .iter()
                .filter(|r| !r.digest.is_empty())
                .map(|r| r.propellant_used_kg)
                .collect(),
            None,
        )],
    )?;
    written.push(path);
    let path = dir.join(FIGURES[3]);
    traces(merged, &path, &title)?;
    written.push(path);
    Ok(written)
}

fn footprint(merged: &Merged, path: &Path, title: &str) -> Result<(), PlotError> {
    let err = backend_err(path);
    let nominal = &merged.nominal;
    let pts: Vec<(f64, f64, bool)> = merged
        .results
        .iter()
        .filter(|r| r.touchdown.is_some())
        .map(|r| {
            let nan = |x: Option<f64>| x.unwrap_or(f64::NAN);
            (
                nan(r.downrange_m) - nan(nominal.downrange_m),
                nan(r.crossrange_m) - nan(nominal.crossrange_m),
                r.outcome == "landed",
            )
        })
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let ellipse = merged
        .summary
        .footprint_3sigma
        .as_ref()
        .map(|e| e.outline(120))
        .unwrap_or_default();
    let xs = pts
        .iter()
        .map(|p| p.0)
        .chain(ellipse.iter().map(|p| p.0))
        .chain([0.0]);
    let ys = pts
        .iter()
        .map(|p| p.1)
        .chain(ellipse.iter().map(|p| p.1))
        .chain([0.0]);
    let (x0, x1) = range(xs).ok_or_else(|| PlotError::NoData("footprint".into()))?;
    let (y0, y1) = range(ys).ok_or_else(|| PlotError::NoData("footprint".into()))?;
    let root = BitMapBackend::new(path, (1000, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{title}: touchdown footprint about the nominal"),
            (FONT_FAMILY, 22).into_font(),
        )
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    mesh(
        &mut chart,
        "downrange from nominal touchdown [m]",
        "crossrange [m]",
        path,
    )?;
    chart
        .draw_series(
            pts.iter()
                .filter(|p| p.2)
                .map(|p| Circle::new((p.0, p.1), 3, BLUE.mix(0.6).filled())),
        )
        .map_err(|e| err(&e))?
        .label("landed")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.filled()));
    chart
        .draw_series(
            pts.iter()
                .filter(|p| !p.2)
                .map(|p| Circle::new((p.0, p.1), 4, RED.filled())),
        )
        .map_err(|e| err(&e))?
        .label("crashed")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, RED.filled()));
    if !ellipse.is_empty() {
        chart
            .draw_series(LineSeries::new(ellipse, BLACK.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label("3-sigma ellipse")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    }
    chart
        .draw_series([Cross::new((0.0, 0.0), 8, BLACK.stroke_width(2))])
        .map_err(|e| err(&e))?
        .label("nominal")
        .legend(|(x, y)| Cross::new((x + 10, y), 5, BLACK.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::UpperRight, path)?;
    root.present().map_err(|e| err(&e))
}

type Histogram<'a> = (&'a str, Vec<f64>, Option<f64>);

fn histograms(path: &Path, title: &str, panels: &[Histogram]) -> Result<(), PlotError> {
    let err = backend_err(path);
    let root = BitMapBackend::new(path, (1200, 40 + 380 * panels.len() as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(title, (FONT_FAMILY, 24).into_font())
        .map_err(|e| err(&e))?;
    for (area, (label, values, limit)) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
        let (lo, hi) = range(values.iter().copied().chain(*limit))
            .ok_or_else(|| PlotError::NoData(label.to_string()))?;
        let bins = ((values.len() as f64).sqrt().ceil() as usize).clamp(5, 60);
        let width = (hi - lo) / bins as f64;
        let mut counts = vec![0u32; bins];
        for v in values.iter().filter(|v| v.is_finite()) {
            let b = (((v - lo) / width) as usize).min(bins - 1);
            counts[b] += 1;
        }
        let top = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(lo..hi, 0.0..top)
            .map_err(|e| err(&e))?;
        mesh(&mut chart, label, "cases", path)?;
        chart
            .draw_series(counts.iter().enumerate().map(|(i, &c)| {
                let x0 = lo + i as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width, c as f64)], BLUE.mix(0.7).filled())
            }))
            .map_err(|e| err(&e))?;
        if let Some(l) = limit {
            chart
                .draw_series(LineSeries::new([(*l, 0.0), (*l, top)], RED.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label("landing limit")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
            legend(&mut chart, SeriesLabelPosition::UpperRight, path)?;
        }
    }
    root.present().map_err(|e| err(&e))
}

fn speed(r: &CaseResult, i: usize) -> f64 {
    let t = &r.trace;
    (t.horizontal_speed_m_s[i] as f64).hypot(t.vertical_speed_m_s[i] as f64)
}

fn traces(merged: &Merged, path: &Path, title: &str) -> Result<(), PlotError> {
    let err = backend_err(path);
    let all = merged.results.iter().chain([&merged.nominal]);
    let xs = all
        .clone()
        .flat_map(|r| (0..r.trace.t_s.len()).map(move |i| speed(r, i)));
    let ys = all.flat_map(|r| r.trace.altitude_m.iter().map(|a| *a as f64));
    let (x0, x1) = range(xs).ok_or_else(|| PlotError::NoData("traces".into()))?;
    let (y0, y1) = range(ys).ok_or_else(|| PlotError::NoData("traces".into()))?;
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{title}: altitude against speed"),
            (FONT_FAMILY, 22).into_font(),
        )
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x0.max(0.0)..x1, y0.max(0.0)..y1)
        .map_err(|e| err(&e))?;
    mesh(&mut chart, "speed [m/s]", "altitude [m]", path)?;
    let line = |r: &CaseResult| -> Vec<(f64, f64)> {
        (0..r.trace.t_s.len())
            .map(|i| (speed(r, i), r.trace.altitude_m[i] as f64))
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect()
    };
    for (k, r) in merged.results.iter().enumerate() {
        let s = chart
            .draw_series(LineSeries::new(line(r), GREY.mix(0.35).stroke_width(1)))
            .map_err(|e| err(&e))?;
        if k == 0 {
            s.label("cases")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREY.stroke_width(2)));
        }
    }
    chart
        .draw_series(LineSeries::new(line(&merged.nominal), BLUE.stroke_width(3)))
        .map_err(|e| err(&e))?
        .label("nominal")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(3)));
    legend(&mut chart, SeriesLabelPosition::UpperLeft, path)?;
    root.present().map_err(|e| err(&e))
}
