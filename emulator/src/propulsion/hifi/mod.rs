//! The `hifi` propulsion model: lumped-parameter physics of the helium-pressurised
//! MMH / MON-3 system feeding four throttleable 800 N engines. It is the bench's truth
//! model, the data source for training the surrogate, and the reference the surrogate
//! is judged against.
//!
//! ```text
//!  He bottle -> latch -> regulator -> outlet vol -+-> check valve -> fuel tank ullage
//!  (real gas,            (poppet                 +-> check valve -> ox tank ullage
//!   wall heat)            dynamics)
//!  tank -> main line (inertance, friction) -> manifold (compliance, shared)
//!       -> per engine: branch line -> solenoid valve -> TFCV -> dome -> injector
//!       -> chamber (Pc dynamics, c*(MR, Pc)) -> nozzle (F = Cf Pc At)
//! ```
//! Modules: `params` (TOML parameters), `gas` (helium, bottle, check valves),
//! `regulator`, `fluid` (tanks, lines, manifold), `engine` (valves, dome, chamber),
//! `calibration` (thrust command to TFCV position), `plant` (state layout and
//! right-hand side), `integrator` (ROS2, and why), `runner` (open-loop CSV runner)
//! (its documentation figures are drawn by the lab, `oils_lab::hifi_figures`).
//!
//! Integration: each bench step is split into equal sub-steps of at most
//! `integration.substep_s` (0.1 ms) integrated by the linearly implicit ROS2 method
//! (see `integrator.rs` for the choice); valve motions are exact functions of time.

pub mod calibration;
pub mod engine;
pub mod fluid;
pub mod gas;
pub mod integrator;
pub mod params;
pub mod plant;
mod reference;
pub mod regulator;
pub mod runner;

pub use params::{HifiParams, ParamError};

use super::{EngineCommand, Propulsion, PropulsionOutput};
use crate::config::PropulsionConfig;
use calibration::{CalibrationPoint, ThrottleTable};
use engine::{Chamber, EngineSide, Solenoid, Tfcv, TfcvDynamics};
use fluid::{Feed, Tank};
use gas::{Bottle, CheckValve, Helium};
use integrator::{Rhs, Ros2};
use oils_shared::ENGINE_COUNT;
use plant::{ix, Actuation, Aux, Drive, Plant, PlantFaults, FUEL, N_STATES, OX};
use regulator::Regulator;
use thiserror::Error;

/// Errors of the hifi model and its tools.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum HifiError {
    /// A parameter is out of range.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// A parameter file is not valid TOML for `HifiParams`.
    #[error("parameter file {path}: {message}")]
    Parse {
        /// File.
        path: String,
        /// Parser's message.
        message: String,
    },
    /// Reading or writing failed.
    #[error("{what}: {message}")]
    Io {
        /// What was being done.
        what: String,
        /// The OS message.
        message: String,
    },
    /// The scenario's propulsion numbers are unusable for this model.
    #[error("propulsion config: {field} = {value} ({why})")]
    Config {
        /// Field of `PropulsionConfig`.
        field: &'static str,
        /// The value.
        value: f64,
        /// What is expected.
        why: &'static str,
    },
    /// The propellant load does not fit its tank with room for ullage gas.
    #[error(
        "{tank} load of {liquid_m3:.4} m^3 does not fit a {tank_m3:.4} m^3 tank with 1 % ullage"
    )]
    TankTooSmall {
        /// Which tank.
        tank: &'static str,
        /// Liquid volume, m^3.
        liquid_m3: f64,
        /// Tank volume, m^3.
        tank_m3: f64,
    },
    /// The throttle calibration has no solution at some thrust.
    #[error("throttle calibration at {thrust_n} N, {propellant}: {why}")]
    Calibration {
        /// Thrust where it failed, N.
        thrust_n: f64,
        /// Which side.
        propellant: &'static str,
        /// Why.
        why: &'static str,
    },
    /// The state became non-finite (numerical failure): the step was rolled back.
    #[error("hifi state became non-finite at t = {t_ns} ns")]
    NonFinite {
        /// Model time of the failed step.
        t_ns: i64,
    },
    /// A thrust-command profile could not be used.
    #[error("{0}")]
    Profile(String),
}

