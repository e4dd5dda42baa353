//! The FMU's variables: what the model description declares and what the binary reads
//! and writes, one table for both. Names are those of the recorded-data CSV
//! (`docs/recorded-data.md`), so an FMU's outputs and a recording read alike.

use oils_emulator::propulsion::{EngineCommand, PropulsionOutput};
use oils_shared::ENGINE_COUNT;

/// FMI type of a variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VarType {
    /// `Float64` (FMI 3.0), `Real` (FMI 2.0).
    Float64,
    /// `Boolean`.
    Boolean,
}

/// FMI causality.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Causality {
    /// Time (FMI 3.0 needs one independent variable).
    Independent,
    /// Set by the importer before each step.
    Input,
    /// Computed by the FMU at the end of each step.
    Output,
}

/// One variable.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Variable {
    /// Value reference.
    pub vr: u32,
    /// Name.
    pub name: &'static str,
    /// Type.
    pub ty: VarType,
    /// Causality.
    pub causality: Causality,
    /// SI unit (`N`, `Pa`, `kg`, `kg/s`, `s`), if any.
    pub unit: Option<&'static str>,
    /// One line for the model description.
    pub description: &'static str,
}

const fn var(
    vr: u32,
    name: &'static str,
    ty: VarType,
    causality: Causality,
    unit: Option<&'static str>,
    description: &'static str,
) -> Variable {
    Variable {
        vr,
        name,
        ty,
        causality,
        unit,
        description,
    }
}

use Causality::{Independent, Input, Output};
use VarType::{Boolean, Float64};

/// Value reference of time.
pub const VR_TIME: u32 = 0;
/// First value reference of the thrust commands (engines 1-4 follow).
pub const VR_CMD: u32 = 1;
/// First value reference of the on/off switches.
pub const VR_ON: u32 = 5;
/// First value reference of the thrusts.
pub const VR_THRUST: u32 = 9;
/// First value reference of the step-mean thrusts.
pub const VR_MEAN_THRUST: u32 = 13;
/// First value reference of the chamber pressures.
pub const VR_CHAMBER: u32 = 17;
/// Value reference of the gas (helium bottle) pressure.
pub const VR_GAS: u32 = 21;
/// Value reference of the fuel tank pressure.
pub const VR_FUEL_TANK: u32 = 22;
/// Value reference of the oxidiser tank pressure.
pub const VR_OX_TANK: u32 = 23;
/// Value reference of the ejected fuel.
pub const VR_EJECTED_FUEL: u32 = 24;
/// Value reference of the ejected oxidiser.
pub const VR_EJECTED_OX: u32 = 25;
/// Value reference of the fuel flow.
pub const VR_FUEL_FLOW: u32 = 26;
/// Value reference of the oxidiser flow.
pub const VR_OX_FLOW: u32 = 27;

