//! Parameters of the hifi propulsion model: plain `Deserialize` structs with `Default`
//! and a `validate()` that names the offending field.
//!
//! Defaults follow `shared/reference/lander-and-propulsion.md`; each field says whether
//! its number is sourced or assumed. The documented copy is `emulator/config/hifi.toml`
//! (a test checks that it parses and equals `HifiParams::default()`).
//!
//! Any subset of fields may be given, except that a per-propellant table
//! (`[tanks.fuel]`, `[feed.ox]`, `[engine.fuel]`, ...) that is given must be complete:
//! fuel and oxidiser defaults differ, so there is no single default to fill it from.
//!
//! The propellant load and mixture ratio are not here: they come from the scenario's
//! `PropulsionConfig`, so the bench's vehicle mass and this model agree.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// A parameter is out of its meaningful range.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("invalid hifi parameter: {field} = {value} ({why})")]
pub struct ParamError {
    /// Dotted path of the field, as in the TOML file.
    pub field: &'static str,
    /// The offending value, printed.
    pub value: f64,
    /// What is expected.
    pub why: &'static str,
}

fn positive(field: &'static str, value: f64) -> Result<(), ParamError> {
    check(value > 0.0, field, value, "> 0")
}

fn non_negative(field: &'static str, value: f64) -> Result<(), ParamError> {
    check(value >= 0.0, field, value, ">= 0")
}

fn fraction(field: &'static str, value: f64) -> Result<(), ParamError> {
    check((0.0..1.0).contains(&value), field, value, "in [0, 1)")
}

fn check(ok: bool, field: &'static str, value: f64, why: &'static str) -> Result<(), ParamError> {
    if !(ok && value.is_finite()) {
        return Err(ParamError { field, value, why });
    }
    let (bound, bound_why) = physical_bound(field);
    if value.abs() > bound {
        return Err(ParamError {
            field,
            value,
            why: bound_why,
        });
    }
    Ok(())
}

/// The largest magnitude a parameter may have, from its unit (the field's suffix) or
/// its kind: far beyond any real pressure-fed lander, and small enough that the model's
/// products and powers of these numbers stay finite (a bottle at 1e300 Pa turned the
/// state into NaN on the first step).
fn physical_bound(field: &str) -> (f64, &'static str) {
    const BOUNDS: &[(&str, f64, &str)] = &[
        ("_pa_s_kg", 1e12, "at most 1e12 Pa s/kg"),
        ("_kg_m3", 3e4, "at most 3e4 kg/m^3"),
        ("_j_kg_k", 1e5, "at most 1e5 J/(kg K)"),
        ("_m3_kg", 1.0, "at most 1 m^3/kg"),
        ("_m6_kg2", 1.0, "at most 1 m^6/kg^2"),
        ("_w_k", 1e6, "at most 1e6 W/K"),
        ("_n_m", 1e9, "at most 1e9 N/m"),
        ("_m_s", 1e5, "at most 1e5 m/s"),
        ("_pa", 1e8, "at most 1e8 Pa (1000 bar)"),
        ("_k", 2000.0, "at most 2000 K"),
        ("_m3", 10.0, "at most 10 m^3"),
        ("_m2", 1.0, "at most 1 m^2"),
        ("_m", 100.0, "at most 100 m"),
        ("_s", 100.0, "at most 100 s"),
        ("_kg", 1e4, "at most 1e4 kg"),
        ("coefficient", 10.0, "at most 10"),
        ("friction_factor", 10.0, "at most 10"),
        ("minor_loss", 1e4, "at most 1e4"),
        ("damping_ratio", 100.0, "at most 100"),
        ("gamma", 3.0, "at most 3"),
        ("mixture_ratio", 100.0, "at most 100"),
    ];
    BOUNDS
        .iter()
        .find(|(suffix, _, _)| field.ends_with(suffix))
        .map_or((1e9, "at most 1e9 in magnitude"), |&(_, b, why)| (b, why))
}

/// Fixed-step integration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IntegrationParams {
    /// Largest sub-step, seconds; a bench step is split into equal sub-steps no longer
    /// than this. 0.1 ms resolves the ~1 ms chamber and feed-line dynamics to well under
    /// 0.1 N (see the convergence test).
    pub substep_s: f64,
    /// Factor by which a sub-step is divided while any solenoid valve is travelling or
    /// a dome is priming (about 60 ms at a start, 25 ms at a stop) and for
    /// `valve_refinement_hold_s` after.
    /// Near closure the branch flow becomes an infinitely stiff quasi-static flow
    /// driven by a moving valve, where Rosenbrock methods drop to first order
    /// (Prothero-Robinson order reduction), and the closure sets off a water hammer
    /// with millisecond rise times. Refining just there keeps the whole run converged
    /// for a negligible cost (starts and stops are rare).
    pub valve_travel_refinement: u32,
    /// How long the refinement holds after the last valve motion, s (the water
    /// hammer rings down in ~10 ms).
    pub valve_refinement_hold_s: f64,
}

