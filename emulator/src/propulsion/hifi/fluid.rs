//! Fluid module: propellant tanks with their helium ullage, the line from each tank to a
//! manifold shared by the four engines, and the friction laws of liquid elements.
//!
//! - Ullage: real-gas helium (see `gas.rs`) whose volume grows as liquid leaves;
//!   energy balance `m c_v dT/dt = mdot_in (h_in - c_v T) - p dV/dt + Q`.
//! - Main line: incompressible slug with inertance `I = L / A`:
//!   `I dm/dt = p_tank - p_manifold - R m |m|`.
//!   plus an unsteady-friction drop on the flow's departure from its recent mean.
//! - Manifold: liquid compliance `dp/dt = a^2 / V (m_in - sum m_branch)`; every engine
//!   draws from it, so one engine's throttle moves the pressure the others see.

use super::gas::Helium;
use super::params::{FeedLineParams, TankParams, TanksParams};

/// Friction law of a liquid element: `dp = R phi(m)` with
/// `phi(m) = m sqrt(m^2 + m_lam^2)`: turbulent `m |m|` above `m_lam`, laminar (linear)
/// below, so the slope at zero flow is finite and the sign follows the flow.
#[inline]
pub fn friction_phi(m: f64, m_lam: f64) -> f64 {
    m * (m * m + m_lam * m_lam).sqrt()
}

/// Derivative of [`friction_phi`] with respect to the flow.
#[inline]
pub fn friction_phi_slope(m: f64, m_lam: f64) -> f64 {
    let s = (m * m + m_lam * m_lam).sqrt();
    (2.0 * m * m + m_lam * m_lam) / s
}

/// Resistance of a pipe, `dp = R m |m|`: `(f L / D + K) / (2 rho A^2)`, Pa s^2/kg^2.
pub fn pipe_resistance(rho: f64, length_m: f64, dia_m: f64, friction: f64, minor: f64) -> f64 {
    let area = std::f64::consts::PI * dia_m * dia_m / 4.0;
    (friction * length_m / dia_m + minor) / (2.0 * rho * area * area)
}

/// Resistance of an orifice of effective area `cd_a`: `1 / (2 rho (Cd A)^2)`.
pub fn orifice_resistance(rho: f64, cd_a: f64) -> f64 {
    1.0 / (2.0 * rho * cd_a * cd_a)
}

/// Inertance `L / A` of a pipe, 1/m.
pub fn pipe_inertance(length_m: f64, dia_m: f64) -> f64 {
    length_m / (std::f64::consts::PI * dia_m * dia_m / 4.0)
}

/// A propellant tank: constants.
#[derive(Debug, Clone, Copy)]
pub struct Tank {
    /// Internal volume, m^3.
    pub volume_m3: f64,
    /// Liquid density, kg/m^3.
    pub rho_liquid: f64,
    heat_transfer_w_k: f64,
    wall_temperature_k: f64,
    starvation_mass_kg: f64,
}

impl Tank {
    /// Constants from parameters.
    pub fn new(p: &TankParams, shared: &TanksParams) -> Self {
        Self {
            volume_m3: p.volume_m3,
            rho_liquid: p.liquid_density_kg_m3,
            heat_transfer_w_k: shared.ullage_heat_transfer_w_k,
            wall_temperature_k: shared.propellant_temperature_k,
            starvation_mass_kg: shared.starvation_mass_kg,
        }
    }

    /// Ullage volume for a liquid mass, m^3 (never below a millilitre, so a tank
    /// overfilled by a user's numbers fails in `new` instead of dividing by zero here).
    #[inline]
    pub fn ullage_volume_m3(&self, liquid_kg: f64) -> f64 {
        (self.volume_m3 - liquid_kg / self.rho_liquid).max(1e-6)
    }

    /// Ullage density (kg/m^3) and pressure (Pa) for a gas mass, its temperature and
    /// the liquid mass.
    #[inline]
    pub fn ullage_state(
        &self,
        he: &Helium,
        gas_kg: f64,
        temp_k: f64,
        liquid_kg: f64,
    ) -> (f64, f64) {
        let rho = gas_kg / self.ullage_volume_m3(liquid_kg);
        (rho, he.pressure(rho, temp_k))
    }

    /// Rate of change of the ullage temperature, K/s.
    ///
    /// `gas_in_kg_s` enters with enthalpy `h_in`; `liquid_out_kg_s` leaves through the
    /// outlet and grows the ullage by `liquid_out / rho_l`; heat comes from the liquid
    /// and walls.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn ullage_dtemp(
        &self,
        he: &Helium,
        gas_kg: f64,
        temp_k: f64,
        pressure_pa: f64,
        gas_in_kg_s: f64,
        h_in_j_kg: f64,
        liquid_out_kg_s: f64,
    ) -> f64 {
        let dvol = liquid_out_kg_s / self.rho_liquid;
        let q = self.heat_transfer_w_k * (self.wall_temperature_k - temp_k);
        (gas_in_kg_s * (h_in_j_kg - he.cv * temp_k) - pressure_pa * dvol + q) / (gas_kg * he.cv)
    }

    /// Fraction of the ullage pressure that reaches the tank outlet: 1 while the outlet
    /// is covered, falling to 0 as the last `starvation_mass_kg` drains (gas ingestion).
    #[inline]
    pub fn outlet_factor(&self, liquid_kg: f64) -> f64 {
        (liquid_kg / self.starvation_mass_kg).clamp(0.0, 1.0)
    }
}