/// Propellant accounting of one propellant, kg.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PropellantBalance {
    /// Liquid loaded in the tank at the start.
    pub loaded_kg: f64,
    /// Liquid in the tank now.
    pub tank_kg: f64,
    /// Liquid held downstream of the tank above the initial line fill: compression of
    /// the manifold plus the engine domes.
    pub lines_kg: f64,
    /// Cumulative mass injected into the chambers.
    pub ejected_kg: f64,
}

impl PropellantBalance {
    /// Mass that left the tank minus mass accounted for downstream (should be ~0).
    pub fn imbalance_kg(&self) -> f64 {
        (self.loaded_kg - self.tank_kg) - (self.lines_kg + self.ejected_kg)
    }
}

/// Everything the model can report at a step boundary (for the runner and plots).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HifiDetail {
    /// The bench-level outputs.
    pub out: PropulsionOutput,
    /// Helium bottle temperature, K.
    pub bottle_temperature_k: f64,
    /// Bottle wall temperature, K.
    pub bottle_wall_temperature_k: f64,
    /// Helium mass in the bottle, kg.
    pub bottle_helium_kg: f64,
    /// Regulator outlet pressure, Pa.
    pub regulator_outlet_pa: f64,
    /// Regulator poppet lift, m.
    pub regulator_lift_m: f64,
    /// Helium flow through the regulator, kg/s.
    pub regulator_flow_kg_s: f64,
    /// Ullage temperature `[fuel, ox]`, K.
    pub ullage_temperature_k: [f64; 2],
    /// Manifold pressure `[fuel, ox]`, Pa.
    pub manifold_pressure_pa: [f64; 2],
    /// Liquid left in each tank `[fuel, ox]`, kg.
    pub tank_liquid_kg: [f64; 2],
    /// Injector flow `[engine][fuel, ox]`, kg/s.
    pub injected_kg_s: [[f64; 2]; ENGINE_COUNT],
    /// TFCV valve position `[engine][fuel, ox]`, fraction of stroke.
    pub tfcv_position: [[f64; 2]; ENGINE_COUNT],
    /// Solenoid opening `[engine][fuel, ox]`, 0-1.
    pub solenoid_opening: [[f64; 2]; ENGINE_COUNT],
}

/// The hifi propulsion model. Construct with [`HifiPropulsion::new`]; drive through the
/// [`Propulsion`] trait.
#[derive(Debug, Clone)]
pub struct HifiPropulsion {
    plant: Plant,
    y: [f64; N_STATES],
    scratch: [f64; N_STATES],
    ros2: Ros2<N_STATES>,
    solenoids: [[Solenoid; 2]; ENGINE_COUNT],
    tfcvs: [[Tfcv; 2]; ENGINE_COUNT],
    tfcv_dynamics: TfcvDynamics,
    solenoid_ramp_s: f64,
    table: ThrottleTable,
    substep_ns: u64,
    valve_refinement: u32,
    refine_hold_s: f64,
    refine_left_s: f64,
    loaded_kg: [f64; 2],
    manifold_ref_pa: [f64; 2],
    t_ns: i64,
    out: PropulsionOutput,
    fault: Option<HifiError>,
    /// Injected valve failures: stuck flags and speed factors per engine.
    valve_stuck: [bool; ENGINE_COUNT],
    valve_speed: [f64; ENGINE_COUNT],
    /// Injected regulator set-point drift, Pa/s (0: none).
    regulator_drift_pa_s: f64,
    /// Calibration conditions kept to size a clog: mixture ratio and rated thrust, N.
    mixture_ratio: f64,
    rated_thrust_n: f64,
}

