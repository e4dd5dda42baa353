//! The plant: the lander as a 6-DOF rigid body of varying mass around a rotating Moon,
//! driven by a propulsion model and attitude thrusters (an ideal saturated body torque,
//! or eight on/off thrusters fired for commanded on-times, [`thrusters`]), standing on
//! four legs once it touches the ground, until it rests or tips.
//!
//! Frames ([`frames`]): the state is integrated in `mci` (Moon-centred inertial); the
//! ground is fixed in `mcmf`, which turns at the sidereal rate, so touchdown speeds are
//! relative to the turning surface. Body +Z is the main-engine thrust axis. See
//! `docs/plant.md`.
//!
//! One bench step: the propulsion model is stepped first with the command held; the
//! rigid body is then integrated over the step (RK4) with the model's mean thrust held
//! and the mass falling linearly by what was ejected. If a footpad reaches the ground
//! inside the step, the first-contact instant is found by re-integrating shorter
//! sub-steps; from there the legs' loads (crushable struts, [`legs`]) join in, in
//! sub-steps of at most [`legs::CONTACT_SUBSTEP_NS`].

pub mod frames;
pub mod ground;
pub mod initial;
pub mod integrator;
pub mod legs;
pub mod model_error;
pub mod rigid_body;
pub mod thrusters;

use crate::config::{ConfigError, ScenarioConfig, TouchdownLimits};
use crate::faults::PlantFault;
use crate::propulsion::{EngineCommand, Propulsion, PropulsionFault, PropulsionOutput};
use frames::MoonRotation;
use ground::Ground;
use integrator::RK4;
use legs::{Legs, CONTACT_SUBSTEP_NS};
use nalgebra::Vector3;
use oils_shared::{
    EngineReading, NavState, PacketHeader, PropulsionReadings, Telemetry, ENGINE_COUNT,
    TLM_FLAG_FOOTPAD_CONTACT,
};
use rigid_body::{Dynamics, HeldLoads, MassModel, StateVector};
use thrusters::ThrusterBank;

pub use rigid_body::RigidBodyState;

/// Standard gravity for specific impulse, m/s^2.
const G0_M_S2: f64 = 9.80665;

/// Contact search: stop when the footpad height is within this of zero, metres.
const CONTACT_TOLERANCE_M: f64 = 1e-9;
/// Contact search: at most this many sub-step re-integrations.
const CONTACT_MAX_ITERATIONS: usize = 60;

/// What the plant is told for one step (already sanitised by the link: finite, in range).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ActuatorCommand {
    /// Main engine commands.
    pub engines: EngineCommand,
    /// Ideal body torque, body axes, N m (saturated here); used when
    /// `use_thrusters` is false.
    pub torque_cmd_body_nm: [f64; 3],
    /// The attitude thrusters fire for `thruster_on_time_ns` (protocol
    /// `ATTITUDE_MODE_THRUSTERS`) instead of the ideal torque.
    pub use_thrusters: bool,
    /// Per attitude thruster, its commanded on-time from `cycle_start_ns`, ns.
    pub thruster_on_time_ns: [u64; oils_shared::THRUSTER_COUNT],
    /// Start of the flight-software cycle this command was issued for, ns since the
    /// start of the run: thruster pulses are timed from it, so a command held over a
    /// missed cycle does not fire its pulses again.
    pub cycle_start_ns: i64,
}

/// The state of the vehicle at the end of a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantStatus {
    /// In the air, or on its legs and not yet at rest.
    Flying,
    /// The landing is over: at rest, tipped, too fast at contact, or out of time to
    /// settle (this step or earlier).
    Touchdown(TouchdownState),
}

/// Why a touchdown is not a landing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CrashReason {
    /// Speed towards the surface at first contact over the limit.
    VerticalSpeed,
    /// Speed along the surface at first contact over the limit.
    HorizontalSpeed,
    /// The vehicle fell over (centre of mass past the footprint's edge).
    TipOver,
    /// A footpad slipped along the ground farther than `touchdown.slide_limit_m`
    /// after first contact.
    Slid,
    /// The ground under the footprint steeper than the limit.
    Slope,
    /// At rest, but tilted more than the limit.
    Tilt,
    /// Still moving when the settling time ran out.
    NotAtRest,
}

impl CrashReason {
    /// The name the report and the log use.
    pub fn as_str(&self) -> &'static str {
        match self {
            CrashReason::VerticalSpeed => "vertical-speed",
            CrashReason::HorizontalSpeed => "horizontal-speed",
            CrashReason::TipOver => "tip-over",
            CrashReason::Slid => "slid",
            CrashReason::Slope => "slope",
            CrashReason::Tilt => "tilt",
            CrashReason::NotAtRest => "not-at-rest",
        }
    }
}

/// How the vehicle met the ground: first contact, and how it ended.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TouchdownState {
    /// First-contact time since the start of the run, seconds.
    pub t_s: f64,
    /// Speed towards the surface at first contact, relative to the (turning) ground,
    /// m/s (>= 0).
    pub vertical_speed_mps: f64,
    /// Speed along the surface at first contact, relative to the ground, m/s.
    pub horizontal_speed_mps: f64,
    /// Angle between body +Z and the local vertical at the end (at rest, tipped, or
    /// at first contact when that ended it), degrees.
    pub tilt_deg: f64,
    /// The same angle at first contact, degrees.
    pub contact_tilt_deg: f64,
    /// Slope of the ground under the footprint at first contact, degrees.
    pub slope_deg: f64,
    /// Roughness of the ground under the footprint at first contact: the largest
    /// height of the terrain above or below the plane fitted through it within
    /// [`FOOTPRINT_RADIUS_M`] of the centre of mass's ground point, metres (a rock or a
    /// hole under the lander; judged by campaigns, not by the landing).
    pub roughness_m: f64,
    /// Farthest any footpad slipped along the ground after first contact, metres.
    pub slide_m: f64,
    /// Fastest footpad speed along the ground while it slipped, m/s.
    pub slide_speed_m_s: f64,
    /// Crushed length of each leg's strut at the end, metres.
    pub leg_crush_m: [f64; legs::FOOTPADS],
    /// The tilt limit judged against (derived from the legs), degrees.
    pub tilt_limit_deg: f64,
    /// The slope limit judged against (derived from the legs), degrees.
    pub slope_limit_deg: f64,
    /// Time the landing ended (at rest, tipped, judged), seconds since the start.
    pub end_t_s: f64,
    /// Main and attitude-thruster propellant used by the end, kilograms.
    pub propellant_used_kg: f64,
    /// Every quantity within the configured touchdown limits, at rest and upright.
    pub landed: bool,
    /// Why it is not a landing (`None` when landed).
    pub reason: Option<CrashReason>,
}

