//! Navigation from the device samples, as guidance and control use it: the error-state
//! Kalman filter of [`super::nav_filter`] turned into a [`NavSolution`], plus what the
//! flight software says of its navigation in the command's [`FswReport`] (estimate,
//! own sigma, which devices it is using, a laser altimeter it has given up on).
//!
//! The filter starts from the ground's state vector (`TLM_FLAG_STATE_VECTOR`: the
//! orbit determination uplinked before the descent, or after a computer reset), or with
//! telemetry `both` from the ideal navigation; before either arrives there is no
//! estimate and [`SensorNav::update`] returns `None`.

use super::nav_filter::{Channel, NavFilter, NavFilterConfig, CHANNELS};
use super::navigation::NavSolution;
use super::terrain_nav::{TerrainNav, TerrainNavConfig};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use oils_shared::{
    FrameAnnouncement, FswReport, Telemetry, NAV_FLAG_FROM_SENSORS, NAV_FLAG_LASER_LOST,
    NAV_FLAG_LASER_USED, NAV_FLAG_RF_USED, NAV_FLAG_STAR_TRACKER_USED, NAV_FLAG_TERRAIN_LOST,
    NAV_FLAG_TERRAIN_USED, NAV_FLAG_VALID, NAV_FLAG_VELOCIMETER_USED, TLM_FLAG_IDEAL_NAV,
    TLM_FLAG_STATE_VECTOR,
};

/// A device "is used" while it updated the filter within this long, ns.
const USED_WINDOW_NS: i64 = 2_000_000_000;

/// What the sensor navigation assumes beyond the filter.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorNavConfig {
    /// The filter.
    pub filter: NavFilterConfig,
    /// Footpads below the centre of mass along the body -Z axis, m (the reference
    /// lander's legs: `shared/reference/lander-and-propulsion.md`).
    pub footpad_below_com_m: f64,
    /// The laser altimeter is declared lost after this long without a valid sample while
    /// the vehicle is below `laser_expected_below_m`, ns.
    pub laser_lost_after_ns: i64,
    /// Height below which the laser altimeter should see the ground, m (its 8 km range
    /// with margin).
    pub laser_expected_below_m: f64,
    /// Terrain-relative navigation (off without a map).
    pub terrain: TerrainNavConfig,
}

impl Default for SensorNavConfig {
    fn default() -> Self {
        Self {
            filter: NavFilterConfig::default(),
            footpad_below_com_m: 1.2,
            laser_lost_after_ns: 10_000_000_000,
            laser_expected_below_m: 7_000.0,
            terrain: TerrainNavConfig::default(),
        }
    }
}

/// The sensor navigation's state.
#[derive(Debug, Clone)]
pub struct SensorNav {
    cfg: SensorNavConfig,
    filter: NavFilter,
    started: bool,
    accepted: [u64; CHANNELS],
    last_used_ns: [i64; CHANNELS],
    /// When the laser last gave a valid sample (or when it became expected to).
    laser_seen_ns: Option<i64>,
    laser_lost: bool,
    last_imu_t_ns: Option<i64>,
    terrain: TerrainNav,
}

impl SensorNav {
    /// Waiting for the ground's state vector (allocates the terrain navigation's
    /// buffers when it has a map).
    pub fn new(cfg: SensorNavConfig) -> Self {
        let terrain = TerrainNav::new(cfg.terrain.clone());
        Self::with_terrain(cfg, terrain)
    }

    /// [`SensorNav::new`] with terrain navigation state already built (a computer
    /// reset keeps its buffers: nothing is allocated).
    pub fn with_terrain(cfg: SensorNavConfig, mut terrain: TerrainNav) -> Self {
        terrain.reset();
        Self {
            terrain,
            filter: NavFilter::new(cfg.filter.clone()),
            cfg,
            started: false,
            accepted: [0; CHANNELS],
            last_used_ns: [i64::MIN; CHANNELS],
            laser_seen_ns: None,
            laser_lost: false,
            last_imu_t_ns: None,
        }
    }

