//! The reference descent GNC: navigation filter, guidance, attitude control, thrust
//! allocation and the thrust loop as plain structs; [`ReferenceGnc`] only wires them.
//!
//! The onboard software never reads the emulator's configuration: it flies on its own
//! [`GncConfig`], whose defaults match `shared/reference/lander-and-propulsion.md`.
//! See `docs/gnc.md` for the phases, laws, gains and the landing-site choice.

pub mod allocation;
pub mod attitude;
pub mod covariance;
pub mod guidance;
pub mod hazard;
pub mod nav_filter;
pub mod navigation;
pub mod sensor_nav;
pub mod terrain_map;
pub mod terrain_nav;
pub mod thrust_loop;
pub mod thruster_control;

use crate::fsw::{FlightSoftware, GncAttitude, GncNavigation};
use allocation::{EngineSet, ThrustAllocator};
use attitude::AttitudeController;
use guidance::{Guidance, GuidanceCommand, Phase};
use nalgebra::Vector3;
use navigation::NavFilter;
use oils_shared::clock::monotonic_ns_if;
use oils_shared::{
    Command, FrameAnnouncement, FswReport, Telemetry, ATTITUDE_MODE_IDEAL_TORQUE,
    ATTITUDE_MODE_THRUSTERS, ENGINE_COUNT, NAV_FLAG_HAZARD_MAPPED, NAV_FLAG_HAZARD_UNMAPPED,
    NAV_FLAG_VALID, RATE_GROUPS, TLM_FLAG_FOOTPAD_CONTACT,
};
use sensor_nav::{SensorNav, SensorNavConfig};
use thrust_loop::ThrustLoop;
use thruster_control::{ThrusterControl, ThrusterLayout};

/// The landing site the descent is aimed at, Moon-fixed (the scenario's `[site]`, handed
/// to the flight software when it is built: see [`crate::build`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteTarget {
    /// Selenographic latitude, degrees, north positive.
    pub latitude_deg: f64,
    /// East longitude, degrees.
    pub longitude_deg: f64,
}

impl SiteTarget {
    /// The default scenario's site (Chandrayaan-3: 69.373 S, 32.319 E).
    pub const CHANDRAYAAN_3: Self = Self {
        latitude_deg: -69.373,
        longitude_deg: 32.319,
    };

    /// Unit vector to the site, Moon-fixed (= `mci` at `t = 0`).
    pub fn unit_mcmf(&self) -> Vector3<f64> {
        let (sl, cl) = self.latitude_deg.to_radians().sin_cos();
        let (so, co) = self.longitude_deg.to_radians().sin_cos();
        Vector3::new(cl * co, cl * so, sl)
    }
}

/// Everything the onboard software assumes about the vehicle, the Moon and its own
/// gains. Plain numbers with defaults; `validate` before use.
#[derive(Debug, Clone, PartialEq)]
pub struct GncConfig {
    /// What it navigates from: the bench's ideal navigation source, or the device
    /// samples through its Kalman filter.
    pub navigation: GncNavigation,
    /// What turns the vehicle: the ideal torque actuator or the attitude thrusters.
    pub attitude_actuator: GncAttitude,
    /// The sensor navigation (with `navigation = Sensors`).
    pub sensor_nav: SensorNavConfig,
    /// Moon gravitational parameter, m^3/s^2.
    pub moon_mu_m3_s2: f64,
    /// Moon rotation rate about the inertial +Z (its pole), rad/s: the ground the
    /// vehicle lands on moves at `omega x r`.
    pub moon_rotation_rad_s: f64,
    /// Moon reference radius, metres (ranges along the surface).
    pub moon_radius_m: f64,
    /// The landing site to fly to; `None`: guidance picks a site on the ground track
    /// when fine braking starts (no targeting).
    pub site: Option<SiteTarget>,
    /// Specific impulse of the main engines, seconds (the range predictor's mass flow).
    pub isp_s: f64,
    /// Main engine positions relative to the centre of mass, body axes, metres.
    pub engine_positions_body_m: [[f64; 3]; ENGINE_COUNT],
    /// Rated thrust per engine, newtons.
    pub max_thrust_n: f64,
    /// Throttle floor as a fraction of rated thrust.
    pub throttle_min_frac: f64,
    /// Attitude-thruster torque limit per axis, N m.
    pub rcs_max_torque_nm: [f64; 3],
    /// The attitude thrusters (with `attitude_actuator = Thrusters`).
    pub thrusters: ThrusterLayout,
    /// The flight-software cycle the GNC is built for, seconds (the bench's default
    /// `fsw_period_ms`, 10 ms): the thrusters' modulation period until the telemetry
    /// gives the real one.
    pub cycle_s: f64,
    /// The guidance rate group's period, seconds: a whole multiple of `cycle_s`; the
    /// group runs on the first cycle of each period (when `floor(t / period)` changes)
    /// and its output is held in between. Navigation and control run every cycle.
    pub guidance_period_s: f64,
    /// The terrain-navigation rate group's period, seconds (the camera's frame period:
    /// a match that takes longer is a cycle slip).
    pub vision_period_s: f64,
    /// Dry mass, kilograms (for the inertia estimate).
    pub dry_mass_kg: f64,
    /// Propellant at descent start, kilograms (for the inertia estimate).
    pub propellant_kg: f64,
    /// Principal inertia with full tanks, kg m^2.
    pub inertia_wet_kg_m2: [f64; 3],
    /// Principal inertia with empty tanks, kg m^2.
    pub inertia_dry_kg_m2: [f64; 3],

    /// Navigation filter gain on position (per step).
    pub nav_gain_position: f64,
    /// Navigation filter gain on velocity (per step).
    pub nav_gain_velocity: f64,
    /// Navigation filter gain on the altimeter (per step).
    pub nav_gain_altitude: f64,

