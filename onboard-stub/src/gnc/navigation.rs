//! Onboard navigation: a constant-gain complementary filter over the telemetry.
//!
//! Position and velocity are propagated with the measured specific force (rotated into
//! `mci` with the telemetry attitude) plus the gravity model, then pulled towards the
//! measured values with small gains; the footpad altitude is propagated with the
//! vertical velocity and pulled towards the altimeter. Without sensor noise this follows
//! the measurements to within the prediction error; with white noise it averages it down
//! (a gain k keeps ~sqrt(k/2) of the noise), which E-guidance near time-to-go zero and the
//! terminal descent near the ground need.

use super::GncConfig;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use oils_shared::Telemetry;

/// What guidance and control use, all in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavSolution {
    /// Simulated time, seconds since the run start.
    pub t_s: f64,
    /// Estimated position, `mci`, metres.
    pub pos_mci_m: Vector3<f64>,
    /// Estimated velocity, `mci`, m/s.
    pub vel_mci_m_s: Vector3<f64>,
    /// Attitude (as measured), body -> `mci`.
    pub q_mci_from_body: UnitQuaternion<f64>,
    /// Body rate (as measured), rad/s.
    pub rate_body_rad_s: Vector3<f64>,
    /// Measured specific force, body axes, m/s^2.
    pub specific_force_body_m_s2: Vector3<f64>,
    /// Estimated footpad altitude, metres.
    pub altitude_m: f64,
    /// Vehicle mass from telemetry, kilograms.
    pub mass_kg: f64,
    /// Local vertical (unit, away from the Moon's centre), `mci`.
    pub up_mci: Vector3<f64>,
    /// Gravity magnitude at the estimated position, m/s^2.
    pub gravity_m_s2: f64,
    /// The Moon's angular velocity, `mci`, rad/s.
    pub omega_moon_mci: Vector3<f64>,
}

impl NavSolution {
    /// Vertical velocity, m/s, positive up.
    pub fn vertical_speed_m_s(&self) -> f64 {
        self.vel_mci_m_s.dot(&self.up_mci)
    }

    /// Horizontal velocity vector, `mci`, m/s.
    pub fn horizontal_velocity_mci_m_s(&self) -> Vector3<f64> {
        let v = self.surface_velocity_mci_m_s();
        v - self.up_mci * v.dot(&self.up_mci)
    }

    /// Velocity relative to the turning ground, `v - omega x r`, `mci` axes.
    pub fn surface_velocity_mci_m_s(&self) -> Vector3<f64> {
        self.vel_mci_m_s - self.omega_moon_mci.cross(&self.pos_mci_m)
    }

    /// Gravity vector, `mci`, m/s^2.
    pub fn gravity_mci_m_s2(&self) -> Vector3<f64> {
        -self.up_mci * self.gravity_m_s2
    }

    /// Body +Z (thrust axis) in `mci`.
    pub fn thrust_axis_mci(&self) -> Vector3<f64> {
        self.q_mci_from_body * Vector3::z()
    }
}

/// The filter's state.
#[derive(Debug, Clone)]
pub struct NavFilter {
    mu_m3_s2: f64,
    omega_moon_mci: Vector3<f64>,
    gain_pos: f64,
    gain_vel: f64,
    gain_alt: f64,
    last: Option<Last>,
}

#[derive(Debug, Clone, Copy)]
struct Last {
    t_ns: i64,
    pos_mci_m: Vector3<f64>,
    vel_mci_m_s: Vector3<f64>,
    altitude_m: f64,
    specific_force_mci_m_s2: Vector3<f64>,
}

impl NavFilter {
    /// A filter that starts on the first telemetry it sees.
    pub fn new(cfg: &GncConfig) -> Self {
        Self {
            mu_m3_s2: cfg.moon_mu_m3_s2,
            omega_moon_mci: Vector3::new(0.0, 0.0, cfg.moon_rotation_rad_s),
            gain_pos: cfg.nav_gain_position,
            gain_vel: cfg.nav_gain_velocity,
            gain_alt: cfg.nav_gain_altitude,
            last: None,
        }
    }

    fn gravity_mci(&self, pos_mci_m: &Vector3<f64>) -> Vector3<f64> {
        let r = pos_mci_m.norm();
        -pos_mci_m * (self.mu_m3_s2 / (r * r * r))
    }

