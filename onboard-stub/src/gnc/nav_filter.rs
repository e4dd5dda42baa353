//! Navigation from the sensors (issue #34 item 1): an error-state Kalman filter (ESKF).
//!
//! Nominal state: position and velocity (`mci`), attitude `q_mci_from_body`, gyro bias
//! (rad/s) and accelerometer bias (m/s^2), propagated by strapdown with every IMU
//! increment. Error state (15): `[δr, δv, δθ (body), δb_g, δb_a]`, covariance 15x15.
//! Updates: star tracker (attitude), laser and RF altimeters (slant range along the beam
//! to a locally flat ground), velocimeter beams (line-of-sight velocity relative to the
//! turning ground). Each measurement channel has a chi-square gate that rejects a spike
//! but re-accepts a sustained, self-consistent offset after `reaccept_after` samples.
//!
//! The step is pure and allocation-free: fixed-size nalgebra types and fixed arrays only.
//! Equations, models and the gating rule: `docs/gnc.md`, "Navigation filter".

use nalgebra::{Matrix3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3};
use oils_shared::{AltimeterSample, Telemetry, VELOCIMETER_BEAMS};

pub use super::covariance::N;
use super::covariance::{self, Mat, Row, Transition, I_BA, I_BG, I_R, I_TH, I_V};

/// Nominal states kept for delayed measurements (one per IMU sample: 64 x 5 ms = 320 ms).
const HISTORY: usize = 64;
/// Rejected innovations kept per channel for the consistency test.
const GATE_WINDOW: usize = 16;

const ARCSEC: f64 = std::f64::consts::PI / (180.0 * 3600.0);
const UG: f64 = 9.806_65e-6;

/// Everything the filter assumes: the Moon, the devices (defaults = `docs/sensors.md`),
/// the gating rule and the initial uncertainty. Plain numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct NavFilterConfig {
    /// Moon gravitational parameter, m^3/s^2 (central gravity).
    pub mu_m3_s2: f64,
    /// Moon mean radius, m: the reference sphere.
    pub moon_radius_m: f64,
    /// Moon rotation rate about `mci` +Z, rad/s.
    pub rotation_rate_rad_s: f64,
    /// Terrain height above the sphere assumed under the vehicle, m (0: the sphere).
    pub terrain_height_m: f64,
    /// Gyro angle random walk, rad/sqrt(s).
    pub gyro_arw_rad_rt_s: f64,
    /// Accelerometer velocity random walk, m/s/sqrt(s).
    pub accel_vrw_m_s_rt_s: f64,
    /// Gyro bias random walk driving noise, rad/s/sqrt(s).
    pub gyro_bias_rw: f64,
    /// Accelerometer bias random walk driving noise, m/s^2/sqrt(s) (also covers the
    /// unmodelled scale factor and misalignment under thrust).
    pub accel_bias_rw: f64,
    /// Star tracker boresight, body axes.
    pub st_boresight_body: [f64; 3],
    /// Star tracker 1-sigma noise across / about the boresight, rad.
    pub st_cross_rad: f64,
    /// See `st_cross_rad`.
    pub st_about_rad: f64,
    /// Laser altimeter beam (unit) and position relative to the centre of mass, body.
    pub laser_beam_body: [f64; 3],
    /// See `laser_beam_body`.
    pub laser_position_body_m: [f64; 3],
    /// Laser altimeter noise `c + k range`: c (m) and k.
    pub laser_noise_m: f64,
    /// See `laser_noise_m`.
    pub laser_noise_frac: f64,
    /// RF altimeter beam (cone axis) and position, body.
    pub rf_beam_body: [f64; 3],
    /// See `rf_beam_body`.
    pub rf_position_body_m: [f64; 3],
    /// RF altimeter cone: half angle (rad) and ring rays around the axis; the device
    /// returns the nearest of the axis and the ring rays (`docs/sensors.md`).
    pub rf_half_cone_rad: f64,
    /// See `rf_half_cone_rad`.
    pub rf_ring_rays: usize,
    /// RF altimeter noise `c + k range`.
    pub rf_noise_m: f64,
    /// See `rf_noise_m`.
    pub rf_noise_frac: f64,
    /// Velocimeter beams (unit), body.
    pub velo_beams_body: [[f64; 3]; VELOCIMETER_BEAMS],
    /// Velocimeter optical head, body, m.
    pub velo_position_body_m: [f64; 3],
    /// Velocimeter line-of-sight noise, m/s.
    pub velo_noise_m_s: f64,
    /// Extra 1-sigma added to the altimeters for the locally flat ground (slope, rocks), m.
    pub ground_model_sigma_m: f64,
    /// Chi-square gate for a scalar measurement (1 dof).
    pub gate_chi2_1dof: f64,
    /// Chi-square gate for the star tracker (3 dof).
    pub gate_chi2_3dof: f64,
    /// Chi-square gate for a horizontal position fix (2 dof; terrain-relative
    /// navigation). A fix beyond it is never re-accepted: a wrong fix (a repeated
    /// pattern, a shifted map) can be self-consistent.
    pub gate_chi2_2dof: f64,
    /// Consecutive rejections after which a self-consistent offset is re-accepted.
    pub reaccept_after: u32,
    /// The rejected innovations are consistent when their spread (max - min) is at most
    /// this many innovation sigmas.
    pub reaccept_spread_sigmas: f64,
    /// Initial 1-sigma per axis: position (m), velocity (m/s), attitude (rad),
    /// gyro bias (rad/s), accelerometer bias (m/s^2).
    pub init_sigma_pos_m: f64,
    /// See `init_sigma_pos_m`.
    pub init_sigma_vel_m_s: f64,
    /// See `init_sigma_pos_m`.
    pub init_sigma_att_rad: f64,
    /// See `init_sigma_pos_m`.
    pub init_sigma_gyro_bias_rad_s: f64,
    /// See `init_sigma_pos_m`.
    pub init_sigma_accel_bias_m_s2: f64,
    /// The orbit-determination error realisation added to the first telemetry's
    /// navigation state (tests draw it from the initial sigmas; 0 in flight).
    pub init_pos_offset_m: [f64; 3],
    /// See `init_pos_offset_m`.
    pub init_vel_offset_m_s: [f64; 3],
}

