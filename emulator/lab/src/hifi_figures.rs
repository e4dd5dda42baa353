//! The documentation figures of the hifi model: a step-stair (rise) response, a fall
//! response with rise and fall steps overlaid, engine cross-coupling through the shared
//! manifolds, and a full open-loop descent. `oils hifi --plots DIR` writes them.

use crate::plot::{write_png, Panel, PlotError, Series};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::runner::{profile_of, simulate, Sample, DESCENT_PROFILE_CSV};
use oils_emulator::propulsion::hifi::{HifiError, HifiParams};
use oils_shared::profile::ThrustProfile;
use oils_shared::ENGINE_COUNT;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A figure could not be made.
#[derive(Debug, Error)]
pub enum FigureError {
    /// The model failed.
    #[error(transparent)]
    Model(#[from] HifiError),
    /// Drawing failed.
    #[error(transparent)]
    Plot(#[from] PlotError),
}

fn series(samples: &[Sample], f: impl Fn(&Sample) -> f64) -> Vec<(f64, f64)> {
    samples.iter().map(|s| (s.t_s, f(s))).collect()
}

const ALL_ON: [bool; ENGINE_COUNT] = [true; ENGINE_COUNT];

/// Writes the four figures into `dir`; returns their paths.
pub fn write_all(
    dir: &Path,
    params: &HifiParams,
    cfg: &PropulsionConfig,
    descent: Option<&ThrustProfile>,
    dt_ns: u64,
) -> Result<Vec<PathBuf>, FigureError> {
    let mut written = Vec::new();
    written.push(step_stair(dir, params, cfg, dt_ns)?);
    written.push(fall(dir, params, cfg, dt_ns)?);
    written.push(cross_coupling(dir, params, cfg, dt_ns)?);
    let committed;
    let descent = match descent {
        Some(p) => p,
        None => {
            committed = ThrustProfile::parse(DESCENT_PROFILE_CSV)
                .map_err(|e| HifiError::Profile(e.to_string()))?;
            &committed
        }
    };
    written.push(full_descent(dir, params, cfg, descent, dt_ns)?);
    Ok(written)
}

fn stairs(levels: &[f64], first_s: f64, hold_s: f64) -> ThrustProfile {
    let rows: Vec<_> = levels
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            let t = if i == 0 {
                0.0
            } else {
                first_s + hold_s * (i - 1) as f64
            };
            (t, [f; ENGINE_COUNT], ALL_ON)
        })
        .collect();
    profile_of(&rows)
}

fn stair_panels<'a>(samples: &'a [Sample], store: &'a mut Vec<Vec<(f64, f64)>>) -> Vec<Panel<'a>> {
    store.push(series(samples, |s| s.cmd.thrust_cmd_n[0]));
    store.push(series(samples, |s| s.d.out.thrust_n[0]));
    store.push(series(samples, |s| s.d.out.fuel_tank_pressure_pa * 1e-5));
    store.push(series(samples, |s| s.d.out.ox_tank_pressure_pa * 1e-5));
    store.push(series(samples, |s| s.d.manifold_pressure_pa[0] * 1e-5));
    store.push(series(samples, |s| s.d.manifold_pressure_pa[1] * 1e-5));
    store.push(series(samples, |s| {
        s.d.injected_kg_s[0][1] / s.d.injected_kg_s[0][0].max(1e-9)
    }));
    let v = &*store;
    let mut mr = Panel::new(
        "Engine 1 mixture ratio",
        "time [s]",
        "O/F [-]",
        vec![Series {
            label: "O/F",
            points: &v[6],
        }],
    );
    mr.log_y = false;
    vec![
        Panel::new(
            "Engine 1 thrust (all four engines commanded alike)",
            "time [s]",
            "thrust [N]",
            vec![
                Series {
                    label: "command",
                    points: &v[0],
                },
                Series {
                    label: "hifi thrust",
                    points: &v[1],
                },
            ],
        ),
        Panel::new(
            "Feed pressures",
            "time [s]",
            "pressure [bar]",
            vec![
                Series {
                    label: "fuel tank",
                    points: &v[2],
                },
                Series {
                    label: "ox tank",
                    points: &v[3],
                },
                Series {
                    label: "fuel manifold",
                    points: &v[4],
                },
                Series {
                    label: "ox manifold",
                    points: &v[5],
                },
            ],
        ),
        mr,
    ]
}