    /// Folds in one telemetry packet.
    pub fn update(&mut self, tlm: &Telemetry) -> NavSolution {
        let n = &tlm.nav;
        let [w, x, y, z] = n.q_mci_from_body;
        let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        let f_body = Vector3::from(tlm.accel_body_m_s2);
        let f_mci = q * f_body;
        let pos_meas = Vector3::from(n.pos_mci_m);
        let vel_meas = Vector3::from(n.vel_mci_m_s);
        let t_ns = tlm.header.t_ns;

        let (pos, vel, alt) = match self.last {
            Some(last) if t_ns > last.t_ns => {
                let dt_s = (t_ns - last.t_ns) as f64 * 1e-9;
                // Trapezoid on the specific force; gravity at the last estimate.
                let accel = 0.5 * (last.specific_force_mci_m_s2 + f_mci)
                    + self.gravity_mci(&last.pos_mci_m);
                let vel_pred = last.vel_mci_m_s + accel * dt_s;
                let pos_pred = last.pos_mci_m + (last.vel_mci_m_s + vel_pred) * (0.5 * dt_s);
                let up = pos_pred.normalize();
                let alt_pred = last.altitude_m + (pos_pred - last.pos_mci_m).dot(&up);
                (
                    pos_pred + (pos_meas - pos_pred) * self.gain_pos,
                    vel_pred + (vel_meas - vel_pred) * self.gain_vel,
                    alt_pred + (tlm.altitude_m - alt_pred) * self.gain_alt,
                )
            }
            _ => (pos_meas, vel_meas, tlm.altitude_m),
        };
        self.last = Some(Last {
            t_ns,
            pos_mci_m: pos,
            vel_mci_m_s: vel,
            altitude_m: alt,
            specific_force_mci_m_s2: f_mci,
        });
        let r = pos.norm();
        NavSolution {
            t_s: t_ns as f64 * 1e-9,
            pos_mci_m: pos,
            vel_mci_m_s: vel,
            q_mci_from_body: q,
            rate_body_rad_s: Vector3::from(n.rate_body_rad_s),
            specific_force_body_m_s2: f_body,
            altitude_m: alt,
            mass_kg: tlm.mass_estimate_kg,
            up_mci: pos / r,
            gravity_m_s2: self.mu_m3_s2 / (r * r),
            omega_moon_mci: self.omega_moon_mci,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_shared::PacketHeader;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::StandardNormal;

    /// True (position, velocity) per step.
    type Truth = Vec<(Vector3<f64>, Vector3<f64>)>;

    /// Free fall from 5 km with 300 m/s horizontal, truth integrated with 1 ms steps.
    fn truth_and_telemetry(
        cfg: &GncConfig,
        noise: Option<&mut ChaCha8Rng>,
    ) -> (Truth, Vec<Telemetry>) {
        let mut noise = noise;
        let radius = 1_737_400.0 + 1.2;
        let mut r = Vector3::new(radius + 5_000.0, 0.0, 0.0);
        let mut v = Vector3::new(-20.0, 300.0, 0.0);
        let (mut truth, mut tlm) = (Vec::new(), Vec::new());
        for k in 0..10_000i64 {
            let mut t = Telemetry {
                header: PacketHeader::new(1, k as u64, k * 10_000_000),
                ..Default::default()
            };
            t.nav.q_mci_from_body = [1.0, 0.0, 0.0, 0.0];
            t.nav.pos_mci_m = r.into();
            t.nav.vel_mci_m_s = v.into();
            t.altitude_m = r.norm() - radius;
            if let Some(rng) = noise.as_deref_mut() {
                for i in 0..3 {
                    t.nav.pos_mci_m[i] += 5.0 * rng.sample::<f64, _>(StandardNormal);
                    t.nav.vel_mci_m_s[i] += 0.05 * rng.sample::<f64, _>(StandardNormal);
                }
                t.altitude_m += 0.5 * rng.sample::<f64, _>(StandardNormal);
            }
            truth.push((r, v));
            tlm.push(t);
            for _ in 0..10 {
                let a = -r * (cfg.moon_mu_m3_s2 / r.norm().powi(3));
                v += a * 1e-3;
                r += v * 1e-3;
            }
        }
        (truth, tlm)
    }

    #[test]
    fn follows_clean_measurements() {
        let cfg = GncConfig::default();
        let (truth, tlm) = truth_and_telemetry(&cfg, None);
        let mut f = NavFilter::new(&cfg);
        let mut worst: (f64, f64) = (0.0, 0.0);
        for (t, (r, v)) in tlm.iter().zip(truth.iter()) {
            let s = f.update(t);
            worst.0 = worst.0.max((s.pos_mci_m - r).norm());
            worst.1 = worst.1.max((s.vel_mci_m_s - v).norm());
        }
        assert!(worst.0 < 0.01 && worst.1 < 1e-3, "{worst:?}");
    }

    #[test]
    fn averages_white_noise_down() {
        let cfg = GncConfig::default();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (truth, tlm) = truth_and_telemetry(&cfg, Some(&mut rng));
        let mut f = NavFilter::new(&cfg);
        let (mut pos_sq, mut vel_sq, mut alt_sq, mut n) = (0.0, 0.0, 0.0, 0.0);
        for (k, (t, (r, v))) in tlm.iter().zip(truth.iter()).enumerate() {
            let s = f.update(t);
            if k > 2_000 {
                pos_sq += (s.pos_mci_m - r).norm_squared() / 3.0;
                vel_sq += (s.vel_mci_m_s - v).norm_squared() / 3.0;
                let alt = r.norm() - 1_737_401.2;
                alt_sq += (s.altitude_m - alt).powi(2);
                n += 1.0;
            }
        }
        let (pos, vel, alt) = (
            (pos_sq / n).sqrt(),
            (vel_sq / n).sqrt(),
            (alt_sq / n).sqrt(),
        );
        // A gain k keeps about sqrt(k / (2 - k)) of white noise: 0.07, 0.1, 0.16.
        assert!(pos < 0.15 * 5.0, "position rms {pos}");
        assert!(vel < 0.2 * 0.05, "velocity rms {vel}");
        assert!(alt < 0.3 * 0.5, "altitude rms {alt}");
    }
}