/// Radius of the ground a touchdown's roughness is judged over, m: the footpads' 1.8 m
/// circle and their pads (`docs/plant.md`).
pub const FOOTPRINT_RADIUS_M: f64 = 2.2;

/// The largest residual of the plane fitted through the ground within
/// [`FOOTPRINT_RADIUS_M`] of the ground point below `p_mcmf` (heights sampled every
/// 0.25 m). No allocation.
fn footprint_roughness_m(ground: &Ground, p_mcmf: &Vector3<f64>) -> f64 {
    let up = p_mcmf.normalize();
    let east = Vector3::z().cross(&up);
    let east = if east.norm() > 1e-9 {
        east.normalize()
    } else {
        Vector3::x()
    };
    let north = up.cross(&east);
    // A sphere through the ground point: heights relative to it.
    let p0 = p_mcmf - up * ground.height_m(p_mcmf);
    let step = 0.25;
    let k = (FOOTPRINT_RADIUS_M / step).floor() as i32;
    let h = |x: f64, y: f64| {
        let q = p0 + east * x + north * y;
        let q = q.normalize() * p0.norm();
        -ground.height_m(&q)
    };
    let mut fit = oils_shared::plane_fit::PlaneFit::default();
    for a in -k..=k {
        for b in -k..=k {
            let (x, y) = (b as f64 * step, a as f64 * step);
            if x.hypot(y) <= FOOTPRINT_RADIUS_M {
                fit.add(x, y, h(x, y));
            }
        }
    }
    let Some([c0, cx, cy]) = fit.solve() else {
        return 0.0;
    };
    let mut rough = 0.0f64;
    for a in -k..=k {
        for b in -k..=k {
            let (x, y) = (b as f64 * step, a as f64 * step);
            if x.hypot(y) <= FOOTPRINT_RADIUS_M {
                rough = rough.max((h(x, y) - (c0 + cx * x + cy * y)).abs());
            }
        }
    }
    rough
}

/// First contact, kept while the vehicle settles on its legs.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Contact {
    td: TouchdownState,
    /// Time spent continuously at rest, seconds.
    rest_s: f64,
}

/// Fixed numbers the plant derives from the configuration at construction.
#[derive(Debug, Clone, Copy)]
struct Setup {
    dynamics: Dynamics,
    rotation: MoonRotation,
    leg_height_m: f64,
    wet_mass_kg: f64,
    engine_pos_body_m: [Vector3<f64>; ENGINE_COUNT],
    /// Thrust axis of each engine, body axes, when any is misaligned (`None`: all +Z,
    /// the exact nominal arithmetic).
    engine_dir_body: Option<[Vector3<f64>; ENGINE_COUNT]>,
    rcs_max_torque_nm: Vector3<f64>,
    rcs_moment_arm_m: Vector3<f64>,
    rcs_exhaust_m_s: f64,
    limits: Limits,
}

#[derive(Debug, Clone, Copy)]
struct Limits {
    vertical_speed_mps: f64,
    horizontal_speed_mps: f64,
    /// Derived from the legs ([`legs::landing_limits`]).
    tilt_deg: f64,
    /// Derived from the legs, as the tilt.
    slope_deg: f64,
    slide_m: f64,
    rest_speed_m_s: f64,
    rest_hold_s: f64,
    settle_timeout_s: f64,
}

impl Limits {
    fn new(l: &TouchdownLimits, derived: &legs::LandingLimits) -> Self {
        Self {
            vertical_speed_mps: l.vertical_speed_mps,
            horizontal_speed_mps: l.horizontal_speed_mps,
            tilt_deg: derived.tilt_deg,
            slope_deg: derived.slope_deg,
            slide_m: l.slide_limit_m,
            rest_speed_m_s: l.rest_speed_m_s,
            rest_hold_s: l.rest_hold_s,
            settle_timeout_s: l.settle_timeout_s,
        }
    }
}

/// The lander plant.
pub struct Plant {
    setup: Setup,
    propulsion: Box<dyn Propulsion>,
    /// Last output of the propulsion model.
    prop_out: PropulsionOutput,
    /// Last engine command (for the valve readings).
    last_engines: EngineCommand,
    state: RigidBodyState,
    /// Specific force at the end of the last step, body axes, m/s^2.
    specific_force_body_m_s2: Vector3<f64>,
    time_ns: i64,
    rcs_used_kg: f64,
    /// The ground the legs meet.
    ground: Ground,
    /// The legs and their stick points.
    legs: Legs,
    /// First contact, while settling.
    contact: Option<Contact>,
    /// Footpads touching at the end of the last step.
    pads_in_contact: u8,
    /// The landing's end, once it is over.
    touchdown: Option<TouchdownState>,
    /// Engine faults acting on the command.
    engine_faults: [EngineFault; ENGINE_COUNT],
    /// Output scale of each engine (the configured thrust scale times a degradation
    /// the model cannot represent).
    output_factor: [f64; ENGINE_COUNT],
    /// The configured thrust scale of each engine.
    thrust_scale: [f64; ENGINE_COUNT],
    /// Injected model error, when configured.
    model_error: Option<model_error::ModelError>,
    /// The attitude thrusters at device level (used when the command asks for them).
    thrusters: ThrusterBank,
    /// State and time at the start of the last step, for [`Plant::sensor_truth`].
    step_start: (RigidBodyState, i64),
    /// The last [`Plant::altitude_m`]: its position, time and value. The scheduler and
    /// the telemetry both ask for it after a step, and the terrain lookup is worth one.
    altitude_memo: std::cell::Cell<Option<(Vector3<f64>, i64, f64)>>,
}