/// Step-stair (rise) response: 320 N up to 800 N in 80 N stairs.
fn step_stair(
    dir: &Path,
    params: &HifiParams,
    cfg: &PropulsionConfig,
    dt_ns: u64,
) -> Result<PathBuf, FigureError> {
    let profile = stairs(&[320.0, 400.0, 480.0, 560.0, 640.0, 720.0, 800.0], 3.0, 2.0);
    let samples = simulate(params, cfg, &profile, dt_ns, 16_000_000_000)?;
    let mut store = Vec::new();
    let panels = stair_panels(&samples, &mut store);
    let path = dir.join("hifi-step-stair.png");
    write_png(
        &path,
        "hifi propulsion: step-stair (rise) response",
        &panels,
    )?;
    Ok(path)
}

/// Normalised response `(F - F0) / (F1 - F0)` of engine 1 after a step at `t_step_s`.
fn normalised_step(samples: &[Sample], t_step_s: f64, f0: f64, f1: f64) -> Vec<(f64, f64)> {
    samples
        .iter()
        .filter(|s| s.t_s >= t_step_s - 0.05 && s.t_s <= t_step_s + 0.6)
        .map(|s| {
            (
                (s.t_s - t_step_s) * 1e3,
                (s.d.out.thrust_n[0] - f0) / (f1 - f0),
            )
        })
        .collect()
}

/// Fall response: 800 N down to 320 N in stairs, and a rise and a fall step overlaid.
fn fall(
    dir: &Path,
    params: &HifiParams,
    cfg: &PropulsionConfig,
    dt_ns: u64,
) -> Result<PathBuf, FigureError> {
    let profile = stairs(&[800.0, 720.0, 640.0, 560.0, 480.0, 400.0, 320.0], 3.0, 2.0);
    let samples = simulate(params, cfg, &profile, dt_ns, 16_000_000_000)?;
    let mut store = Vec::new();
    let mut panels = stair_panels(&samples, &mut store);
    panels.truncate(2);
    panels[0].title = "Engine 1 thrust, falling stairs (all four engines commanded alike)";
    // Rise 400 -> 800 and fall 800 -> 400, same size, on fresh models; 1 ms sampling.
    let fine_ns = 1_000_000;
    let rise = simulate(
        params,
        cfg,
        &profile_of(&[(0.0, [400.0; 4], ALL_ON), (3.0, [800.0; 4], ALL_ON)]),
        fine_ns,
        3_700_000_000,
    )?;
    let fall = simulate(
        params,
        cfg,
        &profile_of(&[(0.0, [800.0; 4], ALL_ON), (3.0, [400.0; 4], ALL_ON)]),
        fine_ns,
        3_700_000_000,
    )?;
    let base = |s: &[Sample]| {
        s.iter()
            .rev()
            .find(|x| x.t_s <= 3.0)
            .map_or(0.0, |x| x.d.out.thrust_n[0])
    };
    let end = |s: &[Sample]| s.last().map_or(0.0, |x| x.d.out.thrust_n[0]);
    let r = normalised_step(&rise, 3.0, base(&rise), end(&rise));
    let f = normalised_step(&fall, 3.0, base(&fall), end(&fall));
    panels.push(Panel::new(
        "Rise 400->800 N vs fall 800->400 N, normalised (a linear system would overlay)",
        "time since step [ms]",
        "(F - F0) / (F1 - F0) [-]",
        vec![
            Series {
                label: "rise",
                points: &r,
            },
            Series {
                label: "fall",
                points: &f,
            },
        ],
    ));
    let path = dir.join("hifi-fall.png");
    write_png(
        &path,
        "hifi propulsion: fall response and nonlinearity",
        &panels,
    )?;
    Ok(path)
}

