//! Scenario configuration: plain `Deserialize` structs with `Default`s taken from
//! `shared/reference/lander-and-propulsion.md`, and a `validate()` run before tick 0.
//!
//! Every number is a default, never a constant buried in code: a TOML file given with
//! `--scenario FILE` overrides any subset of fields.

use serde::{Deserialize, Deserializer, Serialize};
use thiserror::Error;

use crate::fixed_len::fixed_len;

fixed_len! {
    inertia_wet: [f64; 3] => "lander.inertia_wet_kg_m2",
    inertia_dry: [f64; 3] => "lander.inertia_dry_kg_m2",
    engine_positions: [[f64; 3]; 4] => "lander.engine_positions_body_m",
    rcs_moment_arm: [f64; 3] => "lander.rcs_moment_arm_m",
    rcs_positions: [[f64; 3]; oils_shared::THRUSTER_COUNT] => "lander.rcs_positions_body_m",
    rcs_directions: [[f64; 3]; oils_shared::THRUSTER_COUNT] => "lander.rcs_directions_body",
    com_offset: [f64; 3] => "lander.com_offset_body_m",
    engine_thrust_scale: [f64; 4] => "lander.engine_thrust_scale",
    engine_misalignment: [[f64; 2]; 4] => "lander.engine_misalignment_deg",
    footpad_positions: [[f64; 3]; 4] => "lander.footpad_positions_body_m",
    attitude_error: [f64; 3] => "initial.attitude_error_deg",
    body_rate: [f64; 3] => "initial.body_rate_rad_s",
    bias: [f64; 4] => "model_error.bias_n",
}

/// A configuration value is out of its meaningful range.
#[derive(Debug, Error, Clone, PartialEq)]
#[error("invalid configuration: {field} = {value} ({why})")]
pub struct ConfigError {
    /// Dotted path of the field.
    pub field: &'static str,
    /// The offending value, printed.
    pub value: String,
    /// What is expected.
    pub why: &'static str,
}

pub(crate) fn check(
    ok: bool,
    field: &'static str,
    value: f64,
    why: &'static str,
) -> Result<(), ConfigError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(ConfigError {
            field,
            value: value.to_string(),
            why,
        })
    }
}

/// `value` finite and in `[lo, hi]`; `why` states the bound (with its unit).
pub(crate) fn within(
    field: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    why: &'static str,
) -> Result<(), ConfigError> {
    check((lo..=hi).contains(&value), field, value, why)
}

/// `value` finite and in `(0, hi]`.
fn positive_at_most(
    field: &'static str,
    value: f64,
    hi: f64,
    why: &'static str,
) -> Result<(), ConfigError> {
    check(value > 0.0 && value <= hi, field, value, why)
}

/// The Moon: a central gravity field and a reference sphere turning about its north
/// pole (Moon-centred inertial `+Z`) at the sidereal rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MoonConfig {
    /// Gravitational parameter, m^3/s^2 (sourced).
    pub mu_m3_s2: f64,
    /// Mean radius, metres (sourced): the reference sphere terrain heights refer to.
    pub radius_m: f64,
    /// Rotation rate about the pole, rad/s (sourced: 2 pi / 27.321661 days); 0 keeps
    /// the surface fixed in the inertial frame.
    pub rotation_rate_rad_s: f64,
}

impl Default for MoonConfig {
    fn default() -> Self {
        Self {
            mu_m3_s2: 4.9028e12,
            radius_m: 1_737_400.0,
            rotation_rate_rad_s: 2.6617e-6,
        }
    }
}

impl MoonConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        positive_at_most("moon.mu_m3_s2", self.mu_m3_s2, 1e18, "in (0, 1e18] m^3/s^2")?;
        positive_at_most("moon.radius_m", self.radius_m, 1e8, "in (0, 1e8] m")?;
        check(
            self.rotation_rate_rad_s.abs() <= 1e-3,
            "moon.rotation_rate_rad_s",
            self.rotation_rate_rad_s,
            "within 1e-3 rad/s",
        )
    }
}

/// The landing site the scenario is expressed on: where the descent is aimed, and the
/// origin of the site frame (East-North-Up, Moon-fixed) the log and report use.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SiteConfig {
    /// Selenographic latitude, degrees, north positive (sourced: Chandrayaan-3,
    /// 69.373 S).
    pub latitude_deg: f64,
    /// Longitude, degrees, east positive (sourced: Chandrayaan-3, 32.319 E).
    pub longitude_deg: f64,
    /// Direction of travel over the site, degrees clockwise from north (assumed: 180,
    /// a southbound polar approach).
    pub approach_azimuth_deg: f64,
}

impl Default for SiteConfig {
    fn default() -> Self {
        Self {
            latitude_deg: -69.373,
            longitude_deg: 32.319,
            approach_azimuth_deg: 180.0,
        }
    }
}

impl SiteConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        // The poles themselves have no east or north: keep a hair away from them.
        check(
            self.latitude_deg.abs() < 89.999,
            "site.latitude_deg",
            self.latitude_deg,
            "within (-89.999, 89.999) deg",
        )?;
        within(
            "site.longitude_deg",
            self.longitude_deg,
            -360.0,
            360.0,
            "in [-360, 360] deg",
        )?;
        within(
            "site.approach_azimuth_deg",
            self.approach_azimuth_deg,
            -360.0,
            360.0,
            "in [-360, 360] deg",
        )
    }
}