/// A tank-to-manifold line and its manifold: constants.
#[derive(Debug, Clone, Copy)]
pub struct Feed {
    /// Main line inertance, 1/m.
    pub main_inertance: f64,
    /// Main line resistance, Pa s^2/kg^2.
    pub main_resistance: f64,
    /// Laminar blend flow of the main line, kg/s.
    pub main_laminar_kg_s: f64,
    /// Unsteady-friction resistance, Pa s/kg.
    pub main_unsteady_resistance: f64,
    /// Unsteady-friction averaging time, s.
    pub unsteady_time_s: f64,
    /// Manifold stiffness `a^2 / V`, Pa/kg.
    pub manifold_stiffness: f64,
    /// Branch line inertance, 1/m.
    pub branch_inertance: f64,
    /// Branch line resistance, Pa s^2/kg^2.
    pub branch_resistance: f64,
}

impl Feed {
    /// Constants from parameters; `rated_branch_kg_s` is one engine's flow of this
    /// propellant at rated thrust (sets the laminar blend).
    pub fn new(
        p: &FeedLineParams,
        rho: f64,
        rated_branch_kg_s: f64,
        laminar_frac: f64,
        unsteady_time_s: f64,
    ) -> Self {
        Self {
            main_inertance: pipe_inertance(p.main_line_length_m, p.main_line_diameter_m),
            main_resistance: pipe_resistance(
                rho,
                p.main_line_length_m,
                p.main_line_diameter_m,
                p.main_line_friction_factor,
                p.main_line_minor_loss,
            ),
            main_laminar_kg_s: laminar_frac * 4.0 * rated_branch_kg_s,
            main_unsteady_resistance: p.main_line_unsteady_friction_pa_s_kg,
            unsteady_time_s,
            manifold_stiffness: p.wave_speed_m_s * p.wave_speed_m_s / p.manifold_volume_m3,
            branch_inertance: pipe_inertance(p.branch_line_length_m, p.branch_line_diameter_m),
            branch_resistance: pipe_resistance(
                rho,
                p.branch_line_length_m,
                p.branch_line_diameter_m,
                p.branch_line_friction_factor,
                p.branch_line_minor_loss,
            ),
        }
    }

    /// Liquid stored in the manifold by compression above `p_ref`, kg: the manifold's
    /// share of the mass balance.
    #[inline]
    pub fn manifold_excess_kg(&self, p_pa: f64, p_ref_pa: f64) -> f64 {
        (p_pa - p_ref_pa) / self.manifold_stiffness
    }

    /// Main line flow rate of change, (kg/s)/s, and its slope with respect to the flow;
    /// `slow_kg_s` is the flow's recent mean (unsteady friction).
    #[inline]
    pub fn main_line(
        &self,
        p_outlet: f64,
        p_manifold: f64,
        flow_kg_s: f64,
        slow_kg_s: f64,
    ) -> (f64, f64) {
        let drop = self.main_resistance * friction_phi(flow_kg_s, self.main_laminar_kg_s)
            + self.main_unsteady_resistance * (flow_kg_s - slow_kg_s);
        let slope = self.main_resistance * friction_phi_slope(flow_kg_s, self.main_laminar_kg_s)
            + self.main_unsteady_resistance;
        (
            (p_outlet - p_manifold - drop) / self.main_inertance,
            -slope / self.main_inertance,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn friction_is_odd_turbulent_and_laminar() {
        let ml = 0.01;
        assert_eq!(friction_phi(0.0, ml), 0.0);
        assert!((friction_phi(-0.5, ml) + friction_phi(0.5, ml)).abs() < 1e-15);
        assert!((friction_phi(1.0, ml) - 1.0).abs() < 1e-4);
        assert!((friction_phi(1e-5, ml) - 1e-5 * ml).abs() < 1e-10);
        // Slope by finite differences.
        let m = 0.037;
        let fd = (friction_phi(m + 1e-7, ml) - friction_phi(m - 1e-7, ml)) / 2e-7;
        assert!((fd - friction_phi_slope(m, ml)).abs() < 1e-6);
    }

    #[test]
    fn ullage_expands_and_cools_without_inflow() {
        let he = Helium::new(&Default::default());
        let shared = TanksParams {
            ullage_heat_transfer_w_k: 0.0,
            ..Default::default()
        };
        let tank = Tank::new(&shared.fuel, &shared);
        let liquid = 377.0;
        let vol = tank.ullage_volume_m3(liquid);
        let gas = he.density(17e5, 293.15) * vol;
        let (_, p) = tank.ullage_state(&he, gas, 293.15, liquid);
        assert!((p - 17e5).abs() < 1.0);
        // Adiabatic expansion: dT/dt = -p dV/dt / (m c_v) < 0 ...
        let dt = tank.ullage_dtemp(&he, gas, 293.15, p, 0.0, 0.0, 0.1);
        let expect = -p * 0.1 / tank.rho_liquid / (gas * he.cv);
        assert!((dt - expect).abs() < 1e-12 * expect.abs());
        // ... and gas entering at the ullage's own enthalpy with no outflow heats it
        // (flow work p/rho is done on the ullage).
        let h_in = he.enthalpy(gas / vol, 293.15);
        assert!(tank.ullage_dtemp(&he, gas, 293.15, p, 1e-3, h_in, 0.0) > 0.0);
    }
}