/// Cross-coupling: engine 1 steps and switches while 2-4 hold 600 N.
fn cross_coupling(
    dir: &Path,
    params: &HifiParams,
    cfg: &PropulsionConfig,
    dt_ns: u64,
) -> Result<PathBuf, FigureError> {
    let fine_ns = dt_ns.min(2_000_000);
    let e1 = |f: f64, on: bool| ([f, 600.0, 600.0, 600.0], [on, true, true, true]);
    let rows = [
        (0.0, e1(600.0, true)),
        (3.0, e1(800.0, true)),
        (5.0, e1(400.0, true)),
        (7.0, e1(600.0, true)),
        (9.0, e1(600.0, false)),
        (11.0, e1(600.0, true)),
    ];
    let rows: Vec<_> = rows.iter().map(|&(t, (c, on))| (t, c, on)).collect();
    let samples = simulate(params, cfg, &profile_of(&rows), fine_ns, 13_000_000_000)?;
    let shown: Vec<Sample> = samples.into_iter().filter(|s| s.t_s >= 2.0).collect();
    let reference: [f64; 4] = shown.first().map_or([0.0; 4], |s| s.d.out.thrust_n);
    let cmd1 = series(&shown, |s| s.cmd.thrust_cmd_n[0] * s.cmd.on[0] as u8 as f64);
    let f1 = series(&shown, |s| s.d.out.thrust_n[0]);
    let d: Vec<Vec<(f64, f64)>> = (1..4)
        .map(|e| series(&shown, |s| s.d.out.thrust_n[e] - reference[e]))
        .collect();
    let pm_f = series(&shown, |s| s.d.manifold_pressure_pa[0] * 1e-5);
    let pm_o = series(&shown, |s| s.d.manifold_pressure_pa[1] * 1e-5);
    let panels = [
        Panel::new(
            "Engine 1: steps 600 -> 800 -> 400 -> 600 N, off at 9 s, on at 11 s",
            "time [s]",
            "thrust [N]",
            vec![
                Series {
                    label: "engine 1 command",
                    points: &cmd1,
                },
                Series {
                    label: "engine 1 thrust",
                    points: &f1,
                },
            ],
        ),
        Panel::new(
            "Engines 2-4 (commanded 600 N throughout): change of thrust",
            "time [s]",
            "thrust - thrust at 2 s [N]",
            vec![
                Series {
                    label: "engine 2",
                    points: &d[0],
                },
                Series {
                    label: "engine 3",
                    points: &d[1],
                },
                Series {
                    label: "engine 4",
                    points: &d[2],
                },
            ],
        ),
        Panel::new(
            "Shared manifolds",
            "time [s]",
            "pressure [bar]",
            vec![
                Series {
                    label: "fuel manifold",
                    points: &pm_f,
                },
                Series {
                    label: "ox manifold",
                    points: &pm_o,
                },
            ],
        ),
    ];
    let path = dir.join("hifi-cross-coupling.png");
    write_png(&path, "hifi propulsion: engine cross-coupling", &panels)?;
    Ok(path)
}

/// Full open-loop descent: thrusts, pressures, masses.
fn full_descent(
    dir: &Path,
    params: &HifiParams,
    cfg: &PropulsionConfig,
    profile: &ThrustProfile,
    dt_ns: u64,
) -> Result<PathBuf, FigureError> {
    let duration = profile.end_ns() + 2_000_000_000;
    let samples = simulate(params, cfg, profile, dt_ns, duration)?;
    let thrust: Vec<Vec<(f64, f64)>> = (0..ENGINE_COUNT)
        .map(|e| series(&samples, |s| s.d.out.thrust_n[e]))
        .collect();
    let gas = series(&samples, |s| s.d.out.gas_pressure_pa * 1e-5);
    let gas_t = series(&samples, |s| s.d.bottle_temperature_k);
    let tank_f = series(&samples, |s| s.d.out.fuel_tank_pressure_pa * 1e-5);
    let tank_o = series(&samples, |s| s.d.out.ox_tank_pressure_pa * 1e-5);
    let reg = series(&samples, |s| s.d.regulator_outlet_pa * 1e-5);
    let ej_f = series(&samples, |s| s.d.out.ejected_fuel_kg);
    let ej_o = series(&samples, |s| s.d.out.ejected_ox_kg);
    let left_f = series(&samples, |s| s.d.tank_liquid_kg[0]);
    let left_o = series(&samples, |s| s.d.tank_liquid_kg[1]);
    let labels = ["engine 1", "engine 2", "engine 3", "engine 4"];
    let panels = [
        Panel::new(
            "Thrust per engine",
            "time [s]",
            "thrust [N]",
            thrust
                .iter()
                .zip(labels)
                .map(|(p, l)| Series {
                    label: l,
                    points: p,
                })
                .collect(),
        ),
        Panel::new(
            "Helium bottle",
            "time [s]",
            "pressure [bar] / temperature [K]",
            vec![
                Series {
                    label: "bottle pressure [bar]",
                    points: &gas,
                },
                Series {
                    label: "bottle temperature [K]",
                    points: &gas_t,
                },
            ],
        ),
        Panel::new(
            "Regulated pressures",
            "time [s]",
            "pressure [bar]",
            vec![
                Series {
                    label: "regulator outlet",
                    points: &reg,
                },
                Series {
                    label: "fuel tank",
                    points: &tank_f,
                },
                Series {
                    label: "ox tank",
                    points: &tank_o,
                },
            ],
        ),
        Panel::new(
            "Propellant",
            "time [s]",
            "mass [kg]",
            vec![
                Series {
                    label: "fuel ejected",
                    points: &ej_f,
                },
                Series {
                    label: "ox ejected",
                    points: &ej_o,
                },
                Series {
                    label: "fuel in tank",
                    points: &left_f,
                },
                Series {
                    label: "ox in tank",
                    points: &left_o,
                },
            ],
        ),
    ];
    let path = dir.join("hifi-descent.png");
    write_png(&path, "hifi propulsion: open-loop descent profile", &panels)?;
    Ok(path)
}