/// Main propulsion numbers shared by every model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PropulsionConfig {
    /// Rated thrust of one main engine, newtons (sourced: 800 N).
    pub max_thrust_n: f64,
    /// Lowest throttle as a fraction of rated thrust (assumed 0.4).
    pub throttle_min_frac: f64,
    /// Specific impulse, seconds (assumed 310 s).
    pub isp_s: f64,
    /// Oxidiser-to-fuel mass ratio (assumed 1.65).
    pub mixture_ratio: f64,
    /// Usable main propellant at descent start, kilograms (assumed 1000 kg).
    pub propellant_kg: f64,
    /// `ideal` model: thrust time constant, seconds (assumed 50 ms).
    pub thrust_lag_s: f64,
    /// `ideal` model: constant helium bottle pressure reported, pascals.
    pub gas_pressure_pa: f64,
    /// `ideal` model: constant tank pressure reported, pascals (regulated 17 bar).
    pub tank_pressure_pa: f64,
    /// `ideal` model: chamber pressure at rated thrust, pascals (8 bar).
    pub chamber_pressure_max_pa: f64,
}

impl Default for PropulsionConfig {
    fn default() -> Self {
        Self {
            max_thrust_n: 800.0,
            throttle_min_frac: 0.4,
            isp_s: 310.0,
            mixture_ratio: 1.65,
            propellant_kg: 1000.0,
            thrust_lag_s: 0.05,
            gas_pressure_pa: 280e5,
            tank_pressure_pa: 17e5,
            chamber_pressure_max_pa: 8e5,
        }
    }
}

impl PropulsionConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive_at_most(
            "propulsion.max_thrust_n",
            self.max_thrust_n,
            1e6,
            "in (0, 1e6] N",
        )?;
        check(
            (0.0..1.0).contains(&self.throttle_min_frac),
            "propulsion.throttle_min_frac",
            self.throttle_min_frac,
            "in [0, 1)",
        )?;
        positive_at_most("propulsion.isp_s", self.isp_s, 1e4, "in (0, 1e4] s")?;
        positive_at_most(
            "propulsion.mixture_ratio",
            self.mixture_ratio,
            100.0,
            "in (0, 100]",
        )?;
        within(
            "propulsion.propellant_kg",
            self.propellant_kg,
            0.0,
            1e6,
            "in [0, 1e6] kg",
        )?;
        positive_at_most(
            "propulsion.thrust_lag_s",
            self.thrust_lag_s,
            100.0,
            "in (0, 100] s",
        )?;
        for (field, v) in [
            ("propulsion.gas_pressure_pa", self.gas_pressure_pa),
            ("propulsion.tank_pressure_pa", self.tank_pressure_pa),
            (
                "propulsion.chamber_pressure_max_pa",
                self.chamber_pressure_max_pa,
            ),
        ] {
            within(field, v, 0.0, 1e8, "in [0, 1e8] Pa (1000 bar)")?;
        }
        Ok(())
    }
}

/// The vehicle: mass properties, engine layout, attitude thrusters, legs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LanderConfig {
    /// Mass without main propellant, kilograms (1750 wet - 1000 propellant).
    pub dry_mass_kg: f64,
    /// Principal moments of inertia with full tanks, kg m^2 (assumed: a 2 m box).
    #[serde(deserialize_with = "inertia_wet")]
    pub inertia_wet_kg_m2: [f64; 3],
    /// Principal moments of inertia with empty tanks, kg m^2 (assumed).
    #[serde(deserialize_with = "inertia_dry")]
    pub inertia_dry_kg_m2: [f64; 3],
    /// Main engine positions relative to the centre of mass, body axes, metres; each
    /// engine thrusts along +Z body through its position.
    #[serde(deserialize_with = "engine_positions")]
    pub engine_positions_body_m: [[f64; 3]; 4],
    /// Thrust of one attitude thruster, newtons (sourced: 8 x 58 N).
    pub rcs_thrust_n: f64,
    /// Moment arm of the thruster couples about body x, y, z, metres (assumed); each
    /// axis is served by a pair, so the saturation torque is 2 x thrust x arm.
    #[serde(deserialize_with = "rcs_moment_arm")]
    pub rcs_moment_arm_m: [f64; 3],
    /// Attitude thruster specific impulse, seconds (assumed).
    pub rcs_isp_s: f64,
    /// Attitude thruster positions relative to the design centre of mass, body axes,
    /// metres (assumed: four pods of two at the corners of a 2 m square at the centre
    /// of mass's height; see `docs/plant.md`, "Attitude thrusters"). Used when the
    /// flight software commands on-times (`ATTITUDE_MODE_THRUSTERS`); moment arms are
    /// measured from the true centre of mass.
    #[serde(deserialize_with = "rcs_positions")]
    pub rcs_positions_body_m: [[f64; 3]; oils_shared::THRUSTER_COUNT],
    /// Attitude thruster directions: the unit vector of the force each applies to the
    /// vehicle (opposite its exhaust), body axes (assumed, with the positions).
    #[serde(deserialize_with = "rcs_directions")]
    pub rcs_directions_body: [[f64; 3]; oils_shared::THRUSTER_COUNT],
    /// Shortest on-time an attitude thruster fires; a shorter one (not zero) is not
    /// fired, seconds (assumed: the minimum impulse bit's ~10-20 ms).
    pub rcs_min_on_time_s: f64,
    /// Attitude thruster valve opening delay, from the command to the valve open,
    /// seconds (assumed: ~5 ms).
    pub rcs_open_delay_s: f64,
    /// Attitude thruster valve closing delay, from the end of the command to the valve
    /// closed, seconds (assumed: ~5 ms).
    pub rcs_close_delay_s: f64,
    /// Time constant of an attitude thruster's first-order thrust rise and tail,
    /// seconds (assumed; 0 = thrust follows the valve at once).
    pub rcs_time_constant_s: f64,
    /// Footpad centres relative to the centre of mass, body axes, metres (assumed: a
    /// 3.6 m square footprint, 1.2 m below the centre of mass). Their mean height
    /// below the centre of mass is the altitude reference ([`Self::leg_height_m`]).
    #[serde(deserialize_with = "footpad_positions")]
    pub footpad_positions_body_m: [[f64; 3]; 4],
    /// Stiffness of one leg's elastic part (structure and footpad, in series with the
    /// crushable strut), N/m (assumed: stiff, 0.35 mm under a quarter of the ~855 kg
    /// landed weight, 6 mm at the crush load).
    pub leg_stiffness_n_m: f64,
    /// Damping of one leg's elastic part, N s/m (assumed: over critical for a quarter
    /// of the vehicle's mass, so the elastic part unloading from the crush load does
    /// not throw the pads off the ground: a contact cannot pull, and below ~5e4 N s/m
    /// the default vehicle hops a fraction of a millimetre).
    pub leg_damping_n_s_m: f64,
    /// Load at which one leg's strut crushes (honeycomb, constant load), newtons
    /// (assumed: sized so a drop at the vertical limit uses 2/3 of the stroke at the
    /// wet mass; see `docs/plant.md`).
    pub leg_crush_load_n: f64,
    /// Crushable length of one leg's strut, metres (assumed; see `docs/plant.md`).
    pub leg_stroke_m: f64,
    /// Coulomb friction coefficient of a footpad on regolith (assumed).
    pub footpad_friction: f64,
    /// Offset of the true centre of mass from the design one, body axes, metres (a
    /// dispersion; the flight software does not know it). Engine moment arms are
    /// measured from the true centre.
    #[serde(deserialize_with = "com_offset")]
    pub com_offset_body_m: [f64; 3],
    /// Delivered thrust of each engine over what its propulsion model computes, at the
    /// same propellant flow (a thrust-coefficient or alignment loss; 1 = as modelled).
    #[serde(deserialize_with = "engine_thrust_scale")]
    pub engine_thrust_scale: [f64; 4],
    /// Misalignment of each engine's thrust axis from body +Z, degrees: rotation about
    /// body X, then about body Y (a dispersion; 0 = aligned).
    #[serde(deserialize_with = "engine_misalignment")]
    pub engine_misalignment_deg: [[f64; 2]; 4],
}