/// An engine fault acting on the command the engine gets.
#[derive(Debug, Clone, Copy, PartialEq)]
enum EngineFault {
    None,
    Off,
    Stuck { thrust_cmd_n: f64, on: bool },
}

impl Plant {
    /// A plant at the configured initial state. Validates `cfg`. Nothing in it is
    /// random: the seeded streams are the devices' ([`crate::devices::Devices`]).
    pub fn new(
        cfg: &ScenarioConfig,
        propulsion: Box<dyn Propulsion>,
    ) -> Result<Plant, ConfigError> {
        cfg.validate()?;
        let lander = &cfg.lander;
        let setup = Setup {
            dynamics: Dynamics {
                mu_m3_s2: cfg.moon.mu_m3_s2,
                mass: MassModel::new(lander, cfg.propulsion.propellant_kg),
            },
            rotation: MoonRotation {
                rate_rad_s: cfg.moon.rotation_rate_rad_s,
            },
            leg_height_m: lander.leg_height_m(),
            wet_mass_kg: cfg.wet_mass_kg(),
            // Moment arms from the true centre of mass (offset 0: the design one).
            engine_pos_body_m: lander
                .engine_positions_body_m
                .map(|p| Vector3::from(p) - Vector3::from(lander.com_offset_body_m)),
            engine_dir_body: (lander.engine_misalignment_deg != [[0.0; 2]; ENGINE_COUNT]).then(
                || {
                    lander.engine_misalignment_deg.map(|[about_x, about_y]| {
                        let tilt = nalgebra::UnitQuaternion::from_axis_angle(
                            &Vector3::x_axis(),
                            about_x.to_radians(),
                        ) * nalgebra::UnitQuaternion::from_axis_angle(
                            &Vector3::y_axis(),
                            about_y.to_radians(),
                        );
                        tilt * Vector3::z()
                    })
                },
            ),
            rcs_max_torque_nm: Vector3::from(lander.rcs_max_torque_nm()),
            rcs_moment_arm_m: Vector3::from(lander.rcs_moment_arm_m),
            rcs_exhaust_m_s: lander.rcs_isp_s * G0_M_S2,
            limits: Limits::new(&cfg.touchdown, &cfg.landing_limits()),
        };
        let ground = Ground::new(
            &cfg.terrain,
            cfg.site.latitude_deg,
            cfg.site.longitude_deg,
            cfg.moon.radius_m,
        )
        .map_err(|e| ConfigError {
            field: "terrain",
            value: e.to_string(),
            why: "the terrain could not be built",
        })?;
        let prop_out = propulsion.output();
        let mut state = initial::initial_state(cfg);
        state.mass_kg = (setup.wet_mass_kg - prop_out.ejected_kg()).max(lander.dry_mass_kg);
        Ok(Plant {
            setup,
            propulsion,
            prop_out,
            last_engines: EngineCommand::default(),
            state,
            specific_force_body_m_s2: Vector3::zeros(),
            time_ns: 0,
            rcs_used_kg: 0.0,
            ground,
            legs: Legs::new(lander),
            contact: None,
            pads_in_contact: 0,
            touchdown: None,
            engine_faults: [EngineFault::None; ENGINE_COUNT],
            output_factor: lander.engine_thrust_scale,
            thrust_scale: lander.engine_thrust_scale,
            model_error: cfg
                .model_error
                .enabled
                .then(|| model_error::ModelError::new(&cfg.model_error)),
            thrusters: ThrusterBank::from_config(lander),
            step_start: (state, 0),
            altitude_memo: std::cell::Cell::new(None),
        })
    }

    /// The plant's own readings into `tlm`, every field of it: `header`, the exact
    /// navigation state (position, velocity, attitude, rate), the specific force, the
    /// footpads' height, the mass, the propulsion readings and the footpad-contact flag;
    /// the sensor frame zero. What the flight software is told of them is the devices'
    /// business ([`crate::devices::Devices::telemetry_into`]).
    pub fn readings_into(&self, header: PacketHeader, tlm: &mut Telemetry) {
        let s = &self.state;
        let q = s.q_mci_from_body.quaternion();
        let mut engines = [EngineReading::default(); ENGINE_COUNT];
        for (i, e) in engines.iter_mut().enumerate() {
            e.thrust_n = self.prop_out.thrust_n[i];
            e.chamber_pressure_pa = self.prop_out.chamber_pressure_pa[i];
            e.valve_open = u32::from(self.last_engines.on[i]);
        }
        *tlm = Telemetry {
            header,
            nav: NavState {
                pos_mci_m: s.pos_mci_m.into(),
                vel_mci_m_s: s.vel_mci_m_s.into(),
                q_mci_from_body: [q.w, q.i, q.j, q.k],
                rate_body_rad_s: s.rate_body_rad_s.into(),
            },
            accel_body_m_s2: self.specific_force_body_m_s2.into(),
            altitude_m: self.altitude_m(),
            mass_estimate_kg: s.mass_kg,
            propulsion: PropulsionReadings {
                gas_pressure_pa: self.prop_out.gas_pressure_pa,
                fuel_tank_pressure_pa: self.prop_out.fuel_tank_pressure_pa,
                ox_tank_pressure_pa: self.prop_out.ox_tank_pressure_pa,
                engines,
            },
            sensors: Default::default(),
        };
        if self.pads_in_contact > 0 {
            tlm.header.flags |= TLM_FLAG_FOOTPAD_CONTACT;
        }
    }