impl HifiPropulsion {
    /// A model at rest at descent start: engines off, tanks at nominal pressure and
    /// loaded with `cfg.propellant_kg` split by `cfg.mixture_ratio`, the regulator
    /// locked up. Validates the parameters and solves the throttle calibration.
    pub fn new(params: &HifiParams, cfg: &PropulsionConfig) -> Result<Self, HifiError> {
        params.validate()?;
        let cfg_check = |ok: bool, field, value: f64, why| {
            if ok && value.is_finite() {
                Ok(())
            } else {
                Err(HifiError::Config { field, value, why })
            }
        };
        cfg_check(
            cfg.max_thrust_n > 0.0,
            "max_thrust_n",
            cfg.max_thrust_n,
            "> 0",
        )?;
        cfg_check(
            cfg.throttle_min_frac > 0.0 && cfg.throttle_min_frac < 1.0,
            "throttle_min_frac",
            cfg.throttle_min_frac,
            "in (0, 1)",
        )?;
        cfg_check(
            cfg.mixture_ratio > 0.0,
            "mixture_ratio",
            cfg.mixture_ratio,
            "> 0",
        )?;
        cfg_check(
            cfg.propellant_kg >= 0.0,
            "propellant_kg",
            cfg.propellant_kg,
            ">= 0",
        )?;

        let he = Helium::new(&params.helium);
        let bottle = Bottle::new(&params.bottle);
        let regulator = Regulator::new(&params.regulator, params.bottle.initial_pressure_pa);
        let tank_params = [&params.tanks.fuel, &params.tanks.ox];
        let tanks = tank_params.map(|t| Tank::new(t, &params.tanks));
        let mr = cfg.mixture_ratio;
        let loaded_kg = [
            cfg.propellant_kg / (1.0 + mr),
            cfg.propellant_kg * mr / (1.0 + mr),
        ];
        for p in 0..2 {
            let liquid_m3 = loaded_kg[p] / tanks[p].rho_liquid;
            if liquid_m3 > 0.99 * tanks[p].volume_m3 {
                return Err(HifiError::TankTooSmall {
                    tank: if p == FUEL { "fuel" } else { "oxidiser" },
                    liquid_m3,
                    tank_m3: tanks[p].volume_m3,
                });
            }
        }

        // Rated flows fix the laminar blends (numerics only).
        let chamber = Chamber::new(&params.engine, cfg.max_thrust_n, cfg.throttle_min_frac);
        let rated_total = chamber.rated_pc_pa * chamber.throat_area_m2
            / chamber.cstar(mr, 1.0, chamber.rated_pc_pa);
        let rated = [rated_total / (1.0 + mr), rated_total * mr / (1.0 + mr)];
        let feed_params = [&params.feed.fuel, &params.feed.ox];
        let side_params = [&params.engine.fuel, &params.engine.ox];
        let lam = params.feed.laminar_flow_frac;
        let feeds: [Feed; 2] = std::array::from_fn(|p| {
            Feed::new(
                feed_params[p],
                tanks[p].rho_liquid,
                rated[p],
                lam,
                params.feed.unsteady_friction_time_s,
            )
        });
        let sides: [EngineSide; 2] = std::array::from_fn(|p| {
            EngineSide::new(
                side_params[p],
                &params.engine,
                tanks[p].rho_liquid,
                feeds[p].branch_inertance,
                feeds[p].branch_resistance,
                rated[p],
                lam,
            )
        });

        let p_nom = params.tanks.nominal_pressure_pa;
        let table = ThrottleTable::build(
            &CalibrationPoint {
                chamber: &chamber,
                feeds: [&feeds[FUEL], &feeds[OX]],
                sides: [&sides[FUEL], &sides[OX]],
                tank_pressure_pa: p_nom,
                mixture_ratio: mr,
                engines: ENGINE_COUNT,
            },
            cfg.throttle_min_frac * cfg.max_thrust_n,
            cfg.max_thrust_n,
        )?;

        // Initial state.
        let mut y = [0.0; N_STATES];
        let b = &params.bottle;
        let rho_b = he.density(b.initial_pressure_pa, b.initial_temperature_k);
        y[ix::BOTTLE_MASS] = rho_b * bottle.volume_m3;
        y[ix::BOTTLE_TEMP] = b.initial_temperature_k;
        y[ix::WALL_TEMP] = b.initial_temperature_k;
        // Outlet volume at lock-up, at the temperature of gas throttled from the bottle.
        let h_b = he.enthalpy(rho_b, b.initial_temperature_k);
        let p_lock = params.regulator.lockup_pressure_pa;
        let mut rho_o = he.density(p_lock, b.initial_temperature_k);
        for _ in 0..20 {
            rho_o = he.density(p_lock, he.temperature_from_enthalpy(h_b, rho_o));
        }
        y[ix::REG_OUT_MASS] = rho_o * regulator.outlet_volume_m3;
        let t_u = params.tanks.initial_ullage_temperature_k;
        for p in 0..2 {
            let vol = tanks[p].ullage_volume_m3(loaded_kg[p]);
            y[ix::ullage_mass(p)] = he.density(p_nom, t_u) * vol;
            y[ix::ullage_temp(p)] = t_u;
            y[ix::liquid_mass(p)] = loaded_kg[p];
            y[ix::manifold_pressure(p)] = p_nom;
        }

        let e = &params.engine;
        let tfcv_dynamics = TfcvDynamics {
            tau_s: e.tfcv_time_constant_s,
            rate_per_s: 1.0 / e.tfcv_full_stroke_s,
            half_backlash: e.tfcv_backlash_frac / 2.0,
            quantum: e.tfcv_quantum_frac,
        };
        // TFCVs parked at the minimum-throttle position.
        let park = table.positions(0.0);
        let tfcvs = [std::array::from_fn(|p| {
            let x = tfcv_dynamics.quantise(park[p]);
            Tfcv {
                target: x,
                actuator: x,
                valve: x,
            }
        }); ENGINE_COUNT];

        let mut model = Self {
            plant: Plant {
                he,
                bottle,
                regulator,
                check_valve: CheckValve::new(&params.check_valve),
                tanks,
                feeds,
                sides,
                chamber,
                drive: [Drive::default(); 2],
                aux: Aux::default(),
                faults: PlantFaults::default(),
            },
            y,
            scratch: [0.0; N_STATES],
            ros2: Ros2::default(),
            solenoids: [[Solenoid::default(); 2]; ENGINE_COUNT],
            tfcvs,
            tfcv_dynamics,
            solenoid_ramp_s: e.solenoid_ramp_s,
            table,
            substep_ns: ((params.integration.substep_s * 1e9).round() as u64).max(1),
            valve_refinement: params.integration.valve_travel_refinement,
            refine_hold_s: params.integration.valve_refinement_hold_s,
            refine_left_s: 0.0,
            loaded_kg,
            manifold_ref_pa: [p_nom; 2],
            t_ns: 0,
            out: PropulsionOutput::default(),
            fault: None,
            valve_stuck: [false; ENGINE_COUNT],
            valve_speed: [1.0; ENGINE_COUNT],
            regulator_drift_pa_s: 0.0,
            mixture_ratio: mr,
            rated_thrust_n: cfg.max_thrust_n,
        };
        let act = model.actuation();
        model.plant.set_actuation(0, &act);
        model.plant.set_actuation(1, &act);
        model.refresh_outputs();
        model.out.mean_thrust_n = model.out.thrust_n;
        Ok(model)
    }