impl Default for IntegrationParams {
    fn default() -> Self {
        Self {
            substep_s: 1e-4,
            valve_travel_refinement: 16,
            valve_refinement_hold_s: 0.03,
        }
    }
}

/// Helium properties and equation of state `p = rho R T (1 + B rho + C rho^2)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HeliumParams {
    /// Specific gas constant, J/(kg K) (sourced: 8.314462 / 0.0040026).
    pub gas_constant_j_kg_k: f64,
    /// Ratio of specific heats (sourced: monatomic, 5/3).
    pub gamma: f64,
    /// Second virial coefficient B, m^3/kg (fitted, with C, to the reference helium
    /// equation of state over 200-310 K and 17-280 bar: density within 0.3 %; B is
    /// ~11.6 cm^3/mol, close to the literature value near room temperature).
    pub virial_b_m3_kg: f64,
    /// Third virial coefficient C, m^6/kg^2 (fitted with B, see there).
    pub virial_c_m6_kg2: f64,
}

impl Default for HeliumParams {
    fn default() -> Self {
        Self {
            gas_constant_j_kg_k: 2077.26,
            gamma: 5.0 / 3.0,
            virial_b_m3_kg: 2.906e-3,
            virial_c_m6_kg2: 1.046e-5,
        }
    }
}

/// Helium bottle and its high-pressure latch valve.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BottleParams {
    /// Internal volume, m^3 (sourced range 75-90 L; the top of it, so that regulated
    /// flow lasts until the whole 1000 kg load is used).
    pub volume_m3: f64,
    /// Pressure at descent start, Pa (sourced: 280 bar).
    pub initial_pressure_pa: f64,
    /// Gas and wall temperature at descent start, K (assumed).
    pub initial_temperature_k: f64,
    /// Wall (liner and overwrap) mass, kg (assumed).
    pub wall_mass_kg: f64,
    /// Wall specific heat, J/(kg K) (assumed: titanium liner and composite mix).
    pub wall_specific_heat_j_kg_k: f64,
    /// Gas-to-wall heat transfer coefficient times area, W/K (assumed: natural
    /// convection ~45 W/(m^2 K) over a 0.86 m^2 sphere; gives a polytropic exponent of
    /// about 1.2-1.4 over a descent).
    pub wall_heat_transfer_w_k: f64,
    /// Wall-to-spacecraft conductance, W/K (assumed).
    pub ambient_heat_transfer_w_k: f64,
    /// Spacecraft structure temperature, K (assumed).
    pub ambient_temperature_k: f64,
    /// High-pressure latch valve open (closed: no helium reaches the regulator and the
    /// tanks blow down).
    pub latch_valve_open: bool,
    /// Latch valve flow area, m^2, in series with the regulator poppet (assumed).
    pub latch_flow_area_m2: f64,
}

impl Default for BottleParams {
    fn default() -> Self {
        Self {
            volume_m3: 0.09,
            initial_pressure_pa: 280e5,
            initial_temperature_k: 293.15,
            wall_mass_kg: 12.0,
            wall_specific_heat_j_kg_k: 600.0,
            wall_heat_transfer_w_k: 40.0,
            ambient_heat_transfer_w_k: 2.0,
            ambient_temperature_k: 293.15,
            latch_valve_open: true,
            latch_flow_area_m2: 2e-5,
        }
    }
}

/// Single-stage pressure regulator: spring-loaded poppet sensing outlet pressure on a
/// diaphragm, with a small outlet volume (plenum and lines to the check valves).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegulatorParams {
    /// Outlet pressure at which the poppet just closes (lock-up) at the initial bottle
    /// pressure, Pa (assumed: set 17 bar plus lock-up margin, within the sourced +-3 %).
    pub lockup_pressure_pa: f64,
    /// Effective area of the sensing diaphragm, m^2 (assumed).
    pub sensing_area_m2: f64,
    /// Main spring rate plus diaphragm rate, N/m (assumed; with the sensing area it sets
    /// the droop, ~3 % at rated flow and mid bottle pressure).
    pub spring_rate_n_m: f64,
    /// Moving mass (poppet, diaphragm, a third of the spring), kg (assumed; with the
    /// spring rate gives a ~200 Hz natural frequency, sourced range 50-300 Hz).
    pub moving_mass_kg: f64,
    /// Damping ratio of the poppet (assumed within the sourced 0.3-0.7).
    pub damping_ratio: f64,
    /// Seat diameter, m; the flow area is pi D x up to the full seat area at x = D/4.
    pub seat_diameter_m: f64,
    /// Discharge coefficient of the poppet (assumed).
    pub discharge_coefficient: f64,
    /// Net area on which inlet pressure pushes the poppet closed, m^2 (assumed: partly
    /// balanced poppet; sets the supply-pressure effect, outlet rising ~0.1 bar as the
    /// bottle empties).
    pub unbalanced_area_m2: f64,
    /// Outlet plenum plus lines to the check valves, m^3 (assumed).
    pub outlet_volume_m3: f64,
}