    /// Rough braking throttle without a site (leaves headroom for differential-throttle
    /// torque); with a site, the throttle the range predictor starts from.
    pub rough_throttle_frac: f64,
    /// Range control: lowest throttle the range predictor may choose.
    pub rough_min_throttle_frac: f64,
    /// Range control: highest throttle the range predictor may choose (the margin above
    /// the nominal is what absorbs a thrust shortfall).
    pub rough_max_throttle_frac: f64,
    /// Range control: the predictor is solved again this often, seconds.
    pub rough_solve_period_s: f64,
    /// Range control: integration step of the predictor, seconds.
    pub rough_predict_step_s: f64,
    /// Rough braking: gain nulling the velocity across the great circle to the site, 1/s.
    pub rough_gain_cross_speed_1_s: f64,
    /// Rough braking: largest share of the thrust acceleration steering across track.
    pub rough_max_cross_frac: f64,
    /// Rough braking ends at this horizontal speed, m/s (sourced: ~358 m/s).
    pub rough_end_speed_m_s: f64,
    /// Altitude the rough-braking profile reaches at its end, metres (sourced: 7.42 km).
    pub rough_end_altitude_m: f64,
    /// Rough braking also ends below this altitude (safety), metres.
    pub rough_floor_altitude_m: f64,
    /// Vertical-speed gain of the rough-braking altitude channel, 1/s.
    pub rough_gain_vertical_speed_1_s: f64,
    /// Altitude gain of the rough-braking altitude channel, 1/s^2.
    pub rough_gain_altitude_1_s2: f64,
    /// Largest upward share of the thrust acceleration in rough braking.
    pub rough_max_up_frac: f64,
    /// Largest downward share of the thrust acceleration in rough braking.
    pub rough_max_down_frac: f64,
    /// Attitude hold duration, seconds (sourced: ~10 s).
    pub attitude_hold_s: f64,

    /// Fine braking brings the vehicle to rest this high above the site, metres.
    pub fine_target_altitude_m: f64,
    /// Vertical speed at the fine-braking target, m/s (negative: descending).
    pub fine_target_vertical_speed_m_s: f64,
    /// Planned fine-braking duration at its start (with a site), seconds: the rough
    /// braking aims to start fine braking `V T / 2` before the target.
    pub fine_plan_tgo_s: f64,
    /// Fine braking may not plan more than this share of the maximum acceleration.
    pub fine_accel_fraction: f64,
    /// Fine braking must plan at least this multiple of the throttle-floor acceleration.
    pub fine_min_accel_margin: f64,
    /// Shortest fine-braking time-to-go considered, seconds.
    pub fine_min_tgo_s: f64,
    /// Longest fine-braking time-to-go considered, seconds.
    pub fine_max_tgo_s: f64,
    /// Hold the last E-guidance command below this time-to-go, seconds.
    pub fine_hold_tgo_s: f64,
    /// Below this time-to-go fine braking flies the horizontal velocity only, not the
    /// position, seconds.
    pub fine_velocity_only_tgo_s: f64,
    /// Start fine braking (rather than terminal descent) only this far above its target, m.
    pub fine_min_drop_m: f64,

    /// Terminal descent deceleration of the vertical-speed profile, m/s^2.
    pub terminal_decel_m_s2: f64,
    /// Fastest terminal descent, m/s.
    pub terminal_max_speed_m_s: f64,
    /// Vertical-speed loop gain, 1/s.
    pub terminal_gain_vertical_speed_1_s: f64,
    /// Vertical-speed loop integral gain, 1/s^2.
    pub terminal_gain_vertical_integral_1_s2: f64,
    /// Vertical-speed integral limit, m/s^2.
    pub terminal_integral_limit_m_s2: f64,
    /// Horizontal velocity nulling gain, 1/s.
    pub terminal_gain_horizontal_speed_1_s: f64,
    /// Horizontal pull towards the site, 1/s^2 (terminal descent and hover only).
    pub terminal_gain_position_1_s2: f64,
    /// Site offset the pull acts on at most, metres.
    pub terminal_max_position_error_m: f64,
    /// Largest thrust tilt from the vertical in terminal descent, degrees.
    pub terminal_max_tilt_deg: f64,
    /// Hover altitude, metres.
    pub hover_altitude_m: f64,
    /// Hover starts within this of the hover altitude, metres.
    pub hover_capture_m: f64,
    /// Hover duration, seconds (0: no hover).
    pub hover_s: f64,
    /// Longest hover while hazard avoidance holds it (waiting for its map, or flying
    /// its divert), seconds; then the final descent starts wherever the vehicle is.
    pub hover_max_s: f64,
    /// Position gain of the hover while diverting to a safe spot, 1/s^2 (with the 0.3
    /// 1/s speed gain: 0.2 rad/s, damping 0.75, a 15 m divert in about 20 s).
    pub divert_gain_position_1_s2: f64,
    /// Hazard detection and avoidance at the hover (off by default).
    pub hazard: hazard::HazardConfig,
    /// Hover altitude gain, 1/s.
    pub hover_gain_altitude_1_s: f64,
    /// Largest vertical speed while hovering, m/s.
    pub hover_max_speed_m_s: f64,
    /// Final descent deceleration of the vertical-speed profile, m/s^2.
    pub final_decel_m_s2: f64,
    /// Below this altitude the final descent flies at touchdown speed, metres.
    pub final_altitude_m: f64,
    /// Fastest final descent, m/s.
    pub final_max_speed_m_s: f64,
    /// Descent speed at contact, m/s.
    pub touchdown_speed_m_s: f64,
    /// Below this altitude the tilt limit tightens, metres.
    pub final_upright_altitude_m: f64,
    /// Tilt limit near the ground, degrees.
    pub final_max_tilt_deg: f64,

