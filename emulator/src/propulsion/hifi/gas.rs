//! Helium: equation of state, energy of a gas volume, and orifice flow.
//!
//! Real gas by a truncated virial series in density, `p = rho R T (1 + B rho + C rho^2)`,
//! with B and C independent of temperature. At 280 bar and 293 K helium's
//! compressibility is Z ~ 1.13: an ideal gas would over-state the stored mass by ~13 %.
//! With B and C constant the internal energy has no density term (`u = c_v T`, because
//! the departure function is `-R T^2 rho dB/dT ... = 0`), which keeps the energy
//! balances exact and cheap. Stated error against the reference equation of state
//! (checked in `virial_matches_reference_helium_data`): density within 0.3 % over
//! 200-310 K and 17-280 bar (0.6 % at 150 K, 280 bar); neglecting the real-gas part of
//! the internal energy and heat capacity costs ~1-2 % in the bottle's energy balance.

use super::params::HeliumParams;

/// Helium properties, precomputed from the parameters.
#[derive(Debug, Clone, Copy)]
pub struct Helium {
    /// Specific gas constant, J/(kg K).
    pub r: f64,
    /// Specific heat at constant volume (ideal part), J/(kg K).
    pub cv: f64,
    /// Ratio of specific heats.
    pub gamma: f64,
    b: f64,
    c: f64,
    /// Critical pressure ratio `(2/(gamma+1))^(gamma/(gamma-1))`.
    critical_ratio: f64,
    /// The subsonic flow function `r^(2/g) - r^((g+1)/g)` at the critical ratio.
    critical_psi2: f64,
    /// Subsonic factor `2 gamma / (gamma - 1)`.
    subsonic_factor: f64,
}

impl Helium {
    /// Properties from parameters.
    pub fn new(p: &HeliumParams) -> Self {
        let g = p.gamma;
        let rc = (2.0 / (g + 1.0)).powf(g / (g - 1.0));
        Self {
            r: p.gas_constant_j_kg_k,
            cv: p.gas_constant_j_kg_k / (g - 1.0),
            gamma: g,
            b: p.virial_b_m3_kg,
            c: p.virial_c_m6_kg2,
            critical_ratio: rc,
            critical_psi2: rc.powf(2.0 / g) - rc.powf((g + 1.0) / g),
            subsonic_factor: 2.0 * g / (g - 1.0),
        }
    }

    /// Compressibility factor Z at a density, kg/m^3.
    #[inline]
    pub fn z(&self, rho: f64) -> f64 {
        1.0 + rho * (self.b + self.c * rho)
    }

    /// Pressure, Pa, from density (kg/m^3) and temperature (K).
    #[inline]
    pub fn pressure(&self, rho: f64, t_k: f64) -> f64 {
        rho * self.r * t_k * self.z(rho)
    }

    /// Specific enthalpy, J/kg: `c_v T + p / rho`.
    #[inline]
    pub fn enthalpy(&self, rho: f64, t_k: f64) -> f64 {
        t_k * (self.cv + self.r * self.z(rho))
    }

    /// Temperature of gas at density `rho` with specific enthalpy `h`: where an
    /// isenthalpic expansion (a valve, a regulator) lands. Helium above its inversion
    /// temperature warms slightly on throttling, as here.
    #[inline]
    pub fn temperature_from_enthalpy(&self, h: f64, rho: f64) -> f64 {
        h / (self.cv + self.r * self.z(rho))
    }

    /// Density, kg/m^3, at a pressure and temperature (Newton's method; setup only).
    pub fn density(&self, p_pa: f64, t_k: f64) -> f64 {
        let mut rho = p_pa / (self.r * t_k);
        for _ in 0..50 {
            let f = self.pressure(rho, t_k) - p_pa;
            let df = self.r * t_k * (1.0 + rho * (2.0 * self.b + 3.0 * self.c * rho));
            let step = f / df;
            rho -= step;
            if step.abs() < 1e-14 * rho {
                break;
            }
        }
        rho
    }

    /// Mass flow through a gas orifice of effective area `cd_a` (m^2) from an upstream
    /// state `(p_up, rho_up)` to a downstream pressure, kg/s; negative when the
    /// downstream pressure is the higher (then `rho_down` is the source density).
    ///
    /// Isentropic nozzle flow, choked below the critical pressure ratio. Near equal
    /// pressures the flux `sqrt(1 - r)` has an infinite slope; below `laminar_frac` of
    /// the upstream pressure it is blended to a linear law (see [`soft_sqrt`]) so that
    /// a closing regulator does not make the equations stiff.
    #[inline]
    pub fn orifice_flow(
        &self,
        cd_a: f64,
        p_up: f64,
        rho_up: f64,
        p_down: f64,
        rho_down: f64,
        laminar_frac: f64,
    ) -> f64 {
        if cd_a <= 0.0 {
            return 0.0;
        }
        if p_up >= p_down {
            cd_a * self.mass_flux(p_up, rho_up, p_down / p_up, laminar_frac)
        } else {
            -cd_a * self.mass_flux(p_down, rho_down, p_up / p_down, laminar_frac)
        }
    }