impl Default for RegulatorParams {
    fn default() -> Self {
        Self {
            lockup_pressure_pa: 17.3e5,
            sensing_area_m2: 2e-4,
            spring_rate_n_m: 1.06e5,
            moving_mass_kg: 0.067,
            damping_ratio: 0.5,
            seat_diameter_m: 4e-3,
            discharge_coefficient: 0.8,
            unbalanced_area_m2: 8e-8,
            outlet_volume_m3: 5e-4,
        }
    }
}

/// Check valve between the regulator outlet and each tank (one per tank).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CheckValveParams {
    /// Cracking pressure, Pa (assumed).
    pub crack_pressure_pa: f64,
    /// Flow area when open, m^2 (assumed).
    pub flow_area_m2: f64,
    /// Discharge coefficient (assumed).
    pub discharge_coefficient: f64,
    /// Pressure difference below which gas orifice flow is taken as laminar (linear),
    /// Pa: removes the infinite slope of sqrt(dp) at zero, which would make the
    /// equations stiff without changing any steady state of interest.
    pub laminar_dp_pa: f64,
}

impl Default for CheckValveParams {
    fn default() -> Self {
        Self {
            crack_pressure_pa: 0.1e5,
            flow_area_m2: 8e-6,
            discharge_coefficient: 0.7,
            laminar_dp_pa: 300.0,
        }
    }
}

/// One propellant tank.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TankParams {
    /// Internal volume, m^3 (assumed: the descent load plus ~8 % ullage).
    pub volume_m3: f64,
    /// Liquid density, kg/m^3 (sourced: MMH 874, MON-3 ~1440).
    pub liquid_density_kg_m3: f64,
}

/// Both propellant tanks and their ullage gas.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TanksParams {
    /// Nominal (regulated) tank pressure, Pa: the ullage pressure at descent start and
    /// the pressure at which the throttle calibration is made (sourced: 17 bar).
    pub nominal_pressure_pa: f64,
    /// Ullage gas temperature at descent start, K (assumed).
    pub initial_ullage_temperature_k: f64,
    /// Propellant and tank wall temperature, K (assumed constant over a descent).
    pub propellant_temperature_k: f64,
    /// Ullage gas to liquid and wall heat transfer coefficient times area, W/K
    /// (assumed: ~8 W/(m^2 K) over ~2.5 m^2 of wall and liquid surface; the reference
    /// takes the ullage as adiabatic, which over-states how cold it gets).
    pub ullage_heat_transfer_w_k: f64,
    /// Liquid left in a tank below which its outlet starts to uncover (gas ingestion
    /// starves the feed), kg (assumed).
    pub starvation_mass_kg: f64,
    /// Fuel (MMH) tank.
    pub fuel: TankParams,
    /// Oxidiser (MON-3) tank.
    pub ox: TankParams,
}

impl Default for TanksParams {
    fn default() -> Self {
        Self {
            nominal_pressure_pa: 17e5,
            initial_ullage_temperature_k: 293.15,
            propellant_temperature_k: 293.15,
            ullage_heat_transfer_w_k: 20.0,
            starvation_mass_kg: 0.5,
            fuel: TankParams {
                volume_m3: 0.47,
                liquid_density_kg_m3: 874.0,
            },
            ox: TankParams {
                volume_m3: 0.47,
                liquid_density_kg_m3: 1440.0,
            },
        }
    }
}

/// Feed system of one propellant: tank outlet line to a shared manifold, then one
/// branch line per engine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeedLineParams {
    /// Tank-to-manifold line length, m (sourced range 1-2 m).
    pub main_line_length_m: f64,
    /// Tank-to-manifold line inner diameter, m (assumed).
    pub main_line_diameter_m: f64,
    /// Darcy friction factor of the main line (assumed: turbulent, Re ~ 5e4).
    pub main_line_friction_factor: f64,
    /// Minor-loss coefficient of the main line: bends, filter, propellant latch valve
    /// (assumed).
    pub main_line_minor_loss: f64,
    /// Unsteady-friction resistance of the main line, Pa s/kg: an extra drop
    /// `R_u (m - m_slow)` on the flow's departure from its recent mean (Trikha-type
    /// frequency-dependent friction). Steady friction laws under-state the damping of
    /// water hammer several-fold; this gives the manifold / main-line mode a damping
    /// ratio of ~0.15 without changing any steady state (assumed).
    pub main_line_unsteady_friction_pa_s_kg: f64,
    /// Manifold volume including the line volumes that act as its compliance, m^3
    /// (assumed).
    pub manifold_volume_m3: f64,
    /// Effective wave speed in the liquid lines (liquid plus wall compliance), m/s
    /// (sourced range 1000-1200).
    pub wave_speed_m_s: f64,
    /// Manifold-to-engine branch line length, m (assumed).
    pub branch_line_length_m: f64,
    /// Branch line inner diameter, m (assumed within the sourced 6-10 mm).
    pub branch_line_diameter_m: f64,
    /// Darcy friction factor of a branch line (assumed).
    pub branch_line_friction_factor: f64,
    /// Minor-loss coefficient of a branch line (assumed).
    pub branch_line_minor_loss: f64,
}