    /// Fly the diagonal pair from hover on, if it can hold the vehicle with this margin.
    pub two_engine_enabled: bool,
    /// The diagonal pair (engine indices).
    pub two_engine_pair: [usize; 2],
    /// Thrust margin the pair needs over the weight at the surface (0.12: 12 %).
    pub two_engine_margin: f64,
    /// Back to four engines after the pair saturates for this long, seconds.
    pub two_engine_saturation_s: f64,
    /// Below fine braking, fly the pair (whatever `two_engine_enabled` says) once four
    /// engines at their throttle floor have pushed harder than wanted for this long, s.
    pub two_engine_floor_s: f64,
    /// ... and the thrust loop has learned an efficiency above `1 + this` (hot engines).
    pub two_engine_hot_margin: f64,

    /// Attitude loop natural frequency, rad/s.
    pub attitude_natural_freq_rad_s: f64,
    /// Attitude loop damping ratio.
    pub attitude_damping: f64,
    /// Largest commanded slew rate, rad/s.
    pub attitude_max_rate_rad_s: f64,
    /// Integral time of the attitude loop, seconds (0: PD only).
    pub attitude_integral_time_s: f64,
    /// The attitude error is integrated only while smaller than this, degrees.
    pub attitude_integral_band_deg: f64,

    /// Engine lag the thrust loop assumes, seconds.
    pub thrust_lag_model_s: f64,
    /// Thrust efficiency filter time constant, seconds.
    pub thrust_efficiency_filter_s: f64,
    /// Lowest thrust efficiency believed.
    pub thrust_efficiency_min: f64,
    /// Highest thrust efficiency believed.
    pub thrust_efficiency_max: f64,
}

impl Default for GncConfig {
    fn default() -> Self {
        Self {
            navigation: GncNavigation::Bench,
            attitude_actuator: GncAttitude::Torque,
            sensor_nav: SensorNavConfig::default(),
            moon_mu_m3_s2: 4.9028e12,
            moon_rotation_rad_s: 2.6617e-6,
            moon_radius_m: 1_737_400.0,
            site: Some(SiteTarget::CHANDRAYAAN_3),
            isp_s: 310.0,
            engine_positions_body_m: [
                [0.6, 0.6, -0.8],
                [-0.6, 0.6, -0.8],
                [-0.6, -0.6, -0.8],
                [0.6, -0.6, -0.8],
            ],
            max_thrust_n: 800.0,
            throttle_min_frac: 0.4,
            rcs_max_torque_nm: [116.0; 3],
            thrusters: ThrusterLayout::default(),
            cycle_s: 0.010,
            guidance_period_s: 0.010,
            vision_period_s: 1.0,
            dry_mass_kg: 750.0,
            propellant_kg: 1000.0,
            inertia_wet_kg_m2: [1200.0, 1200.0, 1100.0],
            inertia_dry_kg_m2: [700.0, 700.0, 600.0],

            nav_gain_position: 0.01,
            nav_gain_velocity: 0.02,
            nav_gain_altitude: 0.05,

            rough_throttle_frac: 0.98,
            rough_min_throttle_frac: 0.6,
            rough_max_throttle_frac: 1.0,
            rough_solve_period_s: 1.0,
            rough_predict_step_s: 2.0,
            rough_gain_cross_speed_1_s: 0.02,
            rough_max_cross_frac: 0.1,
            rough_end_speed_m_s: 358.0,
            rough_end_altitude_m: 7_400.0,
            rough_floor_altitude_m: 5_000.0,
            rough_gain_vertical_speed_1_s: 0.05,
            rough_gain_altitude_1_s2: 0.0005,
            rough_max_up_frac: 0.9,
            rough_max_down_frac: 0.0,
            attitude_hold_s: 10.0,

            fine_target_altitude_m: 800.0,
            fine_target_vertical_speed_m_s: -15.0,
            fine_plan_tgo_s: 175.0,
            fine_accel_fraction: 0.95,
            fine_min_accel_margin: 1.1,
            fine_min_tgo_s: 20.0,
            fine_max_tgo_s: 900.0,
            fine_hold_tgo_s: 4.0,
            fine_velocity_only_tgo_s: 20.0,
            fine_min_drop_m: 300.0,

            terminal_decel_m_s2: 0.4,
            terminal_max_speed_m_s: 20.0,
            terminal_gain_vertical_speed_1_s: 0.8,
            terminal_gain_vertical_integral_1_s2: 0.1,
            terminal_integral_limit_m_s2: 0.3,
            terminal_gain_horizontal_speed_1_s: 0.3,
            terminal_gain_position_1_s2: 0.01,
            terminal_max_position_error_m: 30.0,
            terminal_max_tilt_deg: 15.0,
            hover_altitude_m: 100.0,
            hover_capture_m: 0.5,
            hover_s: 10.0,
            hover_max_s: 60.0,
            divert_gain_position_1_s2: 0.04,
            hazard: hazard::HazardConfig::default(),
            hover_gain_altitude_1_s: 0.3,
            hover_max_speed_m_s: 2.0,
            final_decel_m_s2: 0.08,
            final_altitude_m: 5.0,
            final_max_speed_m_s: 5.0,
            touchdown_speed_m_s: 1.0,
            final_upright_altitude_m: 10.0,
            final_max_tilt_deg: 4.0,

            two_engine_enabled: false,
            two_engine_pair: [0, 2],
            two_engine_margin: 0.12,
            two_engine_saturation_s: 1.0,
            two_engine_floor_s: 3.0,
            two_engine_hot_margin: 0.03,

            attitude_natural_freq_rad_s: 1.0,
            attitude_damping: 0.8,
            attitude_max_rate_rad_s: 0.1,
            attitude_integral_time_s: 10.0,
            attitude_integral_band_deg: 5.0,

            thrust_lag_model_s: 0.1,
            thrust_efficiency_filter_s: 3.0,
            thrust_efficiency_min: 0.8,
            thrust_efficiency_max: 1.2,
        }
    }
}

