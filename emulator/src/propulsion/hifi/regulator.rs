//! Helium pressure regulator: a poppet on a spring, closed by the outlet pressure on a
//! sensing diaphragm, with a small outlet volume feeding the check valves.
//!
//! Force balance on the moving parts (lift `x` opening):
//! `m x'' = F_pre - k x - A_d p_out - A_u (p_in - p_out) - c x'`.
//! The flow area is the curtain `pi D x`, up to the seat area at `x = D / 4`. The
//! behaviours that matter follow from it without being programmed in:
//! - lock-up: with no demand the outlet pressure rises until the poppet seats;
//! - droop: more flow needs more lift, and more lift means less spring force, so the
//!   outlet pressure falls with flow (more so as the inlet pressure falls, because the
//!   same flow then needs more lift);
//! - supply-pressure effect: the unbalanced area makes the outlet creep up as the
//!   bottle empties;
//! - drop-out: once the bottle is too close to the set pressure the poppet is wide open
//!   and the outlet follows the bottle down.

use super::gas::Helium;
use super::params::RegulatorParams;

/// Regulator constants, precomputed.
#[derive(Debug, Clone, Copy)]
pub struct Regulator {
    sensing_area_m2: f64,
    unbalanced_area_m2: f64,
    spring_rate_n_m: f64,
    inv_mass_kg: f64,
    damping_n_s_m: f64,
    preload_n: f64,
    curtain_per_lift_m: f64,
    /// Lift at which the curtain area equals the seat area, m.
    pub max_lift_m: f64,
    cd: f64,
    /// Outlet volume, m^3.
    pub outlet_volume_m3: f64,
}

impl Regulator {
    /// Constants from parameters; the spring preload puts lock-up at
    /// `lockup_pressure_pa` when the inlet is at `initial_inlet_pa`.
    pub fn new(p: &RegulatorParams, initial_inlet_pa: f64) -> Self {
        let preload_n = p.sensing_area_m2 * p.lockup_pressure_pa
            + p.unbalanced_area_m2 * (initial_inlet_pa - p.lockup_pressure_pa);
        Self {
            sensing_area_m2: p.sensing_area_m2,
            unbalanced_area_m2: p.unbalanced_area_m2,
            spring_rate_n_m: p.spring_rate_n_m,
            inv_mass_kg: 1.0 / p.moving_mass_kg,
            damping_n_s_m: 2.0 * p.damping_ratio * (p.spring_rate_n_m * p.moving_mass_kg).sqrt(),
            preload_n,
            curtain_per_lift_m: std::f64::consts::PI * p.seat_diameter_m,
            max_lift_m: p.seat_diameter_m / 4.0,
            cd: p.discharge_coefficient,
            outlet_volume_m3: p.outlet_volume_m3,
        }
    }

    /// Effective flow area (Cd A) at a lift, m^2.
    #[inline]
    pub fn cd_area(&self, lift_m: f64) -> f64 {
        self.cd * self.curtain_per_lift_m * lift_m.clamp(0.0, self.max_lift_m)
    }

    /// Acceleration of the moving parts, m/s^2, and its derivative with respect to
    /// velocity (the damping term, for the integrator's implicit diagonal).
    #[inline]
    pub fn acceleration(&self, lift_m: f64, vel_m_s: f64, p_in: f64, p_out: f64) -> (f64, f64) {
        let force = self.preload_n
            - self.spring_rate_n_m * lift_m
            - self.sensing_area_m2 * p_out
            - self.unbalanced_area_m2 * (p_in - p_out)
            - self.damping_n_s_m * vel_m_s;
        (
            force * self.inv_mass_kg,
            -self.damping_n_s_m * self.inv_mass_kg,
        )
    }

    /// Moves the lock-up (set) pressure by `dp_pa`: the spring preload a set-point
    /// adjustment (or a drifting spring) changes.
    pub fn shift_set_point(&mut self, dp_pa: f64) {
        self.preload_n += (self.sensing_area_m2 - self.unbalanced_area_m2) * dp_pa;
    }

    /// Outlet pressure at which the poppet is in equilibrium at a lift, Pa (the static
    /// regulation characteristic; used for reports and tests).
    pub fn static_outlet_pa(&self, lift_m: f64, p_in: f64) -> f64 {
        (self.preload_n - self.spring_rate_n_m * lift_m - self.unbalanced_area_m2 * p_in)
            / (self.sensing_area_m2 - self.unbalanced_area_m2)
    }

    /// Hard stops: the seat at zero lift and the full-open stop. Applied after each
    /// sub-step; the impact is inelastic.
    #[inline]
    pub fn apply_stops(&self, lift_m: &mut f64, vel_m_s: &mut f64) {
        if *lift_m <= 0.0 {
            *lift_m = 0.0;
            *vel_m_s = vel_m_s.max(0.0);
        } else if *lift_m >= self.max_lift_m {
            *lift_m = self.max_lift_m;
            *vel_m_s = vel_m_s.min(0.0);
        }
    }
}

/// State of the gas downstream of the poppet: the outlet volume holds helium that
/// went through an isenthalpic expansion from the bottle.
#[derive(Debug, Clone, Copy, Default)]
pub struct OutletGas {
    /// Pressure, Pa.
    pub pressure_pa: f64,
    /// Density, kg/m^3.
    pub density_kg_m3: f64,
    /// Temperature, K.
    pub temperature_k: f64,
    /// Specific enthalpy (equal to the bottle's), J/kg.
    pub enthalpy_j_kg: f64,
}

impl OutletGas {
    /// Outlet state from the gas mass in the outlet volume and the bottle's enthalpy.
    #[inline]
    pub fn new(he: &Helium, mass_kg: f64, volume_m3: f64, bottle_enthalpy_j_kg: f64) -> Self {
        let rho = mass_kg.max(0.0) / volume_m3;
        let t = he.temperature_from_enthalpy(bottle_enthalpy_j_kg, rho);
        Self {
            pressure_pa: he.pressure(rho, t),
            density_kg_m3: rho,
            temperature_k: t,
            enthalpy_j_kg: bottle_enthalpy_j_kg,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lockup_at_set_and_droop_with_lift() {
        let p = RegulatorParams::default();
        let r = Regulator::new(&p, 280e5);
        assert!((r.static_outlet_pa(0.0, 280e5) - p.lockup_pressure_pa).abs() < 1.0);
        let lift = 4e-5;
        let droop = r.static_outlet_pa(0.0, 280e5) - r.static_outlet_pa(lift, 280e5);
        assert!(droop > 0.0);
        // Supply-pressure effect: the outlet creeps up as the inlet falls.
        assert!(r.static_outlet_pa(0.0, 50e5) > r.static_outlet_pa(0.0, 280e5));
    }

    #[test]
    fn stops_are_inelastic() {
        let r = Regulator::new(&RegulatorParams::default(), 280e5);
        let (mut x, mut v) = (-1e-6, -0.1);
        r.apply_stops(&mut x, &mut v);
        assert_eq!((x, v), (0.0, 0.0));
        let (mut x, mut v) = (1.0, 0.3);
        r.apply_stops(&mut x, &mut v);
        assert_eq!((x, v), (r.max_lift_m, 0.0));
    }
}