    /// Advances one bench step of `dt_ns` with `cmd` held (the devices then take the
    /// step's truth: [`crate::devices::Devices::after_plant_step`]). Once the landing is over the state is frozen and every
    /// further call returns the same touchdown. No allocation, I/O or clock.
    pub fn step(&mut self, cmd: &ActuatorCommand, dt_ns: u64) -> PlantStatus {
        if let Some(td) = self.touchdown {
            return PlantStatus::Touchdown(td);
        }
        self.integrate_step(cmd, dt_ns)
    }

    /// One step of the physics (see [`Plant::step`]).
    fn integrate_step(&mut self, cmd: &ActuatorCommand, dt_ns: u64) -> PlantStatus {
        self.step_start = (self.state, self.time_ns);
        let dt_s = dt_ns as f64 * 1e-9;
        let setup = self.setup;
        let dry_mass_kg = setup.dynamics.mass.dry_mass_kg;

        // 1. Propulsion first: its mean thrust over the step is what the body feels.
        // Engine faults act on the command the engines get (every model then follows
        // it physically); a degradation a model cannot represent scales its outputs.
        let mut engines = cmd.engines;
        for (e, o) in self.engine_faults.iter().enumerate() {
            match *o {
                EngineFault::None => {}
                EngineFault::Off => {
                    engines.on[e] = false;
                    engines.thrust_cmd_n[e] = 0.0;
                }
                EngineFault::Stuck { thrust_cmd_n, on } => {
                    engines.on[e] = on;
                    engines.thrust_cmd_n[e] = thrust_cmd_n;
                }
            }
        }
        let ejected_before_kg = self.prop_out.ejected_kg();
        self.prop_out = self.propulsion.step(&engines, dt_ns);
        for (e, &factor) in self.output_factor.iter().enumerate() {
            if factor != 1.0 {
                self.prop_out.thrust_n[e] *= factor;
                self.prop_out.mean_thrust_n[e] *= factor;
                self.prop_out.chamber_pressure_pa[e] *= factor;
            }
        }
        if let Some(error) = self.model_error.as_mut() {
            error.apply(&engines, &mut self.prop_out, dt_s);
        }
        self.last_engines = engines;
        let main_ejected_kg = (self.prop_out.ejected_kg() - ejected_before_kg).max(0.0);

        // 2. Attitude thrusters. Ideal (attitude mode 0): saturated torque; propellant
        // at |torque| / arm / c. Thrusters (mode 1, and the tails of pulses still
        // thrusting after a switch back to mode 0): the bank's mean force and torque over
        // the step, propellant at impulse / c. Both from the same tanks.
        let (mut rcs_torque_nm, mut rcs_kg) = if cmd.use_thrusters {
            (Vector3::zeros(), 0.0)
        } else {
            let torque = Vector3::from(cmd.torque_cmd_body_nm).zip_map(
                &setup.rcs_max_torque_nm,
                |t, max| {
                    if t.is_finite() {
                        t.clamp(-max, max)
                    } else {
                        0.0
                    }
                },
            );
            let rcs_flow_kg_s =
                torque.abs().component_div(&setup.rcs_moment_arm_m).sum() / setup.rcs_exhaust_m_s;
            (torque, rcs_flow_kg_s * dt_s)
        };
        let mut rcs_force_body_n = None;
        if cmd.use_thrusters || self.thrusters.active() {
            if cmd.use_thrusters {
                self.thrusters
                    .command(&cmd.thruster_on_time_ns, cmd.cycle_start_ns);
            }
            let out = self.thrusters.step(self.time_ns, dt_ns);
            rcs_torque_nm += out.torque_body_nm;
            rcs_kg += out.propellant_kg;
            rcs_force_body_n = Some(out.force_body_n);
        }
        let propellant_left_kg = (self.state.mass_kg - main_ejected_kg - dry_mass_kg).max(0.0);
        let mut rcs_scale = 1.0;
        if rcs_kg > propellant_left_kg {
            // Tanks run dry inside the step: deliver the torque the remainder can buy.
            rcs_scale = if rcs_kg > 0.0 {
                propellant_left_kg / rcs_kg
            } else {
                0.0
            };
            rcs_torque_nm *= rcs_scale;
            rcs_kg = propellant_left_kg;
        }

        // 3. Loads held over the step.
        let mut thrust_n = 0.0;
        let mut force_body_n = Vector3::zeros();
        let mut torque_nm = rcs_torque_nm;
        for (e, (pos, &f_n)) in setup
            .engine_pos_body_m
            .iter()
            .zip(self.prop_out.mean_thrust_n.iter())
            .enumerate()
        {
            let force = match &setup.engine_dir_body {
                None => Vector3::new(0.0, 0.0, f_n),
                Some(dirs) => dirs[e] * f_n,
            };
            thrust_n += f_n;
            force_body_n += force;
            torque_nm += pos.cross(&force);
        }
        if setup.engine_dir_body.is_none() {
            // Aligned engines: the nominal arithmetic, bit for bit.
            force_body_n = Vector3::new(0.0, 0.0, thrust_n);
        }
        if let Some(f) = rcs_force_body_n {
            // Thrusters are not pure couples one by one: their net force moves the
            // vehicle too.
            force_body_n += f * rcs_scale;
        }
        let mass_start_kg = self.state.mass_kg;
        // Cumulative accounting keeps the mass exactly "wet - ejected - rcs used", never
        // below dry (the main model does not know what the thrusters took).
        let rcs_used_after_kg = self.rcs_used_kg + rcs_kg;
        let mass_end_kg = (setup.wet_mass_kg - self.prop_out.ejected_kg() - rcs_used_after_kg)
            .max(dry_mass_kg)
            .min(mass_start_kg);
        let loads = HeldLoads {
            force_body_n,
            torque_body_nm: torque_nm,
            mass_start_kg,
            mass_flow_kg_s: if dt_s > 0.0 {
                (mass_start_kg - mass_end_kg) / dt_s
            } else {
                0.0
            },
        };

        // 4. Rigid body over the step.
        let step_start_s = self.time_ns as f64 * 1e-9;
        let x0 = self.state.to_vector();
        self.time_ns = self.time_ns.saturating_add(dt_ns as i64);
        self.specific_force_body_m_s2 = match &setup.engine_dir_body {
            None => Vector3::new(
                0.0,
                0.0,
                self.prop_out.thrust_n.iter().sum::<f64>() / mass_end_kg,
            ),
            Some(dirs) => {
                dirs.iter()
                    .zip(self.prop_out.thrust_n.iter())
                    .map(|(d, &f_n)| d * f_n)
                    .sum::<Vector3<f64>>()
                    / mass_end_kg
            }
        };
        if rcs_force_body_n.is_some() {
            // The thrusters' force at the step's end, as the engines' above.
            self.specific_force_body_m_s2 +=
                self.thrusters.force_now_body_n() * rcs_scale / mass_end_kg;
        }
        self.rcs_used_kg = rcs_used_after_kg;
        let end_s = self.time_ns as f64 * 1e-9;

        if self.contact.is_some() {
            // 5b. On the legs: the whole step with the contact loads.
            let x1 = self.integrate_on_legs(&loads, &x0, 0.0, dt_s, step_start_s, dt_ns);
            self.state = RigidBodyState::from_vector(&x1, mass_end_kg);
            self.add_leg_force(&x1, end_s, mass_end_kg);
            return self.settle(&x1, end_s, dt_s);
        }

        let x1 = self.integrate(&loads, &x0, dt_s);
        if !self.may_touch(&x1, end_s) || self.lowest_pad_m(&x1, end_s) > 0.0 {
            self.state = RigidBodyState::from_vector(&x1, mass_end_kg);
            return PlantStatus::Flying;
        }

        // 5. First contact inside the step: find the instant.
        let frac = self.contact_fraction(&loads, &x0, dt_s, step_start_s);
        let x_c = self.integrate(&loads, &x0, frac * dt_s);
        let mass_c_kg = mass_start_kg - (mass_start_kg - mass_end_kg) * frac;
        let first = RigidBodyState::from_vector(&x_c, mass_c_kg);
        let t_contact_s = step_start_s + frac * dt_s;
        let td = self.first_contact(&first, t_contact_s);
        if td.reason.is_some() {
            // Too fast: a crash at contact, nothing left to settle.
            self.state = first;
            self.touchdown = Some(td);
            self.pads_in_contact = 1;
            return PlantStatus::Touchdown(td);
        }
        self.contact = Some(Contact { td, rest_s: 0.0 });
        let x1 = self.integrate_on_legs(&loads, &x_c, frac * dt_s, dt_s, step_start_s, dt_ns);
        self.state = RigidBodyState::from_vector(&x1, mass_end_kg);
        self.add_leg_force(&x1, end_s, mass_end_kg);
        self.settle(&x1, end_s, dt_s)
    }

