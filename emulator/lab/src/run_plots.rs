//! The figures of one run (`oils plot LOG --out DIR`, `oils run --plots DIR`): the
//! vehicle from the true state recorded per step (never the noisy telemetry), the
//! engines' commanded against delivered thrust, the propulsion system's masses and
//! pressures, and the per-step timing as percentile plots and a timeline of misses
//! ([`crate::timing_plots`]). Drawn with [`crate::plot`] (bundled
//! font, no system library), in the style of the hifi and validation figures.

use crate::mcap_log::{step_timing, StepTiming};
use crate::plot::{write_png, Panel, PlotError, Series};
use crate::timing_plots::{StepMark, TimingLimits};
use oils_emulator::recorder::{Log, Record, REC_DEADLINE_MISS};
use oils_shared::ENGINE_COUNT;
use std::path::{Path, PathBuf};

/// Most points drawn per line: longer series are thinned to every n-th point.
const MAX_POINTS: usize = 20_000;

/// The file names `write_all` writes, in order.
pub const FIGURES: [&str; 8] = [
    "altitude-speeds.png",
    "ground-track.png",
    "thrust.png",
    "mass-propellant.png",
    "pressures.png",
    "attitude-rates.png",
    "timing.png",
    "timing-timeline.png",
];

type Pts = Vec<(f64, f64)>;

fn t_s(r: &Record) -> f64 {
    r.telemetry.header.t_ns as f64 * 1e-9
}

fn stride(n: usize) -> usize {
    n.div_ceil(MAX_POINTS).max(1)
}

/// `(t, f(record))` over the records, thinned.
fn over_time(records: &[Record], f: impl Fn(&Record) -> f64) -> Pts {
    records
        .iter()
        .step_by(stride(records.len()))
        .map(|r| (t_s(r), f(r)))
        .collect()
}

