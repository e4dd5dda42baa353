//! Open-loop runner: drives the model with a thrust-command profile and writes every
//! output at the bench step as CSV, so anyone can generate data or check behaviour
//! without the bench.

use super::{HifiDetail, HifiError, HifiParams, HifiPropulsion};
use crate::config::PropulsionConfig;
use crate::propulsion::{EngineCommand, Propulsion};
use oils_shared::profile::{ProfileRow, ThrustProfile};
use oils_shared::ENGINE_COUNT;
use std::io::Write;

/// CSV header: one quantity per column, unit in the name. A row at `t_s` holds the
/// state at that time and the command held over the step that ended there (the first
/// row: the initial state and the first command).
pub const CSV_HEADER: &str = concat!(
    "t_s,cmd1_n,cmd2_n,cmd3_n,cmd4_n,on1,on2,on3,on4,",
    "thrust1_n,thrust2_n,thrust3_n,thrust4_n,",
    "mean_thrust1_n,mean_thrust2_n,mean_thrust3_n,mean_thrust4_n,",
    "chamber1_pa,chamber2_pa,chamber3_pa,chamber4_pa,",
    "gas_pressure_pa,gas_temperature_k,gas_wall_temperature_k,gas_mass_kg,",
    "regulator_outlet_pa,regulator_lift_m,regulator_flow_kg_s,",
    "fuel_tank_pa,ox_tank_pa,fuel_ullage_k,ox_ullage_k,",
    "fuel_manifold_pa,ox_manifold_pa,fuel_tank_kg,ox_tank_kg,",
    "ejected_fuel_kg,ejected_ox_kg,fuel_flow_kg_s,ox_flow_kg_s,",
    "fuel_flow1_kg_s,fuel_flow2_kg_s,fuel_flow3_kg_s,fuel_flow4_kg_s,",
    "ox_flow1_kg_s,ox_flow2_kg_s,ox_flow3_kg_s,ox_flow4_kg_s,",
    "tfcv_fuel1,tfcv_fuel2,tfcv_fuel3,tfcv_fuel4,",
    "tfcv_ox1,tfcv_ox2,tfcv_ox3,tfcv_ox4"
);

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunSummary {
    /// Bench steps taken.
    pub steps: u64,
    /// Simulated time, s.
    pub duration_s: f64,
    /// Outputs at the end.
    pub last: HifiDetail,
}

/// The command in force at `t_ns` (all engines off before the profile's first row).
pub fn command_at(profile: &ThrustProfile, t_ns: i64) -> EngineCommand {
    profile
        .at(t_ns)
        .map(|r| EngineCommand {
            thrust_cmd_n: r.thrust_cmd_n,
            on: r.on,
        })
        .unwrap_or_default()
}

fn io_err(e: std::io::Error) -> HifiError {
    HifiError::Io {
        what: "writing CSV".into(),
        message: e.to_string(),
    }
}

/// Writes one CSV row (no allocation: formats straight into `out`).
pub fn write_row(
    out: &mut impl Write,
    t_ns: i64,
    cmd: &EngineCommand,
    d: &HifiDetail,
) -> std::io::Result<()> {
    write!(out, "{}", t_ns as f64 * 1e-9)?;
    for c in cmd.thrust_cmd_n {
        write!(out, ",{c}")?;
    }
    for o in cmd.on {
        write!(out, ",{}", o as u8)?;
    }
    let o = &d.out;
    for v in o
        .thrust_n
        .iter()
        .chain(&o.mean_thrust_n)
        .chain(&o.chamber_pressure_pa)
    {
        write!(out, ",{v}")?;
    }
    let scalars = [
        o.gas_pressure_pa,
        d.bottle_temperature_k,
        d.bottle_wall_temperature_k,
        d.bottle_helium_kg,
        d.regulator_outlet_pa,
        d.regulator_lift_m,
        d.regulator_flow_kg_s,
        o.fuel_tank_pressure_pa,
        o.ox_tank_pressure_pa,
        d.ullage_temperature_k[0],
        d.ullage_temperature_k[1],
        d.manifold_pressure_pa[0],
        d.manifold_pressure_pa[1],
        d.tank_liquid_kg[0],
        d.tank_liquid_kg[1],
        o.ejected_fuel_kg,
        o.ejected_ox_kg,
        o.fuel_flow_kg_s,
        o.ox_flow_kg_s,
    ];
    for v in scalars {
        write!(out, ",{v}")?;
    }
    for p in 0..2 {
        for e in 0..ENGINE_COUNT {
            write!(out, ",{}", d.injected_kg_s[e][p])?;
        }
    }
    for p in 0..2 {
        for e in 0..ENGINE_COUNT {
            write!(out, ",{}", d.tfcv_position[e][p])?;
        }
    }
    writeln!(out)
}