/// Default attitude thruster positions (assumed): pods A (+1, +1), B (+1, -1),
/// C (-1, -1), D (-1, +1) at the centre of mass's height, two thrusters each.
const RCS_POSITIONS_BODY_M: [[f64; 3]; oils_shared::THRUSTER_COUNT] = [
    [1.0, 1.0, 0.0],
    [1.0, 1.0, 0.0],
    [1.0, -1.0, 0.0],
    [1.0, -1.0, 0.0],
    [-1.0, -1.0, 0.0],
    [-1.0, -1.0, 0.0],
    [-1.0, 1.0, 0.0],
    [-1.0, 1.0, 0.0],
];

/// Default attitude thruster directions (assumed): per pod one along body Z (A and C
/// +Z, B and D -Z) and one tangential (A and C counter-clockwise about +Z, B and D
/// clockwise). Pure couples: +x (0, 2), -x (4, 6), +y (4, 2), -y (0, 6), +z (1, 5),
/// -z (3, 7).
const RCS_DIRECTIONS_BODY: [[f64; 3]; oils_shared::THRUSTER_COUNT] = {
    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;
    [
        [0.0, 0.0, 1.0],
        [-H, H, 0.0],
        [0.0, 0.0, -1.0],
        [-H, -H, 0.0],
        [0.0, 0.0, 1.0],
        [H, -H, 0.0],
        [0.0, 0.0, -1.0],
        [H, H, 0.0],
    ]
};

impl Default for LanderConfig {
    fn default() -> Self {
        Self {
            dry_mass_kg: 750.0,
            inertia_wet_kg_m2: [1200.0, 1200.0, 1100.0],
            inertia_dry_kg_m2: [700.0, 700.0, 600.0],
            engine_positions_body_m: [
                [0.6, 0.6, -0.8],
                [-0.6, 0.6, -0.8],
                [-0.6, -0.6, -0.8],
                [0.6, -0.6, -0.8],
            ],
            rcs_thrust_n: 58.0,
            rcs_moment_arm_m: [1.0, 1.0, 1.0],
            rcs_isp_s: 220.0,
            rcs_positions_body_m: RCS_POSITIONS_BODY_M,
            rcs_directions_body: RCS_DIRECTIONS_BODY,
            rcs_min_on_time_s: 0.010,
            rcs_open_delay_s: 0.005,
            rcs_close_delay_s: 0.005,
            rcs_time_constant_s: 0.003,
            footpad_positions_body_m: [
                [1.8, 0.0, -1.2],
                [0.0, 1.8, -1.2],
                [-1.8, 0.0, -1.2],
                [0.0, -1.8, -1.2],
            ],
            leg_stiffness_n_m: 1.0e6,
            leg_damping_n_s_m: 6.0e4,
            leg_crush_load_n: 6000.0,
            leg_stroke_m: 0.25,
            footpad_friction: 0.6,
            com_offset_body_m: [0.0; 3],
            engine_thrust_scale: [1.0; 4],
            engine_misalignment_deg: [[0.0; 2]; 4],
        }
    }
}

impl LanderConfig {
    /// Saturation torque of the attitude thrusters per body axis, N m.
    pub fn rcs_max_torque_nm(&self) -> [f64; 3] {
        self.rcs_moment_arm_m
            .map(|arm| 2.0 * self.rcs_thrust_n * arm)
    }

    /// Height of the centre of mass above the footpads (their mean), metres: the
    /// altitude telemetry reports is the footpads' height above the ground below.
    pub fn leg_height_m(&self) -> f64 {
        -self
            .footpad_positions_body_m
            .iter()
            .map(|p| p[2])
            .sum::<f64>()
            / 4.0
    }

