//! One figure per case, like the paper's Fig. 4-9: surrogate against hifi for each
//! engine's thrust, the error with the paper's bound around it, gas pressure and total
//! module mass.

use super::compare::{Trace, GAS, MASS};
use super::report::Bounds;
use crate::plot::{write_png, Panel, PlotError, Series};
use oils_shared::ENGINE_COUNT;
use std::path::{Path, PathBuf};

/// Most points drawn per series: longer series keep each bucket's extremes, so peaks
/// (what the bounds are about) survive the thinning.
const MAX_POINTS: usize = 6000;

fn thin(points: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    if points.len() <= MAX_POINTS {
        return points;
    }
    let bucket = points.len().div_ceil(MAX_POINTS / 2);
    let mut out = Vec::with_capacity(MAX_POINTS + 2);
    for chunk in points.chunks(bucket) {
        let lo = chunk
            .iter()
            .enumerate()
            .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        let hi = chunk
            .iter()
            .enumerate()
            .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1));
        if let (Some((i, a)), Some((j, b))) = (lo, hi) {
            if i <= j {
                out.extend([*a, *b]);
            } else {
                out.extend([*b, *a]);
            }
        }
    }
    out
}

fn series(trace: &Trace, f: impl Fn(&super::compare::Sample) -> f64) -> Vec<(f64, f64)> {
    thin(
        trace
            .samples
            .iter()
            .skip(1)
            .map(|s| (s.t_ns as f64 * 1e-9, f(s)))
            .collect(),
    )
}

/// The paper's thrust bound in force at each sample (it changes between windows).
fn bound_line(trace: &Trace, bounds: &Bounds, sign: f64) -> Vec<(f64, f64)> {
    let mut pts = Vec::new();
    for w in &trace.case.windows {
        let b = sign * bounds.thrust_n(w.kind);
        pts.push((w.start_ns as f64 * 1e-9, b));
        pts.push((w.end_ns as f64 * 1e-9, b));
    }
    pts
}

/// Writes `<dir>/validate-<case>.png`; returns the path.
pub fn write_case(dir: &Path, trace: &Trace, bounds: &Bounds) -> Result<PathBuf, PlotError> {
    let path = dir.join(format!("validate-{}.png", trace.case.name));
    let cmd: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| series(trace, |s| s.cmd.thrust_cmd_n[e]))
        .collect();
    let hifi: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| series(trace, |s| s.truth[e]))
        .collect();
    let sur: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| series(trace, |s| s.model[e]))
        .collect();
    let err: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| series(trace, |s| s.model[e] - s.truth[e]))
        .collect();
    let (up, down) = (
        bound_line(trace, bounds, 1.0),
        bound_line(trace, bounds, -1.0),
    );
    let gas_h = series(trace, |s| s.truth[GAS] * 1e-5);
    let gas_s = series(trace, |s| s.model[GAS] * 1e-5);
    let mass_h = series(trace, |s| s.truth[MASS]);
    let mass_s = series(trace, |s| s.model[MASS]);
    let mass_e = series(trace, |s| s.model[MASS] - s.truth[MASS]);
    let t_end = trace.case.duration_ns as f64 * 1e-9;
    let mass_up = vec![(0.0, bounds.mass_kg), (t_end, bounds.mass_kg)];
    let mass_down = vec![(0.0, -bounds.mass_kg), (t_end, -bounds.mass_kg)];
    let labels = [
        ["command 1", "hifi 1", "surrogate 1"],
        ["command 2", "hifi 2", "surrogate 2"],
        ["command 3", "hifi 3", "surrogate 3"],
        ["command 4", "hifi 4", "surrogate 4"],
    ];
    let pair = |a: usize, b: usize| -> Vec<Series> {
        let mut v = Vec::new();
        for e in [a, b] {
            v.push(Series {
                label: labels[e][0],
                points: &cmd[e],
            });
            v.push(Series {
                label: labels[e][1],
                points: &hifi[e],
            });
            v.push(Series {
                label: labels[e][2],
                points: &sur[e],
            });
        }
        v
    };
    let err_labels = ["engine 1", "engine 2", "engine 3", "engine 4"];
    let mut err_series: Vec<Series> = (0..ENGINE_COUNT)
        .map(|e| Series {
            label: err_labels[e],
            points: &err[e],
        })
        .collect();
    err_series.push(Series {
        label: "+ paper bound",
        points: &up,
    });
    err_series.push(Series {
        label: "- paper bound",
        points: &down,
    });
    let panels = vec![
        Panel::new(
            "Engines 1 and 3 thrust",
            "time [s]",
            "thrust [N]",
            pair(0, 2),
        ),
        Panel::new(
            "Engines 2 and 4 thrust",
            "time [s]",
            "thrust [N]",
            pair(1, 3),
        ),
        Panel::new(
            "Thrust error, surrogate - hifi, with the paper's bound",
            "time [s]",
            "error [N]",
            err_series,
        ),
        Panel::new(
            "Helium bottle pressure",
            "time [s]",
            "pressure [bar]",
            vec![
                Series {
                    label: "hifi",
                    points: &gas_h,
                },
                Series {
                    label: "surrogate",
                    points: &gas_s,
                },
            ],
        ),
        Panel::new(
            "Total module mass",
            "time [s]",
            "mass [kg]",
            vec![
                Series {
                    label: "hifi",
                    points: &mass_h,
                },
                Series {
                    label: "surrogate",
                    points: &mass_s,
                },
            ],
        ),
        Panel::new(
            "Total module mass error, surrogate - hifi",
            "time [s]",
            "error [kg]",
            vec![
                Series {
                    label: "error",
                    points: &mass_e,
                },
                Series {
                    label: "+ paper bound",
                    points: &mass_up,
                },
                Series {
                    label: "- paper bound",
                    points: &mass_down,
                },
            ],
        ),
    ];
    let title = format!(
        "Validation case `{}`: surrogate against hifi",
        trace.case.name
    );
    write_png(&path, &title, &panels)?;
    Ok(path)
}