/// Runs `model` open loop over `[0, duration_ns]` in bench steps of `dt_ns`, holding
/// each step's command from `profile`, and writes the CSV (header first).
///
/// Calls `on_step` after each step with the time, command and outputs (for plots and
/// tests; pass `|_, _, _| {}` when not needed).
pub fn run_profile_with(
    model: &mut HifiPropulsion,
    profile: &ThrustProfile,
    dt_ns: u64,
    duration_ns: i64,
    out: &mut impl Write,
    mut on_step: impl FnMut(i64, &EngineCommand, &HifiDetail),
) -> Result<RunSummary, HifiError> {
    if dt_ns == 0 {
        return Err(HifiError::Profile("bench step must be > 0 ns".into()));
    }
    writeln!(out, "{CSV_HEADER}").map_err(io_err)?;
    let t0 = model.time_ns();
    let mut cmd = command_at(profile, 0);
    let first = model.detail();
    write_row(out, 0, &cmd, &first).map_err(io_err)?;
    on_step(0, &cmd, &first);
    let mut steps = 0u64;
    let mut t_rel = 0i64;
    while t_rel < duration_ns {
        cmd = command_at(profile, t_rel);
        model.step(&cmd, dt_ns);
        if let Some(f) = model.fault() {
            return Err(f.clone());
        }
        steps += 1;
        t_rel = model.time_ns() - t0;
        let d = model.detail();
        write_row(out, t_rel, &cmd, &d).map_err(io_err)?;
        on_step(t_rel, &cmd, &d);
    }
    out.flush().map_err(io_err)?;
    Ok(RunSummary {
        steps,
        duration_s: t_rel as f64 * 1e-9,
        last: model.detail(),
    })
}

/// [`run_profile_with`] without a per-step callback.
pub fn run_profile(
    model: &mut HifiPropulsion,
    profile: &ThrustProfile,
    dt_ns: u64,
    duration_ns: i64,
    out: &mut impl Write,
) -> Result<RunSummary, HifiError> {
    run_profile_with(model, profile, dt_ns, duration_ns, out, |_, _, _| {})
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PropulsionConfig;

    #[test]
    fn header_names_every_column_and_rows_match() {
        let names: Vec<&str> = CSV_HEADER.split(',').collect();
        for required in [
            "t_s",
            "thrust1_n",
            "thrust4_n",
            "gas_pressure_pa",
            "ejected_fuel_kg",
            "ejected_ox_kg",
        ] {
            assert!(names.contains(&required), "{required}");
        }
        let profile = ThrustProfile::parse(
            "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,600,600,600,600,1,1,1,1\n",
        )
        .unwrap();
        let mut m = HifiPropulsion::new(&Default::default(), &PropulsionConfig::default()).unwrap();
        let mut buf = Vec::new();
        let s = run_profile(&mut m, &profile, 10_000_000, 50_000_000, &mut buf).unwrap();
        assert_eq!(s.steps, 5);
        let text = String::from_utf8(buf).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 7);
        for l in &lines[1..] {
            assert_eq!(l.split(',').count(), names.len());
        }
        assert!(lines[6].starts_with("0.05,600,"));
    }
}

/// The committed Chandrayaan-3-like open-loop descent profile
/// (`emulator/data/descent-profile.csv`).
pub const DESCENT_PROFILE_CSV: &str = include_str!("../../../data/descent-profile.csv");

/// One sample of a simulated run.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Time, s.
    pub t_s: f64,
    /// Command held over the step that ended here.
    pub cmd: EngineCommand,
    /// Outputs.
    pub d: HifiDetail,
}

/// Runs a fresh model over a profile and keeps every bench-step sample.
pub fn simulate(
    params: &HifiParams,
    cfg: &PropulsionConfig,
    profile: &ThrustProfile,
    dt_ns: u64,
    duration_ns: i64,
) -> Result<Vec<Sample>, HifiError> {
    let mut model = HifiPropulsion::new(params, cfg)?;
    let mut samples = Vec::with_capacity((duration_ns.max(0) as u64 / dt_ns.max(1)) as usize + 2);
    run_profile_with(
        &mut model,
        profile,
        dt_ns,
        duration_ns,
        &mut std::io::sink(),
        |t_ns, cmd, d| {
            samples.push(Sample {
                t_s: t_ns as f64 * 1e-9,
                cmd: *cmd,
                d: *d,
            })
        },
    )?;
    Ok(samples)
}

/// A profile of `(t_s, [thrust per engine], [on per engine])` rows.
pub fn profile_of(rows: &[(f64, [f64; ENGINE_COUNT], [bool; ENGINE_COUNT])]) -> ThrustProfile {
    let rows = rows
        .iter()
        .map(|&(t, c, on)| ProfileRow {
            t_ns: (t * 1e9).round() as i64,
            thrust_cmd_n: c,
            on,
        })
        .collect();
    // Profiles built this way are literals in figures and tests; a bad one is a
    // programming error.
    ThrustProfile::from_rows(rows).expect("literal profiles are valid")
}