    /// Mass flux per unit effective area, kg/(s m^2), for a pressure ratio `ratio`.
    #[inline]
    fn mass_flux(&self, p_up: f64, rho_up: f64, ratio: f64, laminar_frac: f64) -> f64 {
        if p_up <= 0.0 || rho_up <= 0.0 {
            return 0.0;
        }
        let scale = (p_up * rho_up).sqrt();
        let g = self.gamma;
        // Below the critical ratio the flow is choked: the flux stays at its value at
        // the critical ratio (evaluated with the same blend, so the two branches join
        // exactly).
        let psi2 = if ratio <= self.critical_ratio {
            self.critical_psi2
        } else {
            ratio.powf(2.0 / g) - ratio.powf((g + 1.0) / g)
        };
        // psi2 ~ (g-1)/g (1 - ratio) near ratio 1: blend there.
        let psi2_laminar = (g - 1.0) / g * laminar_frac;
        scale * self.subsonic_factor.sqrt() * soft_sqrt(psi2.max(0.0), psi2_laminar)
    }
}

/// `sqrt(x)` for `x >> x_lam`, `x / sqrt(x_lam)` for `x << x_lam`, smooth in between;
/// zero and below is zero. Gives orifice and friction laws a finite slope at zero flow.
#[inline]
pub fn soft_sqrt(x: f64, x_lam: f64) -> f64 {
    if x <= 0.0 {
        0.0
    } else {
        x / (x * x + x_lam * x_lam).sqrt().sqrt()
    }
}

/// Incompressible orifice (or check valve) flow for a gas of density `rho`, kg/s:
/// `Cd A sqrt(2 rho dp)`, laminar-blended below `dp_lam`; zero for `dp <= 0`.
#[inline]
pub fn incompressible_orifice_flow(cd_a: f64, rho: f64, dp: f64, dp_lam: f64) -> f64 {
    cd_a * (2.0 * rho.max(0.0)).sqrt() * soft_sqrt(dp, dp_lam)
}

/// Relative pressure difference below which gas orifice flow is blended to linear
/// (numerical regularisation, see [`Helium::orifice_flow`]).
pub const GAS_LAMINAR_FRAC: f64 = 2e-3;

/// Helium bottle with a wall that exchanges heat with the gas, and the high-pressure
/// latch valve at its outlet.
#[derive(Debug, Clone, Copy)]
pub struct Bottle {
    /// Internal volume, m^3.
    pub volume_m3: f64,
    wall_heat_capacity_j_k: f64,
    wall_ua_w_k: f64,
    ambient_ua_w_k: f64,
    ambient_temperature_k: f64,
    /// Effective latch valve area (Cd A), m^2; zero when the latch is closed.
    pub latch_cd_area_m2: f64,
}

/// Rates of the bottle states.
#[derive(Debug, Clone, Copy, Default)]
pub struct BottleRates {
    /// Gas temperature rate, K/s.
    pub dgas_temp_k_s: f64,
    /// Wall temperature rate, K/s.
    pub dwall_temp_k_s: f64,
}

impl Bottle {
    /// Constants from parameters.
    pub fn new(p: &super::params::BottleParams) -> Self {
        Self {
            volume_m3: p.volume_m3,
            wall_heat_capacity_j_k: p.wall_mass_kg * p.wall_specific_heat_j_kg_k,
            wall_ua_w_k: p.wall_heat_transfer_w_k,
            ambient_ua_w_k: p.ambient_heat_transfer_w_k,
            ambient_temperature_k: p.ambient_temperature_k,
            // Cd ~ 1 for a full-bore latch valve: its area is already effective.
            latch_cd_area_m2: if p.latch_valve_open {
                p.latch_flow_area_m2
            } else {
                0.0
            },
        }
    }

    /// Temperature rates for an outflow `out_kg_s`.
    ///
    /// Open system with `u = c_v T`: `m c_v dT/dt = -mdot (h - u) + Q = -mdot p/rho + Q`,
    /// i.e. the gas left behind does the flow work of pushing the rest out.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn rates(
        &self,
        he: &Helium,
        gas_kg: f64,
        gas_temp_k: f64,
        wall_temp_k: f64,
        pressure_pa: f64,
        density: f64,
        out_kg_s: f64,
    ) -> BottleRates {
        let q_wall = self.wall_ua_w_k * (wall_temp_k - gas_temp_k);
        let q_amb = self.ambient_ua_w_k * (self.ambient_temperature_k - wall_temp_k);
        BottleRates {
            dgas_temp_k_s: (-out_kg_s * pressure_pa / density + q_wall) / (gas_kg * he.cv),
            dwall_temp_k_s: (q_amb - q_wall) / self.wall_heat_capacity_j_k,
        }
    }

    /// Effective area of the latch valve in series with a downstream area, m^2:
    /// `1 / A^2 = 1 / A_1^2 + 1 / A_2^2` (the incompressible series rule).
    #[inline]
    pub fn in_series_with_latch(&self, cd_a: f64) -> f64 {
        let l = self.latch_cd_area_m2;
        if l <= 0.0 || cd_a <= 0.0 {
            0.0
        } else {
            l * cd_a / (l * l + cd_a * cd_a).sqrt()
        }
    }
}