    fn validate(&self) -> Result<(), ConfigError> {
        positive_at_most(
            "lander.dry_mass_kg",
            self.dry_mass_kg,
            1e6,
            "in (0, 1e6] kg",
        )?;
        for i in 0..3 {
            positive_at_most(
                "lander.inertia_wet_kg_m2",
                self.inertia_wet_kg_m2[i],
                1e9,
                "in (0, 1e9] kg m^2",
            )?;
            positive_at_most(
                "lander.inertia_dry_kg_m2",
                self.inertia_dry_kg_m2[i],
                1e9,
                "in (0, 1e9] kg m^2",
            )?;
            positive_at_most(
                "lander.rcs_moment_arm_m",
                self.rcs_moment_arm_m[i],
                100.0,
                "in (0, 100] m",
            )?;
        }
        for p in self.engine_positions_body_m.iter().flatten() {
            within(
                "lander.engine_positions_body_m",
                *p,
                -100.0,
                100.0,
                "in [-100, 100] m",
            )?;
        }
        within(
            "lander.rcs_thrust_n",
            self.rcs_thrust_n,
            0.0,
            1e5,
            "in [0, 1e5] N",
        )?;
        positive_at_most("lander.rcs_isp_s", self.rcs_isp_s, 1e4, "in (0, 1e4] s")?;
        for c in self.rcs_positions_body_m.iter().flatten() {
            within(
                "lander.rcs_positions_body_m",
                *c,
                -100.0,
                100.0,
                "in [-100, 100] m",
            )?;
        }
        for d in &self.rcs_directions_body {
            for c in d {
                check(
                    c.is_finite(),
                    "lander.rcs_directions_body",
                    *c,
                    "finite components",
                )?;
            }
            let norm = d.iter().map(|c| c * c).sum::<f64>().sqrt();
            check(
                (norm - 1.0).abs() <= 1e-6,
                "lander.rcs_directions_body",
                norm,
                "unit vectors (norm within 1e-6 of 1)",
            )?;
        }
        within(
            "lander.rcs_min_on_time_s",
            self.rcs_min_on_time_s,
            0.0,
            1.0,
            "in [0, 1] s",
        )?;
        within(
            "lander.rcs_open_delay_s",
            self.rcs_open_delay_s,
            0.0,
            0.1,
            "in [0, 0.1] s",
        )?;
        within(
            "lander.rcs_close_delay_s",
            self.rcs_close_delay_s,
            0.0,
            0.1,
            "in [0, 0.1] s",
        )?;
        within(
            "lander.rcs_time_constant_s",
            self.rcs_time_constant_s,
            0.0,
            0.1,
            "in [0, 0.1] s",
        )?;
        for p in &self.footpad_positions_body_m {
            for c in p {
                within(
                    "lander.footpad_positions_body_m",
                    *c,
                    -100.0,
                    100.0,
                    "in [-100, 100] m",
                )?;
            }
            check(
                p[2] < 0.0,
                "lander.footpad_positions_body_m",
                p[2],
                "each footpad below the centre of mass (z < 0)",
            )?;
        }
        positive_at_most(
            "lander.leg_stiffness_n_m",
            self.leg_stiffness_n_m,
            1e9,
            "in (0, 1e9] N/m",
        )?;
        within(
            "lander.leg_damping_n_s_m",
            self.leg_damping_n_s_m,
            0.0,
            1e8,
            "in [0, 1e8] N s/m",
        )?;
        positive_at_most(
            "lander.leg_crush_load_n",
            self.leg_crush_load_n,
            1e8,
            "in (0, 1e8] N",
        )?;
        within(
            "lander.leg_stroke_m",
            self.leg_stroke_m,
            0.0,
            10.0,
            "in [0, 10] m",
        )?;
        within(
            "lander.footpad_friction",
            self.footpad_friction,
            0.0,
            5.0,
            "in [0, 5]",
        )?;
        for c in self.com_offset_body_m {
            check(c.abs() <= 1.0, "lander.com_offset_body_m", c, "within 1 m")?;
        }
        for k in self.engine_thrust_scale {
            check(
                (0.5..=1.5).contains(&k),
                "lander.engine_thrust_scale",
                k,
                "in [0.5, 1.5]",
            )?;
        }
        for a in self.engine_misalignment_deg.iter().flatten() {
            check(
                a.abs() <= 10.0,
                "lander.engine_misalignment_deg",
                *a,
                "within 10 deg",
            )?;
        }
        Ok(())
    }
}

/// Where the powered descent starts (default: Chandrayaan-3-like).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitialStateConfig {
    /// Surface arc from the start, back along the approach track, to the site, metres
    /// (assumed: where the reference descent's nominal touchdown falls on the site).
    pub range_to_site_m: f64,
    /// Altitude of the footpads above the reference sphere, metres (sourced: ~30 km).
    pub altitude_m: f64,
    /// Horizontal speed relative to the surface, along the track, m/s (sourced:
    /// ~1.68 km/s).
    pub horizontal_speed_m_s: f64,
    /// Vertical speed relative to the surface, m/s, positive up.
    pub vertical_speed_m_s: f64,
    /// Pitch of the thrust axis above the retrograde horizontal, degrees (0: thrust
    /// exactly against the horizontal velocity).
    pub thrust_pitch_deg: f64,
    /// Start moved along the ground track, metres of surface arc (a dispersion).
    pub downrange_m: f64,
    /// Start moved across the ground track (towards the orbit normal), metres of
    /// surface arc (a dispersion).
    pub crossrange_m: f64,
    /// Velocity across the ground track (along the orbit normal), m/s.
    pub crossrange_speed_m_s: f64,
    /// Attitude error: rotation of the body from its nominal start attitude about body
    /// X, Y, Z, degrees (applied in that order).
    #[serde(deserialize_with = "attitude_error")]
    pub attitude_error_deg: [f64; 3],
    /// Body rates at the start, rad/s.
    #[serde(deserialize_with = "body_rate")]
    pub body_rate_rad_s: [f64; 3],
}