/// Both feed systems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FeedParams {
    /// Flow below which liquid friction is blended to laminar (linear), as a fraction
    /// of the element's rated flow: keeps the friction slope finite at zero flow.
    pub laminar_flow_frac: f64,
    /// Time over which the "recent mean" flow of the unsteady friction is taken, s
    /// (assumed: several periods of the ~100 Hz line modes).
    pub unsteady_friction_time_s: f64,
    /// Fuel feed.
    pub fuel: FeedLineParams,
    /// Oxidiser feed.
    pub ox: FeedLineParams,
}

impl Default for FeedParams {
    fn default() -> Self {
        Self {
            laminar_flow_frac: 0.01,
            unsteady_friction_time_s: 0.05,
            fuel: FeedLineParams {
                main_line_length_m: 1.5,
                main_line_diameter_m: 12e-3,
                main_line_friction_factor: 0.02,
                main_line_minor_loss: 3.0,
                main_line_unsteady_friction_pa_s_kg: 2.2e6,
                manifold_volume_m3: 3e-4,
                wave_speed_m_s: 1100.0,
                branch_line_length_m: 0.6,
                branch_line_diameter_m: 6e-3,
                branch_line_friction_factor: 0.025,
                branch_line_minor_loss: 2.0,
            },
            ox: FeedLineParams {
                main_line_length_m: 1.5,
                main_line_diameter_m: 14e-3,
                main_line_friction_factor: 0.02,
                main_line_minor_loss: 3.0,
                main_line_unsteady_friction_pa_s_kg: 2.2e6,
                manifold_volume_m3: 3e-4,
                wave_speed_m_s: 1100.0,
                branch_line_length_m: 0.6,
                branch_line_diameter_m: 7e-3,
                branch_line_friction_factor: 0.025,
                branch_line_minor_loss: 2.0,
            },
        }
    }
}

/// The per-propellant hardware of one engine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnginePropellantParams {
    /// Solenoid valve delay from energising to the start of opening, s (sourced range
    /// 2-5 ms).
    pub solenoid_open_delay_s: f64,
    /// Solenoid valve delay from de-energising to the start of closing, s.
    pub solenoid_close_delay_s: f64,
    /// Solenoid valve flow area when open, m^2 (assumed: ~0.3 bar at rated flow).
    pub solenoid_flow_area_m2: f64,
    /// Solenoid valve discharge coefficient (assumed).
    pub solenoid_discharge_coefficient: f64,
    /// TFCV flow area at full stroke, m^2 (assumed: rated thrust near 85 % stroke).
    pub tfcv_max_area_m2: f64,
    /// TFCV discharge coefficient (assumed).
    pub tfcv_discharge_coefficient: f64,
    /// Injector orifice area, m^2 (assumed: drop ~25 % of chamber pressure at rated).
    pub injector_area_m2: f64,
    /// Injector discharge coefficient (sourced range 0.6-0.8).
    pub injector_discharge_coefficient: f64,
    /// Volume between the solenoid valve seat and the injector face (dome, passages)
    /// that must fill before propellant reaches the chamber, m^3 (assumed; with the
    /// valve timing gives a start to 90 % thrust of ~80 ms).
    pub dome_volume_m3: f64,
}

/// One throttleable engine (all four are alike).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EngineParams {
    /// Solenoid valve travel time, closed to open or back, s (sourced range 10-30 ms).
    pub solenoid_ramp_s: f64,
    /// TFCV actuator time constant, s (sourced range 10-20 ms).
    pub tfcv_time_constant_s: f64,
    /// TFCV full-stroke time at the rate limit, s (sourced range 100-300 ms).
    pub tfcv_full_stroke_s: f64,
    /// TFCV backlash (play between actuator and valve), fraction of stroke (sourced
    /// range 0.5-1 %).
    pub tfcv_backlash_frac: f64,
    /// TFCV position command resolution, fraction of stroke (sourced range 0.1-0.5 %).
    pub tfcv_quantum_frac: f64,
    /// Dome fill fraction at which propellant starts to reach the injector (assumed).
    pub dome_fill_knee_frac: f64,
    /// Time for a full dome to dribble into the chamber after the valve shuts, s
    /// (assumed; sets the low tail of the tail-off, starting at ~13 % of rated flow).
    pub dome_drain_time_s: f64,
    /// Nozzle throat area, m^2 (sourced: ~5.5e-4).
    pub throat_area_m2: f64,
    /// Vacuum thrust coefficient including nozzle losses (sourced: 1.89 x 0.97).
    pub thrust_coefficient: f64,
    /// Chamber characteristic length L* = V_c / A_t, m (sourced: ~0.75 m).
    pub characteristic_length_m: f64,
    /// Ratio of specific heats of the combustion gas (assumed).
    pub chamber_gamma: f64,
    /// Ideal c* at its peak mixture ratio, m/s (assumed: fit giving the sourced ideal
    /// 1738 m/s at O/F 1.65).
    pub cstar_ideal_peak_m_s: f64,
    /// Mixture ratio (O/F) of the ideal c* peak (assumed).
    pub cstar_peak_mixture_ratio: f64,
    /// c* of unburnt vapour far from any combustible ratio, m/s (assumed).
    pub cstar_floor_m_s: f64,
    /// c* efficiency at rated chamber pressure (sourced range 0.93-0.97; 0.955 gives an
    /// Isp of ~310 s with the thrust coefficient).
    pub cstar_efficiency_rated: f64,
    /// Drop of c* efficiency from rated to minimum throttle, absolute (sourced: 2-4 %).
    pub cstar_efficiency_drop_at_min: f64,
    /// Fuel-side hardware.
    pub fuel: EnginePropellantParams,
    /// Oxidiser-side hardware.
    pub ox: EnginePropellantParams,
}