/// Check valve from the regulator outlet into a tank ullage: flows only forward, and
/// only once the pressure difference exceeds the cracking pressure.
#[derive(Debug, Clone, Copy)]
pub struct CheckValve {
    cd_area_m2: f64,
    crack_pa: f64,
    laminar_dp_pa: f64,
}

impl CheckValve {
    /// Constants from parameters.
    pub fn new(p: &super::params::CheckValveParams) -> Self {
        Self {
            cd_area_m2: p.discharge_coefficient * p.flow_area_m2,
            crack_pa: p.crack_pressure_pa,
            laminar_dp_pa: p.laminar_dp_pa,
        }
    }

    /// Flow, kg/s, from gas of density `rho_up` at `p_up` into `p_down`.
    #[inline]
    pub fn flow(&self, p_up: f64, rho_up: f64, p_down: f64) -> f64 {
        incompressible_orifice_flow(
            self.cd_area_m2,
            rho_up,
            p_up - p_down - self.crack_pa,
            self.laminar_dp_pa,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn he() -> Helium {
        Helium::new(&HeliumParams::default())
    }

    #[test]
    fn density_inverts_pressure() {
        let h = he();
        for (p, t) in [(280e5, 293.15), (17e5, 250.0), (1e5, 150.0)] {
            let rho = h.density(p, t);
            assert!((h.pressure(rho, t) - p).abs() < 1e-6 * p);
        }
    }

    /// Reference densities of helium (see `reference.rs`): the truncated virial series
    /// must stay within 0.5 % of them over the bottle's range; an ideal gas misses the
    /// high-pressure points by more than 10 %.
    #[test]
    fn virial_matches_reference_helium_data() {
        let h = he();
        for &(p, t, rho_ref) in super::super::reference::HELIUM_DENSITY {
            let rho = h.density(p, t);
            let err = (rho - rho_ref) / rho_ref;
            assert!(
                err.abs() < 0.005,
                "p {p} T {t}: {rho} vs {rho_ref} ({err:+.4})"
            );
        }
        let (p, t, rho_ref) = super::super::reference::HELIUM_DENSITY[0];
        let ideal = p / (h.r * t);
        assert!(
            (ideal - rho_ref) / rho_ref > 0.10,
            "first point must be dense"
        );
    }

    #[test]
    fn choked_and_subsonic_flow_join_continuously() {
        let h = he();
        let (p, rho) = (50e5, h.density(50e5, 250.0));
        let rc = h.critical_ratio;
        let below = h.orifice_flow(1e-6, p, rho, p * (rc - 1e-9), 1.0, 0.01);
        let above = h.orifice_flow(1e-6, p, rho, p * (rc + 1e-9), 1.0, 0.01);
        assert!((below - above).abs() < 1e-6 * below);
        // Choked flux is the textbook one: sqrt(gamma p rho (2/(g+1))^((g+1)/(g-1))).
        let g = h.gamma;
        let textbook = 1e-6 * (g * p * rho * (2.0 / (g + 1.0)).powf((g + 1.0) / (g - 1.0))).sqrt();
        let deep = h.orifice_flow(1e-6, p, rho, p * 0.1, 1.0, 1e-4);
        assert!(
            (deep - textbook).abs() < 1e-6 * textbook,
            "{deep} {textbook}"
        );
        // Flow falls to zero as the pressures meet and reverses past them.
        let near = h.orifice_flow(1e-6, p, rho, p * 0.999_999, rho, 0.01);
        assert!(near > 0.0 && near < 1e-3 * below);
        let rev = h.orifice_flow(1e-6, p * 0.9, rho * 0.9, p, rho, 0.01);
        assert!(rev < 0.0);
    }

    #[test]
    fn throttling_conserves_enthalpy_and_warms_helium() {
        let h = he();
        let (rho1, t1) = (h.density(280e5, 293.15), 293.15);
        let h1 = h.enthalpy(rho1, t1);
        let rho2 = h.density(17e5, 300.0);
        let t2 = h.temperature_from_enthalpy(h1, rho2);
        assert!(t2 > t1 && t2 < t1 + 25.0, "{t2}");
        assert!((h.enthalpy(rho2, t2) - h1).abs() < 1e-9 * h1);
    }
}