    /// The throttle calibration: commanded thrust to TFCV positions (the surrogate's
    /// valve filter takes its stroke map from it, `emulator/config/train.toml`).
    pub fn throttle_table(&self) -> &ThrottleTable {
        &self.table
    }

    /// The injector area fractions `[fuel, ox]` of a clog that leaves an engine
    /// `thrust_fraction` of its rated thrust at nominal conditions (see
    /// [`CalibrationPoint::injector_open_frac`]): `thrust-degraded` means the same
    /// fraction here as at the surrogate's and ideal model's outputs.
    pub fn clog_open_frac(&self, thrust_fraction: f64) -> [f64; 2] {
        let pl = &self.plant;
        CalibrationPoint {
            chamber: &pl.chamber,
            feeds: [&pl.feeds[FUEL], &pl.feeds[OX]],
            sides: [&pl.sides[FUEL], &pl.sides[OX]],
            // The manifolds start at the nominal tank pressure the table was made at.
            tank_pressure_pa: self.manifold_ref_pa[FUEL],
            mixture_ratio: self.mixture_ratio,
            engines: ENGINE_COUNT,
        }
        .injector_open_frac(self.rated_thrust_n, thrust_fraction)
        // The table was solved at this point when the model was built, so this cannot
        // fail; a healthy injector if it ever did.
        .unwrap_or([1.0; 2])
    }