/// A GNC configuration value is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid GNC configuration: {field} ({why})")]
pub struct GncConfigError {
    /// The field.
    pub field: &'static str,
    /// What is expected.
    pub why: &'static str,
}

impl GncConfig {
    /// Checks the numbers the laws divide by or take roots of.
    pub fn validate(&self) -> Result<(), GncConfigError> {
        let err = |field, why| Err(GncConfigError { field, why });
        let positive = [
            (self.moon_mu_m3_s2, "moon_mu_m3_s2"),
            (self.moon_radius_m, "moon_radius_m"),
            (self.isp_s, "isp_s"),
            (self.rough_solve_period_s, "rough_solve_period_s"),
            (self.rough_predict_step_s, "rough_predict_step_s"),
            (self.fine_plan_tgo_s, "fine_plan_tgo_s"),
            (self.max_thrust_n, "max_thrust_n"),
            (self.cycle_s, "cycle_s"),
            (self.guidance_period_s, "guidance_period_s"),
            (self.vision_period_s, "vision_period_s"),
            (self.thrusters.thrust_n, "thrusters.thrust_n"),
            (self.thrusters.min_on_time_s, "thrusters.min_on_time_s"),
            (self.dry_mass_kg, "dry_mass_kg"),
            (self.rough_end_speed_m_s, "rough_end_speed_m_s"),
            (self.fine_min_tgo_s, "fine_min_tgo_s"),
            (self.terminal_decel_m_s2, "terminal_decel_m_s2"),
            (self.final_decel_m_s2, "final_decel_m_s2"),
            (self.touchdown_speed_m_s, "touchdown_speed_m_s"),
            (
                self.attitude_natural_freq_rad_s,
                "attitude_natural_freq_rad_s",
            ),
            (self.attitude_damping, "attitude_damping"),
            (self.attitude_max_rate_rad_s, "attitude_max_rate_rad_s"),
            (self.thrust_lag_model_s, "thrust_lag_model_s"),
            (
                self.thrust_efficiency_filter_s,
                "thrust_efficiency_filter_s",
            ),
        ];
        for (v, name) in positive {
            if !(v.is_finite() && v > 0.0) {
                return err(name, "finite and > 0");
            }
        }
        if !(0.0..1.0).contains(&self.throttle_min_frac) {
            return err("throttle_min_frac", "in [0, 1)");
        }
        for (v, name) in [
            (self.nav_gain_position, "nav_gain_position"),
            (self.nav_gain_velocity, "nav_gain_velocity"),
            (self.nav_gain_altitude, "nav_gain_altitude"),
            (self.rough_throttle_frac, "rough_throttle_frac"),
            (self.rough_min_throttle_frac, "rough_min_throttle_frac"),
            (self.rough_max_throttle_frac, "rough_max_throttle_frac"),
            (self.rough_max_cross_frac, "rough_max_cross_frac"),
            (self.fine_accel_fraction, "fine_accel_fraction"),
        ] {
            if !(v > 0.0 && v <= 1.0) {
                return err(name, "in (0, 1]");
            }
        }
        if self.rough_max_throttle_frac < self.rough_min_throttle_frac {
            return err("rough_max_throttle_frac", ">= rough_min_throttle_frac");
        }
        if let Some(site) = self.site {
            if !(site.latitude_deg.abs() < 90.0 && site.longitude_deg.is_finite()) {
                return err("site", "latitude within (-90, 90) deg, finite longitude");
            }
        }
        if !(self.attitude_integral_time_s.is_finite() && self.attitude_integral_time_s >= 0.0) {
            return err(
                "attitude_integral_time_s",
                "finite and >= 0 (0: no integral)",
            );
        }
        if !(self.fine_velocity_only_tgo_s.is_finite() && self.fine_velocity_only_tgo_s >= 0.0) {
            return err("fine_velocity_only_tgo_s", "finite and >= 0 (0: never)");
        }
        if !(self.attitude_integral_band_deg.is_finite() && self.attitude_integral_band_deg >= 0.0)
        {
            return err("attitude_integral_band_deg", "finite and >= 0");
        }
        if self.rough_gain_cross_speed_1_s.is_nan() || self.rough_gain_cross_speed_1_s < 0.0 {
            return err("rough_gain_cross_speed_1_s", ">= 0");
        }
        let cycles = (self.guidance_period_s / self.cycle_s).round();
        if !(cycles >= 1.0 && (self.guidance_period_s - cycles * self.cycle_s).abs() < 1e-9) {
            return err("guidance_period_s", "a whole multiple of cycle_s");
        }
        let t = &self.thrusters;
        if !(t.open_delay_s.is_finite()
            && t.open_delay_s >= 0.0
            && t.close_delay_s.is_finite()
            && t.close_delay_s >= 0.0)
        {
            return err("thrusters.open_delay_s", "delays finite and >= 0");
        }
        if t.positions_body_m
            .iter()
            .chain(t.directions_body.iter())
            .flatten()
            .any(|v| !v.is_finite())
            || t.directions_body
                .iter()
                .any(|d| (Vector3::from(*d).norm() - 1.0).abs() > 1e-6)
        {
            return err(
                "thrusters.directions_body",
                "finite positions and unit directions",
            );
        }
        if self.fine_max_tgo_s < self.fine_min_tgo_s {
            return err("fine_max_tgo_s", ">= fine_min_tgo_s");
        }
        if self.two_engine_pair.iter().any(|&i| i >= ENGINE_COUNT)
            || self.two_engine_pair[0] == self.two_engine_pair[1]
        {
            return err("two_engine_pair", "two different engine indices < 4");
        }
        Ok(())
    }

