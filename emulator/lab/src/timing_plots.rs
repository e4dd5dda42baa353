//! A run's timing as latency people read it: percentile plots (latency against
//! percentile, both axes logarithmic, as HdrHistogram draws them) of round trip,
//! transport, wake error and the flight software's compute, with the run's bounds
//! drawn; and a timeline of deadline misses and steps over the command budget, where
//! a histogram's linear count axis would hide the tail a timing test is about.

use crate::mcap_log::StepTiming;
use crate::plot::{backend_err, font, legend, register_font, tick_label, PlotError};
use plotters::element::PathElement;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The files [`write_all`] writes.
pub const FIGURES: [&str; 2] = ["timing.png", "timing-timeline.png"];

/// Most points drawn per timeline series.
const MAX_POINTS: usize = 20_000;

const BLUE: RGBColor = RGBColor(31, 119, 180);
const RED: RGBColor = RGBColor(214, 39, 40);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const PURPLE: RGBColor = RGBColor(148, 103, 189);
const GRID: RGBColor = RGBColor(235, 235, 235);

/// The bounds a run's timing is held to, microseconds, from its configuration.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TimingLimits {
    /// `thresholds.max_round_trip_p99_us`.
    pub round_trip_p99_us: Option<f64>,
    /// `thresholds.max_transport_p99_us`.
    pub transport_p99_us: Option<f64>,
    /// `thresholds.max_wake_p99_us`.
    pub wake_p99_us: Option<f64>,
    /// The command budget: `deadline_frac` of a step period at the run's speed (in
    /// lockstep not enforced, but what realtime would ask).
    pub budget_us: Option<f64>,
    /// Whether the run was paced in realtime.
    pub realtime: bool,
}

impl TimingLimits {
    /// The limits of the run configuration `config` (a log header's `config`); what
    /// it does not give is absent.
    pub fn of_config(config: &serde_json::Value) -> Self {
        let t = &config["thresholds"];
        let f = |v: &serde_json::Value| v.as_f64().filter(|x| x.is_finite() && *x > 0.0);
        let dt_ms = f(&config["dt_ms"]);
        let speed = f(&config["speed"]).unwrap_or(1.0);
        let frac = f(&config["deadline_frac"]).unwrap_or(0.5);
        Self {
            round_trip_p99_us: f(&t["max_round_trip_p99_us"]),
            transport_p99_us: f(&t["max_transport_p99_us"]),
            wake_p99_us: f(&t["max_wake_p99_us"]),
            budget_us: dt_ms.map(|dt| dt * 1e3 / speed * frac),
            realtime: config["mode"].as_str() == Some("realtime"),
        }
    }
}

/// One step's timing and whether its command missed the deadline, for the timeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMark {
    /// Simulated time, seconds.
    pub t_s: f64,
    /// The step's command missed its deadline.
    pub deadline_miss: bool,
}

/// `(x, latency)` of a percentile plot: x = log10(1 / (1 - p)), so 90 %, 99 %, 99.9 %
/// are equally spaced, out to the last percentile the sample resolves, where the curve
/// ends at the largest sample.
pub fn percentile_curve(sorted_us: &[f64]) -> Vec<(f64, f64)> {
    let n = sorted_us.len();
    if n == 0 {
        return Vec::new();
    }
    let x_max = (n as f64).log10();
    let steps = ((x_max / 0.01).ceil() as usize).max(1);
    (0..=steps)
        .map(|i| {
            let x = x_max * i as f64 / steps as f64;
            let p = 1.0 - 10f64.powf(-x);
            // Nearest rank, as HdrHistogram reports a percentile.
            let rank = ((p * n as f64 - 1e-9).ceil() as usize).clamp(1, n);
            let v = if i == steps {
                sorted_us[n - 1]
            } else {
                sorted_us[rank - 1]
            };
            (x, v)
        })
        .collect()
}

/// The tick label of a percentile axis position x = log10(1 / (1 - p)).
fn percentile_label(x: &f64) -> String {
    if (x - x.round()).abs() > 1e-6 {
        return String::new();
    }
    let p = 100.0 * (1.0 - 10f64.powf(-x.round()));
    format!("{}%", tick_label(p))
}