fn default_velo_beams() -> [[f64; 3]; VELOCIMETER_BEAMS] {
    let cant = 20f64.to_radians();
    [0.0f64, 120.0, 240.0].map(|az| {
        let az = az.to_radians();
        [cant.sin() * az.cos(), cant.sin() * az.sin(), -cant.cos()]
    })
}

impl Default for NavFilterConfig {
    fn default() -> Self {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        Self {
            mu_m3_s2: 4.9028e12,
            moon_radius_m: 1_737_400.0,
            rotation_rate_rad_s: 2.6617e-6,
            terrain_height_m: 0.0,
            // 0.005 deg/sqrt(h)
            gyro_arw_rad_rt_s: 0.005f64.to_radians() / 60.0,
            // 30 ug/sqrt(Hz)
            accel_vrw_m_s_rt_s: 30.0 * UG,
            // 0.01 deg/h over ~600 s
            gyro_bias_rw: 0.01f64.to_radians() / 3600.0 / 600f64.sqrt() * 3.0,
            // 10 ug instability, plus 50 ppm scale and 0.1 mrad misalignment at ~5 m/s^2
            accel_bias_rw: 5e-4 / 100f64.sqrt(),
            st_boresight_body: [0.0, s, s],
            st_cross_rad: 5.0 * ARCSEC,
            st_about_rad: 30.0 * ARCSEC,
            laser_beam_body: [0.0, 0.0, -1.0],
            laser_position_body_m: [0.0, 0.0, -0.8],
            laser_noise_m: 0.5,
            laser_noise_frac: 0.001,
            rf_beam_body: [0.0, 0.0, -1.0],
            rf_position_body_m: [0.0, 0.0, -0.8],
            rf_half_cone_rad: 10f64.to_radians(),
            rf_ring_rays: 6,
            rf_noise_m: 1.0,
            rf_noise_frac: 0.005,
            velo_beams_body: default_velo_beams(),
            velo_position_body_m: [0.0, 0.0, -0.8],
            velo_noise_m_s: 0.01,
            ground_model_sigma_m: 1.0,
            gate_chi2_1dof: 16.0,
            gate_chi2_3dof: 21.1,
            // 99.9 % of a chi-square with 2 dof.
            gate_chi2_2dof: 13.8,
            reaccept_after: 5,
            reaccept_spread_sigmas: 6.0,
            init_sigma_pos_m: 200.0,
            init_sigma_vel_m_s: 0.5,
            init_sigma_att_rad: 30.0 * ARCSEC,
            init_sigma_gyro_bias_rad_s: 0.01f64.to_radians() / 3600.0,
            init_sigma_accel_bias_m_s2: 50.0 * UG,
            init_pos_offset_m: [0.0; 3],
            init_vel_offset_m_s: [0.0; 3],
        }
    }
}

/// Measurement channels, each with its own gate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    /// Star tracker attitude (3 dof).
    StarTracker = 0,
    /// Laser altimeter slant range.
    Laser = 1,
    /// RF altimeter slant range.
    Rf = 2,
    /// Velocimeter beam 0..2 line-of-sight velocity.
    Velo0 = 3,
    /// See `Velo0`.
    Velo1 = 4,
    /// See `Velo0`.
    Velo2 = 5,
    /// Terrain-relative position fix (2 dof, from the camera and the onboard map).
    Terrain = 6,
}

/// Number of gated channels.
pub const CHANNELS: usize = 7;

/// Per-channel counters.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ChannelStats {
    /// Samples used in an update.
    pub accepted: u64,
    /// Samples rejected by the gate.
    pub rejected: u64,
    /// Times a consistent run of rejections was re-accepted.
    pub reaccepted: u64,
    /// Current run of consecutive rejections.
    pub consecutive_rejected: u32,
    /// Last normalised innovation squared.
    pub last_nis: f64,
}

/// The filter's output: the estimate and its 1-sigma per axis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct NavEstimate {
    /// Time of the estimate (last IMU sample), ns.
    pub t_ns: i64,
    /// Position, `mci`, m.
    pub pos_mci_m: [f64; 3],
    /// Velocity, `mci`, m/s.
    pub vel_mci_m_s: [f64; 3],
    /// Attitude `[w, x, y, z]`, body to `mci`.
    pub q_mci_from_body: [f64; 4],
    /// Body rate from the last IMU increment (bias removed), rad/s.
    pub rate_body_rad_s: [f64; 3],
    /// Gyro bias estimate, rad/s.
    pub gyro_bias_rad_s: [f64; 3],
    /// Accelerometer bias estimate, m/s^2.
    pub accel_bias_m_s2: [f64; 3],
    /// 1-sigma of position per `mci` axis, m.
    pub sigma_pos_m: [f64; 3],
    /// 1-sigma of velocity per `mci` axis, m/s.
    pub sigma_vel_m_s: [f64; 3],
    /// 1-sigma of attitude per body axis, rad.
    pub sigma_att_rad: [f64; 3],
    /// Altitude of the centre of mass above the sphere plus `terrain_height_m`, m (not
    /// the footpads': they are ~1.2 m below it on the reference lander).
    pub altitude_m: f64,
    /// Per channel counters (index: [`Channel`]).
    pub channels: [ChannelStats; CHANNELS],
    /// False until the first telemetry initialised the filter.
    pub initialised: bool,
}