impl Default for InitialStateConfig {
    fn default() -> Self {
        Self {
            range_to_site_m: DEFAULT_RANGE_TO_SITE_M,
            altitude_m: 30_000.0,
            horizontal_speed_m_s: 1680.0,
            vertical_speed_m_s: 0.0,
            thrust_pitch_deg: 0.0,
            downrange_m: 0.0,
            crossrange_m: 0.0,
            crossrange_speed_m_s: 0.0,
            attitude_error_deg: [0.0; 3],
            body_rate_rad_s: [0.0; 3],
        }
    }
}

/// Where the default start sits before the site: the surface arc the reference descent
/// covers from its start to its nominal touchdown (measured on the default scenario,
/// `emulator/tests/plant_physics.rs` checks the landing falls near the site).
pub const DEFAULT_RANGE_TO_SITE_M: f64 = 704_550.0;

impl InitialStateConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        within(
            "initial.range_to_site_m",
            self.range_to_site_m,
            0.0,
            5e6,
            "in [0, 5000] km",
        )?;
        positive_at_most("initial.altitude_m", self.altitude_m, 1e7, "in (0, 1e7] m")?;
        within(
            "initial.horizontal_speed_m_s",
            self.horizontal_speed_m_s,
            -1e4,
            1e4,
            "in [-1e4, 1e4] m/s",
        )?;
        within(
            "initial.vertical_speed_m_s",
            self.vertical_speed_m_s,
            -1e4,
            1e4,
            "in [-1e4, 1e4] m/s",
        )?;
        check(
            self.thrust_pitch_deg.abs() <= 90.0,
            "initial.thrust_pitch_deg",
            self.thrust_pitch_deg,
            "in [-90, 90]",
        )?;
        check(
            self.downrange_m.abs() <= 1e6,
            "initial.downrange_m",
            self.downrange_m,
            "within 1000 km",
        )?;
        check(
            self.crossrange_m.abs() <= 1e6,
            "initial.crossrange_m",
            self.crossrange_m,
            "within 1000 km",
        )?;
        check(
            self.crossrange_speed_m_s.abs() <= 1e3,
            "initial.crossrange_speed_m_s",
            self.crossrange_speed_m_s,
            "within 1 km/s",
        )?;
        for a in self.attitude_error_deg {
            check(
                a.abs() <= 90.0,
                "initial.attitude_error_deg",
                a,
                "within 90 deg",
            )?;
        }
        for w in self.body_rate_rad_s {
            check(
                w.abs() <= 1.0,
                "initial.body_rate_rad_s",
                w,
                "within 1 rad/s",
            )?;
        }
        Ok(())
    }
}

/// The ground's orbit determination uplinked to the flight software before the descent
/// (and again after a computer reset): the true position and velocity plus a seeded
/// Gaussian error of these one-sigma sizes per `mci` axis, sent in `nav` on the first
/// cycle with `TLM_FLAG_STATE_VECTOR` when the devices are on. Defaults assumed: a few
/// hundred metres and decimetres per second is the usual class of a lunar-orbit
/// determination from ground tracking; `docs/sensors.md`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StateVectorConfig {
    /// Position error, metres (1-sigma per axis).
    pub position_sigma_m: f64,
    /// Velocity error, m/s (1-sigma per axis).
    pub velocity_sigma_m_s: f64,
}

impl Default for StateVectorConfig {
    fn default() -> Self {
        Self {
            position_sigma_m: 200.0,
            velocity_sigma_m_s: 0.5,
        }
    }
}

impl StateVectorConfig {
    /// At the defaults (omitted when a configuration is written).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// Finite, not negative, and not absurd.
    pub fn validate(&self) -> Result<(), ConfigError> {
        within(
            "state_vector.position_sigma_m",
            self.position_sigma_m,
            0.0,
            1e5,
            "in [0, 1e5] m",
        )?;
        within(
            "state_vector.velocity_sigma_m_s",
            self.velocity_sigma_m_s,
            0.0,
            100.0,
            "in [0, 100] m/s",
        )
    }
}

/// One-sigma navigation noise added to telemetry when enabled (seeded).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NavNoiseConfig {
    /// Add noise at all.
    pub enabled: bool,
    /// Position noise, metres.
    pub position_m: f64,
    /// Velocity noise, m/s.
    pub velocity_m_s: f64,
    /// Body rate noise, rad/s.
    pub rate_rad_s: f64,
    /// Accelerometer noise, m/s^2.
    pub accel_m_s2: f64,
    /// Altimeter noise, metres.
    pub altitude_m: f64,
}

impl Default for NavNoiseConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            position_m: 5.0,
            velocity_m_s: 0.05,
            rate_rad_s: 1e-4,
            accel_m_s2: 1e-3,
            altitude_m: 0.5,
        }
    }
}

impl NavNoiseConfig {
    /// Checks every sigma: finite, not negative, and below a size that would make the
    /// telemetry meaningless (checked whether or not the noise is enabled).
    pub fn validate(&self) -> Result<(), ConfigError> {
        within(
            "nav_noise.position_m",
            self.position_m,
            0.0,
            1e4,
            "in [0, 1e4] m",
        )?;
        within(
            "nav_noise.velocity_m_s",
            self.velocity_m_s,
            0.0,
            100.0,
            "in [0, 100] m/s",
        )?;
        within(
            "nav_noise.rate_rad_s",
            self.rate_rad_s,
            0.0,
            1.0,
            "in [0, 1] rad/s",
        )?;
        within(
            "nav_noise.accel_m_s2",
            self.accel_m_s2,
            0.0,
            100.0,
            "in [0, 100] m/s^2",
        )?;
        within(
            "nav_noise.altitude_m",
            self.altitude_m,
            0.0,
            1e4,
            "in [0, 1e4] m",
        )?;
        Ok(())
    }
}