/// A timing figure's samples in microseconds: the positive ones, sorted, and how many
/// were zero or negative (a wake error can be early).
fn sorted_us(values: impl Iterator<Item = f64>) -> (Vec<f64>, usize) {
    let (mut pos, mut rest) = (Vec::new(), 0);
    for v in values.filter(|v| v.is_finite()) {
        if v > 0.0 {
            pos.push(v * 1e-3);
        } else {
            rest += 1;
        }
    }
    pos.sort_by(f64::total_cmp);
    (pos, rest)
}

fn quantile_label(v: &[f64], p: f64) -> String {
    let rank = ((p * v.len() as f64 - 1e-9).ceil() as usize).clamp(1, v.len());
    tick_label(v[rank - 1])
}

/// Writes the timing figures of a run into `dir`: `timing` per step, `marks` per step
/// (deadline misses), `limits` from the configuration, `heading` naming the run.
pub fn write_all(
    timing: &[StepTiming],
    marks: &[StepMark],
    limits: &TimingLimits,
    dir: &Path,
    heading: &str,
) -> Result<Vec<PathBuf>, PlotError> {
    register_font()?;
    let p0 = dir.join(FIGURES[0]);
    percentiles(timing, limits, &p0, heading)?;
    let p1 = dir.join(FIGURES[1]);
    timeline(timing, marks, limits, &p1, heading)?;
    Ok(vec![p0, p1])
}