    /// Principal inertia at a vehicle mass (linear in the propellant fraction).
    pub fn inertia_kg_m2(&self, mass_kg: f64) -> Vector3<f64> {
        let frac = if self.propellant_kg > 0.0 {
            ((mass_kg - self.dry_mass_kg) / self.propellant_kg).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let wet = Vector3::from(self.inertia_wet_kg_m2);
        let dry = Vector3::from(self.inertia_dry_kg_m2);
        dry + (wet - dry) * frac
    }
}

/// The reference GNC as flight software.
#[derive(Debug, Clone)]
pub struct ReferenceGnc {
    cfg: GncConfig,
    nav: NavFilter,
    sensor_nav: SensorNav,
    /// Hazard detection and avoidance at the hover (with sensor navigation).
    hazard: hazard::HazardDetection,
    /// Boots so far (kept across a computer reset, as a real boot counter in protected
    /// memory is).
    boot_count: u32,
    /// The computer is down (a reset under way).
    down: bool,
    guidance: Guidance,
    attitude: AttitudeController,
    allocator: ThrustAllocator,
    thrust_loop: ThrustLoop,
    thrusters: ThrusterControl,
    engine_set: EngineSet,
    /// Four engines forced back after the pair saturated (latched).
    pair_abandoned: bool,
    pair_saturated_s: f64,
    /// How long four engines at their floor have pushed harder than wanted, s.
    floor_held_s: f64,
    last_cmd_total_n: f64,
    last_t_s: f64,
    /// Telemetry time of the last step, ns (the cycle the thrusters modulate over).
    last_t_ns: Option<i64>,
    /// Pointing error of body +Z from the demanded thrust direction at the last
    /// powered step, rad.
    pointing_error_rad: f64,
    /// Rate groups: the guidance group's period, ns; the period it last ran in
    /// (`floor(t / period)`) and its output, held until it runs again.
    guidance_period_ns: i64,
    guidance_slot: Option<i64>,
    held_guidance: Option<GuidanceCommand>,
    /// Rate-group overruns so far (compute time over the group's period; wall clock,
    /// for the report only).
    cycle_slips: u32,
    /// Engine-out detection.
    monitor: EngineMonitor,
    /// A footpad touched: the engines stay off.
    touched_down: bool,
    /// Whether the rate groups are timed on the wall clock
    /// ([`FlightSoftware::set_compute_timing`]).
    compute_timing: bool,
}

/// Detects a main engine that stopped delivering: lit and commanded for a while, yet
/// its thrust reading stays below half of the command. What it sees is telemetry only.
#[derive(Debug, Clone, Default)]
struct EngineMonitor {
    /// Last command per engine (thrust, lit).
    commanded_n: [f64; ENGINE_COUNT],
    lit: [bool; ENGINE_COUNT],
    /// How long each engine has been lit, s.
    lit_s: [f64; ENGINE_COUNT],
    /// How long each engine's reading has been short, s.
    short_s: [f64; ENGINE_COUNT],
    /// The engine declared failed, once.
    failed: Option<usize>,
}

impl EngineMonitor {
    /// An engine needs this long lit before its reading is judged (start-up transient).
    const SETTLE_S: f64 = 2.0;
    /// A reading below this fraction of the command is short.
    const SHORT_FRAC: f64 = 0.5;
    /// Short for this long means failed.
    const CONFIRM_S: f64 = 0.3;

    fn update(&mut self, tlm: &Telemetry, dt_s: f64) -> Option<usize> {
        if self.failed.is_some() {
            return self.failed;
        }
        for e in 0..ENGINE_COUNT {
            if !self.lit[e] {
                self.lit_s[e] = 0.0;
                self.short_s[e] = 0.0;
                continue;
            }
            self.lit_s[e] += dt_s;
            let reading = tlm.propulsion.engines[e].thrust_n;
            // A reading that is not a number counts as short, too.
            let short = reading.is_nan() || reading < Self::SHORT_FRAC * self.commanded_n[e];
            if self.lit_s[e] > Self::SETTLE_S && short {
                self.short_s[e] += dt_s;
            } else {
                self.short_s[e] = 0.0;
            }
            if self.short_s[e] > Self::CONFIRM_S {
                self.failed = Some(e);
                break;
            }
        }
        self.failed
    }

    fn commanded(&mut self, thrust_n: &[f64; ENGINE_COUNT], on: &[bool; ENGINE_COUNT]) {
        self.commanded_n = *thrust_n;
        self.lit = *on;
    }
}

impl ReferenceGnc {
    /// Builds the GNC; allocation happens here, never in `step`.
    pub fn new(cfg: GncConfig) -> Result<Self, GncConfigError> {
        let terrain = terrain_nav::TerrainNav::new(cfg.sensor_nav.terrain.clone());
        let hazard = hazard::HazardDetection::new(cfg.hazard.clone());
        Self::with_terrain(cfg, terrain, hazard)
    }

