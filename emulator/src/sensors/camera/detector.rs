//! From I/F to digital numbers: photo-electrons, shot and read noise, the full well and
//! the ADC.
//!
//! ```text
//! e    = (I/F) (F / pi) (pi p^2 / (4 N^2)) t tau (lambda / (h c))
//!      = (I/F) F p^2 t tau lambda / (4 N^2 h c)             (etendue of one pixel)
//! e'   = clamp(e + sqrt(e + sigma_r^2) n, 0, full_well)     (n ~ N(0, 1), one per pixel)
//! DN   = min(round(e' / g), 2^bits - 1),  g = full_well / (2^bits - 1)
//! ```
//!
//! Shot noise is the Gaussian limit of the Poisson count (good above ~20 e-; at lower
//! counts it spreads a little too symmetric); read noise adds in quadrature in the same
//! draw. A pixel is saturated when its charge reaches the full well.

use super::super::gauss;
use crate::sensors::CameraConfig;
use rand_chacha::ChaCha8Rng;

/// Planck's constant times the speed of light, J m (CODATA 2018, exact).
const HC_J_M: f64 = 6.626_070_15e-34 * 299_792_458.0;

/// The sensor chain of a camera, fixed at construction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detector {
    /// Electrons per unit I/F in one exposure.
    pub electrons_per_iof: f64,
    /// Full-well capacity, e-.
    pub full_well_e: f64,
    /// Read noise, e-.
    pub read_noise_e: f64,
    /// Electrons per digital number.
    pub gain_e_per_dn: f64,
    /// Largest digital number, `2^bits - 1`.
    pub max_dn: u16,
    /// Noise on.
    pub noise: bool,
}

impl Detector {
    /// The chain of a validated `cfg`.
    pub fn new(cfg: &CameraConfig) -> Self {
        let p = cfg.pixel_pitch_um * 1e-6;
        let t = cfg.exposure_ms * 1e-3;
        let lambda = cfg.wavelength_nm * 1e-9;
        let electrons_per_iof =
            cfg.solar_band_irradiance_w_m2 * p * p * t * cfg.throughput * lambda
                / (4.0 * cfg.f_number * cfg.f_number * HC_J_M);
        let max_dn = ((1u32 << cfg.bits) - 1) as u16;
        Self {
            electrons_per_iof,
            full_well_e: cfg.full_well_e,
            read_noise_e: cfg.read_noise_e,
            gain_e_per_dn: cfg.full_well_e / max_dn as f64,
            max_dn,
            noise: cfg.noise,
        }
    }

    /// The digital number of a pixel collecting `electrons` (the expected charge), and
    /// whether it saturated. Draws exactly one normal whether or not noise is on.
    #[inline]
    pub fn read(&self, electrons: f64, rng: &mut ChaCha8Rng) -> (u16, bool) {
        let n = gauss(rng);
        let e = if self.noise {
            electrons + (electrons.max(0.0) + self.read_noise_e * self.read_noise_e).sqrt() * n
        } else {
            electrons
        };
        let e = e.clamp(0.0, self.full_well_e);
        let dn = (e / self.gain_e_per_dn).round().min(self.max_dn as f64) as u16;
        (dn, e >= self.full_well_e)
    }

    /// The noiseless digital number of an I/F (what tests compare against).
    pub fn expected_dn(&self, iof: f64) -> u16 {
        let e = (iof * self.electrons_per_iof).clamp(0.0, self.full_well_e);
        (e / self.gain_e_per_dn).round().min(self.max_dn as f64) as u16
    }
}