    /// Forgets everything (a computer reset): waits for a state vector again.
    pub fn reset(&mut self) {
        self.filter = NavFilter::new(self.cfg.filter.clone());
        self.started = false;
        self.accepted = [0; CHANNELS];
        self.last_used_ns = [i64::MIN; CHANNELS];
        self.laser_seen_ns = None;
        self.laser_lost = false;
        self.last_imu_t_ns = None;
        self.terrain.reset();
    }

    /// Hands the terrain navigation out (its buffers), leaving one without a map.
    pub fn take_terrain(&mut self) -> TerrainNav {
        std::mem::replace(
            &mut self.terrain,
            TerrainNav::new(TerrainNavConfig::default()),
        )
    }

    /// The terrain-relative navigation (its counters and last fix).
    pub fn terrain(&self) -> &TerrainNav {
        &self.terrain
    }

    /// A frame the coming telemetry announces (the camera's goes to the terrain
    /// navigation).
    pub fn frame(&mut self, ann: &FrameAnnouncement, pixels: &[u8]) {
        self.terrain.frame(ann, pixels);
    }

    /// The terrain navigation's rate group: matches the frame taken in, if any, and
    /// fixes the filter. Returns whether a frame was matched (the group ran).
    pub fn terrain_group(&mut self, omega_rad_s: f64, t_ns: i64) -> bool {
        if !self.started || !self.terrain.enabled() {
            return false;
        }
        let pending = self.terrain.has_pending();
        self.terrain.process(&mut self.filter, omega_rad_s, t_ns);
        pending
    }

    /// Whether the laser altimeter has been declared lost.
    pub fn laser_lost(&self) -> bool {
        self.laser_lost
    }

    /// The filter (for its counters and covariance).
    pub fn filter(&self) -> &NavFilter {
        &self.filter
    }