/// What counts as a safe landing: the contact speeds (sourced design limits), the
/// margin the tilt and slope limits are derived with from the legs
/// ([`crate::plant::legs::LandingLimits`]), the slide allowed, and when the vehicle is
/// at rest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TouchdownLimits {
    /// Largest vertical speed, m/s.
    pub vertical_speed_mps: f64,
    /// Largest horizontal speed, m/s.
    pub horizontal_speed_mps: f64,
    /// At rest the centre of mass may be at most `1 / stability_factor` of the way to
    /// the footprint's nearest edge: the tilt limit is `atan(tan(tip-over) / factor)`,
    /// the slope limit that less what the legs can tilt (assumed: 3).
    pub stability_factor: f64,
    /// A footpad that slipped farther than this along the ground after first contact
    /// makes the landing `slid`, metres (assumed: 0.5 m, a footpad's size).
    pub slide_limit_m: f64,
    /// At rest: every footpad's speed over the ground below this, m/s (assumed).
    pub rest_speed_m_s: f64,
    /// ... held this long, seconds (assumed).
    pub rest_hold_s: f64,
    /// The run ends this long after first contact even if the vehicle is still
    /// moving; it is then judged as it is, seconds (assumed).
    pub settle_timeout_s: f64,
}

impl Default for TouchdownLimits {
    fn default() -> Self {
        Self {
            vertical_speed_mps: 2.0,
            horizontal_speed_mps: 0.5,
            stability_factor: 3.0,
            slide_limit_m: 0.5,
            rest_speed_m_s: 0.01,
            rest_hold_s: 0.5,
            settle_timeout_s: 20.0,
        }
    }
}

impl TouchdownLimits {
    /// Checks every limit: finite and positive (a NaN limit would call every landing a
    /// crash).
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive_at_most(
            "touchdown.vertical_speed_mps",
            self.vertical_speed_mps,
            100.0,
            "in (0, 100] m/s",
        )?;
        positive_at_most(
            "touchdown.horizontal_speed_mps",
            self.horizontal_speed_mps,
            100.0,
            "in (0, 100] m/s",
        )?;
        within(
            "touchdown.stability_factor",
            self.stability_factor,
            1.0,
            100.0,
            "in [1, 100]",
        )?;
        positive_at_most(
            "touchdown.slide_limit_m",
            self.slide_limit_m,
            1e4,
            "in (0, 1e4] m",
        )?;
        positive_at_most(
            "touchdown.rest_speed_m_s",
            self.rest_speed_m_s,
            10.0,
            "in (0, 10] m/s",
        )?;
        within(
            "touchdown.rest_hold_s",
            self.rest_hold_s,
            0.0,
            100.0,
            "in [0, 100] s",
        )?;
        positive_at_most(
            "touchdown.settle_timeout_s",
            self.settle_timeout_s,
            3600.0,
            "in (0, 3600] s",
        )?;
        Ok(())
    }
}

/// Everything the plant needs.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ScenarioConfig {
    /// Central body.
    pub moon: MoonConfig,
    /// Landing site: the scenario's origin.
    pub site: SiteConfig,
    /// Terrain about the site (default: the bare sphere).
    pub terrain: crate::world::terrain::TerrainSpec,
    /// The sun at the site: an epoch or a direction (`docs/world.md`; default: the
    /// Chandrayaan-3 landing epoch).
    #[serde(skip_serializing_if = "crate::world::sun::SunSpec::is_default")]
    pub sun: crate::world::sun::SunSpec,
    /// Vehicle.
    pub lander: LanderConfig,
    /// Main propulsion.
    pub propulsion: PropulsionConfig,
    /// Initial state.
    pub initial: InitialStateConfig,
    /// Navigation noise.
    pub nav_noise: NavNoiseConfig,
    /// The ground's state vector a `sensors` run starts the flight software from.
    #[serde(skip_serializing_if = "StateVectorConfig::is_default")]
    pub state_vector: StateVectorConfig,
    /// Touchdown limits.
    pub touchdown: TouchdownLimits,
    /// Injected propulsion model error (the seed paper's Monte Carlo use of the
    /// surrogate's validated error); off by default.
    pub model_error: ModelErrorConfig,
    /// The devices on board: IMU, star tracker, altimeters, velocimeter
    /// (`docs/sensors.md`).
    pub sensors: crate::sensors::SensorsConfig,
}

/// A seeded per-engine thrust error added to what the propulsion model delivers: how a
/// Monte Carlo feeds the surrogate's validated error back in as model uncertainty (seed
/// paper, Section VI). Each firing engine gets `bias_n` (the steady error, drawn once
/// per case) plus a transient error: at an engine start or a command step larger than
/// `step_threshold_n`, an amplitude is drawn from N(`transient_mean_n`,
/// `transient_std_n`) clipped to +-`transient_max_abs_n`, and decays with
/// `transient_tau_s`. Delivered thrust never goes below zero; propellant flow is the
/// model's (the error is in thrust, as validated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ModelErrorConfig {
    /// Inject at all.
    pub enabled: bool,
    /// Steady thrust error of each engine, newtons.
    #[serde(deserialize_with = "bias")]
    pub bias_n: [f64; 4],
    /// Mean of a transient's starting error, newtons.
    pub transient_mean_n: f64,
    /// Standard deviation of a transient's starting error, newtons.
    pub transient_std_n: f64,
    /// Largest transient error, newtons.
    pub transient_max_abs_n: f64,
    /// Decay time of a transient error, seconds.
    pub transient_tau_s: f64,
    /// Command change within one step that starts a transient, newtons.
    pub step_threshold_n: f64,
    /// Seed of the transient draws.
    pub seed: u64,
}