    fn actuation(&self) -> Actuation {
        let mut a = Actuation::default();
        for e in 0..ENGINE_COUNT {
            for p in 0..2 {
                a.solenoid[e][p] = self.solenoids[e][p].opening;
                a.dribble[e][p] = self.solenoids[e][p].dribble_gate();
                a.tfcv[e][p] = self.tfcvs[e][p].valve;
            }
        }
        a
    }

    /// Recomputes the algebraic outputs at the current state.
    fn refresh_outputs(&mut self) {
        let act = self.actuation();
        self.plant.set_actuation(1, &act);
        self.plant.eval(true, &self.y, &mut self.scratch, None);
        let aux = &self.plant.aux;
        let y = &self.y;
        let o = &mut self.out;
        o.thrust_n = aux.thrust_n;
        for e in 0..ENGINE_COUNT {
            o.chamber_pressure_pa[e] = y[ix::chamber_pressure(e)];
        }
        o.gas_pressure_pa = aux.bottle_pressure_pa;
        o.fuel_tank_pressure_pa = aux.tank_pressure_pa[FUEL];
        o.ox_tank_pressure_pa = aux.tank_pressure_pa[OX];
        o.ejected_fuel_kg = y[ix::ejected(FUEL)];
        o.ejected_ox_kg = y[ix::ejected(OX)];
        o.fuel_flow_kg_s = aux.injected_kg_s.iter().map(|f| f[FUEL]).sum();
        o.ox_flow_kg_s = aux.injected_kg_s.iter().map(|f| f[OX]).sum();
    }

    /// The raw state vector (layout in [`plant::ix`]); for diagnostics and tests.
    pub fn state(&self) -> &[f64; N_STATES] {
        &self.y
    }

    /// Model time, ns since construction.
    pub fn time_ns(&self) -> i64 {
        self.t_ns
    }

    /// The numerical failure that stopped the model, if any (the step was rolled back
    /// and every later step is a no-op).
    pub fn fault(&self) -> Option<&HifiError> {
        self.fault.as_ref()
    }

    /// The sub-step length used for a bench step of `dt_ns`, ns (bench steps are split
    /// into equal sub-steps no longer than the configured one).
    pub fn substep_ns(&self, dt_ns: u64) -> f64 {
        dt_ns as f64 / dt_ns.div_ceil(self.substep_ns).max(1) as f64
    }

    /// TFCV positions `[fuel, ox]` the calibration assigns to a thrust command.
    pub fn calibrated_positions(&self, thrust_n: f64) -> [f64; 2] {
        self.table.positions(thrust_n)
    }

    /// Propellant accounting `[fuel, ox]`.
    pub fn propellant_balance(&self) -> [PropellantBalance; 2] {
        std::array::from_fn(|p| {
            let domes: f64 = (0..ENGINE_COUNT).map(|e| self.y[ix::dome_mass(e, p)]).sum();
            PropellantBalance {
                loaded_kg: self.loaded_kg[p],
                tank_kg: self.y[ix::liquid_mass(p)],
                lines_kg: self.plant.feeds[p]
                    .manifold_excess_kg(self.y[ix::manifold_pressure(p)], self.manifold_ref_pa[p])
                    + domes,
                ejected_kg: self.y[ix::ejected(p)],
            }
        })
    }

    /// Helium in the system (bottle, regulator outlet, both ullages), kg: constant.
    pub fn helium_inventory_kg(&self) -> f64 {
        self.y[ix::BOTTLE_MASS]
            + self.y[ix::REG_OUT_MASS]
            + self.y[ix::ullage_mass(FUEL)]
            + self.y[ix::ullage_mass(OX)]
    }