    /// Folds in one telemetry. `None` until a state vector has started the filter.
    pub fn update(
        &mut self,
        tlm: &Telemetry,
        omega_moon_mci: Vector3<f64>,
        report: &mut FswReport,
    ) -> Option<NavSolution> {
        if !self.started {
            // The ground's state vector (`sensors`), or the ideal navigation (`both`:
            // then the start carries no orbit-determination error).
            if tlm.header.flags & (TLM_FLAG_STATE_VECTOR | TLM_FLAG_IDEAL_NAV) == 0 {
                return None;
            }
            self.started = true;
        }
        let est = self.filter.step(tlm);
        let t_ns = tlm.header.t_ns;
        for (c, stats) in est.channels.iter().enumerate() {
            if stats.accepted > self.accepted[c] {
                self.accepted[c] = stats.accepted;
                self.last_used_ns[c] = t_ns;
            }
        }
        let r = Vector3::from(est.pos_mci_m);
        let up = r / r.norm();
        let q = est.q_mci_from_body;
        let q = UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]));
        // Footpads: below the centre of mass along the thrust axis, projected on the
        // vertical.
        let pad_drop_m = self.cfg.footpad_below_com_m * (q * Vector3::z()).dot(&up);
        let altitude_m = est.altitude_m - pad_drop_m;
        self.watch_laser(tlm, altitude_m);

        // Radial 1-sigma from the position covariance.
        let p = self.filter.covariance();
        let p_rr = p.fixed_view::<3, 3>(0, 0);
        let alt_sigma = (up.transpose() * p_rr * up)[(0, 0)].max(0.0).sqrt();

        let mu = self.cfg.filter.mu_m3_s2;
        let rn = r.norm();
        let solution = NavSolution {
            t_s: t_ns as f64 * 1e-9,
            pos_mci_m: r,
            vel_mci_m_s: Vector3::from(est.vel_mci_m_s),
            q_mci_from_body: q,
            rate_body_rad_s: Vector3::from(est.rate_body_rad_s),
            specific_force_body_m_s2: cycle_specific_force(
                tlm,
                &mut self.last_imu_t_ns,
                &est.accel_bias_m_s2,
            ),
            altitude_m,
            mass_kg: tlm.mass_estimate_kg,
            up_mci: up,
            gravity_m_s2: mu / (rn * rn),
            omega_moon_mci,
        };

        report.nav_pos_mci_m = est.pos_mci_m;
        report.nav_vel_mci_m_s = est.vel_mci_m_s;
        report.nav_pos_sigma_m = est.sigma_pos_m;
        report.nav_vel_sigma_m_s = est.sigma_vel_m_s;
        report.nav_altitude_m = altitude_m;
        report.nav_altitude_sigma_m = alt_sigma;
        let used =
            |c: Channel| t_ns.saturating_sub(self.last_used_ns[c as usize]) <= USED_WINDOW_NS;
        let mut flags = NAV_FLAG_VALID | NAV_FLAG_FROM_SENSORS;
        if used(Channel::StarTracker) {
            flags |= NAV_FLAG_STAR_TRACKER_USED;
        }
        if used(Channel::Laser) {
            flags |= NAV_FLAG_LASER_USED;
        }
        if used(Channel::Rf) {
            flags |= NAV_FLAG_RF_USED;
        }
        if used(Channel::Velo0) || used(Channel::Velo1) || used(Channel::Velo2) {
            flags |= NAV_FLAG_VELOCIMETER_USED;
        }
        if self.laser_lost {
            flags |= NAV_FLAG_LASER_LOST;
        }
        if self.terrain.used_within(t_ns, USED_WINDOW_NS) {
            flags |= NAV_FLAG_TERRAIN_USED;
        }
        if self.terrain.enabled() && self.terrain.lost(t_ns) {
            flags |= NAV_FLAG_TERRAIN_LOST;
        }
        report.nav_flags = flags;
        Some(solution)
    }

    /// Declares the laser altimeter lost after `laser_lost_after_ns` without a valid
    /// sample below `laser_expected_below_m`; a valid sample later brings it back.
    fn watch_laser(&mut self, tlm: &Telemetry, altitude_m: f64) {
        let s = &tlm.sensors;
        let t_ns = tlm.header.t_ns;
        let valid = s
            .laser_altimeter
            .iter()
            .take(s.laser_altimeter_count as usize)
            .any(|a| a.valid != 0);
        if valid {
            self.laser_seen_ns = Some(t_ns);
            self.laser_lost = false;
            return;
        }
        if altitude_m > self.cfg.laser_expected_below_m {
            self.laser_seen_ns = None;
            return;
        }
        let since = *self.laser_seen_ns.get_or_insert(t_ns);
        if t_ns - since > self.cfg.laser_lost_after_ns {
            self.laser_lost = true;
        }
    }
}

/// The cycle's mean specific force, body axes, m/s^2: its IMU velocity increments over
/// the time they span (from the last sample before the cycle), bias removed.
fn cycle_specific_force(
    tlm: &Telemetry,
    last_imu_t_ns: &mut Option<i64>,
    accel_bias_m_s2: &[f64; 3],
) -> Vector3<f64> {
    let s = &tlm.sensors;
    let (mut dv, mut span_ns) = (Vector3::zeros(), 0i64);
    for imu in s.imu.iter().take(s.imu_count as usize) {
        if imu.valid == 0 {
            continue;
        }
        if let Some(prev) = *last_imu_t_ns {
            if imu.t_ns > prev {
                dv += Vector3::from(imu.delta_v_body_m_s);
                span_ns += imu.t_ns - prev;
            }
        }
        *last_imu_t_ns = Some(imu.t_ns);
    }
    if span_ns == 0 {
        return Vector3::zeros();
    }
    dv / (span_ns as f64 * 1e-9) - Vector3::from(*accel_bias_m_s2)
}