impl Default for EngineParams {
    fn default() -> Self {
        Self {
            solenoid_ramp_s: 0.02,
            tfcv_time_constant_s: 0.015,
            tfcv_full_stroke_s: 0.15,
            tfcv_backlash_frac: 0.005,
            tfcv_quantum_frac: 0.001,
            dome_fill_knee_frac: 0.9,
            dome_drain_time_s: 0.6,
            throat_area_m2: 5.455e-4,
            thrust_coefficient: 1.8333,
            characteristic_length_m: 0.75,
            chamber_gamma: 1.2,
            cstar_ideal_peak_m_s: 1743.7,
            cstar_peak_mixture_ratio: 1.9,
            cstar_floor_m_s: 600.0,
            cstar_efficiency_rated: 0.955,
            cstar_efficiency_drop_at_min: 0.03,
            fuel: EnginePropellantParams {
                solenoid_open_delay_s: 0.005,
                solenoid_close_delay_s: 0.003,
                solenoid_flow_area_m2: 2.0e-5,
                solenoid_discharge_coefficient: 0.7,
                tfcv_max_area_m2: 5.2e-6,
                tfcv_discharge_coefficient: 0.7,
                injector_area_m2: 7.6e-6,
                injector_discharge_coefficient: 0.7,
                dome_volume_m3: 6e-6,
            },
            ox: EnginePropellantParams {
                solenoid_open_delay_s: 0.003,
                solenoid_close_delay_s: 0.003,
                solenoid_flow_area_m2: 2.5e-5,
                solenoid_discharge_coefficient: 0.7,
                tfcv_max_area_m2: 6.6e-6,
                tfcv_discharge_coefficient: 0.7,
                injector_area_m2: 9.7e-6,
                injector_discharge_coefficient: 0.7,
                dome_volume_m3: 6e-6,
            },
        }
    }
}

/// Everything the hifi model needs besides the scenario's `PropulsionConfig`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HifiParams {
    /// Integration.
    pub integration: IntegrationParams,
    /// Helium properties.
    pub helium: HeliumParams,
    /// Helium bottle and latch valve.
    pub bottle: BottleParams,
    /// Pressure regulator.
    pub regulator: RegulatorParams,
    /// Check valves (one per tank).
    pub check_valve: CheckValveParams,
    /// Propellant tanks.
    pub tanks: TanksParams,
    /// Feed lines and manifolds.
    pub feed: FeedParams,
    /// Engines.
    pub engine: EngineParams,
}