    /// Adds the legs' force at the step's end to the specific force the ideal
    /// navigation reports, as the engines' above: an accelerometer feels the ground's
    /// push (1.62 m/s^2 up at rest), the same force the IMU model senses.
    fn add_leg_force(&mut self, x: &StateVector, t_s: f64, mass_kg: f64) {
        let c = self.legs.loads(x, t_s, &self.setup.rotation, &self.ground);
        self.specific_force_body_m_s2 +=
            self.state.q_mci_from_body.inverse() * (c.force_mci_n / mass_kg);
    }

    /// Integrates from `t_from_s` to `t_to_s` (seconds into the step that started at
    /// `step_start_s`) with the legs' loads, in sub-steps of at most
    /// [`CONTACT_SUBSTEP_NS`]; the stick points are updated between sub-steps.
    fn integrate_on_legs(
        &mut self,
        loads: &HeldLoads,
        x0: &StateVector,
        t_from_s: f64,
        t_to_s: f64,
        step_start_s: f64,
        dt_ns: u64,
    ) -> StateVector {
        let n = dt_ns.div_ceil(CONTACT_SUBSTEP_NS).max(1) as usize;
        let h_s = (t_to_s - t_from_s) / n as f64;
        let mut x = *x0;
        let dyn_ = self.setup.dynamics;
        let rotation = self.setup.rotation;
        for k in 0..n {
            let t_a = t_from_s + h_s * k as f64;
            let legs = &self.legs;
            let ground = &self.ground;
            x = RK4.step(t_a, h_s, &x, |t, x| {
                let mut dx = dyn_.derivative(loads, t, x);
                let c = legs.loads(x, step_start_s + t, &rotation, ground);
                let mass_kg = loads.mass_start_kg - loads.mass_flow_kg_s * t;
                let inertia = dyn_.mass.inertia_kg_m2(mass_kg);
                let accel = c.force_mci_n / mass_kg;
                let w_dot = c.torque_body_nm.component_div(&inertia);
                for i in 0..3 {
                    dx[3 + i] += accel[i];
                    dx[10 + i] += w_dot[i];
                }
                dx
            });
            // Keep the quaternion unit between sub-steps, as the state conversion does.
            let q_norm = x.fixed_rows::<4>(6).norm();
            for i in 6..10 {
                x[i] /= q_norm;
            }
            self.legs.update_between_substeps(
                &x,
                step_start_s + t_a + h_s,
                &rotation,
                &self.ground,
            );
        }
        x
    }