impl Default for ModelErrorConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            bias_n: [0.0; 4],
            transient_mean_n: 0.0,
            transient_std_n: 0.0,
            transient_max_abs_n: 0.0,
            transient_tau_s: 0.2,
            step_threshold_n: 40.0,
            seed: 0,
        }
    }
}

impl ModelErrorConfig {
    fn validate(&self) -> Result<(), ConfigError> {
        for b in self.bias_n {
            check(b.abs() <= 200.0, "model_error.bias_n", b, "within 200 N")?;
        }
        check(
            self.transient_mean_n.abs() <= 200.0,
            "model_error.transient_mean_n",
            self.transient_mean_n,
            "within 200 N",
        )?;
        check(
            (0.0..=200.0).contains(&self.transient_std_n),
            "model_error.transient_std_n",
            self.transient_std_n,
            "in [0, 200] N",
        )?;
        check(
            (0.0..=800.0).contains(&self.transient_max_abs_n),
            "model_error.transient_max_abs_n",
            self.transient_max_abs_n,
            "in [0, 800] N",
        )?;
        check(
            self.transient_tau_s > 0.0 && self.transient_tau_s <= 100.0,
            "model_error.transient_tau_s",
            self.transient_tau_s,
            "in (0, 100] s",
        )?;
        check(
            self.step_threshold_n > 0.0,
            "model_error.step_threshold_n",
            self.step_threshold_n,
            "> 0",
        )?;
        Ok(())
    }
}