type Figure = (&'static str, fn(&StepTiming) -> Option<f64>);

const KINDS: [Figure; 4] = [
    ("round trip", |t| t.round_trip_ns.map(|v| v as f64)),
    ("transport", |t| t.transport_ns.map(|v| v as f64)),
    ("wake error", |t| t.wake_error_ns.map(|v| v as f64)),
    ("flight software compute", |t| {
        t.stub_compute_ns.map(|v| v as f64)
    }),
];

fn percentiles(
    timing: &[StepTiming],
    limits: &TimingLimits,
    path: &Path,
    heading: &str,
) -> Result<(), PlotError> {
    let err = backend_err(path);
    let panels: Vec<(&str, Vec<f64>, usize)> = KINDS
        .iter()
        .map(|(name, f)| {
            let (v, rest) = sorted_us(timing.iter().filter_map(f));
            (*name, v, rest)
        })
        .collect();
    // Steps without a command have no round trip: the deadline misses, told apart.
    let uncommanded = timing.iter().filter(|t| t.round_trip_ns.is_none()).count();
    let missing: Vec<&str> = panels
        .iter()
        .filter(|p| p.1.is_empty())
        .map(|p| p.0)
        .collect();
    let shown: Vec<&(&str, Vec<f64>, usize)> = panels.iter().filter(|p| !p.1.is_empty()).collect();
    let n = shown.len().max(1) as u32;
    let root = BitMapBackend::new(path, (1200, 60 + 380 * n)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let title = format!(
        "Timing per step, percentile plots: {heading}{}",
        if missing.is_empty() {
            String::new()
        } else {
            format!(" ({} not measured in this run)", missing.join(", "))
        }
    );
    let root = root.titled(&title, font(20)).map_err(|e| err(&e))?;
    if shown.is_empty() {
        root.draw(&Text::new(
            "No per-step timing in this log",
            (40, 40),
            font(20),
        ))
        .map_err(|e| err(&e))?;
        return root.present().map_err(|e| err(&e));
    }
    for (area, (name, v, rest)) in root.split_evenly((shown.len(), 1)).iter().zip(&shown) {
        let curve = percentile_curve(v);
        let bound: Vec<(String, f64, RGBColor)> = match *name {
            "round trip" => [
                limits
                    .round_trip_p99_us
                    .map(|b| ("p99 bound (thresholds)".to_string(), b, RED)),
                limits.budget_us.map(|b| {
                    let what = if limits.realtime {
                        "deadline: command budget"
                    } else {
                        "command budget in realtime (not enforced in lockstep)"
                    };
                    (what.to_string(), b, ORANGE)
                }),
            ]
            .into_iter()
            .flatten()
            .collect(),
            "transport" => limits
                .transport_p99_us
                .map(|b| ("p99 bound (thresholds)".to_string(), b, RED))
                .into_iter()
                .collect(),
            "wake error" => limits
                .wake_p99_us
                .map(|b| ("p99 bound (thresholds)".to_string(), b, RED))
                .into_iter()
                .collect(),
            _ => Vec::new(),
        };
        let lo = v[0].min(bound.iter().map(|b| b.1).fold(f64::INFINITY, f64::min));
        let hi = v[v.len() - 1].max(bound.iter().map(|b| b.1).fold(0.0, f64::max));
        let (lo, hi) = if hi / lo < 10.0 {
            (lo / 3.0, hi * 3.0)
        } else {
            (lo / 1.5, hi * 1.5)
        };
        let x_max = curve.last().map_or(1.0, |p| p.0).max(1.0).ceil();
        let caption = format!(
            "{name}: p50 {} us, p99 {} us, p99.9 {} us, max {} us, {} steps{}",
            quantile_label(v, 0.5),
            quantile_label(v, 0.99),
            quantile_label(v, 0.999),
            tick_label(v[v.len() - 1]),
            v.len(),
            if *rest > 0 {
                format!(" ({rest} at or below 0 not on the log axis)")
            } else if uncommanded > 0 && matches!(*name, "round trip" | "transport") {
                format!(" ({uncommanded} steps without a command not in the curve)")
            } else {
                String::new()
            }
        );
        let mut chart = ChartBuilder::on(area)
            .caption(caption, font(17))
            .margin(12)
            .margin_right(36)
            .x_label_area_size(44)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..x_max, (lo..hi).log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("percentile (log scale of 1 / (1 - p))")
            .y_desc(format!("{name} [us] (log)"))
            .x_labels(x_max as usize + 1)
            .x_label_formatter(&percentile_label)
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(font(15))
            .axis_desc_style(font(16))
            .light_line_style(GRID)
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(LineSeries::new(curve, BLUE.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(format!("{name}, measured"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(3)));
        for (what, b, c) in bound {
            chart
                .draw_series(LineSeries::new([(0.0, b), (x_max, b)], c.stroke_width(2)))
                .map_err(|e| err(&e))?
                .label(format!("{what} {} us", tick_label(b)))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        legend(&mut chart, SeriesLabelPosition::UpperLeft, 14).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

fn timeline(
    timing: &[StepTiming],
    marks: &[StepMark],
    limits: &TimingLimits,
    path: &Path,
    heading: &str,
) -> Result<(), PlotError> {
    let err = backend_err(path);
    let budget_ns = limits.budget_us.map(|b| b * 1e3);
    let over: Vec<f64> = timing
        .iter()
        .filter(|t| match (t.round_trip_ns, budget_ns) {
            (Some(rt), Some(b)) => rt as f64 > b,
            _ => false,
        })
        .map(|t| t.t_s)
        .collect();
    let late_start: Vec<f64> = timing
        .iter()
        .filter(|t| match (t.wake_error_ns, budget_ns) {
            (Some(w), Some(b)) => w as f64 > b,
            _ => false,
        })
        .map(|t| t.t_s)
        .collect();
    let misses: Vec<f64> = marks
        .iter()
        .filter(|m| m.deadline_miss)
        .map(|m| m.t_s)
        .collect();
    let t_end = marks
        .iter()
        .map(|m| m.t_s)
        .chain(timing.iter().map(|t| t.t_s))
        .fold(0.0, f64::max)
        .max(1e-3);
    let root = BitMapBackend::new(path, (1200, 60 + 2 * 380)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(
            &format!("Deadline misses and overruns: {heading}"),
            font(20),
        )
        .map_err(|e| err(&e))?;
    let (top, bottom) = root.split_vertically(380);

    // Round trip per step, thinned, on a log axis, the budget across it.
    let stride = timing.len().div_ceil(MAX_POINTS).max(1);
    let rt: Vec<(f64, f64)> = timing
        .iter()
        .step_by(stride)
        .filter_map(|t| t.round_trip_ns.map(|v| (t.t_s, v as f64 * 1e-3)))
        .filter(|p| p.1 > 0.0)
        .collect();
    if rt.is_empty() {
        top.draw(&Text::new(
            "No round trip measured in this log",
            (40, 40),
            font(18),
        ))
        .map_err(|e| err(&e))?;
    } else {
        let lo = rt.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        let hi = rt
            .iter()
            .map(|p| p.1)
            .chain(limits.budget_us)
            .fold(0.0, f64::max);
        let mut chart = ChartBuilder::on(&top)
            .caption(
                format!(
                    "round trip per step{}",
                    if stride > 1 {
                        format!(" (every {stride}th step drawn; every step counted)")
                    } else {
                        String::new()
                    }
                ),
                font(16),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, ((lo / 1.5)..(hi * 2.0)).log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("simulated time [s]")
            .y_desc("round trip [us] (log)")
            .x_label_formatter(&|v| tick_label(*v))
            .y_label_formatter(&|v| tick_label(*v))
            .label_style(font(15))
            .axis_desc_style(font(16))
            .light_line_style(GRID)
            .draw()
            .map_err(|e| err(&e))?;
        chart
            .draw_series(
                rt.iter()
                    .map(|p| Circle::new(*p, 1, BLUE.mix(0.5).filled())),
            )
            .map_err(|e| err(&e))?
            .label("round trip")
            .legend(|(x, y)| Circle::new((x + 10, y), 3, BLUE.filled()));
        // Each deadline miss as a red tick along the top: where in the run they fall.
        let (tick_lo, tick_hi) = (hi * 1.3, hi * 1.9);
        chart
            .draw_series(misses.iter().map(|t| {
                PathElement::new(
                    vec![(*t, tick_lo), (*t, tick_hi)],
                    RED.mix(0.6).stroke_width(1),
                )
            }))
            .map_err(|e| err(&e))?
            .label(format!("deadline miss ({})", misses.len()))
            .legend(|(x, y)| {
                PathElement::new(vec![(x + 10, y - 6), (x + 10, y + 6)], RED.stroke_width(2))
            });
        if let Some(b) = limits.budget_us {
            chart
                .draw_series(LineSeries::new(
                    [(0.0, b), (t_end, b)],
                    ORANGE.stroke_width(2),
                ))
                .map_err(|e| err(&e))?
                .label(format!("command budget {} us", tick_label(b)))
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], ORANGE.stroke_width(2))
                });
        }
        legend(&mut chart, SeriesLabelPosition::UpperRight, 14).map_err(|e| err(&e))?;
    }

    // Cumulative counts: when in the run they happened.
    let cumulative = |times: &[f64]| -> Vec<(f64, u64)> {
        let mut pts = vec![(0.0, 0u64)];
        for (i, t) in times.iter().enumerate() {
            pts.push((*t, i as u64));
            pts.push((*t, i as u64 + 1));
        }
        pts.push((t_end, times.len() as u64));
        pts
    };
    let top_count = misses.len().max(over.len()).max(late_start.len()).max(1) as u64;
    let top_count = top_count + (top_count / 8).max(1);
    let mut chart = ChartBuilder::on(&bottom)
        .caption("cumulative count over the run", font(16))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..t_end, 0u64..top_count)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("simulated time [s]")
        .y_desc("steps")
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v: &u64| v.to_string())
        .label_style(font(15))
        .axis_desc_style(font(16))
        .light_line_style(GRID)
        .draw()
        .map_err(|e| err(&e))?;
    for (label, times, c) in [
        ("deadline misses (no command by the deadline)", &misses, RED),
        ("round trip over the command budget", &over, ORANGE),
        (
            "late step start (wake error over the budget)",
            &late_start,
            PURPLE,
        ),
    ] {
        chart
            .draw_series(LineSeries::new(cumulative(times), c.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(format!("{label}: {}", times.len()))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperLeft, 14).map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_percentile_curve_reads_the_nearest_rank_at_90_99_and_99_9() {
        let v: Vec<f64> = (1..=1000).map(|i| i as f64).collect();
        let c = percentile_curve(&v);
        let at = |x: f64| c.iter().find(|p| (p.0 - x).abs() < 1e-9).unwrap().1;
        assert_eq!(at(0.0), 1.0);
        assert_eq!(at(1.0), 900.0);
        assert_eq!(at(2.0), 990.0);
        assert_eq!(at(3.0), 1000.0);
        assert_eq!(percentile_label(&2.0), "99%");
        assert_eq!(percentile_label(&3.0), "99.9%");
        assert_eq!(percentile_label(&1.5), "");
    }

    #[test]
    fn limits_come_from_the_configuration() {
        let cfg = serde_json::json!({
            "mode": "realtime", "dt_ms": 10, "speed": 2.0, "deadline_frac": 0.5,
            "thresholds": { "max_round_trip_p99_us": 800.0 }
        });
        let l = TimingLimits::of_config(&cfg);
        assert_eq!(l.budget_us, Some(2500.0));
        assert_eq!(l.round_trip_p99_us, Some(800.0));
        assert_eq!(l.transport_p99_us, None);
        assert!(l.realtime);
        assert_eq!(
            TimingLimits::of_config(&serde_json::Value::Null),
            TimingLimits::default()
        );
    }
}