    /// After a step on the legs: tipped, at rest, or out of time ends the landing.
    fn settle(&mut self, x: &StateVector, t_s: f64, dt_s: f64) -> PlantStatus {
        let rotation = self.setup.rotation;
        self.pads_in_contact = self.legs.pads_in_contact(x, t_s, &rotation, &self.ground);
        let Some(mut contact) = self.contact else {
            return PlantStatus::Flying;
        };
        let lim = self.setup.limits;
        let tilt_deg = self.tilt_deg(&self.state);
        let tilt_from_ground_deg = self.tilt_from_ground_deg(&self.state, t_s);
        let fastest = self.legs.fastest_pad_m_s(x, t_s, &rotation, &self.ground);
        contact.rest_s = if fastest < lim.rest_speed_m_s && self.pads_in_contact > 0 {
            contact.rest_s + dt_s
        } else {
            0.0
        };
        self.contact = Some(contact);
        let tipped = tilt_from_ground_deg > self.legs.tip_over_deg();
        let at_rest = contact.rest_s >= lim.rest_hold_s && contact.rest_s > 0.0;
        let timed_out = t_s - contact.td.t_s >= lim.settle_timeout_s;
        if !(tipped || at_rest || timed_out) {
            return PlantStatus::Flying;
        }
        let mut td = contact.td;
        td.end_t_s = t_s;
        td.tilt_deg = tilt_deg;
        td.propellant_used_kg = self.setup.wet_mass_kg - self.state.mass_kg;
        td.slide_m = self.legs.slide_m();
        td.slide_speed_m_s = self.legs.slide_speed_m_s();
        td.leg_crush_m = self.legs.crush_m();
        // The worst first: fell over, slid (a slide that ended on its legs still moved
        // the vehicle off where it touched), then the ground and the state at the end.
        td.reason = if tipped {
            Some(CrashReason::TipOver)
        } else if td.slide_m > lim.slide_m {
            Some(CrashReason::Slid)
        } else if td.slope_deg > lim.slope_deg {
            Some(CrashReason::Slope)
        } else if !at_rest {
            Some(CrashReason::NotAtRest)
        } else if tilt_deg > lim.tilt_deg {
            Some(CrashReason::Tilt)
        } else {
            None
        };
        td.landed = td.reason.is_none();
        self.touchdown = Some(td);
        PlantStatus::Touchdown(td)
    }

    /// Whether any footpad could reach the ground from state `x` at `t_s` (the cheap
    /// test that skips the per-footpad queries high up).
    fn may_touch(&self, x: &StateVector, t_s: f64) -> bool {
        let r = x.fixed_rows::<3>(0).into_owned();
        let p_mcmf = self.setup.rotation.mcmf_from_mci(t_s) * r;
        self.ground.height_m(&p_mcmf) - self.ground.max_elevation_m() <= self.legs.reach_m() + 1.0
    }

    /// Lowest footpad's height above the ground, metres.
    fn lowest_pad_m(&self, x: &StateVector, t_s: f64) -> f64 {
        self.legs
            .lowest_height_m(x, t_s, &self.setup.rotation, &self.ground)
    }

    /// One RK4 step of `h_s` seconds from `x0` at the start of the bench step.
    fn integrate(&self, loads: &HeldLoads, x0: &StateVector, h_s: f64) -> StateVector {
        let dyn_ = &self.setup.dynamics;
        RK4.step(0.0, h_s, x0, |t, x| dyn_.derivative(loads, t, x))
    }

    /// Fraction of the step at which the footpads touch: regula falsi (Illinois) on the
    /// footpad height of a re-integrated sub-step; height > 0 at 0, <= 0 at 1.
    fn contact_fraction(
        &self,
        loads: &HeldLoads,
        x0: &StateVector,
        dt_s: f64,
        step_start_s: f64,
    ) -> f64 {
        let height = |frac: f64| {
            let x = self.integrate(loads, x0, frac * dt_s);
            self.lowest_pad_m(&x, step_start_s + frac * dt_s)
        };
        let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
        let (mut h_lo, mut h_hi) = (height(lo), height(hi));
        if h_lo <= 0.0 {
            return 0.0;
        }
        let mut side = 0i8;
        let mut frac = hi;
        for _ in 0..CONTACT_MAX_ITERATIONS {
            frac = (lo * h_hi - hi * h_lo) / (h_hi - h_lo);
            if !(lo..=hi).contains(&frac) {
                frac = 0.5 * (lo + hi);
            }
            let h = height(frac);
            if h.abs() < CONTACT_TOLERANCE_M || hi - lo < 1e-12 {
                break;
            }
            if h > 0.0 {
                lo = frac;
                h_lo = h;
                if side == 1 {
                    h_hi *= 0.5;
                }
                side = 1;
            } else {
                hi = frac;
                h_hi = h;
                if side == -1 {
                    h_lo *= 0.5;
                }
                side = -1;
            }
        }
        frac
    }