fn xy(records: &[Record], f: impl Fn(&Record) -> (f64, f64)) -> Pts {
    records
        .iter()
        .step_by(stride(records.len()))
        .map(f)
        .collect()
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Unit radial vector of the true position.
fn up(r: &Record) -> [f64; 3] {
    let p = r.truth.pos_mci_m;
    let n = norm(p).max(1e-9);
    p.map(|x| x / n)
}

fn vertical_m_s(r: &Record) -> f64 {
    dot(r.truth.vel_mci_m_s, up(r))
}

fn horizontal_m_s(r: &Record) -> f64 {
    let v = r.truth.vel_mci_m_s;
    let vv = vertical_m_s(r);
    let u = up(r);
    norm([v[0] - vv * u[0], v[1] - vv * u[1], v[2] - vv * u[2]])
}

/// Body +Z (thrust axis) in mci from `[w, x, y, z]`.
fn thrust_axis(q: [f64; 4]) -> [f64; 3] {
    let [w, x, y, z] = q;
    [
        2.0 * (x * z + w * y),
        2.0 * (y * z - w * x),
        1.0 - 2.0 * (x * x + y * y),
    ]
}

fn tilt_deg(r: &Record) -> f64 {
    let a = thrust_axis(r.truth.q_mci_from_body);
    (dot(a, up(r)) / norm(a).max(1e-12))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

fn lat_lon_deg(r: &Record) -> (f64, f64) {
    let p = r.truth.pos_mci_m;
    let lat = (p[2] / norm(p).max(1e-9))
        .clamp(-1.0, 1.0)
        .asin()
        .to_degrees();
    let lon = p[1].atan2(p[0]).to_degrees();
    (lon, lat)
}

/// Surface distance from the first record's sub-vehicle point, km.
fn downrange_km(first: &Record, r: &Record) -> f64 {
    let radius_m = norm(first.truth.pos_mci_m) - first.truth.altitude_m;
    let angle = dot(up(first), up(r)).clamp(-1.0, 1.0).acos();
    angle * radius_m * 1e-3
}

/// Surface distance off the plane of the first record's position and velocity, m
/// (positive on the side of r x v).
fn crossrange_m(first: &Record, r: &Record) -> f64 {
    let (p, v) = (first.truth.pos_mci_m, first.truth.vel_mci_m_s);
    let n = [
        p[1] * v[2] - p[2] * v[1],
        p[2] * v[0] - p[0] * v[2],
        p[0] * v[1] - p[1] * v[0],
    ];
    let len = norm(n);
    if len == 0.0 {
        return 0.0;
    }
    let radius_m = norm(p) - first.truth.altitude_m;
    (dot(up(r), n) / len).clamp(-1.0, 1.0).asin() * radius_m
}

fn s<'a>(label: &'a str, points: &'a Pts) -> Series<'a> {
    Series { label, points }
}

/// The timing of every step: a step without a command still has its wake error, and
/// the misses are the tail a timing figure is for.
fn steps_timing(recs: &[Record]) -> Vec<StepTiming> {
    recs.iter().map(step_timing).collect()
}

/// A figure could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RunPlotError {
    /// The log has no record to plot.
    #[error("the log has no record to plot")]
    Empty,
    /// The output folder could not be created.
    #[error("creating {path}")]
    Dir {
        /// The folder.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

/// Writes the run's figures ([`FIGURES`]) into `dir`; returns their paths. `timing`:
/// per-step timing when the log carries more than the records give (an MCAP log's
/// timing channel); `None` takes it from the records ([`step_timing`]). `title`: names
/// the run in each figure's title.
pub fn write_all(
    log: &Log,
    timing: Option<&[StepTiming]>,
    dir: &Path,
    title: &str,
) -> Result<Vec<PathBuf>, RunPlotError> {
    let recs = &log.records[..];
    let first = recs.first().ok_or(RunPlotError::Empty)?;
    std::fs::create_dir_all(dir).map_err(|source| RunPlotError::Dir {
        path: dir.to_path_buf(),
        source,
    })?;
    let path = |i: usize| dir.join(FIGURES[i]);
    let heading = |what: &str| format!("{what}: {title}");
    let mut written = Vec::new();

    // 1. Altitude and speeds.
    let alt = over_time(recs, |r| r.truth.altitude_m * 1e-3);
    let vert = over_time(recs, vertical_m_s);
    let horiz = over_time(recs, horizontal_m_s);
    let low: Vec<Record> = recs
        .iter()
        .filter(|r| r.truth.altitude_m < 1000.0)
        .copied()
        .collect();
    let low_alt = over_time(&low, |r| r.truth.altitude_m);
    let low_vert = over_time(&low, vertical_m_s);
    let low_horiz = over_time(&low, horizontal_m_s);
    let mut panels = vec![
        Panel::new(
            "Altitude (true)",
            "time [s]",
            "altitude [km]",
            vec![s("altitude", &alt)],
        ),
        Panel::new(
            "Speeds relative to the local vertical (true)",
            "time [s]",
            "speed [m/s]",
            vec![s("vertical", &vert), s("horizontal", &horiz)],
        ),
    ];
    if !low.is_empty() {
        panels.push(Panel::new(
            "Last kilometre: altitude (true)",
            "time [s]",
            "altitude [m]",
            vec![s("altitude", &low_alt)],
        ));
        panels.push(Panel::new(
            "Last kilometre: speeds (true)",
            "time [s]",
            "speed [m/s]",
            vec![s("vertical", &low_vert), s("horizontal", &low_horiz)],
        ));
    }
    write_png(&path(0), &heading("Altitude and speeds"), &panels)?;
    written.push(path(0));

    // 2. Ground track.
    let track = xy(recs, |r| (downrange_km(first, r), crossrange_m(first, r)));
    let lat_lon = xy(recs, lat_lon_deg);
    let profile = xy(recs, |r| {
        (downrange_km(first, r), r.truth.altitude_m * 1e-3)
    });
    write_png(
        &path(1),
        &heading("Ground track"),
        &[
            Panel::new(
                "Sub-vehicle point: off the initial orbit plane",
                "downrange from start [km]",
                "crossrange [m]",
                vec![s("track", &track)],
            ),
            Panel::new(
                "Sub-vehicle point (Moon-fixed)",
                "longitude [deg]",
                "latitude [deg]",
                vec![s("track", &lat_lon)],
            ),
            Panel::new(
                "Altitude over downrange",
                "downrange from start [km]",
                "altitude [km]",
                vec![s("trajectory", &profile)],
            ),
        ],
    )?;
    written.push(path(1));

    // 3. Thrust per engine: applied command (after the link's guard) vs delivered.
    let titles: Vec<String> = (1..=ENGINE_COUNT)
        .map(|e| format!("Engine {e}: thrust commanded (applied) vs delivered (true)"))
        .collect();
    let cmd: Vec<Pts> = (0..ENGINE_COUNT)
        .map(|e| {
            over_time(recs, |r| {
                if r.applied.engines.on[e] {
                    r.applied.engines.thrust_cmd_n[e]
                } else {
                    0.0
                }
            })
        })
        .collect();
    let out: Vec<Pts> = (0..ENGINE_COUNT)
        .map(|e| over_time(recs, |r| r.truth.propulsion.thrust_n[e]))
        .collect();
    let panels: Vec<Panel> = (0..ENGINE_COUNT)
        .map(|e| {
            Panel::new(
                &titles[e],
                "time [s]",
                "thrust [N]",
                vec![s("commanded", &cmd[e]), s("delivered", &out[e])],
            )
        })
        .collect();
    write_png(&path(2), &heading("Thrust per engine"), &panels)?;
    written.push(path(2));

    // 4. Mass and propellant.
    let mass = over_time(recs, |r| r.truth.mass_kg);
    let fuel = over_time(recs, |r| r.truth.propulsion.ejected_fuel_kg);
    let ox = over_time(recs, |r| r.truth.propulsion.ejected_ox_kg);
    let used = over_time(recs, |r| first.truth.mass_kg - r.truth.mass_kg);
    let fuel_flow = over_time(recs, |r| r.truth.propulsion.fuel_flow_kg_s);
    let ox_flow = over_time(recs, |r| r.truth.propulsion.ox_flow_kg_s);
    write_png(
        &path(3),
        &heading("Mass and propellant"),
        &[
            Panel::new(
                "Vehicle mass (true)",
                "time [s]",
                "mass [kg]",
                vec![s("mass", &mass)],
            ),
            Panel::new(
                "Propellant used",
                "time [s]",
                "mass [kg]",
                vec![
                    s("mass lost", &used),
                    s("fuel ejected", &fuel),
                    s("oxidiser ejected", &ox),
                ],
            ),
            Panel::new(
                "Propellant flow",
                "time [s]",
                "flow [kg/s]",
                vec![s("fuel", &fuel_flow), s("oxidiser", &ox_flow)],
            ),
        ],
    )?;
    written.push(path(3));

    // 5. Pressures (bar). Models without a state give NaN, which is not drawn.
    let bar = |f: fn(&Record) -> f64| over_time(recs, move |r| f(r) * 1e-5);
    let gas = bar(|r| r.truth.propulsion.gas_pressure_pa);
    let reg = bar(|r| r.truth.internals.regulator_outlet_pa);
    let ftank = bar(|r| r.truth.propulsion.fuel_tank_pressure_pa);
    let otank = bar(|r| r.truth.propulsion.ox_tank_pressure_pa);
    let fman = bar(|r| r.truth.internals.manifold_pressure_pa[0]);
    let oman = bar(|r| r.truth.internals.manifold_pressure_pa[1]);
    let chamber: Vec<Pts> = (0..ENGINE_COUNT)
        .map(|e| over_time(recs, |r| r.truth.propulsion.chamber_pressure_pa[e] * 1e-5))
        .collect();
    let labels = ["engine 1", "engine 2", "engine 3", "engine 4"];
    let mut panels = Vec::new();
    let gas_series: Vec<Series> = [("helium bottle", &gas), ("regulator outlet", &reg)]
        .into_iter()
        .filter(|(_, p)| p.iter().any(|(_, y)| y.is_finite()))
        .map(|(l, p)| s(l, p))
        .collect();
    if !gas_series.is_empty() {
        panels.push(Panel::new(
            "Pressurant gas",
            "time [s]",
            "pressure [bar]",
            gas_series,
        ));
    }
    let feed: Vec<Series> = [
        ("fuel tank", &ftank),
        ("oxidiser tank", &otank),
        ("fuel manifold", &fman),
        ("oxidiser manifold", &oman),
    ]
    .into_iter()
    .filter(|(_, p)| p.iter().any(|(_, y)| y.is_finite()))
    .map(|(l, p)| s(l, p))
    .collect();
    if !feed.is_empty() {
        panels.push(Panel::new(
            "Tanks and manifolds",
            "time [s]",
            "pressure [bar]",
            feed,
        ));
    }
    let chambers: Vec<Series> = (0..ENGINE_COUNT)
        .filter(|&e| chamber[e].iter().any(|(_, y)| y.is_finite()))
        .map(|e| s(labels[e], &chamber[e]))
        .collect();
    if !chambers.is_empty() {
        panels.push(Panel::new(
            "Chamber pressures",
            "time [s]",
            "pressure [bar]",
            chambers,
        ));
    }
    let thrust_sum = over_time(recs, |r| r.truth.propulsion.thrust_n.iter().sum());
    if panels.is_empty() {
        // A model without pressures (ideal): say so, with the total thrust it has.
        panels.push(Panel::new(
            "No pressure in this propulsion model: total delivered thrust instead",
            "time [s]",
            "thrust [N]",
            vec![s("sum of delivered thrust", &thrust_sum)],
        ));
    }
    write_png(&path(4), &heading("Gas and tank pressures"), &panels)?;
    written.push(path(4));

    // 6. Attitude and rates.
    let tilt = over_time(recs, tilt_deg);
    let quat: Vec<Pts> = (0..4)
        .map(|i| over_time(recs, |r| r.truth.q_mci_from_body[i]))
        .collect();
    let rates: Vec<Pts> = (0..3)
        .map(|i| over_time(recs, |r| r.truth.rate_body_rad_s[i].to_degrees()))
        .collect();
    let torque: Vec<Pts> = (0..3)
        .map(|i| over_time(recs, |r| r.applied.torque_cmd_body_nm[i]))
        .collect();
    write_png(
        &path(5),
        &heading("Attitude and rates"),
        &[
            Panel::new(
                "Tilt: thrust axis from the local vertical (true)",
                "time [s]",
                "tilt [deg]",
                vec![s("tilt", &tilt)],
            ),
            Panel::new(
                "Attitude quaternion, body to Moon-fixed (true)",
                "time [s]",
                "[-]",
                vec![
                    s("w", &quat[0]),
                    s("x", &quat[1]),
                    s("y", &quat[2]),
                    s("z", &quat[3]),
                ],
            ),
            Panel::new(
                "Body rates (true)",
                "time [s]",
                "rate [deg/s]",
                vec![s("x", &rates[0]), s("y", &rates[1]), s("z", &rates[2])],
            ),
            Panel::new(
                "Torque applied",
                "time [s]",
                "torque [N m]",
                vec![s("x", &torque[0]), s("y", &torque[1]), s("z", &torque[2])],
            ),
        ],
    )?;
    written.push(path(5));

    // 7. Timing: percentile plots and the timeline of misses and overruns.
    let own: Vec<StepTiming>;
    let timing = match timing {
        Some(t) => t,
        None => {
            own = steps_timing(recs);
            &own
        }
    };
    let marks: Vec<StepMark> = recs
        .iter()
        .map(|r| StepMark {
            t_s: t_s(r),
            deadline_miss: r.flags & REC_DEADLINE_MISS != 0,
        })
        .collect();
    let header: serde_json::Value = serde_json::from_str(&log.header_json).unwrap_or_default();
    let limits = TimingLimits::of_config(&header["config"]);
    written.extend(crate::timing_plots::write_all(
        timing, &marks, &limits, dir, title,
    )?);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_timing_keeps_the_steps_without_a_command() {
        let mut recs = [Record::default(); 3];
        for (k, r) in recs.iter_mut().enumerate() {
            r.timing.wake_error_ns = Some(1000 * (k as i64 + 1));
        }
        recs[0].flags = oils_emulator::recorder::REC_COMMAND_RECEIVED;
        recs[0].timing.round_trip_ns = Some(50_000);
        recs[1].flags = REC_DEADLINE_MISS;
        let t = steps_timing(&recs);
        assert_eq!(t.len(), 3);
        assert_eq!(t.iter().filter(|t| t.wake_error_ns.is_some()).count(), 3);
        assert_eq!(t.iter().filter(|t| t.round_trip_ns.is_some()).count(), 1);
    }

    #[test]
    fn thrust_axis_of_identity_is_z_and_tilt_follows_rotation() {
        assert_eq!(thrust_axis([1.0, 0.0, 0.0, 0.0]), [0.0, 0.0, 1.0]);
        let mut r = Record::default();
        r.truth.pos_mci_m = [0.0, 0.0, 1_737_400.0];
        let half = 30f64.to_radians() / 2.0;
        r.truth.q_mci_from_body = [half.cos(), half.sin(), 0.0, 0.0];
        assert!((tilt_deg(&r) - 30.0).abs() < 1e-9);
    }
}
