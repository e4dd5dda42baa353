//! A campaign's figures, drawn for the questions a GNC engineer brings to them: where
//! did the landed cases come down (equal axis scales, about the reference point, the
//! 3-sigma ellipse of the landed cases only, crashes counted apart), how close are the
//! touchdown figures to their limits (histograms and empirical CDFs of the landed
//! cases, the limits drawn, what is not shown counted in the title), and what drives
//! the failures (rank correlations, the outcome against the two strongest drivers).
//! Drawn with plotters and the bundled font of [`crate::plot`].
//!
//! The reference point is the scenario's landing site (downrange along the approach
//! azimuth, crossrange across it), and every figure says so.

use super::case::CaseResult;
use super::compare::Comparison;
use super::drivers::{self, Driver};
use super::spec::CampaignSpec;
use super::summary::{quantile, Ellipse, Merged};
use crate::plot::{backend_err, font, legend, register_font, tick_label, PlotError};
use plotters::element::{Cross, PathElement, Text};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::{Path, PathBuf};

/// The files [`write_all`] may write, in the order a reader takes them.
/// `drivers-outcome.png` needs two drivers and is left out without them.
pub const FIGURES: [&str; 7] = [
    "footprint.png",
    "touchdown.png",
    "propellant.png",
    "cdf.png",
    "drivers.png",
    "drivers-outcome.png",
    "altitude-speed.png",
];

/// The file [`write_compare`] writes.
pub const COMPARE_FIGURE: &str = "compare-cdf.png";

/// What names the reference point of the footprint, wherever it is drawn.
pub const REFERENCE_POINT: &str = "the scenario's landing site";

const BLUE: RGBColor = RGBColor(31, 119, 180);
const RED: RGBColor = RGBColor(214, 39, 40);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);
const GREY: RGBColor = RGBColor(150, 150, 150);
const GRID: RGBColor = RGBColor(235, 235, 235);

/// An integer count as a tick label (the count axis ticks on integers only).
fn count_label(v: &u32) -> String {
    v.to_string()
}

/// A round step near `span / target`: 1, 2 or 5 times a power of ten.
pub fn nice_step(span: f64, target: usize) -> f64 {
    let raw = (span / target.max(1) as f64).max(f64::MIN_POSITIVE);
    let p = 10f64.powf(raw.log10().floor());
    let m = raw / p;
    let n = if m <= 1.0 {
        1.0
    } else if m <= 2.0 {
        2.0
    } else if m <= 5.0 {
        5.0
    } else {
        10.0
    };
    n * p
}