    /// The touchdown as first contact sees it; a speed over the limits ends it there.
    fn first_contact(&self, s: &RigidBodyState, t_s: f64) -> TouchdownState {
        let rotation = &self.setup.rotation;
        let up = s.pos_mci_m.normalize();
        let v_rel = rotation.surface_relative_mci(&s.pos_mci_m, &s.vel_mci_m_s);
        let v_up = v_rel.dot(&up);
        let horizontal = (v_rel - up * v_up).norm();
        let vertical = v_up.abs();
        let tilt_deg = self.tilt_deg(s);
        let p_mcmf = rotation.mcmf_from_mci(t_s) * s.pos_mci_m;
        let slope_deg = self
            .ground
            .normal_mcmf(&p_mcmf)
            .dot(&p_mcmf.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let lim = &self.setup.limits;
        let reason = if vertical > lim.vertical_speed_mps {
            Some(CrashReason::VerticalSpeed)
        } else if horizontal > lim.horizontal_speed_mps {
            Some(CrashReason::HorizontalSpeed)
        } else {
            None
        };
        TouchdownState {
            t_s,
            vertical_speed_mps: vertical,
            horizontal_speed_mps: horizontal,
            tilt_deg,
            contact_tilt_deg: tilt_deg,
            slope_deg,
            roughness_m: footprint_roughness_m(&self.ground, &p_mcmf),
            slide_m: 0.0,
            slide_speed_m_s: 0.0,
            leg_crush_m: [0.0; legs::FOOTPADS],
            tilt_limit_deg: lim.tilt_deg,
            slope_limit_deg: lim.slope_deg,
            end_t_s: t_s,
            propellant_used_kg: self.setup.wet_mass_kg - s.mass_kg,
            landed: false,
            reason,
        }
    }

    /// Angle between body +Z and the local vertical, degrees.
    fn tilt_deg(&self, s: &RigidBodyState) -> f64 {
        s.thrust_axis_mci()
            .dot(&s.pos_mci_m.normalize())
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    /// Angle between body +Z and the ground's normal below the vehicle, degrees.
    fn tilt_from_ground_deg(&self, s: &RigidBodyState, t_s: f64) -> f64 {
        let to_mcmf = self.setup.rotation.mcmf_from_mci(t_s);
        let n_mci = to_mcmf.inverse() * self.ground.normal_mcmf(&(to_mcmf * s.pos_mci_m));
        s.thrust_axis_mci()
            .dot(&n_mci)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    /// Height of the footpad plane above the ground below the centre of mass, metres.
    fn footpad_height_m(&self, pos_mci_m: &Vector3<f64>) -> f64 {
        let t_s = self.time_ns as f64 * 1e-9;
        let p_mcmf = self.setup.rotation.mcmf_from_mci(t_s) * pos_mci_m;
        self.ground.height_m(&p_mcmf) - self.setup.leg_height_m
    }

    /// True height of the footpads above the surface, metres.
    pub fn altitude_m(&self) -> f64 {
        let (pos, t_ns) = (self.state.pos_mci_m, self.time_ns);
        // Same position (bit for bit, so no NaN matches) and time: the same height.
        if let Some((p, t, h)) = self.altitude_memo.get() {
            if t == t_ns
                && p.iter()
                    .zip(pos.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            {
                return h;
            }
        }
        let h = self.footpad_height_m(&pos);
        self.altitude_memo.set(Some((pos, t_ns, h)));
        h
    }

    /// Simulated time at the end of the last step, nanoseconds. After touchdown the
    /// state is the contact state (see [`TouchdownState::t_s`]) and time stops.
    pub fn time_ns(&self) -> i64 {
        self.time_ns
    }

    /// The ground the legs meet and the sensor beams are cast on.
    pub fn ground(&self) -> &Ground {
        &self.ground
    }

    /// What the sensor models need after a step ([`crate::sensors::SensorSuite`]): the
    /// state at its start and end, and the mean specific force over it, from the
    /// velocity change less gravity (trapezoidal over the step), so every force the step
    /// integrated (engines, thrusters, legs) is sensed. Call after each [`Plant::step`];
    /// after touchdown time stops and `dt_ns` is 0.
    pub fn sensor_truth(&self) -> crate::sensors::SensorTruth<'_> {
        let (s0, t0_ns) = &self.step_start;
        let s1 = &self.state;
        let dt_ns = self.time_ns - t0_ns;
        let mu = self.setup.dynamics.mu_m3_s2;
        // The plant's gravity model (rigid_body::Dynamics): a central field.
        let g = |r: &Vector3<f64>| -r * (mu / (r.norm() * r.norm() * r.norm()));
        let q0 = s0.q_mci_from_body;
        let q1 = s1.q_mci_from_body;
        let f_mci = if dt_ns > 0 {
            (s1.vel_mci_m_s - s0.vel_mci_m_s) / (dt_ns as f64 * 1e-9)
                - (g(&s0.pos_mci_m) + g(&s1.pos_mci_m)) * 0.5
        } else {
            -g(&s1.pos_mci_m)
        };
        let q_mid = q0
            * nalgebra::UnitQuaternion::from_scaled_axis((q0.inverse() * q1).scaled_axis() * 0.5);
        let to_arr = |q: &nalgebra::UnitQuaternion<f64>| [q.w, q.i, q.j, q.k];
        crate::sensors::SensorTruth {
            t_ns: self.time_ns,
            dt_ns: dt_ns.max(0) as u64,
            pos_mci_m: s1.pos_mci_m.into(),
            vel_mci_m_s: s1.vel_mci_m_s.into(),
            q_start_mci_from_body: to_arr(&q0),
            q_mci_from_body: to_arr(&q1),
            rate_body_rad_s: s1.rate_body_rad_s.into(),
            specific_force_body_m_s2: (q_mid.inverse() * f_mci).into(),
            moon_rotation_rate_rad_s: self.setup.rotation.rate_rad_s,
            ground: &self.ground,
        }
    }

    /// The true rigid-body state.
    pub fn state(&self) -> &RigidBodyState {
        &self.state
    }

    /// What the propulsion model reports about itself (envelope exits, shadow
    /// divergence); for the end-of-run report.
    pub fn propulsion_diagnostics(&self) -> Option<crate::propulsion::PropulsionDiagnostics> {
        self.propulsion.diagnostics()
    }

    /// Propellant used so far (main engines and attitude thrusters), kilograms.
    pub fn propellant_used_kg(&self) -> f64 {
        self.setup.wet_mass_kg - self.state.mass_kg
    }

    /// Attitude-thruster propellant used so far, kilograms.
    pub fn rcs_propellant_used_kg(&self) -> f64 {
        self.rcs_used_kg
    }

    /// The attitude thrusters at device level (their on-times, valves and thrust at
    /// the end of the last step, for logs).
    pub fn thrusters(&self) -> &ThrusterBank {
        &self.thrusters
    }

    /// The propulsion model's last output.
    pub fn propulsion_output(&self) -> &PropulsionOutput {
        &self.prop_out
    }

    /// Name of the propulsion model.
    pub fn propulsion_name(&self) -> &'static str {
        self.propulsion.name()
    }

    /// The legs: their crushed lengths and how far the footpads slipped so far.
    pub fn legs(&self) -> &Legs {
        &self.legs
    }

    /// How many footpads touched the ground at the end of the last step.
    pub fn footpads_in_contact(&self) -> u8 {
        self.pads_in_contact
    }

    /// The touchdown, once it happened.
    pub fn touchdown(&self) -> Option<TouchdownState> {
        self.touchdown
    }

    /// Whether this plant's propulsion model can take `fault`: engine-off and stuck act
    /// on the command and a degradation may act on the outputs, so every model takes
    /// those; the rest need a model that represents them physically.
    pub fn supports(&self, fault: &PlantFault) -> bool {
        match fault {
            PlantFault::EngineOff(_)
            | PlantFault::EngineStuck(_)
            | PlantFault::ThrustScaled { .. } => true,
            PlantFault::Propulsion(PropulsionFault::ThrustDegraded { .. }) => true,
            PlantFault::Propulsion(f) => self.propulsion.represents(f),
        }
    }

    /// Starts (`active`) or clears a fault. A stuck engine holds the command it was
    /// last given.
    pub fn set_fault(&mut self, fault: &PlantFault, active: bool) {
        match *fault {
            PlantFault::EngineOff(e) => {
                self.engine_faults[e] = if active {
                    EngineFault::Off
                } else {
                    EngineFault::None
                }
            }
            PlantFault::EngineStuck(e) => {
                self.engine_faults[e] = if active {
                    EngineFault::Stuck {
                        thrust_cmd_n: self.last_engines.thrust_cmd_n[e],
                        on: self.last_engines.on[e],
                    }
                } else {
                    EngineFault::None
                }
            }
            PlantFault::ThrustScaled { engine, factor } => {
                let scale = self.thrust_scale[engine];
                self.output_factor[engine] = if active { scale * factor } else { scale };
            }
            PlantFault::Propulsion(f) => {
                if self.propulsion.represents(&f) {
                    self.propulsion.inject(&f, active);
                } else if let PropulsionFault::ThrustDegraded { engine, factor } = f {
                    let scale = self.thrust_scale[engine];
                    self.output_factor[engine] = if active { scale * factor } else { scale };
                }
            }
        }
    }

    /// The first state quantity that is not finite, by name; `None` while all are. A
    /// handful of comparisons a step: the scheduler ends the run on the first bad one,
    /// so a NaN never flies on silently.
    pub fn first_non_finite(&self) -> Option<&'static str> {
        let s = &self.state;
        let p = &self.prop_out;
        let finite = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
        if !finite(s.pos_mci_m.as_slice()) {
            Some("position")
        } else if !finite(s.vel_mci_m_s.as_slice()) {
            Some("velocity")
        } else if !finite(s.q_mci_from_body.coords.as_slice()) {
            Some("attitude")
        } else if !finite(s.rate_body_rad_s.as_slice()) {
            Some("body rate")
        } else if !s.mass_kg.is_finite() {
            Some("mass")
        } else if !finite(&p.thrust_n) || !finite(&p.mean_thrust_n) {
            Some("engine thrust")
        } else if !finite(&[
            p.gas_pressure_pa,
            p.fuel_tank_pressure_pa,
            p.ox_tank_pressure_pa,
        ]) || !finite(&p.chamber_pressure_pa)
        {
            Some("propulsion pressure")
        } else if !finite(&[p.ejected_fuel_kg, p.ejected_ox_kg]) {
            Some("ejected propellant mass")
        } else {
            None
        }
    }

    /// Why the propulsion model can no longer step, if it cannot
    /// ([`crate::propulsion::Propulsion::failure`]); checked after every step.
    pub fn propulsion_failure(&self) -> Option<&'static str> {
        self.propulsion.failure()
    }