#[derive(Debug, Clone, Copy, Default)]
struct Hist {
    t_ns: i64,
    r: Vector3<f64>,
    v: Vector3<f64>,
    q: UnitQuaternion<f64>,
}

#[derive(Debug, Clone, Copy, Default)]
struct Gate {
    stats: ChannelStats,
    /// Rejected innovations of the current run (ring), and their sigma.
    rej: [f64; GATE_WINDOW],
    rej_sigma: [f64; GATE_WINDOW],
    /// Ground-height offset attributed to this channel's beam by a re-accepted step, m.
    ground_offset_m: f64,
    /// Variance of that offset (the mean of `reaccept_after` innovations), m^2.
    ground_offset_var: f64,
    /// Variance of the last re-accepted mean innovation.
    reaccept_var: f64,
}

/// The error-state Kalman filter.
#[derive(Debug, Clone)]
pub struct NavFilter {
    cfg: NavFilterConfig,
    init: bool,
    t_ns: i64,
    r: Vector3<f64>,
    v: Vector3<f64>,
    q: UnitQuaternion<f64>,
    bg: Vector3<f64>,
    ba: Vector3<f64>,
    w_body: Vector3<f64>,
    /// The last valid IMU sample's increments per second (angle, velocity), held over a
    /// lost sample.
    held_rates: (Vector3<f64>, Vector3<f64>),
    p: Mat,
    hist: [Hist; HISTORY],
    hist_len: usize,
    hist_head: usize,
    gates: [Gate; CHANNELS],
    st_r_body: Matrix3<f64>,
    /// The onboard terrain map's heights, when there is one: the altimeters' ground is
    /// then the map's under each beam instead of the sphere at `terrain_height_m`.
    ground_map: Option<std::sync::Arc<super::terrain_map::TerrainMap>>,
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

/// Largest RF ring used.
const MAX_RING: usize = 16;

/// The device's frame about a beam axis (as `emulator/src/sensors/devices.rs`).
fn frame_about(axis: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let z = axis.normalize();
    let seed = if z.x.abs() <= z.y.abs() && z.x.abs() <= z.z.abs() {
        Vector3::x()
    } else if z.y.abs() <= z.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    let x = seed.cross(&z).normalize();
    let y = z.cross(&x);
    (x, y, z)
}

fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

impl NavFilter {
    /// A filter waiting for its first telemetry.
    pub fn new(cfg: NavFilterConfig) -> Self {
        // Star tracker noise in body axes: C diag(c, c, b) C^T, C = [x y z] of the tracker
        // (x, y any completion: the two cross-boresight sigmas are equal).
        let z = v3(cfg.st_boresight_body).normalize();
        let t = if z.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        let x = (t - z * z.dot(&t)).normalize();
        let y = z.cross(&x);
        let c = Matrix3::from_columns(&[x, y, z]);
        let d = Matrix3::from_diagonal(&Vector3::new(
            cfg.st_cross_rad.powi(2),
            cfg.st_cross_rad.powi(2),
            cfg.st_about_rad.powi(2),
        ));
        let st_r_body = c * d * c.transpose();
        Self {
            cfg,
            init: false,
            t_ns: 0,
            r: Vector3::zeros(),
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            bg: Vector3::zeros(),
            ba: Vector3::zeros(),
            w_body: Vector3::zeros(),
            held_rates: (Vector3::zeros(), Vector3::zeros()),
            p: Mat::zeros(),
            hist: [Hist::default(); HISTORY],
            ground_map: None,
            hist_len: 0,
            hist_head: 0,
            gates: [Gate::default(); CHANNELS],
            st_r_body,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &NavFilterConfig {
        &self.cfg
    }

    /// The full error covariance (15x15, order `[δr, δv, δθ, δb_g, δb_a]`).
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// Consumes one telemetry: IMU increments first (propagation), then the star tracker,
    /// altimeters and velocimeter samples, each against the nominal state at its time of
    /// validity. Returns the estimate.
    pub fn step(&mut self, tlm: &Telemetry) -> NavEstimate {
        if !self.init {
            self.initialise(tlm);
        }
        let s = &tlm.sensors;
        // Strapdown per IMU sample; the covariance once for all of this telemetry's
        // samples, with their transitions summed (`Transition::then`).
        let mut phi: Option<Transition> = None;
        for imu in s.imu.iter().take(s.imu_count as usize) {
            if imu.t_ns <= self.t_ns {
                continue;
            }
            let dt = (imu.t_ns - self.t_ns) as f64 * 1e-9;
            let period = if imu.valid == 0 {
                // A lost IMU sample: hold the last valid sample's rates over its period.
                let (dth, dv) = (self.held_rates.0 * dt, self.held_rates.1 * dt);
                self.strapdown(dt, &dth, &dv)
            } else {
                let (dth, dv) = (v3(imu.delta_theta_body_rad), v3(imu.delta_v_body_m_s));
                if dt > 0.0 {
                    self.held_rates = (dth / dt, dv / dt);
                }
                self.strapdown(dt, &dth, &dv)
            };
            phi = Some(match phi {
                Some(before) => before.then(&period),
                None => period,
            });
            self.t_ns = imu.t_ns;
            self.push_hist();
        }
        if let Some(phi) = phi {
            self.propagate_covariance(&phi);
        }
        for st in s.star_tracker.iter().take(s.star_tracker_count as usize) {
            if st.valid != 0 {
                let q = st.q_mci_from_body;
                let qm = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
                self.update_star_tracker(st.t_ns, &qm);
            }
        }
        for a in s
            .laser_altimeter
            .iter()
            .take(s.laser_altimeter_count as usize)
        {
            self.update_altimeter(Channel::Laser, a);
        }
        for a in s.rf_altimeter.iter().take(s.rf_altimeter_count as usize) {
            self.update_altimeter(Channel::Rf, a);
        }
        for vs in s.velocimeter.iter().take(s.velocimeter_count as usize) {
            for b in 0..VELOCIMETER_BEAMS {
                if vs.valid[b] != 0 && vs.los_velocity_m_s[b].is_finite() {
                    self.update_velocimeter(vs.t_ns, b, vs.los_velocity_m_s[b]);
                }
            }
        }
        self.estimate()
    }

    /// The current estimate.
    pub fn estimate(&self) -> NavEstimate {
        let sd = |i: usize| {
            [
                self.p[(i, i)].max(0.0).sqrt(),
                self.p[(i + 1, i + 1)].max(0.0).sqrt(),
                self.p[(i + 2, i + 2)].max(0.0).sqrt(),
            ]
        };
        let q = self.q.quaternion();
        let mut channels = [ChannelStats::default(); CHANNELS];
        for (c, g) in channels.iter_mut().zip(self.gates.iter()) {
            *c = g.stats;
        }
        NavEstimate {
            t_ns: self.t_ns,
            pos_mci_m: self.r.into(),
            vel_mci_m_s: self.v.into(),
            q_mci_from_body: [q.w, q.i, q.j, q.k],
            rate_body_rad_s: self.w_body.into(),
            gyro_bias_rad_s: self.bg.into(),
            accel_bias_m_s2: self.ba.into(),
            sigma_pos_m: sd(I_R),
            sigma_vel_m_s: sd(I_V),
            sigma_att_rad: sd(I_TH),
            altitude_m: self.r.norm() - self.cfg.moon_radius_m - self.cfg.terrain_height_m,
            channels,
            initialised: self.init,
        }
    }

    fn initialise(&mut self, tlm: &Telemetry) {
        let c = &self.cfg;
        self.r = v3(tlm.nav.pos_mci_m) + v3(c.init_pos_offset_m);
        self.v = v3(tlm.nav.vel_mci_m_s) + v3(c.init_vel_offset_m_s);
        let mut q = tlm.nav.q_mci_from_body;
        let s = &tlm.sensors;
        if let Some(st) = s
            .star_tracker
            .iter()
            .take(s.star_tracker_count as usize)
            .rfind(|st| st.valid != 0)
        {
            q = st.q_mci_from_body;
        }
        self.q = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
        self.t_ns = tlm.header.t_ns;
        let mut p = Mat::zeros();
        for i in 0..3 {
            p[(I_R + i, I_R + i)] = c.init_sigma_pos_m.powi(2);
            p[(I_V + i, I_V + i)] = c.init_sigma_vel_m_s.powi(2);
            p[(I_TH + i, I_TH + i)] = c.init_sigma_att_rad.powi(2);
            p[(I_BG + i, I_BG + i)] = c.init_sigma_gyro_bias_rad_s.powi(2);
            p[(I_BA + i, I_BA + i)] = c.init_sigma_accel_bias_m_s2.powi(2);
        }
        self.p = p;
        self.init = true;
        self.push_hist();
    }

    fn gravity(&self, r: &Vector3<f64>) -> Vector3<f64> {
        let n = r.norm();
        -r * (self.cfg.mu_m3_s2 / (n * n * n))
    }

    /// Strapdown over one IMU period; returns the period's error transition `Φ = I + F dt`.
    fn strapdown(&mut self, dt: f64, dtheta: &Vector3<f64>, dv: &Vector3<f64>) -> Transition {
        let dth = dtheta - self.bg * dt;
        let dvc = dv - self.ba * dt;
        let rot = self.q.to_rotation_matrix().into_inner();
        // Velocity: v_k = v_{k-1} + R(q_{k-1}) dv + g dt (gravity at the midpoint).
        let r_mid = self.r + self.v * (0.5 * dt);
        let g = self.gravity(&r_mid);
        let v_new = self.v + rot * dvc + g * dt;
        self.r += (self.v + v_new) * (0.5 * dt);
        self.v = v_new;
        self.q *= UnitQuaternion::from_scaled_axis(dth);
        self.w_body = if dt > 0.0 { dth / dt } else { Vector3::zeros() };

        // Error dynamics.
        let rn = r_mid.norm();
        let u = r_mid / rn;
        let gg = (u * u.transpose() * 3.0 - Matrix3::identity()) * (self.cfg.mu_m3_s2 / rn.powi(3));
        Transition {
            dt_s: dt,
            v_from_r: gg * dt,
            v_from_theta: -rot * skew(&dvc),
            v_from_ba: -rot * dt,
            theta_from_theta: Matrix3::identity() - skew(&dth),
        }
    }

    /// `P = Φ P Φ^T + Q T` over the transition's period `T`.
    fn propagate_covariance(&mut self, phi: &Transition) {
        let dt = phi.dt_s;
        self.p = phi.propagate(&self.p);
        let c = &self.cfg;
        for i in 0..3 {
            self.p[(I_V + i, I_V + i)] += c.accel_vrw_m_s_rt_s.powi(2) * dt;
            self.p[(I_TH + i, I_TH + i)] += c.gyro_arw_rad_rt_s.powi(2) * dt;
            self.p[(I_BG + i, I_BG + i)] += c.gyro_bias_rw.powi(2) * dt;
            self.p[(I_BA + i, I_BA + i)] += c.accel_bias_rw.powi(2) * dt;
        }
    }

    fn push_hist(&mut self) {
        self.hist_head = (self.hist_head + 1) % HISTORY;
        self.hist[self.hist_head] = Hist {
            t_ns: self.t_ns,
            r: self.r,
            v: self.v,
            q: self.q,
        };
        self.hist_len = (self.hist_len + 1).min(HISTORY);
    }

    /// The nominal state at `t_ns` (the newest kept state not after it; the current state
    /// when the time is not older than it or older than the history).
    fn at(&self, t_ns: i64) -> Hist {
        for k in 0..self.hist_len {
            let h = self.hist[(self.hist_head + HISTORY - k) % HISTORY];
            if h.t_ns <= t_ns {
                return h;
            }
        }
        self.hist[self.hist_head]
    }

    /// Takes the altimeters' ground from `map` (terrain-relative altimetry: a crater
    /// under the beam is no longer a height error of the vehicle). Only once the
    /// horizontal position is known to about a map cell (terrain navigation has
    /// acquired): the beam's hit is looked up where the estimate says it is.
    /// The altimeters' learned ground offsets (steps of the flat-ground model) are
    /// dropped: the map's heights replace them.
    pub fn set_ground_map(&mut self, map: Option<std::sync::Arc<super::terrain_map::TerrainMap>>) {
        self.ground_map = map;
        for ch in [Channel::Laser, Channel::Rf] {
            let g = &mut self.gates[ch as usize];
            g.ground_offset_m = 0.0;
            g.ground_offset_var = 0.0;
        }
    }

    /// The ground's radius under the `mci` point `p` at `t_ns`: the map's height there
    /// (outside it, or without one, `terrain_height_m`) above the sphere, plus `offset_m`.
    fn ground_radius_m(&self, p: &Vector3<f64>, t_ns: i64, offset_m: f64) -> f64 {
        let c = &self.cfg;
        let h = self.ground_map.as_ref().and_then(|m| {
            let turn = -c.rotation_rate_rad_s * t_ns as f64 * 1e-9;
            let (s, co) = turn.sin_cos();
            let q = Vector3::new(co * p.x - s * p.y, s * p.x + co * p.y, p.z);
            let (e, n, _) = m.frame.map_of_mcmf(&q);
            m.height_at(e, n)
        });
        c.moon_radius_m + h.unwrap_or(c.terrain_height_m) + offset_m
    }

    /// The nominal position (`mci`) and attitude at `t_ns`: the kept state just before
    /// it moved on by its velocity (a camera frame's time of validity falls between IMU
    /// samples; 5 ms at 100 m/s is half a metre).
    pub fn pose_at(&self, t_ns: i64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let h = self.at(t_ns);
        let dt_s = (t_ns - h.t_ns) as f64 * 1e-9;
        (h.r + h.v * dt_s, h.q)
    }

    /// Widens the position uncertainty along the unit `mci` direction `axis` to at
    /// least `sigma_m` (scaling that direction's rows and columns of the covariance, so
    /// its correlations are kept). Terrain navigation's acquisition: the first fix is an
    /// absolute position found over a search wider than the filter's own sigma (the
    /// orbit determination's error is not always what the ground says it is).
    pub fn widen_position(&mut self, axis: &Vector3<f64>, sigma_m: f64) {
        let p_rr = self.p.fixed_view::<3, 3>(I_R, I_R).into_owned();
        let var = (axis.transpose() * p_rr * axis)[(0, 0)];
        if !(sigma_m.is_finite() && var > 0.0 && var < sigma_m * sigma_m) {
            return;
        }
        // T = I + (k - 1) a a^T on the position block: P' = T P T^T scales the variance
        // along `a` by k^2 and leaves the orthogonal directions alone.
        let k = sigma_m / var.sqrt();
        let mut t = Mat::identity();
        let a = axis.normalize();
        for i in 0..3 {
            for j in 0..3 {
                t[(I_R + i, I_R + j)] += (k - 1.0) * a[i] * a[j];
            }
        }
        self.p = t * self.p * t.transpose();
    }

    /// A position fix of two components: `y_m[i]` is the measured value of
    /// `rows[i] . (true - estimated position)` (`mci`, m) at the fix's time of validity,
    /// each with 1-sigma `sigma_m` (terrain-relative navigation: the shift of the ground
    /// under the camera, which an oblique view ties to the height error too). Gated as a
    /// whole (2 dof, `gate_chi2_2dof`), then applied as two scalar updates to the
    /// current state (the delay, one frame's announcement, is a few ms: the position
    /// error does not move in it). Returns whether it was used and its normalised
    /// innovation squared.
    pub fn update_position_fix(
        &mut self,
        rows: [Vector3<f64>; 2],
        y_m: [f64; 2],
        sigma_m: f64,
    ) -> (bool, f64) {
        let axes = rows;
        let r_var = sigma_m * sigma_m;
        let p_rr = self.p.fixed_view::<3, 3>(I_R, I_R).into_owned();
        let s00 = (axes[0].transpose() * p_rr * axes[0])[(0, 0)] + r_var;
        let s11 = (axes[1].transpose() * p_rr * axes[1])[(0, 0)] + r_var;
        let s01 = (axes[0].transpose() * p_rr * axes[1])[(0, 0)];
        let det = s00 * s11 - s01 * s01;
        let g = &mut self.gates[Channel::Terrain as usize];
        if !(det > 0.0 && y_m.iter().all(|v| v.is_finite())) {
            g.stats.rejected += 1;
            return (false, f64::NAN);
        }
        let (a, b) = (y_m[0], y_m[1]);
        let nis = (s11 * a * a - 2.0 * s01 * a * b + s00 * b * b) / det;
        g.stats.last_nis = nis;
        if nis > self.cfg.gate_chi2_2dof {
            g.stats.rejected += 1;
            g.stats.consecutive_rejected += 1;
            return (false, nis);
        }
        g.stats.accepted += 1;
        g.stats.consecutive_rejected = 0;
        let mut moved = Vector3::zeros();
        for (axis, y) in axes.iter().zip(y_m) {
            let mut h = Row::zeros();
            for i in 0..3 {
                h[(0, I_R + i)] = axis[i];
            }
            // What earlier updates of this fix moved the estimate along this axis is no
            // longer an error.
            let y = y - axis.dot(&moved);
            let before = self.r;
            self.update_scalar(&h, y, r_var);
            moved += self.r - before;
        }
        (true, nis)
    }

    /// Applies an accepted error estimate to the current nominal state (and shifts the
    /// history by the same correction).
    fn inject(&mut self, dx: &SVector<f64, N>) {
        let dr = dx.fixed_rows::<3>(I_R).into_owned();
        let dv = dx.fixed_rows::<3>(I_V).into_owned();
        let dth = dx.fixed_rows::<3>(I_TH).into_owned();
        self.r += dr;
        self.v += dv;
        let dq = UnitQuaternion::from_scaled_axis(dth);
        self.q *= dq;
        self.bg += dx.fixed_rows::<3>(I_BG);
        self.ba += dx.fixed_rows::<3>(I_BA);
        for k in 0..self.hist_len {
            let h = &mut self.hist[(self.hist_head + HISTORY - k) % HISTORY];
            h.r += dr;
            h.v += dv;
            h.q *= dq;
        }
    }

    /// Gate test for a scalar innovation `y` with variance `s`: returns whether to update,
    /// and on a re-accept the mean of the consistent rejected innovations (else 0), which
    /// the caller attributes (altimeters: the ground; velocimeter: the covariance).
    fn gate_scalar(&mut self, ch: Channel, y: f64, s: f64) -> (bool, f64) {
        let gate = self.cfg.gate_chi2_1dof;
        let k = self.cfg.reaccept_after.clamp(1, GATE_WINDOW as u32) as usize;
        let spread_max = self.cfg.reaccept_spread_sigmas;
        let g = &mut self.gates[ch as usize];
        let nis = y * y / s;
        g.stats.last_nis = nis;
        if nis <= gate {
            g.stats.accepted += 1;
            g.stats.consecutive_rejected = 0;
            return (true, 0.0);
        }
        let slot = g.stats.consecutive_rejected as usize % GATE_WINDOW;
        g.rej[slot] = y;
        g.rej_sigma[slot] = s.sqrt();
        g.stats.consecutive_rejected += 1;
        let n = g.stats.consecutive_rejected as usize;
        if n >= k {
            // The last k rejected innovations: consistent when their spread is within
            // `spread_max` of their largest sigma.
            let (mut lo, mut hi, mut sig, mut sum) = (f64::MAX, f64::MIN, 0.0f64, 0.0);
            for j in 0..k {
                let i = (n - 1 - j) % GATE_WINDOW;
                lo = lo.min(g.rej[i]);
                hi = hi.max(g.rej[i]);
                sig = sig.max(g.rej_sigma[i]);
                sum += g.rej[i];
            }
            if hi - lo <= spread_max * sig {
                g.reaccept_var = sig * sig / k as f64;
                g.stats.reaccepted += 1;
                g.stats.accepted += 1;
                g.stats.consecutive_rejected = 0;
                return (true, sum / k as f64);
            }
        }
        g.stats.rejected += 1;
        (false, 0.0)
    }

    fn update_scalar(&mut self, h: &Row, y: f64, r: f64) {
        let (k, _, p) = covariance::scalar_update(&self.p, h, r);
        self.p = p;
        self.inject(&(k * y));
    }

    fn update_altimeter(&mut self, ch: Channel, a: &AltimeterSample) {
        if a.valid == 0 || !(a.range_m.is_finite() && a.range_m > 0.0) {
            return;
        }
        let c = &self.cfg;
        let (beam, pos, n0, nk) = match ch {
            Channel::Laser => (
                c.laser_beam_body,
                c.laser_position_body_m,
                c.laser_noise_m,
                c.laser_noise_frac,
            ),
            _ => (
                c.rf_beam_body,
                c.rf_position_body_m,
                c.rf_noise_m,
                c.rf_noise_frac,
            ),
        };
        let hs = self.at(a.t_ns);
        let rot = hs.q.to_rotation_matrix().into_inner();
        let pb = v3(pos);
        let o = hs.r + rot * pb;
        let offset_m = self.gates[ch as usize].ground_offset_m;
        let flat_ground = c.moon_radius_m + c.terrain_height_m + offset_m;
        // The rays: the beam, and for the RF altimeter its ring (the nearest return wins).
        let (fx, fy, fz) = frame_about(&v3(beam));
        let (ring, half) = match ch {
            Channel::Laser => (0, 0.0),
            _ => (c.rf_ring_rays.min(MAX_RING), c.rf_half_cone_rad),
        };
        let (sh, chc) = half.sin_cos();
        // (range, ray body, normal at the hit, cos incidence)
        let mut best: Option<(f64, Vector3<f64>, Vector3<f64>, f64)> = None;
        for k in 0..=ring {
            let ub = if k == 0 {
                fz
            } else {
                let phi = std::f64::consts::TAU * (k - 1) as f64 / ring as f64;
                fz * chc + (fx * phi.cos() + fy * phi.sin()) * sh
            };
            let d = rot * ub;
            // Ray-sphere: |o + ρ d| = ground, nearest root; with a map, the sphere
            // through the map's height where the ray meets it (twice: a few metres of
            // relief move the hit by less than a cell).
            let od = o.dot(&d);
            let mut ground = flat_ground;
            let mut hit = None;
            for _ in 0..if self.ground_map.is_some() { 3 } else { 1 } {
                let disc = od * od - (o.norm_squared() - ground * ground);
                if disc <= 0.0 || od >= 0.0 {
                    hit = None;
                    break;
                }
                let range = -od - disc.sqrt();
                hit = Some(range);
                ground = self.ground_radius_m(&(o + d * range), a.t_ns, offset_m);
            }
            let Some(range) = hit else {
                continue;
            };
            if range <= 0.0 {
                continue;
            }
            let nh = (o + d * range).normalize();
            let cosi = -nh.dot(&d);
            if cosi < 0.2 {
                continue; // near grazing: the model is too sensitive to trust
            }
            if best.is_none_or(|b| range < b.0) {
                best = Some((range, ub, nh, cosi));
            }
        }
        let Some((pred, ub, nh, cosi)) = best else {
            return;
        };
        // d(range)/dr = nh^T / cos; d/dθ = nh^T (-R[p]x - range R[u]x) / cos, with nh the
        // normal at the hit point and cos the incidence cosine.
        let mut hrow = Row::zeros();
        let dr = nh.transpose() / cosi;
        let dth = (nh.transpose() * (-rot * (skew(&pb) + skew(&ub) * pred))) / cosi;
        hrow.fixed_view_mut::<1, 3>(0, I_R).copy_from(&dr);
        hrow.fixed_view_mut::<1, 3>(0, I_TH).copy_from(&dth);
        let sig = n0 + nk * a.range_m;
        let r =
            sig * sig + c.ground_model_sigma_m.powi(2) + self.gates[ch as usize].ground_offset_var;
        let mut y = a.range_m - pred;
        let s = (hrow * self.p * hrow.transpose())[(0, 0)] + r;
        let (ok, shift) = self.gate_scalar(ch, y, s);
        if !ok {
            return;
        }
        if shift != 0.0 {
            // A consistent step: the ground under this beam moved by -shift * cos.
            let g = &mut self.gates[ch as usize];
            g.ground_offset_m -= shift * cosi;
            g.ground_offset_var += g.reaccept_var * cosi * cosi;
            y -= shift;
        }
        self.update_scalar(&hrow, y, r);
    }

    fn update_velocimeter(&mut self, t_ns: i64, beam: usize, los: f64) {
        let c = &self.cfg;
        let hs = self.at(t_ns);
        let rot = hs.q.to_rotation_matrix().into_inner();
        let ub = v3(c.velo_beams_body[beam]).normalize();
        let pb = v3(c.velo_position_body_m);
        let om = Vector3::new(0.0, 0.0, c.rotation_rate_rad_s);
        let head = hs.r + rot * pb;
        let v_rel = hs.v + rot * self.w_body.cross(&pb) - om.cross(&head);
        let d = rot * ub;
        let pred = v_rel.dot(&d);
        let mut hrow = Row::zeros();
        hrow.fixed_view_mut::<1, 3>(0, I_V)
            .copy_from(&d.transpose());
        hrow.fixed_view_mut::<1, 3>(0, I_R)
            .copy_from(&(-d.transpose() * skew(&om)));
        hrow.fixed_view_mut::<1, 3>(0, I_TH)
            .copy_from(&(-v_rel.transpose() * rot * skew(&ub)));
        let r = c.velo_noise_m_s.powi(2);
        let y = los - pred;
        let s = (hrow * self.p * hrow.transpose())[(0, 0)] + r;
        let ch = match beam {
            0 => Channel::Velo0,
            1 => Channel::Velo1,
            _ => Channel::Velo2,
        };
        let (ok, shift) = self.gate_scalar(ch, y, s);
        if ok {
            if shift != 0.0 {
                // A genuine, consistent offset: open the velocity covariance along the
                // beam to it before the update.
                let dd = d * d.transpose() * (shift * shift);
                let mut pv = self.p.fixed_view_mut::<3, 3>(I_V, I_V);
                pv += dd;
            }
            self.update_scalar(&hrow, y, r);
        }
    }

    fn update_star_tracker(&mut self, t_ns: i64, qm: &UnitQuaternion<f64>) {
        let hs = self.at(t_ns);
        // q_meas = q_true exp(δ); q_true = q_nom exp(δθ): innovation = log(q_nom^-1 q_meas).
        let y = (hs.q.inverse() * qm).scaled_axis();
        let r = self.st_r_body;
        let s = self.p.fixed_view::<3, 3>(I_TH, I_TH).into_owned() + r;
        let Some(si) = s.try_inverse() else {
            return;
        };
        let nis = (y.transpose() * si * y)[(0, 0)];
        let gate = self.cfg.gate_chi2_3dof;
        let k = self.cfg.reaccept_after.max(1);
        let g = &mut self.gates[Channel::StarTracker as usize];
        g.stats.last_nis = nis;
        if nis > gate {
            // Rejected: re-accept after k consecutive rejections whose innovations agree.
            let slot = g.stats.consecutive_rejected as usize % GATE_WINDOW;
            g.rej[slot] = y.norm();
            g.rej_sigma[slot] = s.trace().sqrt();
            g.stats.consecutive_rejected += 1;
            let n = g.stats.consecutive_rejected;
            let mut consistent = n >= k;
            if consistent {
                let (mut lo, mut hi, mut sig) = (f64::MAX, f64::MIN, 0.0f64);
                for j in 0..k.min(GATE_WINDOW as u32) as usize {
                    let i = (n as usize - 1 - j) % GATE_WINDOW;
                    lo = lo.min(g.rej[i]);
                    hi = hi.max(g.rej[i]);
                    sig = sig.max(g.rej_sigma[i]);
                }
                consistent = hi - lo <= self.cfg.reaccept_spread_sigmas * sig;
            }
            if !consistent {
                g.stats.rejected += 1;
                return;
            }
            g.stats.reaccepted += 1;
            g.stats.consecutive_rejected = 0;
            // A genuine attitude offset: open the attitude covariance to it.
            for i in 0..3 {
                self.p[(I_TH + i, I_TH + i)] += y.norm_squared();
            }
        } else {
            g.stats.consecutive_rejected = 0;
        }
        self.gates[Channel::StarTracker as usize].stats.accepted += 1;
        let mut h = SMatrix::<f64, 3, N>::zeros();
        h.fixed_view_mut::<3, 3>(0, I_TH)
            .copy_from(&Matrix3::identity());
        let s = h * self.p * h.transpose() + r;
        let Some(si) = s.try_inverse() else {
            return;
        };
        let kk = self.p * h.transpose() * si;
        let dx = kk * y;
        let ikh = Mat::identity() - kk * h;
        self.p = ikh * self.p * ikh.transpose() + kk * r * kk.transpose();
        self.p = (self.p + self.p.transpose()) * 0.5;
        self.inject(&dx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_shared::{ImuSample, StarTrackerSample};

    fn tlm_at(t_ns: i64, r: [f64; 3], v: [f64; 3]) -> Telemetry {
        let mut t = Telemetry::default();
        t.header.t_ns = t_ns;
        t.nav.pos_mci_m = r;
        t.nav.vel_mci_m_s = v;
        t.nav.q_mci_from_body = [1.0, 0.0, 0.0, 0.0];
        t
    }

    /// A free-fall coast on a circular orbit: the strapdown with zero specific force
    /// follows the two-body orbit (100 s, error below 1 m).
    #[test]
    fn nav_strapdown_follows_a_circular_orbit() {
        let c = NavFilterConfig::default();
        let r0 = c.moon_radius_m + 100_000.0;
        let v0 = (c.mu_m3_s2 / r0).sqrt();
        let mut f = NavFilter::new(c.clone());
        let mut t = tlm_at(0, [r0, 0.0, 0.0], [0.0, v0, 0.0]);
        f.step(&t);
        let dt = 5_000_000i64;
        let mut tn = 0;
        for _ in 0..(100 * 200 / 4) {
            t.sensors.imu_count = 4;
            for i in 0..4 {
                tn += dt;
                // Every 7th sample lost: held (zero) increments keep the coast.
                t.sensors.imu[i] = ImuSample {
                    t_ns: tn,
                    valid: u32::from(tn % 7 != 0),
                    ..Default::default()
                };
            }
            t.header.t_ns = tn;
            f.step(&t);
        }
        let e = f.estimate();
        let w = v0 / r0;
        let tt = tn as f64 * 1e-9;
        let truth = [r0 * (w * tt).cos(), r0 * (w * tt).sin(), 0.0];
        let err = (v3(e.pos_mci_m) - v3(truth)).norm();
        assert!(err < 1.0, "position error {err} m after 100 s");
        // With no measurement the position sigma only grows.
        assert!(e.sigma_pos_m[0] >= 200.0);
    }

    /// A star tracker sample far off (a spike) is rejected, a consistent offset is
    /// re-accepted after `reaccept_after` samples.
    #[test]
    fn nav_star_tracker_spike_rejected_then_consistent_offset_reaccepted() {
        let c = NavFilterConfig::default();
        let r0 = c.moon_radius_m + 100_000.0;
        let mut f = NavFilter::new(c.clone());
        let mut t = tlm_at(0, [r0, 0.0, 0.0], [0.0, 1600.0, 0.0]);
        f.step(&t);
        let off = UnitQuaternion::from_scaled_axis(Vector3::new(0.01, 0.0, 0.0));
        let q = off.quaternion();
        t.sensors.star_tracker_count = 1;
        t.sensors.star_tracker[0] = StarTrackerSample {
            t_ns: 0,
            q_mci_from_body: [q.w, q.i, q.j, q.k],
            valid: 1,
            flags: 0,
        };
        f.step(&t);
        let e = f.estimate();
        assert_eq!(e.channels[0].rejected, 1);
        assert!(e.q_mci_from_body[1].abs() < 1e-9);
        for _ in 1..c.reaccept_after {
            f.step(&t);
        }
        let e = f.estimate();
        assert_eq!(e.channels[0].reaccepted, 1, "{:?}", e.channels[0]);
        assert!((2.0 * e.q_mci_from_body[1] - 0.01).abs() < 1e-3);
    }

    /// Under a constant specific force and rate, losing every 7th IMU sample changes
    /// nothing: the lost samples are bridged with the held increments.
    #[test]
    fn nav_lost_imu_samples_are_bridged_with_held_increments() {
        let run = |lose: bool| {
            let c = NavFilterConfig::default();
            let r0 = c.moon_radius_m + 10_000.0;
            let mut f = NavFilter::new(c);
            let mut t = tlm_at(0, [r0, 0.0, 0.0], [0.0, 1600.0, 0.0]);
            f.step(&t);
            let dt = 5_000_000i64;
            let mut tn = 0;
            for _ in 0..2000 {
                tn += dt;
                t.sensors.imu_count = 1;
                t.sensors.imu[0] = ImuSample {
                    t_ns: tn,
                    delta_v_body_m_s: [0.02, 0.0, 0.005],
                    delta_theta_body_rad: [0.0, 1e-4, 0.0],
                    valid: u32::from(!(lose && (tn / dt) % 7 == 0)),
                    flags: 0,
                };
                t.header.t_ns = tn;
                f.step(&t);
            }
            f.estimate()
        };
        let (a, b) = (run(false), run(true));
        let dp = (v3(a.pos_mci_m) - v3(b.pos_mci_m)).norm();
        let dv = (v3(a.vel_mci_m_s) - v3(b.vel_mci_m_s)).norm();
        assert!(dp < 1e-6 && dv < 1e-9, "position {dp} m, velocity {dv} m/s");
    }
}
