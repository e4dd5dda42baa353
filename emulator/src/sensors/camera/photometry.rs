//! Reflectance of the lunar surface: McEwen's lunar-Lambert function (McEwen 1996,
//! "A precise lunar photometric function", LPSC XXVII, 841; the coefficients as in USGS
//! ISIS's `LunarLambertMcEwen`):
//!
//! ```text
//! I/F = A [ 2 L(a) mu0 / (mu0 + mu) + (1 - L(a)) mu0 ]
//! L(a) = 1 - 0.019 a + 2.42e-4 a^2 - 1.46e-6 a^3          (a: phase angle, degrees)
//! ```
//!
//! `mu0` the cosine of the incidence (sun to normal), `mu` of the emission (viewer to
//! normal), `A` the normal albedo (at `a = 0`, `mu0 = mu = 1`, I/F = A). The
//! Lommel-Seeliger term `mu0/(mu0+mu)` makes a full Moon a uniformly bright disk; the
//! Lambert term takes over towards large phase. Radiance `I = (I/F) F / pi` for a
//! solar irradiance `F`.

use nalgebra::Vector3;

/// McEwen's phase weight `L(a)`, `a` in degrees.
#[inline]
pub fn mcewen_l(phase_deg: f64) -> f64 {
    let a = phase_deg;
    1.0 + a * (-0.019 + a * (2.42e-4 - 1.46e-6 * a))
}

/// Lunar-Lambert I/F for `mu0`, `mu` and the phase angle in degrees; 0 where the sun
/// or the viewer is below the local horizon (`mu0 <= 0` or `mu <= 0`).
#[inline]
pub fn lunar_lambert_iof(albedo: f64, mu0: f64, mu: f64, phase_deg: f64) -> f64 {
    if mu0 <= 0.0 || mu <= 0.0 {
        return 0.0;
    }
    let l = mcewen_l(phase_deg);
    albedo * (2.0 * l * mu0 / (mu0 + mu) + (1.0 - l) * mu0)
}

/// I/F of a surface element with unit normal `normal`, seen along the unit ray `view`
/// (viewer to surface) under the unit sun direction `sun` (surface to sun), all in one
/// frame. Shadowing is the caller's.
#[inline]
pub fn iof_at(albedo: f64, normal: &Vector3<f64>, view: &Vector3<f64>, sun: &Vector3<f64>) -> f64 {
    let mu0 = normal.dot(sun);
    let mu = -normal.dot(view);
    let cos_phase = (-view.dot(sun)).clamp(-1.0, 1.0);
    lunar_lambert_iof(albedo, mu0, mu, cos_phase.acos().to_degrees())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closed_form_values() {
        // a = 0: L = 1, pure Lommel-Seeliger; normal view and sun: I/F = A.
        assert!((lunar_lambert_iof(0.12, 1.0, 1.0, 0.0) - 0.12).abs() < 1e-15);
        // a = 60: L = 1 - 1.14 + 0.8712 - 0.31536 = 0.41584.
        assert!((mcewen_l(60.0) - 0.41584).abs() < 1e-12);
        let mu0 = 0.5f64;
        let r = lunar_lambert_iof(0.1, mu0, 1.0, 60.0);
        let want = 0.1 * (2.0 * 0.41584 * 0.5 / 1.5 + (1.0 - 0.41584) * 0.5);
        assert!((r - want).abs() < 1e-12);
        assert_eq!(lunar_lambert_iof(0.1, -0.1, 1.0, 30.0), 0.0);
    }
}