impl ScenarioConfig {
    /// Checks every field; run before tick 0.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.moon.validate()?;
        self.site.validate()?;
        if let Err(e) = self.terrain.validate() {
            return Err(ConfigError {
                field: "terrain",
                value: e.to_string(),
                why: "see docs/terrain.md",
            });
        }
        if let Err(e) = self.sun.validate() {
            return Err(ConfigError {
                field: "sun",
                value: e.to_string(),
                why: "see docs/world.md",
            });
        }
        self.lander.validate()?;
        self.propulsion.validate()?;
        self.initial.validate()?;
        self.model_error.validate()?;
        self.nav_noise.validate()?;
        self.state_vector.validate()?;
        self.touchdown.validate()?;
        let limits = self.landing_limits();
        check(
            limits.slope_deg > 0.0,
            "touchdown.stability_factor",
            self.touchdown.stability_factor,
            "leaves a tilt limit above what the legs' stroke can tilt the body (a derived \
             slope limit above 0 deg): lower the factor or the stroke",
        )?;
        self.sensors.validate()?;
        Ok(())
    }

    /// The tilt and slope limits the legs allow with `touchdown.stability_factor`.
    pub fn landing_limits(&self) -> crate::plant::legs::LandingLimits {
        crate::plant::legs::landing_limits(&self.lander, self.touchdown.stability_factor)
    }

    /// Wet mass at descent start, kilograms.
    pub fn wet_mass_kg(&self) -> f64 {
        self.lander.dry_mass_kg + self.propulsion.propellant_kg
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_match_reference() {
        let c = ScenarioConfig::default();
        c.validate().unwrap();
        assert!((c.wet_mass_kg() - 1750.0).abs() < 1.0);
    }

    #[test]
    fn partial_toml_overrides_and_unknown_fields_fail() {
        let c: ScenarioConfig = toml::from_str("[initial]\naltitude_m = 1000.0\n").unwrap();
        assert_eq!(c.initial.altitude_m, 1000.0);
        assert_eq!(c.lander, LanderConfig::default());
        assert!(toml::from_str::<ScenarioConfig>("[initial]\naltitude = 1.0\n").is_err());
    }

    #[test]
    fn bad_values_are_named() {
        let mut c = ScenarioConfig::default();
        c.propulsion.isp_s = f64::NAN;
        let e = c.validate().unwrap_err();
        assert_eq!(e.field, "propulsion.isp_s");
    }

    /// Issue #24: `[nav_noise] position_m = nan` and `[touchdown] vertical_speed_mps =
    /// nan` were accepted (every command rejected, a perfect landing called a crash).
    #[test]
    fn every_field_is_checked_finite_and_in_range() {
        type Set = fn(&mut ScenarioConfig, f64);
        let fields: &[(&str, Set)] = &[
            ("nav_noise.position_m", |c, v| c.nav_noise.position_m = v),
            ("nav_noise.velocity_m_s", |c, v| {
                c.nav_noise.velocity_m_s = v
            }),
            ("nav_noise.rate_rad_s", |c, v| c.nav_noise.rate_rad_s = v),
            ("nav_noise.accel_m_s2", |c, v| c.nav_noise.accel_m_s2 = v),
            ("nav_noise.altitude_m", |c, v| c.nav_noise.altitude_m = v),
            ("touchdown.vertical_speed_mps", |c, v| {
                c.touchdown.vertical_speed_mps = v
            }),
            ("touchdown.horizontal_speed_mps", |c, v| {
                c.touchdown.horizontal_speed_mps = v
            }),
            ("touchdown.stability_factor", |c, v| {
                c.touchdown.stability_factor = v
            }),
            ("touchdown.slide_limit_m", |c, v| {
                c.touchdown.slide_limit_m = v
            }),
            ("lander.leg_crush_load_n", |c, v| {
                c.lander.leg_crush_load_n = v
            }),
            ("lander.leg_stroke_m", |c, v| c.lander.leg_stroke_m = v),
            ("propulsion.gas_pressure_pa", |c, v| {
                c.propulsion.gas_pressure_pa = v
            }),
            ("propulsion.tank_pressure_pa", |c, v| {
                c.propulsion.tank_pressure_pa = v
            }),
            ("propulsion.chamber_pressure_max_pa", |c, v| {
                c.propulsion.chamber_pressure_max_pa = v
            }),
            ("propulsion.max_thrust_n", |c, v| {
                c.propulsion.max_thrust_n = v
            }),
            ("propulsion.propellant_kg", |c, v| {
                c.propulsion.propellant_kg = v
            }),
            ("moon.mu_m3_s2", |c, v| c.moon.mu_m3_s2 = v),
            ("moon.radius_m", |c, v| c.moon.radius_m = v),
            ("lander.dry_mass_kg", |c, v| c.lander.dry_mass_kg = v),
            ("lander.rcs_thrust_n", |c, v| c.lander.rcs_thrust_n = v),
            ("lander.rcs_min_on_time_s", |c, v| {
                c.lander.rcs_min_on_time_s = v
            }),
            ("lander.rcs_open_delay_s", |c, v| {
                c.lander.rcs_open_delay_s = v
            }),
            ("lander.rcs_close_delay_s", |c, v| {
                c.lander.rcs_close_delay_s = v
            }),
            ("lander.rcs_time_constant_s", |c, v| {
                c.lander.rcs_time_constant_s = v
            }),
            ("lander.rcs_positions_body_m", |c, v| {
                c.lander.rcs_positions_body_m[3][1] = v
            }),
            ("lander.rcs_directions_body", |c, v| {
                c.lander.rcs_directions_body[6][0] = v
            }),
            ("initial.altitude_m", |c, v| c.initial.altitude_m = v),
            ("initial.horizontal_speed_m_s", |c, v| {
                c.initial.horizontal_speed_m_s = v
            }),
            ("initial.vertical_speed_m_s", |c, v| {
                c.initial.vertical_speed_m_s = v
            }),
        ];
        for (field, set) in fields {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, -1e300] {
                let mut c = ScenarioConfig::default();
                set(&mut c, bad);
                let e = c
                    .validate()
                    .expect_err(&format!("{field} = {bad} was accepted"));
                assert_eq!(e.field, *field, "{e}");
                assert!(!e.why.is_empty(), "{e}");
            }
        }
    }

    /// Issue #36: a fifth `engine_thrust_scale` element, even `"x"`, was dropped
    /// silently (a short array was refused). Every fixed-size array, nested ones at
    /// each level, now refuses another length by name.
    #[test]
    fn arrays_of_another_length_are_refused_by_name() {
        for (table, key, len, want) in [
            ("lander", "engine_thrust_scale", 4, 4),
            ("lander", "inertia_wet_kg_m2", 3, 3),
            ("lander", "inertia_dry_kg_m2", 3, 3),
            ("lander", "rcs_moment_arm_m", 3, 3),
            ("lander", "com_offset_body_m", 3, 3),
            ("initial", "attitude_error_deg", 3, 3),
            ("initial", "body_rate_rad_s", 3, 3),
            ("model_error", "bias_n", 4, 4),
        ] {
            let ones = vec!["0.0"; len].join(", ");
            let ok = format!("[{table}]\n{key} = [{ones}]\n");
            toml::from_str::<ScenarioConfig>(&ok).unwrap_or_else(|e| panic!("{ok}: {e}"));
            for extra in [", \"x\"", ", 1.0", ", 1.0, 1.0"] {
                let text = format!("[{table}]\n{key} = [{ones}{extra}]\n");
                let e = toml::from_str::<ScenarioConfig>(&text)
                    .unwrap_err()
                    .to_string();
                let got = len + extra.matches(',').count();
                assert!(
                    e.contains(&format!(
                        "`{table}.{key}` has {got} elements, expected {want}"
                    )),
                    "{text}: {e}"
                );
            }
        }
        let e = toml::from_str::<ScenarioConfig>(
            "[lander]\nengine_positions_body_m = [[0.6, 0.6, -0.8], [0.6, 0.6, -0.8], [0.6, 0.6, -0.8], [0.6, 0.6, -0.8, 9.0]]\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`lander.engine_positions_body_m` has 4 elements, expected 3"),
            "{e}"
        );
        let e = toml::from_str::<ScenarioConfig>(
            "[lander]\nrcs_directions_body = [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`lander.rcs_directions_body` has 7 elements, expected 8"),
            "{e}"
        );
        let e = toml::from_str::<ScenarioConfig>(
            "[lander]\nengine_misalignment_deg = [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]\n",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("`lander.engine_misalignment_deg` has 5 elements, expected 4"),
            "{e}"
        );
    }

    #[test]
    fn a_nan_in_a_scenario_file_is_refused_by_name() {
        let c: ScenarioConfig = toml::from_str("[nav_noise]\nposition_m = nan\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(
            e.contains("nav_noise.position_m") && e.contains("NaN"),
            "{e}"
        );
        let c: ScenarioConfig = toml::from_str("[touchdown]\nvertical_speed_mps = nan\n").unwrap();
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("touchdown.vertical_speed_mps"), "{e}");
    }
}

#[cfg(test)]
mod file_tests {
    use super::*;

    #[test]
    fn committed_scenario_file_equals_the_defaults() {
        let text = include_str!("../config/scenario.toml");
        let from_file: ScenarioConfig = toml::from_str(text).expect("config/scenario.toml parses");
        assert_eq!(from_file, ScenarioConfig::default());
    }
}