/// Every variable, in value-reference order (index = value reference).
pub const VARIABLES: [Variable; 28] = [
    var(
        0,
        "time",
        Float64,
        Independent,
        Some("s"),
        "Simulation time",
    ),
    var(
        1,
        "cmd1_n",
        Float64,
        Input,
        Some("N"),
        "Thrust command, engine 1",
    ),
    var(
        2,
        "cmd2_n",
        Float64,
        Input,
        Some("N"),
        "Thrust command, engine 2",
    ),
    var(
        3,
        "cmd3_n",
        Float64,
        Input,
        Some("N"),
        "Thrust command, engine 3",
    ),
    var(
        4,
        "cmd4_n",
        Float64,
        Input,
        Some("N"),
        "Thrust command, engine 4",
    ),
    var(5, "on1", Boolean, Input, None, "Engine 1 on"),
    var(6, "on2", Boolean, Input, None, "Engine 2 on"),
    var(7, "on3", Boolean, Input, None, "Engine 3 on"),
    var(8, "on4", Boolean, Input, None, "Engine 4 on"),
    var(
        9,
        "thrust1_n",
        Float64,
        Output,
        Some("N"),
        "Thrust at the step's end, engine 1",
    ),
    var(
        10,
        "thrust2_n",
        Float64,
        Output,
        Some("N"),
        "Thrust at the step's end, engine 2",
    ),
    var(
        11,
        "thrust3_n",
        Float64,
        Output,
        Some("N"),
        "Thrust at the step's end, engine 3",
    ),
    var(
        12,
        "thrust4_n",
        Float64,
        Output,
        Some("N"),
        "Thrust at the step's end, engine 4",
    ),
    var(
        13,
        "mean_thrust1_n",
        Float64,
        Output,
        Some("N"),
        "Mean thrust over the step, engine 1",
    ),
    var(
        14,
        "mean_thrust2_n",
        Float64,
        Output,
        Some("N"),
        "Mean thrust over the step, engine 2",
    ),
    var(
        15,
        "mean_thrust3_n",
        Float64,
        Output,
        Some("N"),
        "Mean thrust over the step, engine 3",
    ),
    var(
        16,
        "mean_thrust4_n",
        Float64,
        Output,
        Some("N"),
        "Mean thrust over the step, engine 4",
    ),
    var(
        17,
        "chamber1_pa",
        Float64,
        Output,
        Some("Pa"),
        "Chamber pressure, engine 1",
    ),
    var(
        18,
        "chamber2_pa",
        Float64,
        Output,
        Some("Pa"),
        "Chamber pressure, engine 2",
    ),
    var(
        19,
        "chamber3_pa",
        Float64,
        Output,
        Some("Pa"),
        "Chamber pressure, engine 3",
    ),
    var(
        20,
        "chamber4_pa",
        Float64,
        Output,
        Some("Pa"),
        "Chamber pressure, engine 4",
    ),
    var(
        21,
        "gas_pressure_pa",
        Float64,
        Output,
        Some("Pa"),
        "Helium bottle pressure",
    ),
    var(
        22,
        "fuel_tank_pa",
        Float64,
        Output,
        Some("Pa"),
        "Fuel tank ullage pressure",
    ),
    var(
        23,
        "ox_tank_pa",
        Float64,
        Output,
        Some("Pa"),
        "Oxidiser tank ullage pressure",
    ),
    var(
        24,
        "ejected_fuel_kg",
        Float64,
        Output,
        Some("kg"),
        "Fuel ejected since the start",
    ),
    var(
        25,
        "ejected_ox_kg",
        Float64,
        Output,
        Some("kg"),
        "Oxidiser ejected since the start",
    ),
    var(
        26,
        "fuel_flow_kg_s",
        Float64,
        Output,
        Some("kg/s"),
        "Fuel mass flow at the step's end",
    ),
    var(
        27,
        "ox_flow_kg_s",
        Float64,
        Output,
        Some("kg/s"),
        "Oxidiser mass flow at the step's end",
    ),
];

/// The units the variables use, with their SI base-unit exponents (kg, m, s).
pub const UNITS: [(&str, [i32; 3]); 5] = [
    ("s", [0, 0, 1]),
    ("N", [1, 1, -2]),
    ("Pa", [1, -1, -2]),
    ("kg", [1, 0, 0]),
    ("kg/s", [1, 0, -1]),
];

/// The variable named `name`.
pub fn by_name(name: &str) -> Option<&'static Variable> {
    VARIABLES.iter().find(|v| v.name == name)
}

/// The value of a `Float64` variable given the outputs, the held command and the time;
/// `None` for a Boolean or unknown reference.
pub fn float_value(
    vr: u32,
    out: &PropulsionOutput,
    cmd: &EngineCommand,
    time_s: f64,
) -> Option<f64> {
    let e = |base: u32| (vr - base) as usize;
    let in_block = |base: u32| (base..base + ENGINE_COUNT as u32).contains(&vr);
    Some(match vr {
        VR_TIME => time_s,
        _ if in_block(VR_CMD) => cmd.thrust_cmd_n[e(VR_CMD)],
        _ if in_block(VR_THRUST) => out.thrust_n[e(VR_THRUST)],
        _ if in_block(VR_MEAN_THRUST) => out.mean_thrust_n[e(VR_MEAN_THRUST)],
        _ if in_block(VR_CHAMBER) => out.chamber_pressure_pa[e(VR_CHAMBER)],
        VR_GAS => out.gas_pressure_pa,
        VR_FUEL_TANK => out.fuel_tank_pressure_pa,
        VR_OX_TANK => out.ox_tank_pressure_pa,
        VR_EJECTED_FUEL => out.ejected_fuel_kg,
        VR_EJECTED_OX => out.ejected_ox_kg,
        VR_FUEL_FLOW => out.fuel_flow_kg_s,
        VR_OX_FLOW => out.ox_flow_kg_s,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_in_value_reference_order_with_unique_names() {
        for (i, v) in VARIABLES.iter().enumerate() {
            assert_eq!(v.vr as usize, i);
            assert_eq!(by_name(v.name), Some(v));
            if let Some(u) = v.unit {
                assert!(UNITS.iter().any(|(n, _)| *n == u), "{u}");
            }
        }
        let out = PropulsionOutput {
            gas_pressure_pa: 2e7,
            ..Default::default()
        };
        assert_eq!(
            float_value(VR_GAS, &out, &EngineCommand::default(), 0.0),
            Some(2e7)
        );
        assert_eq!(
            float_value(VR_ON, &out, &EngineCommand::default(), 0.0),
            None
        );
        assert_eq!(float_value(99, &out, &EngineCommand::default(), 0.0), None);
    }
}