    /// Everything reportable at the current step boundary.
    pub fn detail(&self) -> HifiDetail {
        let y = &self.y;
        let aux = &self.plant.aux;
        HifiDetail {
            out: self.out,
            bottle_temperature_k: y[ix::BOTTLE_TEMP],
            bottle_wall_temperature_k: y[ix::WALL_TEMP],
            bottle_helium_kg: y[ix::BOTTLE_MASS],
            regulator_outlet_pa: aux.regulator_outlet_pa,
            regulator_lift_m: y[ix::POPPET_LIFT],
            regulator_flow_kg_s: aux.regulator_flow_kg_s,
            ullage_temperature_k: [y[ix::ullage_temp(FUEL)], y[ix::ullage_temp(OX)]],
            manifold_pressure_pa: [y[ix::manifold_pressure(FUEL)], y[ix::manifold_pressure(OX)]],
            tank_liquid_kg: [y[ix::liquid_mass(FUEL)], y[ix::liquid_mass(OX)]],
            injected_kg_s: aux.injected_kg_s,
            tfcv_position: std::array::from_fn(|e| {
                [self.tfcvs[e][FUEL].valve, self.tfcvs[e][OX].valve]
            }),
            solenoid_opening: std::array::from_fn(|e| {
                [
                    self.solenoids[e][FUEL].opening,
                    self.solenoids[e][OX].opening,
                ]
            }),
        }
    }

    /// Whether a solenoid moves in the next `h` seconds, an open engine's dome is still
    /// priming, or a throttle valve strokes at its rate limit (a large throttle change:
    /// the flow then swings the shared manifold hard): the events whose sharp transients
    /// get refined sub-steps. Rate-limited strokes were found by the convergence test
    /// on a closed-loop descent (a 705 -> 320 N throttle-down moved thrust by 0.2 N
    /// between 0.1 and 0.05 ms sub-steps without refinement).
    #[inline]
    fn valve_event_within(&self, h: f64) -> bool {
        let band = self.tfcv_dynamics.rate_per_s * self.tfcv_dynamics.tau_s;
        (0..ENGINE_COUNT).any(|e| {
            (0..2).any(|p| {
                let s = &self.solenoids[e][p];
                let v = &self.tfcvs[e][p];
                s.moves_within(h)
                    || (s.commanded_open()
                        && self.y[ix::dome_mass(e, p)] < 0.999 * self.plant.sides[p].dome_full_kg)
                    || (v.target - v.actuator).abs() > band
            })
        })
    }

    /// One sub-step: move the valves (exactly), integrate, apply the constraints.
    #[inline]
    fn substep(&mut self, h: f64, tfcv_decay: f64) {
        self.plant.drive[0] = self.plant.drive[1];
        let mut act = self.plant.drive[1].act;
        for e in 0..ENGINE_COUNT {
            for p in 0..2 {
                let s = &mut self.solenoids[e][p];
                s.advance(h, self.solenoid_ramp_s);
                act.solenoid[e][p] = s.opening;
                act.dribble[e][p] = s.dribble_gate();
                let v = &mut self.tfcvs[e][p];
                let speed = self.valve_speed[e];
                if self.valve_stuck[e] {
                    // A stuck valve does not move, whatever its actuator is told.
                } else if speed < 1.0 {
                    // A slowed actuator: its rate limit and time constant scaled.
                    let slow = TfcvDynamics {
                        rate_per_s: self.tfcv_dynamics.rate_per_s * speed,
                        tau_s: self.tfcv_dynamics.tau_s / speed,
                        ..self.tfcv_dynamics
                    };
                    v.advance(h, &slow, tfcv_decay.powf(speed));
                } else {
                    v.advance(h, &self.tfcv_dynamics, tfcv_decay);
                }
                act.tfcv[e][p] = v.valve;
            }
        }
        self.plant.set_actuation(1, &act);
        self.ros2.step(&mut self.y, h, &mut self.plant);
        self.plant.project(&mut self.y);
    }

    /// Applies a command at the current time: valve targets and coil states.
    #[allow(clippy::needless_range_loop)]
    fn apply_command(&mut self, cmd: &EngineCommand) {
        for e in 0..ENGINE_COUNT {
            let f = cmd.thrust_cmd_n[e];
            // Off engines keep their TFCVs where the command puts them; a non-finite
            // command (the link should never pass one) parks them at minimum.
            let positions = self.table.positions(if f.is_finite() { f } else { 0.0 });
            for p in 0..2 {
                self.tfcvs[e][p].target = self.tfcv_dynamics.quantise(positions[p]);
                let side = &self.plant.sides[p];
                self.solenoids[e][p].command(cmd.on[e], side.open_delay_s, side.close_delay_s);
            }
        }
    }
}