    /// [`ReferenceGnc::new`] around terrain navigation buffers already allocated (a
    /// computer reset hands its own back: nothing is allocated).
    fn with_terrain(
        cfg: GncConfig,
        terrain: terrain_nav::TerrainNav,
        mut hazard: hazard::HazardDetection,
    ) -> Result<Self, GncConfigError> {
        cfg.validate()?;
        hazard.reset();
        let allocator = ThrustAllocator::new(&cfg).ok_or(GncConfigError {
            field: "engine_positions_body_m",
            why: "engines must be able to produce x/y torque",
        })?;
        let thrusters = ThrusterControl::new(&cfg.thrusters).map_err(|_| GncConfigError {
            field: "thrusters",
            why: "the layout must give a pure couple about each body axis, both signs",
        })?;
        Ok(Self {
            nav: NavFilter::new(&cfg),
            sensor_nav: SensorNav::with_terrain(cfg.sensor_nav.clone(), terrain),
            hazard,
            boot_count: 1,
            down: false,
            guidance: Guidance::new(&cfg),
            attitude: AttitudeController::new(&cfg),
            thrust_loop: ThrustLoop::new(&cfg),
            allocator,
            thrusters,
            engine_set: EngineSet::Four,
            pair_abandoned: false,
            pair_saturated_s: 0.0,
            floor_held_s: 0.0,
            last_cmd_total_n: 0.0,
            last_t_s: 0.0,
            last_t_ns: None,
            pointing_error_rad: 0.0,
            guidance_period_ns: (cfg.guidance_period_s * 1e9).round() as i64,
            guidance_slot: None,
            held_guidance: None,
            cycle_slips: 0,
            monitor: EngineMonitor::default(),
            touched_down: false,
            compute_timing: true,
            cfg,
        })
    }

    /// The sensor navigation (its filter's counters), when it flies on it.
    pub fn sensor_nav(&self) -> Option<&SensorNav> {
        (self.cfg.navigation == GncNavigation::Sensors).then_some(&self.sensor_nav)
    }

    /// Current descent phase.
    pub fn phase(&self) -> Phase {
        self.guidance.phase()
    }

    /// Engines in use.
    pub fn engine_set(&self) -> EngineSet {
        self.engine_set
    }

    /// The main engine declared failed (0-based), if one was.
    pub fn failed_engine(&self) -> Option<usize> {
        self.monitor.failed
    }

    /// The landing site, once chosen.
    pub fn site(&self) -> Option<guidance::LandingSite> {
        self.guidance.site()
    }

    /// Pointing error of the thrust axis from the demanded thrust direction at the last
    /// powered step, rad.
    pub fn pointing_error_rad(&self) -> f64 {
        self.pointing_error_rad
    }

    /// Thrust efficiency the thrust loop has learned.
    pub fn thrust_efficiency(&self) -> f64 {
        self.thrust_loop.efficiency()
    }

    /// Chooses the engine set: the pair from hover on, once both the weight and the
    /// current demand fit under its maximum with margin; back to four (for good) if the
    /// pair runs out of thrust.
    fn manage_engines(&mut self, mass_kg: f64, gravity_m_s2: f64, wanted_n: f64, dt_s: f64) {
        if let Some(failed) = self.monitor.failed {
            // Engine out: its diagonal partner goes off too (balanced thrust about the
            // centre of mass), and the other pair flies to the end.
            self.engine_set = self.allocator.pair_without(failed);
            return;
        }
        let phase = self.guidance.phase();
        let late = matches!(phase, Phase::Hover | Phase::FinalDescent);
        // Four engines at their throttle floor still push harder than wanted (engines
        // hotter than rated, a light vehicle): the vehicle cannot come down. Held for
        // `two_engine_floor_s` below fine braking, that calls for the pair.
        // Only with engines measurably hotter than rated (the nominal vehicle's floor is
        // below its landing weight, docs/gnc.md).
        let at_floor = wanted_n < self.allocator.min_total_n(EngineSet::Four)
            && self.thrust_loop.efficiency() > 1.0 + self.cfg.two_engine_hot_margin;
        self.floor_held_s = if at_floor {
            self.floor_held_s + dt_s
        } else {
            0.0
        };
        let floor_bound = matches!(
            phase,
            Phase::TerminalDescent | Phase::Hover | Phase::FinalDescent
        ) && self.floor_held_s > self.cfg.two_engine_floor_s;
        match self.engine_set {
            EngineSet::Four => {
                let pair_max = self.allocator.max_total_n(EngineSet::DiagonalPair)
                    * self.thrust_loop.efficiency();
                let weight = mass_kg * gravity_m_s2;
                let margin = 1.0 + self.cfg.two_engine_margin;
                if ((self.cfg.two_engine_enabled && late && !self.pair_abandoned) || floor_bound)
                    && pair_max >= weight * margin
                    && wanted_n * margin <= pair_max
                {
                    self.engine_set = EngineSet::DiagonalPair;
                    self.pair_saturated_s = 0.0;
                }
            }
            EngineSet::OtherPair => {}
            EngineSet::DiagonalPair => {
                let max = self.allocator.max_total_n(EngineSet::DiagonalPair);
                if wanted_n > max {
                    self.pair_saturated_s += dt_s;
                } else {
                    self.pair_saturated_s = 0.0;
                }
                if self.pair_saturated_s > self.cfg.two_engine_saturation_s {
                    self.engine_set = EngineSet::Four;
                    self.pair_abandoned = true;
                }
            }
        }
    }
}

impl FlightSoftware for ReferenceGnc {
    fn name(&self) -> &'static str {
        "gnc"
    }

    fn set_compute_timing(&mut self, on: bool) {
        self.compute_timing = on;
    }

    fn computer_reset(&mut self) {
        // Everything but the configuration and the boot counter is lost (a real boot
        // counter lives in protected memory); nothing here allocates (fixed-size state).
        // Called on every cycle the computer is down: the state is lost once.
        if self.down {
            return;
        }
        let boots = self.boot_count;
        let slips = self.cycle_slips;
        let timing = self.compute_timing;
        let terrain = self.sensor_nav.take_terrain();
        let hazard = std::mem::replace(
            &mut self.hazard,
            hazard::HazardDetection::new(hazard::HazardConfig::default()),
        );
        if let Ok(fresh) = Self::with_terrain(self.cfg.clone(), terrain, hazard) {
            *self = fresh;
        }
        self.boot_count = boots;
        self.cycle_slips = slips;
        self.compute_timing = timing;
        self.down = true;
    }

