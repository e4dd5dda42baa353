//! Seeded Gaussian navigation noise added to telemetry.
//!
//! One ChaCha8 stream of its own: seeded from the run seed and switched to
//! [`NAV_NOISE_STREAM`], so a random stream added elsewhere later never shifts it.

use crate::config::NavNoiseConfig;
use oils_shared::Telemetry;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// ChaCha stream id of the navigation noise (fixed; other streams take other ids).
pub const NAV_NOISE_STREAM: u64 = 0x6e61_765f_6e6f_6973; // "nav_nois"

/// Adds one-sigma noise of the configured sizes to navigation fields.
#[derive(Debug, Clone)]
pub struct NavNoise {
    /// One-sigma sizes: position m, velocity m/s, rate rad/s, specific force m/s^2,
    /// altitude m.
    sigma: [f64; 5],
    rng: ChaCha8Rng,
}

impl NavNoise {
    /// A noise source for run `seed`.
    pub fn new(sigma: &NavNoiseConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(NAV_NOISE_STREAM);
        Self {
            sigma: [
                sigma.position_m,
                sigma.velocity_m_s,
                sigma.rate_rad_s,
                sigma.accel_m_s2,
                sigma.altitude_m,
            ],
            rng,
        }
    }

    fn gauss(&mut self, sigma: f64) -> f64 {
        let n: f64 = self.rng.sample(StandardNormal);
        n * sigma
    }

    /// Perturbs position, velocity, rate, specific force and altitude, in that fixed
    /// order (the order is part of the determinism contract). Attitude stays exact.
    pub fn apply(&mut self, tlm: &mut Telemetry) {
        let s = self.sigma;
        for i in 0..3 {
            tlm.nav.pos_mci_m[i] += self.gauss(s[0]);
        }
        for i in 0..3 {
            tlm.nav.vel_mci_m_s[i] += self.gauss(s[1]);
        }
        for i in 0..3 {
            tlm.nav.rate_body_rad_s[i] += self.gauss(s[2]);
        }
        for i in 0..3 {
            tlm.accel_body_m_s2[i] += self.gauss(s[3]);
        }
        tlm.altitude_m += self.gauss(s[4]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_noise_other_seed_other_noise() {
        let cfg = NavNoiseConfig::default();
        let run = |seed| {
            let mut n = NavNoise::new(&cfg, seed);
            let mut t = Telemetry::default();
            n.apply(&mut t);
            t
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }

    #[test]
    fn noise_has_configured_spread() {
        let cfg = NavNoiseConfig::default();
        let mut n = NavNoise::new(&cfg, 1);
        let count = 20_000;
        let mut sum_sq = 0.0;
        for _ in 0..count {
            let mut t = Telemetry::default();
            n.apply(&mut t);
            sum_sq += t.nav.pos_mci_m[0] * t.nav.pos_mci_m[0];
        }
        let sigma = (sum_sq / count as f64).sqrt();
        // Standard error of a sigma estimate from 20k samples is ~0.5 %.
        assert!((sigma / cfg.position_m - 1.0).abs() < 0.03, "sigma {sigma}");
    }
}

/// ChaCha stream id of the ground's state-vector error (fixed, apart from the others).
pub const STATE_VECTOR_STREAM: u64 = 0x7374_6174_6576_6563; // "statevec"

/// The ground's orbit determination: the true position and velocity plus a seeded error
/// of the configured one-sigma sizes, drawn afresh for every uplink (the descent start,
/// each computer reset) from its own stream.
#[derive(Debug, Clone)]
pub struct StateVectorUplink {
    sigma_pos_m: f64,
    sigma_vel_m_s: f64,
    rng: ChaCha8Rng,
}

impl StateVectorUplink {
    /// The uplinks of run `seed`.
    pub fn new(cfg: &crate::config::StateVectorConfig, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(STATE_VECTOR_STREAM);
        Self {
            sigma_pos_m: cfg.position_sigma_m,
            sigma_vel_m_s: cfg.velocity_sigma_m_s,
            rng,
        }
    }

    /// Adds one uplink's error to `nav` (position, then velocity, x y z each).
    pub fn apply(&mut self, nav: &mut oils_shared::NavState) {
        for i in 0..3 {
            let n: f64 = self.rng.sample(StandardNormal);
            nav.pos_mci_m[i] += n * self.sigma_pos_m;
        }
        for i in 0..3 {
            let n: f64 = self.rng.sample(StandardNormal);
            nav.vel_mci_m_s[i] += n * self.sigma_vel_m_s;
        }
    }
}