impl HifiParams {
    /// Reads and validates a TOML file (any subset of fields; the rest default).
    pub fn load(path: &std::path::Path) -> Result<Self, super::HifiError> {
        let text = std::fs::read_to_string(path).map_err(|e| super::HifiError::Io {
            what: format!("reading {}", path.display()),
            message: e.to_string(),
        })?;
        let p: Self = toml::from_str(&text).map_err(|e| super::HifiError::Parse {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        p.validate()?;
        Ok(p)
    }

    /// Checks every field; `HifiPropulsion::new` runs it.
    pub fn validate(&self) -> Result<(), ParamError> {
        positive("integration.substep_s", self.integration.substep_s)?;
        check(
            self.integration.substep_s <= 1e-3,
            "integration.substep_s",
            self.integration.substep_s,
            "<= 1 ms (the chamber time constant is ~1 ms)",
        )?;
        check(
            (1..=1000).contains(&self.integration.valve_travel_refinement),
            "integration.valve_travel_refinement",
            self.integration.valve_travel_refinement as f64,
            "in 1..=1000",
        )?;
        non_negative(
            "integration.valve_refinement_hold_s",
            self.integration.valve_refinement_hold_s,
        )?;
        let h = &self.helium;
        positive("helium.gas_constant_j_kg_k", h.gas_constant_j_kg_k)?;
        check(h.gamma > 1.0, "helium.gamma", h.gamma, "> 1")?;
        non_negative("helium.virial_b_m3_kg", h.virial_b_m3_kg)?;
        non_negative("helium.virial_c_m6_kg2", h.virial_c_m6_kg2)?;
        let b = &self.bottle;
        positive("bottle.volume_m3", b.volume_m3)?;
        positive("bottle.initial_pressure_pa", b.initial_pressure_pa)?;
        positive("bottle.initial_temperature_k", b.initial_temperature_k)?;
        positive("bottle.wall_mass_kg", b.wall_mass_kg)?;
        positive(
            "bottle.wall_specific_heat_j_kg_k",
            b.wall_specific_heat_j_kg_k,
        )?;
        non_negative("bottle.wall_heat_transfer_w_k", b.wall_heat_transfer_w_k)?;
        non_negative(
            "bottle.ambient_heat_transfer_w_k",
            b.ambient_heat_transfer_w_k,
        )?;
        positive("bottle.ambient_temperature_k", b.ambient_temperature_k)?;
        positive("bottle.latch_flow_area_m2", b.latch_flow_area_m2)?;
        let r = &self.regulator;
        positive("regulator.lockup_pressure_pa", r.lockup_pressure_pa)?;
        check(
            r.lockup_pressure_pa > self.tanks.nominal_pressure_pa,
            "regulator.lockup_pressure_pa",
            r.lockup_pressure_pa,
            "> tanks.nominal_pressure_pa",
        )?;
        check(
            r.lockup_pressure_pa < b.initial_pressure_pa,
            "regulator.lockup_pressure_pa",
            r.lockup_pressure_pa,
            "< bottle.initial_pressure_pa",
        )?;
        positive("regulator.sensing_area_m2", r.sensing_area_m2)?;
        positive("regulator.spring_rate_n_m", r.spring_rate_n_m)?;
        positive("regulator.moving_mass_kg", r.moving_mass_kg)?;
        positive("regulator.damping_ratio", r.damping_ratio)?;
        positive("regulator.seat_diameter_m", r.seat_diameter_m)?;
        positive("regulator.discharge_coefficient", r.discharge_coefficient)?;
        non_negative("regulator.unbalanced_area_m2", r.unbalanced_area_m2)?;
        check(
            r.unbalanced_area_m2 < r.sensing_area_m2,
            "regulator.unbalanced_area_m2",
            r.unbalanced_area_m2,
            "< regulator.sensing_area_m2",
        )?;
        positive("regulator.outlet_volume_m3", r.outlet_volume_m3)?;
        let c = &self.check_valve;
        non_negative("check_valve.crack_pressure_pa", c.crack_pressure_pa)?;
        positive("check_valve.flow_area_m2", c.flow_area_m2)?;
        positive("check_valve.discharge_coefficient", c.discharge_coefficient)?;
        positive("check_valve.laminar_dp_pa", c.laminar_dp_pa)?;
        let t = &self.tanks;
        positive("tanks.nominal_pressure_pa", t.nominal_pressure_pa)?;
        positive(
            "tanks.initial_ullage_temperature_k",
            t.initial_ullage_temperature_k,
        )?;
        positive("tanks.propellant_temperature_k", t.propellant_temperature_k)?;
        non_negative("tanks.ullage_heat_transfer_w_k", t.ullage_heat_transfer_w_k)?;
        positive("tanks.starvation_mass_kg", t.starvation_mass_kg)?;
        positive("tanks.fuel.volume_m3", t.fuel.volume_m3)?;
        positive(
            "tanks.fuel.liquid_density_kg_m3",
            t.fuel.liquid_density_kg_m3,
        )?;
        positive("tanks.ox.volume_m3", t.ox.volume_m3)?;
        positive("tanks.ox.liquid_density_kg_m3", t.ox.liquid_density_kg_m3)?;
        let f = &self.feed;
        check(
            f.laminar_flow_frac > 0.0 && f.laminar_flow_frac < 0.2,
            "feed.laminar_flow_frac",
            f.laminar_flow_frac,
            "in (0, 0.2)",
        )?;
        positive("feed.unsteady_friction_time_s", f.unsteady_friction_time_s)?;
        validate_feed(&f.fuel, FUEL_FEED_FIELDS)?;
        validate_feed(&f.ox, OX_FEED_FIELDS)?;
        let e = &self.engine;
        positive("engine.solenoid_ramp_s", e.solenoid_ramp_s)?;
        positive("engine.tfcv_time_constant_s", e.tfcv_time_constant_s)?;
        positive("engine.tfcv_full_stroke_s", e.tfcv_full_stroke_s)?;
        fraction("engine.tfcv_backlash_frac", e.tfcv_backlash_frac)?;
        fraction("engine.tfcv_quantum_frac", e.tfcv_quantum_frac)?;
        check(
            e.dome_fill_knee_frac > 0.0 && e.dome_fill_knee_frac < 1.0,
            "engine.dome_fill_knee_frac",
            e.dome_fill_knee_frac,
            "in (0, 1)",
        )?;
        positive("engine.dome_drain_time_s", e.dome_drain_time_s)?;
        positive("engine.throat_area_m2", e.throat_area_m2)?;
        positive("engine.thrust_coefficient", e.thrust_coefficient)?;
        positive("engine.characteristic_length_m", e.characteristic_length_m)?;
        check(
            e.chamber_gamma > 1.0,
            "engine.chamber_gamma",
            e.chamber_gamma,
            "> 1",
        )?;
        positive("engine.cstar_ideal_peak_m_s", e.cstar_ideal_peak_m_s)?;
        positive(
            "engine.cstar_peak_mixture_ratio",
            e.cstar_peak_mixture_ratio,
        )?;
        positive("engine.cstar_floor_m_s", e.cstar_floor_m_s)?;
        check(
            e.cstar_floor_m_s < e.cstar_ideal_peak_m_s,
            "engine.cstar_floor_m_s",
            e.cstar_floor_m_s,
            "< engine.cstar_ideal_peak_m_s",
        )?;
        check(
            e.cstar_efficiency_rated > 0.0 && e.cstar_efficiency_rated <= 1.0,
            "engine.cstar_efficiency_rated",
            e.cstar_efficiency_rated,
            "in (0, 1]",
        )?;
        check(
            e.cstar_efficiency_drop_at_min >= 0.0
                && e.cstar_efficiency_drop_at_min < e.cstar_efficiency_rated,
            "engine.cstar_efficiency_drop_at_min",
            e.cstar_efficiency_drop_at_min,
            "in [0, cstar_efficiency_rated)",
        )?;
        validate_engine_side(&e.fuel, FUEL_ENGINE_FIELDS)?;
        validate_engine_side(&e.ox, OX_ENGINE_FIELDS)?;
        Ok(())
    }
}

/// Field names for one propellant's feed, so errors name the TOML path exactly.
struct FeedFields {
    main_len: &'static str,
    main_dia: &'static str,
    main_f: &'static str,
    main_k: &'static str,
    main_uf: &'static str,
    manifold: &'static str,
    wave: &'static str,
    branch_len: &'static str,
    branch_dia: &'static str,
    branch_f: &'static str,
    branch_k: &'static str,
}

const FUEL_FEED_FIELDS: FeedFields = FeedFields {
    main_len: "feed.fuel.main_line_length_m",
    main_dia: "feed.fuel.main_line_diameter_m",
    main_f: "feed.fuel.main_line_friction_factor",
    main_k: "feed.fuel.main_line_minor_loss",
    main_uf: "feed.fuel.main_line_unsteady_friction_pa_s_kg",
    manifold: "feed.fuel.manifold_volume_m3",
    wave: "feed.fuel.wave_speed_m_s",
    branch_len: "feed.fuel.branch_line_length_m",
    branch_dia: "feed.fuel.branch_line_diameter_m",
    branch_f: "feed.fuel.branch_line_friction_factor",
    branch_k: "feed.fuel.branch_line_minor_loss",
};

const OX_FEED_FIELDS: FeedFields = FeedFields {
    main_len: "feed.ox.main_line_length_m",
    main_dia: "feed.ox.main_line_diameter_m",
    main_f: "feed.ox.main_line_friction_factor",
    main_k: "feed.ox.main_line_minor_loss",
    main_uf: "feed.ox.main_line_unsteady_friction_pa_s_kg",
    manifold: "feed.ox.manifold_volume_m3",
    wave: "feed.ox.wave_speed_m_s",
    branch_len: "feed.ox.branch_line_length_m",
    branch_dia: "feed.ox.branch_line_diameter_m",
    branch_f: "feed.ox.branch_line_friction_factor",
    branch_k: "feed.ox.branch_line_minor_loss",
};

fn validate_feed(p: &FeedLineParams, n: FeedFields) -> Result<(), ParamError> {
    positive(n.main_len, p.main_line_length_m)?;
    positive(n.main_dia, p.main_line_diameter_m)?;
    non_negative(n.main_f, p.main_line_friction_factor)?;
    non_negative(n.main_k, p.main_line_minor_loss)?;
    check(
        p.main_line_friction_factor > 0.0 || p.main_line_minor_loss > 0.0,
        n.main_k,
        p.main_line_minor_loss,
        "some loss is needed (friction factor or minor loss > 0)",
    )?;
    non_negative(n.main_uf, p.main_line_unsteady_friction_pa_s_kg)?;
    positive(n.manifold, p.manifold_volume_m3)?;
    positive(n.wave, p.wave_speed_m_s)?;
    positive(n.branch_len, p.branch_line_length_m)?;
    positive(n.branch_dia, p.branch_line_diameter_m)?;
    non_negative(n.branch_f, p.branch_line_friction_factor)?;
    non_negative(n.branch_k, p.branch_line_minor_loss)?;
    Ok(())
}

struct EngineFields {
    open_delay: &'static str,
    close_delay: &'static str,
    sol_area: &'static str,
    sol_cd: &'static str,
    tfcv_area: &'static str,
    tfcv_cd: &'static str,
    inj_area: &'static str,
    inj_cd: &'static str,
    dome: &'static str,
}

const FUEL_ENGINE_FIELDS: EngineFields = EngineFields {
    open_delay: "engine.fuel.solenoid_open_delay_s",
    close_delay: "engine.fuel.solenoid_close_delay_s",
    sol_area: "engine.fuel.solenoid_flow_area_m2",
    sol_cd: "engine.fuel.solenoid_discharge_coefficient",
    tfcv_area: "engine.fuel.tfcv_max_area_m2",
    tfcv_cd: "engine.fuel.tfcv_discharge_coefficient",
    inj_area: "engine.fuel.injector_area_m2",
    inj_cd: "engine.fuel.injector_discharge_coefficient",
    dome: "engine.fuel.dome_volume_m3",
};

const OX_ENGINE_FIELDS: EngineFields = EngineFields {
    open_delay: "engine.ox.solenoid_open_delay_s",
    close_delay: "engine.ox.solenoid_close_delay_s",
    sol_area: "engine.ox.solenoid_flow_area_m2",
    sol_cd: "engine.ox.solenoid_discharge_coefficient",
    tfcv_area: "engine.ox.tfcv_max_area_m2",
    tfcv_cd: "engine.ox.tfcv_discharge_coefficient",
    inj_area: "engine.ox.injector_area_m2",
    inj_cd: "engine.ox.injector_discharge_coefficient",
    dome: "engine.ox.dome_volume_m3",
};

fn validate_engine_side(p: &EnginePropellantParams, n: EngineFields) -> Result<(), ParamError> {
    non_negative(n.open_delay, p.solenoid_open_delay_s)?;
    non_negative(n.close_delay, p.solenoid_close_delay_s)?;
    positive(n.sol_area, p.solenoid_flow_area_m2)?;
    positive(n.sol_cd, p.solenoid_discharge_coefficient)?;
    positive(n.tfcv_area, p.tfcv_max_area_m2)?;
    positive(n.tfcv_cd, p.tfcv_discharge_coefficient)?;
    positive(n.inj_area, p.injector_area_m2)?;
    positive(n.inj_cd, p.injector_discharge_coefficient)?;
    positive(n.dome, p.dome_volume_m3)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_parses_and_equals_default() {
        let text = include_str!("../../../config/hifi.toml");
        let p: HifiParams = toml::from_str(text).unwrap();
        assert_eq!(p, HifiParams::default());
        p.validate().unwrap();
    }

    #[test]
    fn unknown_fields_fail_and_bad_values_are_named() {
        assert!(toml::from_str::<HifiParams>("[bottle]\nvolume = 1.0\n").is_err());
        // A per-propellant table must be complete.
        let e = toml::from_str::<HifiParams>("[feed.ox]\nbranch_line_diameter_m = 7e-3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field"), "{e}");
        let mut p = HifiParams::default();
        p.feed.ox.branch_line_diameter_m = -1.0;
        assert_eq!(
            p.validate().unwrap_err().field,
            "feed.ox.branch_line_diameter_m"
        );
        let mut p = HifiParams::default();
        p.engine.fuel.injector_area_m2 = f64::NAN;
        assert_eq!(
            p.validate().unwrap_err().field,
            "engine.fuel.injector_area_m2"
        );
        // Issue #24: a bottle at 1e300 Pa was accepted, and the first step was NaN.
        for (field, set) in [
            (
                "bottle.initial_pressure_pa",
                (|p: &mut HifiParams| p.bottle.initial_pressure_pa = 1e300) as fn(&mut _),
            ),
            ("bottle.initial_temperature_k", |p| {
                p.bottle.initial_temperature_k = 1e300
            }),
            ("bottle.volume_m3", |p| p.bottle.volume_m3 = 1e300),
            ("engine.throat_area_m2", |p| p.engine.throat_area_m2 = 1e30),
            ("feed.fuel.main_line_length_m", |p| {
                p.feed.fuel.main_line_length_m = 1e30
            }),
            ("engine.thrust_coefficient", |p| {
                p.engine.thrust_coefficient = 1e300
            }),
        ] {
            let mut p = HifiParams::default();
            set(&mut p);
            let e = p.validate().unwrap_err();
            assert_eq!(e.field, field, "{e}");
            assert!(e.to_string().contains("at most"), "{e}");
        }
        let mut p = HifiParams::default();
        p.regulator.lockup_pressure_pa = 10e5;
        assert_eq!(
            p.validate().unwrap_err().field,
            "regulator.lockup_pressure_pa"
        );
    }
}