    /// The vehicle and its propulsion as they truly are now (no navigation noise): what
    /// the log records beside the wire packets, for plots and statistics.
    pub fn truth(&self) -> TruthState {
        let s = &self.state;
        let q = s.q_mci_from_body.quaternion();
        TruthState {
            pos_mci_m: s.pos_mci_m.into(),
            vel_mci_m_s: s.vel_mci_m_s.into(),
            q_mci_from_body: [q.w, q.i, q.j, q.k],
            rate_body_rad_s: s.rate_body_rad_s.into(),
            mass_kg: s.mass_kg,
            altitude_m: self.altitude_m(),
            // From the first footpad contact on, not only once the landing is judged.
            contact: self.contact.is_some() || self.touchdown.is_some(),
            propulsion: self.prop_out,
            internals: self.propulsion.internals(),
        }
    }
}

/// The true state of the vehicle at a step boundary (see [`Plant::truth`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TruthState {
    /// Position, Moon-centred inertial, metres.
    pub pos_mci_m: [f64; 3],
    /// Velocity, Moon-centred inertial, m/s.
    pub vel_mci_m_s: [f64; 3],
    /// Attitude, body to mci, `[w, x, y, z]`.
    pub q_mci_from_body: [f64; 4],
    /// Body rates, body axes, rad/s.
    pub rate_body_rad_s: [f64; 3],
    /// Vehicle mass, kilograms.
    pub mass_kg: f64,
    /// Footpads above the surface, metres.
    pub altitude_m: f64,
    /// The footpads have touched the surface.
    pub contact: bool,
    /// The propulsion model's outputs.
    pub propulsion: PropulsionOutput,
    /// The propulsion model's internal states (NaN where it has none).
    pub internals: crate::propulsion::PropulsionInternals,
}