/// The axis range of a figure over `sorted` values: Tukey's far fences (3 IQR beyond
/// the quartiles), so one outlier does not squash the rest into a bin; `limit` is
/// included when that at most triples the span (otherwise the title gives it).
fn robust_range(sorted: &[f64], limit: Option<f64>) -> (f64, f64) {
    let (min, max) = (sorted[0], sorted[sorted.len() - 1]);
    let (q1, q3) = (quantile(sorted, 0.25), quantile(sorted, 0.75));
    let iqr = q3 - q1;
    let (mut lo, mut hi) = ((q1 - 3.0 * iqr).max(min), (q3 + 3.0 * iqr).min(max));
    let span = (hi - lo).max(1e-9 * hi.abs().max(1.0));
    if let Some(l) = limit.filter(|l| l.is_finite()) {
        let (a, b) = (lo.min(l), hi.max(l));
        if b - a <= 3.0 * span {
            (lo, hi) = (a, b);
        }
    }
    if hi - lo < 1e-9 * hi.abs().max(1.0) {
        let w = (hi.abs() * 0.01).max(1e-3);
        (lo, hi) = (lo - w, hi + w);
    }
    let pad = 0.04 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Cases by how they ended, for markers and counts.
fn landed(r: &CaseResult) -> bool {
    r.outcome == "landed"
}

/// One figure of the landed cases, with its limit.
struct Quantity {
    /// Its name in `summary.json` and `compare.json`.
    key: &'static str,
    /// Axis label with unit.
    label: &'static str,
    /// Short name for titles.
    short: &'static str,
    unit: &'static str,
    /// The value of a case (`None`: the case has none).
    value: fn(&CaseResult) -> Option<f64>,
    limit: Option<(f64, &'static str)>,
}

fn quantities(spec: &CampaignSpec) -> [Quantity; 4] {
    let td = &spec.base.scenario.touchdown;
    [
        Quantity {
            key: "vertical_speed_mps",
            label: "vertical speed at touchdown [m/s]",
            short: "vertical speed",
            unit: "m/s",
            value: |r| r.touchdown.map(|t| t.vertical_speed_mps),
            limit: Some((td.vertical_speed_mps, "landing limit")),
        },
        Quantity {
            key: "horizontal_speed_mps",
            label: "horizontal speed at touchdown [m/s]",
            short: "horizontal speed",
            unit: "m/s",
            value: |r| r.touchdown.map(|t| t.horizontal_speed_mps),
            limit: Some((td.horizontal_speed_mps, "landing limit")),
        },
        Quantity {
            key: "tilt_deg",
            label: "tilt at touchdown [deg]",
            short: "tilt",
            unit: "deg",
            value: |r| r.touchdown.map(|t| t.tilt_deg),
            limit: Some((
                spec.base.scenario.landing_limits().tilt_deg,
                "landing limit",
            )),
        },
        Quantity {
            key: "propellant_used_kg",
            label: "propellant used [kg]",
            short: "propellant used",
            unit: "kg",
            value: |r| (!r.digest.is_empty()).then_some(r.propellant_used_kg),
            limit: Some((
                spec.base.scenario.propulsion.propellant_kg,
                "propellant loaded",
            )),
        },
    ]
}

/// The landed cases' sorted values of `q`.
fn landed_values(results: &[CaseResult], q: &Quantity) -> Vec<f64> {
    let mut v: Vec<f64> = results
        .iter()
        .filter(|r| landed(r))
        .filter_map(q.value)
        .filter(|x| x.is_finite())
        .collect();
    v.sort_by(f64::total_cmp);
    v
}

/// What a panel of landed cases leaves out, for its title.
fn left_out(
    merged: &Merged,
    beyond: usize,
    limit: Option<(f64, &str)>,
    view: (f64, f64),
    unit: &str,
) -> String {
    let not_landed = merged.results.iter().filter(|r| !landed(r)).count();
    let mut parts = Vec::new();
    if not_landed > 0 {
        parts.push(format!("{not_landed} cases that did not land not shown"));
    }
    if beyond > 0 {
        parts.push(format!("{beyond} landed beyond the axis"));
    }
    if let Some((l, what)) = limit {
        if !(view.0..=view.1).contains(&l) {
            parts.push(format!("{what} {} {unit} off the axis", tick_label(l)));
        }
    }
    if parts.is_empty() {
        String::new()
    } else {
        format!(" ({})", parts.join("; "))
    }
}

/// Writes the campaign's figures into `dir`; returns their paths.
pub fn write_all(
    spec: &CampaignSpec,
    merged: &Merged,
    dir: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    register_font()?;
    std::fs::create_dir_all(dir).map_err(|e| PlotError::Backend {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    let title = format!(
        "{}: {} cases, {}",
        merged.summary.name, merged.summary.merged, merged.summary.propulsion
    );
    let q = quantities(spec);
    let mut written = Vec::new();
    let mut put = |name: &str| {
        let p = dir.join(name);
        written.push(p.clone());
        p
    };
    footprint(spec, merged, &put(FIGURES[0]), &title)?;
    histograms(
        merged,
        &put(FIGURES[1]),
        &format!("{title}: touchdown, landed cases"),
        &q[..3],
    )?;
    histograms(
        merged,
        &put(FIGURES[2]),
        &format!("{title}: propellant, landed cases"),
        &q[3..],
    )?;
    cdfs(
        &[("", merged)],
        &put(FIGURES[3]),
        &format!("{title}: empirical CDFs, landed cases"),
        &q,
        None,
    )?;
    let d = &merged.summary.drivers;
    drivers_figure(d, &put(FIGURES[4]), &title)?;
    if d.len() >= 2 {
        outcome_scatter(merged, &put(FIGURES[5]), &title)?;
    }
    traces(merged, &put(FIGURES[6]), &title)?;
    Ok(written)
}

/// `oils mc compare`: the landed cases' CDFs under both models on the same axes, with
/// the two-sample KS statistic of each figure. Returns the path written.
pub fn write_compare(
    spec: &CampaignSpec,
    a: &Merged,
    b: &Merged,
    comparison: &Comparison,
    dir: &Path,
) -> Result<PathBuf, PlotError> {
    register_font()?;
    std::fs::create_dir_all(dir).map_err(|e| PlotError::Backend {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    let path = dir.join(COMPARE_FIGURE);
    let title = format!(
        "{}: {} against {}, {} cases, landed cases",
        a.summary.name, a.summary.propulsion, b.summary.propulsion, comparison.cases
    );
    cdfs(
        &[
            (a.summary.propulsion.as_str(), a),
            (b.summary.propulsion.as_str(), b),
        ],
        &path,
        &title,
        &quantities(spec),
        Some(comparison),
    )?;
    Ok(path)
}

/// Ranges of `x` and `y` widened so that a metre is as long on both axes of a plot area
/// `w` by `h` pixels.
fn equal_scale(x: (f64, f64), y: (f64, f64), w: u32, h: u32) -> ((f64, f64), (f64, f64)) {
    let (sx, sy) = ((x.1 - x.0) / w as f64, (y.1 - y.0) / h as f64);
    let s = sx.max(sy);
    let grow = |r: (f64, f64), px: u32| {
        let c = 0.5 * (r.0 + r.1);
        let half = 0.5 * s * px as f64;
        (c - half, c + half)
    };
    (grow(x, w), grow(y, h))
}

fn footprint(
    spec: &CampaignSpec,
    merged: &Merged,
    path: &Path,
    title: &str,
) -> Result<(), PlotError> {
    let err = backend_err(path);
    let at = |r: &CaseResult| -> Option<(f64, f64)> {
        r.touchdown?;
        let p = (r.downrange_m?, r.crossrange_m?);
        (p.0.is_finite() && p.1.is_finite()).then_some(p)
    };
    let landed_pts: Vec<(f64, f64)> = merged
        .results
        .iter()
        .filter(|r| landed(r))
        .filter_map(at)
        .collect();
    let crashed_pts: Vec<(f64, f64)> = merged
        .results
        .iter()
        .filter(|r| !landed(r))
        .filter_map(at)
        .collect();
    let no_touchdown = merged
        .results
        .iter()
        .filter(|r| !landed(r) && at(r).is_none())
        .count();
    let ellipse = Ellipse::of(&landed_pts);
    let outline = ellipse.as_ref().map(|e| e.outline(180)).unwrap_or_default();
    let zone = spec
        .requirements
        .and_then(|r| r.footprint_m)
        .map(|[a, b]| Ellipse {
            centre_m: [0.0, 0.0],
            semi_major_m: 0.5 * a,
            semi_minor_m: 0.5 * b,
            angle_deg: 0.0,
        });
    let zone_outline = zone.as_ref().map(|z| z.outline(180)).unwrap_or_default();
    // The view: the landed cases, their ellipse, the zone and the reference point.
    let view: Vec<(f64, f64)> = landed_pts
        .iter()
        .chain(&outline)
        .chain(&zone_outline)
        .copied()
        .chain([(0.0, 0.0)])
        .chain(if landed_pts.is_empty() {
            crashed_pts.clone()
        } else {
            vec![]
        })
        .collect();
    let bound = |f: fn(&(f64, f64)) -> f64| {
        view.iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
    };
    let (mut x, mut y) = (bound(|p| p.0), bound(|p| p.1));
    let span = (x.1 - x.0).max(y.1 - y.0).max(100.0);
    let pad = 0.08 * span;
    x = (x.0 - pad, x.1 + pad);
    y = (y.0 - pad, y.1 + pad);
    // km once the view is wider than 5 km: ticks stay short.
    let (k, unit) = if span > 5000.0 {
        (1e-3, "km")
    } else {
        (1.0, "m")
    };
    let (w, h) = (1100u32, 1000u32);
    let (margin, xl, yl, cap) = (16u32, 60u32, 90u32, 70u32);
    let ((x0, x1), (y0, y1)) = equal_scale(
        (x.0 * k, x.1 * k),
        (y.0 * k, y.1 * k),
        w - 2 * margin - yl,
        h - 2 * margin - xl - cap,
    );
    let inside = |p: &(f64, f64)| (x0..=x1).contains(&(p.0 * k)) && (y0..=y1).contains(&(p.1 * k));
    let beyond = crashed_pts.iter().filter(|p| !inside(p)).count();
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (top, rest) = root.split_vertically(cap);
    let lines = [
        format!("{title}: touchdown footprint"),
        format!(
            "about {REFERENCE_POINT}; equal scales; {} landed, {} did not land ({} beyond the view{})",
            landed_pts.len(),
            crashed_pts.len() + no_touchdown,
            beyond,
            if no_touchdown > 0 { format!(", {no_touchdown} without a touchdown") } else { String::new() }
        ),
    ];
    for (i, l) in lines.iter().enumerate() {
        top.draw(&Text::new(
            l.clone(),
            (w as i32 / 2, 12 + 30 * i as i32),
            font(if i == 0 { 22 } else { 14 }).pos(Pos::new(HPos::Center, VPos::Top)),
        ))
        .map_err(|e| err(&e))?;
    }
    let mut chart = ChartBuilder::on(&rest)
        .margin(margin)
        .x_label_area_size(xl)
        .y_label_area_size(yl)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(format!("downrange from the reference point [{unit}]"))
        .y_desc(format!("crossrange from the reference point [{unit}]"))
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .label_style(font(15))
        .axis_desc_style(font(16))
        .light_line_style(GRID)
        .draw()
        .map_err(|e| err(&e))?;
    let scaled = |p: &(f64, f64)| (p.0 * k, p.1 * k);
    if let Some(z) = &zone {
        let outside = landed_pts
            .iter()
            .filter(|p| (p.0 / z.semi_major_m).powi(2) + (p.1 / z.semi_minor_m).powi(2) > 1.0)
            .count();
        let (a, b) = (2.0 * z.semi_major_m, 2.0 * z.semi_minor_m);
        chart
            .draw_series(std::iter::once(Polygon::new(
                zone_outline.iter().map(scaled).collect::<Vec<_>>(),
                GREEN.mix(0.12).filled(),
            )))
            .map_err(|e| err(&e))?;
        chart
            .draw_series(LineSeries::new(
                zone_outline.iter().map(scaled),
                GREEN.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(format!(
                "requirement zone {} x {} m ({outside} landed outside)",
                tick_label(a),
                tick_label(b)
            ))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREEN.stroke_width(2)));
    }
    chart
        .draw_series(
            landed_pts
                .iter()
                .map(|p| Circle::new(scaled(p), 3, BLUE.mix(0.6).filled())),
        )
        .map_err(|e| err(&e))?
        .label(format!("landed ({})", landed_pts.len()))
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.filled()));
    chart
        .draw_series(
            crashed_pts
                .iter()
                .filter(|p| inside(p))
                .map(|p| Cross::new(scaled(p), 6, RED.stroke_width(2))),
        )
        .map_err(|e| err(&e))?
        .label(format!(
            "did not land ({}, {beyond} beyond the view)",
            crashed_pts.len()
        ))
        .legend(|(x, y)| Cross::new((x + 10, y), 5, RED.stroke_width(2)));
    if let Some(e) = &ellipse {
        chart
            .draw_series(LineSeries::new(
                outline.iter().map(scaled),
                BLACK.stroke_width(2),
            ))
            .map_err(|e| err(&e))?
            .label(format!(
                "3-sigma ellipse of the landed cases ({} x {} m)",
                tick_label((2.0 * e.semi_major_m).round()),
                tick_label((2.0 * e.semi_minor_m).round())
            ))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    }
    chart
        .draw_series([Cross::new((0.0, 0.0), 9, BLACK.stroke_width(3))])
        .map_err(|e| err(&e))?
        .label("the landing site")
        .legend(|(x, y)| Cross::new((x + 10, y), 5, BLACK.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::UpperRight, 14).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

/// Stacked histograms of the landed cases, one panel per quantity: round bin edges over
/// the robust range, integer counts, the limit drawn, what is not shown in the title.
fn histograms(merged: &Merged, path: &Path, title: &str, qs: &[Quantity]) -> Result<(), PlotError> {
    let err = backend_err(path);
    let root = BitMapBackend::new(path, (1200, 50 + 360 * qs.len() as u32)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root.titled(title, font(24)).map_err(|e| err(&e))?;
    for (area, q) in root.split_evenly((qs.len(), 1)).iter().zip(qs) {
        let v = landed_values(&merged.results, q);
        if v.is_empty() {
            area.draw(&Text::new(
                format!("{}: no landed case", q.short),
                (40, 40),
                font(20),
            ))
            .map_err(|e| err(&e))?;
            continue;
        }
        let (lo, hi) = robust_range(&v, q.limit.map(|l| l.0));
        let step = nice_step(hi - lo, 24);
        let first = (lo / step).floor() * step;
        let bins = (((hi - first) / step).ceil() as usize).clamp(1, 200);
        let mut counts = vec![0u32; bins];
        let mut beyond = 0;
        for x in &v {
            if *x < lo || *x > hi {
                beyond += 1;
                continue;
            }
            counts[(((x - first) / step) as usize).min(bins - 1)] += 1;
        }
        let top = counts.iter().copied().max().unwrap_or(1).max(1);
        let top = top + (top / 8).max(1);
        let x1 = first + bins as f64 * step;
        let caption = format!(
            "{}: {} landed, median {} {u}, p99 {} {u}{}",
            q.short,
            v.len(),
            tick_label(quantile(&v, 0.5)),
            tick_label(quantile(&v, 0.99)),
            left_out(merged, beyond, q.limit, (first, x1), q.unit),
            u = q.unit,
        );
        let mut chart = ChartBuilder::on(area)
            .caption(caption, font(17))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(first..x1, 0u32..top)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(q.label)
            .y_desc("cases")
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&count_label)
            .label_style(font(15))
            .axis_desc_style(font(16))
            .light_line_style(GRID)
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(
                counts
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| **c > 0)
                    .map(|(i, &c)| {
                        let a = first + i as f64 * step;
                        Rectangle::new([(a, 0), (a + step, c)], BLUE.mix(0.7).filled())
                    }),
            )
            .map_err(|e| err(&e))?;
        // Outlines, so neighbouring bars of one height stay two bars.
        chart
            .draw_series(
                counts
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| **c > 0)
                    .map(|(i, &c)| {
                        let a = first + i as f64 * step;
                        Rectangle::new([(a, 0), (a + step, c)], WHITE.stroke_width(1))
                    }),
            )
            .map_err(|e| err(&e))?;
        if let Some((l, what)) = q.limit.filter(|(l, _)| (first..=x1).contains(l)) {
            chart
                .draw_series(LineSeries::new([(l, 0), (l, top)], RED.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(format!("{what} {} {}", tick_label(l), q.unit))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
            legend(&mut chart, SeriesLabelPosition::UpperRight, 15).map_err(|e| err(&e))?;
        }
    }
    root.present().map_err(|e| err(&e))
}

/// The empirical CDF of sorted `v` as a stair line.
fn ecdf(v: &[f64]) -> Vec<(f64, f64)> {
    let n = v.len() as f64;
    let mut pts = Vec::with_capacity(2 * v.len());
    for (i, x) in v.iter().enumerate() {
        pts.push((*x, i as f64 / n));
        pts.push((*x, (i + 1) as f64 / n));
    }
    pts
}

/// Empirical CDFs of the landed cases, a 2 x 2 grid of quantities; one line per
/// campaign in `sets` (a label each), with the KS statistic when comparing.
fn cdfs(
    sets: &[(&str, &Merged)],
    path: &Path,
    title: &str,
    qs: &[Quantity],
    comparison: Option<&Comparison>,
) -> Result<(), PlotError> {
    let err = backend_err(path);
    let colours = [BLUE, ORANGE];
    let root = BitMapBackend::new(path, (1400, 1000)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root.titled(title, font(24)).map_err(|e| err(&e))?;
    for (area, q) in root.split_evenly((2, 2)).iter().zip(qs) {
        let values: Vec<Vec<f64>> = sets
            .iter()
            .map(|(_, m)| landed_values(&m.results, q))
            .collect();
        let all: Vec<f64> = {
            let mut a: Vec<f64> = values.iter().flatten().copied().collect();
            a.sort_by(f64::total_cmp);
            a
        };
        if all.is_empty() {
            area.draw(&Text::new(
                format!("{}: no landed case", q.short),
                (40, 40),
                font(20),
            ))
            .map_err(|e| err(&e))?;
            continue;
        }
        let (lo, hi) = robust_range(&all, q.limit.map(|l| l.0));
        let beyond = all.iter().filter(|x| **x < lo || **x > hi).count();
        let ks = comparison
            .and_then(|c| c.figures.get(q.key))
            .and_then(|f| f.ks)
            .map(|k| format!(", KS D {:.3} p {:.2}", k.d, k.p_value))
            .unwrap_or_default();
        let caption = if sets.len() == 1 {
            format!(
                "{}{}",
                q.short,
                left_out(sets[0].1, beyond, q.limit, (lo, hi), q.unit)
            )
        } else {
            let off = if beyond > 0 {
                format!(" ({beyond} beyond the axis)")
            } else {
                String::new()
            };
            format!("{}{ks}{off}", q.short)
        };
        let mut chart = ChartBuilder::on(area)
            .caption(caption, font(16))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(lo..hi, 0.0..1.0)
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(q.label)
            .y_desc("fraction of landed cases")
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(font(14))
            .axis_desc_style(font(15))
            .light_line_style(GRID)
            .draw()
            .map_err(|e| err(&e))?;
        for (i, ((label, _), v)) in sets.iter().zip(&values).enumerate() {
            let c = colours[i % colours.len()];
            let pts: Vec<(f64, f64)> = ecdf(v)
                .into_iter()
                .map(|(x, y)| (x.clamp(lo, hi), y))
                .collect();
            let s = chart
                .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                .map_err(|e| err(&e))?;
            if !label.is_empty() {
                s.label(format!("{label} ({} landed)", v.len()))
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                    });
            }
        }
        let limit = q.limit.filter(|(l, _)| (lo..=hi).contains(l));
        if let Some((l, what)) = limit {
            chart
                .draw_series(LineSeries::new([(l, 0.0), (l, 1.0)], RED.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(format!("{what} {} {}", tick_label(l), q.unit))
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        }
        if limit.is_none() && sets.len() == 1 {
            continue;
        }
        legend(&mut chart, SeriesLabelPosition::LowerRight, 14).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

/// Most drivers drawn in the drivers figure.
const MAX_DRIVERS_DRAWN: usize = 16;

/// A diverging colour for a correlation: blue (-1) through white to red (+1).
fn rho_colour(rho: f64) -> RGBColor {
    let t = rho.clamp(-1.0, 1.0).abs();
    let to = if rho >= 0.0 { RED } else { BLUE };
    let mix = |a: u8| (255.0 + (a as f64 - 255.0) * t).round() as u8;
    RGBColor(mix(to.0), mix(to.1), mix(to.2))
}

/// A correlation with two decimals (never `-0.00`).
fn rho_text(rho: f64) -> String {
    if rho.abs() < 0.005 {
        "0.00".into()
    } else {
        format!("{rho:.2}")
    }
}

/// Short column titles of the matrix.
const MATRIX_COLUMNS: [&str; 5] = [
    "vert. speed",
    "horiz. speed",
    "tilt",
    "pos. error",
    "propellant",
];

/// The drivers: a tornado of the rank correlation with failure (left) and the matrix of
/// rank correlations with each touchdown figure (right), strongest driver on top.
fn drivers_figure(d: &[Driver], path: &Path, title: &str) -> Result<(), PlotError> {
    let err = backend_err(path);
    let rows = d.len().clamp(1, MAX_DRIVERS_DRAWN);
    let shown = &d[..d.len().min(MAX_DRIVERS_DRAWN)];
    let h = 150 + 34 * rows as u32;
    let root = BitMapBackend::new(path, (1500, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let any_failure = shown.iter().any(|d| d.failure_rho.is_some());
    let root = root
        .titled(
            &format!(
                "{title}: what drives the failures (Spearman rank correlation; pale: p >= 0.01){}",
                if d.len() > rows {
                    format!(", top {rows} of {}", d.len())
                } else {
                    String::new()
                }
            ),
            font(20),
        )
        .map_err(|e| err(&e))?;
    let (left, right) = root.split_horizontally(800);
    // Row i from the top sits at y = rows - 1 - i.
    let y_of = |i: usize| (rows - 1 - i) as f64;
    let names: Vec<String> = shown.iter().map(|d| d.name.clone()).collect();
    let label_of = |v: &f64| {
        let i = rows as i64 - 1 - v.round() as i64;
        if (v - v.round()).abs() < 1e-6 && (0..names.len() as i64).contains(&i) {
            names[i as usize].clone()
        } else {
            String::new()
        }
    };
    let mut chart = ChartBuilder::on(&left)
        .caption(
            if any_failure {
                "with failure (did not land); > 0: more of it, more failures"
            } else {
                "with failure: every case ended alike, nothing to correlate"
            },
            font(16),
        )
        .margin(14)
        .x_label_area_size(46)
        .y_label_area_size(260)
        .build_cartesian_2d(-1.0..1.0, -0.5..rows as f64 - 0.5)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("rank correlation with failure [-]")
        .x_label_formatter(&|v| tick_label(*v))
        .y_labels(rows)
        .y_label_formatter(&label_of)
        .disable_y_mesh()
        .label_style(font(14))
        .axis_desc_style(font(15))
        .light_line_style(GRID)
        .draw()
        .map_err(|e| err(&e))?;
    chart
        .draw_series(shown.iter().enumerate().filter_map(|(i, d)| {
            let rho = d.failure_rho?;
            let strong = d.failure_p.is_some_and(|p| p < 0.01);
            let c = if rho >= 0.0 { RED } else { BLUE };
            let style = if strong {
                c.filled()
            } else {
                c.mix(0.3).filled()
            };
            let y = y_of(i);
            Some(Rectangle::new([(0.0, y - 0.35), (rho, y + 0.35)], style))
        }))
        .map_err(|e| err(&e))?;
    chart
        .draw_series(LineSeries::new(
            [(0.0, -0.5), (0.0, rows as f64 - 0.5)],
            BLACK.stroke_width(1),
        ))
        .map_err(|e| err(&e))?;
    chart
        .draw_series(shown.iter().enumerate().filter_map(|(i, d)| {
            let rho = d.failure_rho?;
            let (x, anchor) = if rho >= 0.0 {
                (rho + 0.02, HPos::Left)
            } else {
                (rho - 0.02, HPos::Right)
            };
            Some(Text::new(
                rho_text(rho),
                (x, y_of(i)),
                font(13).pos(Pos::new(anchor, VPos::Center)),
            ))
        }))
        .map_err(|e| err(&e))?;

    let cols = MATRIX_COLUMNS.len();
    let col_label = |v: &f64| {
        let i = v.round() as i64;
        if (v - v.round()).abs() < 1e-6 && (0..cols as i64).contains(&i) {
            MATRIX_COLUMNS[i as usize].to_string()
        } else {
            String::new()
        }
    };
    let mut m = ChartBuilder::on(&right)
        .caption(
            "with each touchdown figure (cases that touched down)",
            font(16),
        )
        .margin(14)
        .x_label_area_size(46)
        .y_label_area_size(10)
        .build_cartesian_2d(-0.5..cols as f64 - 0.5, -0.5..rows as f64 - 0.5)
        .map_err(|e| err(&e))?;
    m.configure_mesh()
        .x_labels(cols)
        .x_label_formatter(&col_label)
        .disable_mesh()
        .y_labels(0)
        .label_style(font(14))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, d) in shown.iter().enumerate() {
        let y = y_of(i);
        for (j, f) in drivers::FIGURES.iter().enumerate() {
            let x = j as f64;
            let cell = [(x - 0.48, y - 0.45), (x + 0.48, y + 0.45)];
            match d.figures.get(*f) {
                Some(rho) => {
                    m.draw_series([Rectangle::new(cell, rho_colour(*rho).filled())])
                        .map_err(|e| err(&e))?;
                    m.draw_series([Text::new(
                        rho_text(*rho),
                        (x, y),
                        font(13).pos(Pos::new(HPos::Center, VPos::Center)),
                    )])
                    .map_err(|e| err(&e))?;
                }
                None => {
                    m.draw_series([Rectangle::new(cell, RGBColor(245, 245, 245).filled())])
                        .map_err(|e| err(&e))?;
                }
            }
        }
    }
    root.present().map_err(|e| err(&e))
}

/// A driver's value for the scatter: a fault as struck or not, spread a little by the
/// case index so the cases do not sit on one point.
fn scatter_value(r: &CaseResult, d: &Driver, salt: u64) -> Option<f64> {
    let fault = d.kind == "fault";
    let v = drivers::value(r, &d.name, fault)?;
    if fault {
        let i = r.index.unwrap_or(0);
        let h = blake3::hash(&[i.to_le_bytes(), salt.to_le_bytes()].concat());
        let u = u16::from_le_bytes([h.as_bytes()[0], h.as_bytes()[1]]) as f64 / 65536.0;
        let jitter = (u - 0.5) * 0.3;
        Some(v + jitter)
    } else {
        Some(v)
    }
}

/// Tick labels of a driver's axis: a fault's only at 0 (not struck) and 1 (struck).
fn ticks(d: &Driver) -> &'static dyn Fn(&f64) -> String {
    if d.kind == "fault" {
        &|v: &f64| match v.round() as i64 {
            0 if v.abs() < 1e-9 => "0".into(),
            1 if (v - 1.0).abs() < 1e-9 => "1".into(),
            _ => String::new(),
        }
    } else {
        &|v: &f64| tick_label(*v)
    }
}

fn axis_name(d: &Driver) -> String {
    if d.kind == "fault" {
        format!("{} (fault: 0 not struck, 1 struck)", d.name)
    } else {
        format!("{} (applied value)", d.name)
    }
}

/// Every case's outcome against the values of the two strongest drivers.
fn outcome_scatter(merged: &Merged, path: &Path, title: &str) -> Result<(), PlotError> {
    let err = backend_err(path);
    let (a, b) = (&merged.summary.drivers[0], &merged.summary.drivers[1]);
    let pts: Vec<(f64, f64, &str)> = merged
        .results
        .iter()
        .filter(|r| drivers::flew(r))
        .filter_map(|r| {
            Some((
                scatter_value(r, a, 0)?,
                scatter_value(r, b, 1)?,
                r.outcome.as_str(),
            ))
        })
        .collect();
    let range = |f: fn(&(f64, f64, &str)) -> f64| {
        let (lo, hi) = pts
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        if lo > hi {
            return (0.0, 1.0);
        }
        let span = (hi - lo).max(1e-9 * hi.abs().max(1.0));
        (lo - 0.06 * span, hi + 0.06 * span)
    };
    let ((x0, x1), (y0, y1)) = (range(|p| p.0), range(|p| p.1));
    let rho = |d: &Driver| d.failure_rho.map_or("-".into(), |r| format!("{r:.2}"));
    let root = BitMapBackend::new(path, (1100, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{title}: outcome against the two strongest drivers (rank correlation with failure {} and {})",
                rho(a),
                rho(b)
            ),
            font(18),
        )
        .margin(16)
        .x_label_area_size(56)
        .y_label_area_size(90)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(axis_name(a))
        .y_desc(axis_name(b))
        .x_label_formatter(ticks(a))
        .y_label_formatter(ticks(b))
        .label_style(font(15))
        .axis_desc_style(font(16))
        .light_line_style(GRID)
        .draw()
        .map_err(|e| err(&e))?;
    let n_landed = pts.iter().filter(|p| p.2 == "landed").count();
    chart
        .draw_series(
            pts.iter()
                .filter(|p| p.2 == "landed")
                .map(|p| Circle::new((p.0, p.1), 3, BLUE.mix(0.6).filled())),
        )
        .map_err(|e| err(&e))?
        .label(format!("landed ({n_landed})"))
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.filled()));
    chart
        .draw_series(
            pts.iter()
                .filter(|p| p.2 != "landed")
                .map(|p| Cross::new((p.0, p.1), 6, RED.stroke_width(2))),
        )
        .map_err(|e| err(&e))?
        .label(format!("did not land ({})", pts.len() - n_landed))
        .legend(|(x, y)| Cross::new((x + 10, y), 5, RED.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::UpperRight, 15).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

fn speed(r: &CaseResult, i: usize) -> f64 {
    let t = &r.trace;
    (t.horizontal_speed_m_s[i] as f64).hypot(t.vertical_speed_m_s[i] as f64)
}

/// Every case's altitude against speed over the nominal one (crashes in red).
fn traces(merged: &Merged, path: &Path, title: &str) -> Result<(), PlotError> {
    let err = backend_err(path);
    let all = merged.results.iter().chain([&merged.nominal]);
    let xs = all
        .clone()
        .flat_map(|r| (0..r.trace.t_s.len()).map(move |i| speed(r, i)));
    let ys = all.flat_map(|r| r.trace.altitude_m.iter().map(|a| *a as f64 * 1e-3));
    let fold = |it: &mut dyn Iterator<Item = f64>| {
        it.filter(|x| x.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
    };
    let (x0, x1) = fold(&mut xs.into_iter());
    let (_, y1) = fold(&mut ys.into_iter());
    if x0 > x1 {
        return Err(PlotError::NoData("traces".into()));
    }
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{title}: altitude against speed"), font(22))
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..x1 * 1.03, 0.0..y1.max(0.001) * 1.03)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("speed [m/s]")
        .y_desc("altitude [km]")
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .label_style(font(15))
        .axis_desc_style(font(16))
        .light_line_style(GRID)
        .draw()
        .map_err(|e| err(&e))?;
    let line = |r: &CaseResult| -> Vec<(f64, f64)> {
        (0..r.trace.t_s.len())
            .map(|i| (speed(r, i), r.trace.altitude_m[i] as f64 * 1e-3))
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .collect()
    };
    let (mut first_landed, mut first_other) = (true, true);
    for r in &merged.results {
        let ok = landed(r);
        let style = if ok {
            GREY.mix(0.35).stroke_width(1)
        } else {
            RED.mix(0.8).stroke_width(2)
        };
        let s = chart
            .draw_series(LineSeries::new(line(r), style))
            .map_err(|e| err(&e))?;
        if ok && first_landed {
            first_landed = false;
            s.label("landed cases")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], GREY.stroke_width(2)));
        } else if !ok && first_other {
            first_other = false;
            s.label("cases that did not land")
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        }
    }
    chart
        .draw_series(LineSeries::new(line(&merged.nominal), BLUE.stroke_width(3)))
        .map_err(|e| err(&e))?
        .label("nominal")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(3)));
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 15).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_are_round_and_ranges_ignore_a_far_outlier() {
        assert_eq!(nice_step(0.07, 20), 0.005);
        assert_eq!(nice_step(37.0, 10), 5.0);
        assert_eq!(nice_step(900.0, 10), 100.0);
        // 199 landings near 0.93 m/s and one at 40: the axis stays on the 199.
        let mut v: Vec<f64> = (0..199).map(|i| 0.92 + 0.0001 * i as f64).collect();
        v.push(40.0);
        let (lo, hi) = robust_range(&v, None);
        assert!(lo > 0.9 && hi < 1.0, "{lo} {hi}");
        // A limit near the data is drawn; one far away is not allowed to squash it.
        let (_, hi) = robust_range(&v[..199], Some(0.96));
        assert!(hi >= 0.96);
        let (_, hi) = robust_range(&v[..199], Some(2.0));
        assert!(hi < 0.96);
    }

    #[test]
    fn equal_scale_gives_a_metre_the_same_pixels_on_both_axes() {
        let ((x0, x1), (y0, y1)) = equal_scale((-800.0, 800.0), (-30.0, 30.0), 1000, 800);
        assert!(((x1 - x0) / 1000.0 - (y1 - y0) / 800.0).abs() < 1e-12);
        assert!(x0 <= -800.0 && x1 >= 800.0 && y0 <= -30.0 && y1 >= 30.0);
    }
}