impl Propulsion for HifiPropulsion {
    fn name(&self) -> &'static str {
        "hifi"
    }

    fn internals(&self) -> super::PropulsionInternals {
        super::PropulsionInternals {
            regulator_outlet_pa: self.plant.aux.regulator_outlet_pa,
            manifold_pressure_pa: [
                self.y[ix::manifold_pressure(FUEL)],
                self.y[ix::manifold_pressure(OX)],
            ],
            valve_position: std::array::from_fn(|e| {
                [self.tfcvs[e][FUEL].valve, self.tfcvs[e][OX].valve]
            }),
        }
    }

    fn represents(&self, _fault: &super::PropulsionFault) -> bool {
        true
    }

    fn inject(&mut self, fault: &super::PropulsionFault, active: bool) {
        use super::PropulsionFault as F;
        if let F::ThrustDegraded { engine, factor } = *fault {
            let open = if active {
                self.clog_open_frac(factor)
            } else {
                [1.0; 2]
            };
            self.plant.faults.injector_open_frac[engine] = open;
            return;
        }
        let f = &mut self.plant.faults;
        match *fault {
            F::ThrustDegraded { .. } => {}
            F::ValveStuck { engine } => self.valve_stuck[engine] = active,
            F::ValveSlow { engine, factor } => {
                self.valve_speed[engine] = if active { factor } else { 1.0 }
            }
            F::RegulatorOpen => f.regulator_held_open = active.then_some(true),
            F::RegulatorClosed => f.regulator_held_open = active.then_some(false),
            F::RegulatorDrift { rate_pa_s } => {
                self.regulator_drift_pa_s = if active { rate_pa_s } else { 0.0 }
            }
            F::PressurantLeak { area_m2 } => {
                f.pressurant_leak_m2 = if active { area_m2 } else { 0.0 }
            }
            F::PropellantLeak { side, kg_s } => {
                f.propellant_leak_kg_s[side] = if active { kg_s } else { 0.0 }
            }
        }
    }

    fn failure(&self) -> Option<&'static str> {
        self.fault
            .is_some()
            .then_some("the hifi propulsion state became non-finite (the step was rolled back)")
    }

    fn diagnostics(&self) -> Option<super::PropulsionDiagnostics> {
        Some(super::PropulsionDiagnostics {
            hifi_non_finite_rollbacks: Some(u64::from(self.fault.is_some())),
            ..Default::default()
        })
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        if dt_ns == 0 || self.fault.is_some() {
            return self.out;
        }
        if self.regulator_drift_pa_s != 0.0 {
            self.plant
                .regulator
                .shift_set_point(self.regulator_drift_pa_s * dt_ns as f64 * 1e-9);
        }
        let saved = self.y;
        self.apply_command(cmd);
        let n = dt_ns.div_ceil(self.substep_ns);
        let h = dt_ns as f64 * 1e-9 / n as f64;
        let decay = (-h / self.tfcv_dynamics.tau_s).exp();
        let mut impulse_start = [0.0; ENGINE_COUNT];
        for (e, imp) in impulse_start.iter_mut().enumerate() {
            *imp = self.y[ix::impulse(e)];
        }
        let refine = self.valve_refinement;
        let h_fine = h / refine as f64;
        let decay_fine = (-h_fine / self.tfcv_dynamics.tau_s).exp();
        let act = self.actuation();
        self.plant.set_actuation(1, &act);
        for _ in 0..n {
            let moving = self.valve_event_within(h);
            if moving {
                self.refine_left_s = self.refine_hold_s;
            }
            if refine > 1 && (moving || self.refine_left_s > 0.0) {
                for _ in 0..refine {
                    self.substep(h_fine, decay_fine);
                }
            } else {
                self.substep(h, decay);
            }
            self.refine_left_s -= h;
        }
        self.t_ns += dt_ns as i64;
        if self.y.iter().any(|v| !v.is_finite()) {
            self.y = saved;
            self.fault = Some(HifiError::NonFinite { t_ns: self.t_ns });
            return self.out;
        }
        self.refresh_outputs();
        let dt_s = dt_ns as f64 * 1e-9;
        for (e, imp) in impulse_start.iter().enumerate() {
            self.out.mean_thrust_n[e] = (self.y[ix::impulse(e)] - imp) / dt_s;
        }
        self.out
    }

    fn output(&self) -> PropulsionOutput {
        self.out
    }
}