    fn frame(&mut self, ann: &FrameAnnouncement, pixels: &[u8]) {
        if self.cfg.navigation == GncNavigation::Sensors {
            self.sensor_nav.frame(ann, pixels);
            self.hazard.frame(ann, pixels);
        }
    }

    fn step(&mut self, tlm: &Telemetry) -> Command {
        if self.down {
            // The first cycle after a reset: booted again.
            self.down = false;
            self.boot_count += 1;
        }
        let mut report = FswReport {
            boot_count: self.boot_count,
            ..Default::default()
        };
        // Rate group 3, terrain navigation: at the camera's rate, on the cycle a frame
        // arrives, before the filter takes this cycle's samples (the fix is for the
        // frame's time of validity, a few ms back).
        if self.cfg.navigation == GncNavigation::Sensors {
            let vision_ns = self.clock_ns();
            let matched = self
                .sensor_nav
                .terrain_group(self.cfg.moon_rotation_rad_s, tlm.header.t_ns);
            if matched | self.hazard_group() {
                let period_ns = (self.cfg.vision_period_s * 1e9).round() as i64;
                self.time_group(&mut report, 3, vision_ns, period_ns);
            }
        }
        // Rate group 0, navigation: every cycle, all of its samples.
        let start_ns = self.clock_ns();
        let nav = match self.cfg.navigation {
            GncNavigation::Bench => {
                let nav = self.nav.update(tlm);
                report.nav_pos_mci_m = nav.pos_mci_m.into();
                report.nav_vel_mci_m_s = nav.vel_mci_m_s.into();
                report.nav_altitude_m = nav.altitude_m;
                report.nav_flags = NAV_FLAG_VALID;
                nav
            }
            GncNavigation::Sensors => {
                let omega = Vector3::new(0.0, 0.0, self.cfg.moon_rotation_rad_s);
                match self.sensor_nav.update(tlm, omega, &mut report) {
                    Some(nav) => nav,
                    // No state vector yet: nothing to fly on, engines stay off.
                    None => {
                        self.time_group(&mut report, 0, start_ns, self.cycle_ns());
                        return Command {
                            fsw: report,
                            ..Default::default()
                        };
                    }
                }
            }
        };
        if self.hazard.enabled() {
            if self.hazard.choice().is_some() {
                report.nav_flags |= NAV_FLAG_HAZARD_MAPPED;
            } else if self.guidance.phase() == Phase::FinalDescent {
                report.nav_flags |= NAV_FLAG_HAZARD_UNMAPPED;
            }
        }
        // Group 2 starts where group 0 ended: one clock read for both.
        let nav_done_ns = self.time_group(&mut report, 0, start_ns, self.cycle_ns());
        report.phase = self.guidance.phase() as u32;
        let mut cmd = self.fly(tlm, &nav, &mut report, nav_done_ns);
        cmd.fsw = report;
        cmd
    }
}

impl ReferenceGnc {
    /// Hazard detection (in rate group 3): armed on entering the hover, it assesses the
    /// first lidar frame then and diverts guidance to the spot it chooses. Returns
    /// whether it assessed a frame.
    fn hazard_group(&mut self) -> bool {
        if !self.hazard.enabled() {
            return false;
        }
        if self.guidance.phase() == Phase::Hover && self.hazard.choice().is_none() {
            self.hazard.arm();
        }
        if !self.hazard.armed() {
            return false;
        }
        let Some(site) = self.guidance.site() else {
            return false;
        };
        let omega = self.cfg.moon_rotation_rad_s;
        let aim = |t_ns: i64| site.turned(&site.surface_mci_m, t_ns as f64 * 1e-9, omega);
        match self.hazard.assess(self.sensor_nav.filter(), aim) {
            Some(choice) => {
                self.guidance
                    .divert_to(&choice.spot_mci_m, choice.t_ns as f64 * 1e-9);
                true
            }
            None => false,
        }
    }

    /// The hazard choice (with hazard avoidance on, once made).
    pub fn hazard_choice(&self) -> Option<&hazard::SpotChoice> {
        self.hazard.choice()
    }

    /// The wall clock for the rate groups' compute times, ns; 0 when they are not timed
    /// (every group then reports 1 ns, "ran", and no cycle slip).
    fn clock_ns(&self) -> u64 {
        monotonic_ns_if(self.compute_timing)
    }

    /// The configured cycle, ns.
    fn cycle_ns(&self) -> i64 {
        (self.cfg.cycle_s * 1e9).round() as i64
    }

    /// Records rate group `group`'s compute time since `start_ns` (wall clock, for the
    /// report only: nothing flown depends on it); over `period_ns` is a cycle slip.
    /// Returns the clock's reading at the group's end.
    fn time_group(
        &mut self,
        report: &mut FswReport,
        group: usize,
        start_ns: u64,
        period_ns: i64,
    ) -> u64 {
        let now_ns = self.clock_ns();
        self.record_group(report, group, now_ns.saturating_sub(start_ns), period_ns);
        now_ns
    }

    fn record_group(&mut self, report: &mut FswReport, group: usize, ns: u64, period_ns: i64) {
        debug_assert!(group < RATE_GROUPS);
        // 0 means "did not run": a group that ran reports at least 1 ns.
        report.group_compute_ns[group] = ns.clamp(1, u64::from(u32::MAX)) as u32;
        if ns > period_ns.max(0) as u64 {
            self.cycle_slips = self.cycle_slips.saturating_add(1);
        }
        report.cycle_slips = self.cycle_slips;
    }

    /// Rate group 1, guidance: runs on the first cycle of each of its periods (and on
    /// the first cycle flown); in between, its last output is held.
    fn guidance_group(
        &mut self,
        nav: &navigation::NavSolution,
        t_ns: i64,
        max_accel_m_s2: f64,
        min_accel_m_s2: f64,
        report: &mut FswReport,
    ) -> (GuidanceCommand, u64) {
        let slot = t_ns.div_euclid(self.guidance_period_ns.max(1));
        if let Some(held) = self.held_guidance {
            if self.guidance_slot == Some(slot) {
                return (held, 0);
            }
        }
        let start_ns = self.clock_ns();
        let guid = self.guidance.update(nav, max_accel_m_s2, min_accel_m_s2);
        let ns = self.clock_ns().saturating_sub(start_ns);
        self.guidance_slot = Some(slot);
        self.held_guidance = Some(guid);
        self.record_group(report, 1, ns, self.guidance_period_ns);
        (guid, ns)
    }

    /// Rate groups 1 (guidance) and 2 (control: thrust loop, attitude, allocation,
    /// thrusters) on this cycle's navigation solution; `start_ns` is the clock's reading
    /// when they start.
    fn fly(
        &mut self,
        tlm: &Telemetry,
        nav: &navigation::NavSolution,
        report: &mut FswReport,
        start_ns: u64,
    ) -> Command {
        let (cmd, guidance_ns) = self.control(tlm, nav, report);
        let ns = self
            .clock_ns()
            .saturating_sub(start_ns)
            .saturating_sub(guidance_ns);
        self.record_group(report, 2, ns, self.cycle_ns());
        cmd
    }

    /// Guidance (through its rate group), control and allocation; also the guidance
    /// group's compute time this cycle (0 when it did not run).
    fn control(
        &mut self,
        tlm: &Telemetry,
        nav: &navigation::NavSolution,
        report: &mut FswReport,
    ) -> (Command, u64) {
        let nav = *nav;
        if tlm.header.flags & TLM_FLAG_FOOTPAD_CONTACT != 0 {
            // On the legs: engines off for good (the touchdown switches' cut-off), no
            // attitude torque; the vehicle settles under its own weight.
            self.touched_down = true;
        }
        if self.touched_down {
            self.monitor
                .commanded(&[0.0; ENGINE_COUNT], &[false; ENGINE_COUNT]);
            return (Command::default(), 0);
        }
        let dt_s = (nav.t_s - self.last_t_s).max(0.0);
        self.last_t_s = nav.t_s;
        let cycle_ns = match self.last_t_ns {
            Some(last) if tlm.header.t_ns > last => (tlm.header.t_ns - last) as u64,
            _ => (self.cfg.cycle_s * 1e9).round() as u64,
        };
        self.last_t_ns = Some(tlm.header.t_ns);
        if self.monitor.failed.is_none() && self.monitor.update(tlm, dt_s).is_some() {
            // Reconfigure before this step's allocation.
            self.engine_set = self
                .allocator
                .pair_without(self.monitor.failed.unwrap_or(0));
        }
        let mass_kg = if nav.mass_kg > 0.0 {
            nav.mass_kg
        } else {
            self.cfg.dry_mass_kg + self.cfg.propellant_kg
        };
        self.thrust_loop.update(
            nav.t_s,
            nav.specific_force_body_m_s2.z * mass_kg,
            self.last_cmd_total_n,
        );
        let eta = self.thrust_loop.efficiency();
        let set = self.engine_set;
        let max_accel = self.allocator.max_total_n(set) * eta / mass_kg;
        let min_accel = self.allocator.min_total_n(set) * eta / mass_kg;
        // Hazard avoidance holds the hover while it waits for its map or flies its
        // divert (within half a metre of the chosen spot).
        let hold = self.hazard.enabled()
            && (self.hazard.armed()
                || (self.hazard.choice().is_some()
                    && self.guidance.site_offset_m(&nav).is_some_and(|d| d > 0.5)));
        self.guidance.set_hover_hold(hold);
        let (guid, guidance_ns) =
            self.guidance_group(&nav, tlm.header.t_ns, max_accel, min_accel, report);

        let accel = guid.accel_mci_m_s2;
        let accel_norm = accel.norm();
        let dir = if accel_norm > 1e-9 {
            accel / accel_norm
        } else {
            nav.up_mci
        };
        // Thrust along the axis the vehicle actually points: the projection keeps the
        // vertical channel right while the attitude loop catches up.
        let wanted_n = match guid.throttle_frac {
            Some(frac) => frac * self.allocator.max_total_n(set),
            None => (accel.dot(&nav.thrust_axis_mci()) * mass_kg / eta).max(0.0),
        };
        self.manage_engines(mass_kg, nav.gravity_m_s2, wanted_n, dt_s);
        let set = self.engine_set;

        let inertia = self.cfg.inertia_kg_m2(mass_kg);
        let error_body = AttitudeController::pointing_error_body(&nav, &dir);
        let torque = self
            .attitude
            .torque_for_error_body_nm(&nav, &error_body, &inertia, dt_s);
        self.pointing_error_rad = error_body.norm();
        let alloc = self.allocator.allocate(set, wanted_n, torque);
        self.last_cmd_total_n = alloc.thrust_cmd_n.iter().sum();
        self.monitor.commanded(&alloc.thrust_cmd_n, &alloc.on);

        let mut cmd = Command {
            thrust_cmd_n: alloc.thrust_cmd_n,
            engine_on: alloc.on.map(u32::from),
            torque_cmd_body_nm: alloc.rcs_torque_body_nm.into(),
            attitude_mode: ATTITUDE_MODE_IDEAL_TORQUE,
            ..Default::default()
        };
        if self.cfg.attitude_actuator == GncAttitude::Thrusters {
            // What the ideal actuator would have been given, as thruster pulses; the
            // torque field stays filled for the log (the plant ignores it in this mode).
            cmd.thruster_on_time_ns = self
                .thrusters
                .on_times_ns(&alloc.rcs_torque_body_nm, cycle_ns);
            cmd.attitude_mode = ATTITUDE_MODE_THRUSTERS;
        }
        (cmd, guidance_ns)
    }
}
