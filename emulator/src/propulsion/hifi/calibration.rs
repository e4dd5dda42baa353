//! Throttle calibration: commanded thrust to TFCV positions.
//!
//! The flight system commands thrust; the valves need positions. Like a real engine's
//! acceptance-test table, the map is made once, at nominal conditions: tank pressure
//! at its nominal value, all four engines at the same thrust, the nominal mixture
//! ratio. It is solved in closed form from the model's own steady-state equations, so
//! at those conditions steady thrust equals command (up to TFCV quantisation and
//! backlash). Away from them (an engine at another level, the regulator drooping, the
//! ullage drifting) the thrust departs from the command as the physics says: that is
//! the open-loop error the onboard loop and the surrogate have to live with.

use super::engine::{Chamber, EngineSide};
use super::fluid::{friction_phi, Feed};
use super::HifiError;

/// Commanded thrust to TFCV positions `[fuel, ox]`, by linear interpolation in a table
/// with 1 N spacing (interpolation error far below the command quantum).
#[derive(Debug, Clone, PartialEq)]
pub struct ThrottleTable {
    min_thrust_n: f64,
    max_thrust_n: f64,
    step_n: f64,
    positions: Vec<[f64; 2]>,
}

/// Steady-state conditions the table is made at.
#[derive(Debug, Clone, Copy)]
pub struct CalibrationPoint<'a> {
    /// Chamber constants.
    pub chamber: &'a Chamber,
    /// Feeds `[fuel, ox]`.
    pub feeds: [&'a Feed; 2],
    /// Engine sides `[fuel, ox]`.
    pub sides: [&'a EngineSide; 2],
    /// Tank pressure, Pa.
    pub tank_pressure_pa: f64,
    /// Oxidiser-to-fuel mass ratio.
    pub mixture_ratio: f64,
    /// Engines sharing each manifold at the same thrust.
    pub engines: usize,
}

impl CalibrationPoint<'_> {
    /// TFCV positions `[fuel, ox]` giving `thrust_n` in steady state.
    pub fn positions(&self, thrust_n: f64) -> Result<[f64; 2], HifiError> {
        let ch = self.chamber;
        let pc = thrust_n / (ch.thrust_coefficient * ch.throat_area_m2);
        let cstar = ch.efficiency(pc) * ch.cstar_ideal(self.mixture_ratio, 1.0);
        let total = pc * ch.throat_area_m2 / cstar;
        let mr = self.mixture_ratio;
        let flows = [total / (1.0 + mr), total * mr / (1.0 + mr)];
        let mut out = [0.0; 2];
        for p in 0..2 {
            let (feed, side, m) = (self.feeds[p], self.sides[p], flows[p]);
            let main = self.engines as f64 * m;
            let p_manifold = self.tank_pressure_pa
                - feed.main_resistance * friction_phi(main, feed.main_laminar_kg_s);
            let phi = friction_phi(m, side.laminar_kg_s);
            let fixed =
                side.line_resistance + side.solenoid_resistance_open + side.injector_resistance;
            let r_tfcv = (p_manifold - pc) / phi - fixed;
            let position = if r_tfcv > 0.0 {
                (side.tfcv_resistance_full / r_tfcv).sqrt()
            } else {
                f64::INFINITY
            };
            if !(position > 0.0 && position <= 1.0) {
                return Err(HifiError::Calibration {
                    thrust_n,
                    propellant: if p == 0 { "fuel" } else { "oxidiser" },
                    why: "the TFCV cannot pass the flow at nominal tank pressure (needs more than full stroke)",
                });
            }
            out[p] = position;
        }
        Ok(out)
    }
}

impl CalibrationPoint<'_> {
    /// The fraction of the injector area `Cd A` `[fuel, ox]` that leaves an engine at
    /// `thrust_fraction` of `thrust_n` in steady state, its valves where the table puts
    /// them for `thrust_n` and the other engines healthy: how a thrust loss stated as a
    /// fraction (`thrust-degraded`, the surrogate's and ideal model's output factor) is
    /// made a clog in hifi. Both injectors shrink so that each side passes the same
    /// fraction of its flow, which keeps the mixture ratio.
    ///
    /// With the chamber at `k Pc` (thrust `Cf Pc At`, `k` the fraction), the degraded
    /// flow `m' = k Pc At / c*(k Pc)` must cross `p_manifold - k Pc` through the healthy
    /// series resistances plus the injector's `R_inj / a^2`: solving for `a` gives
    /// `a = sqrt(R_inj / ((p_manifold - k Pc) / phi(m') - R_series))`.
    pub fn injector_open_frac(
        &self,
        thrust_n: f64,
        thrust_fraction: f64,
    ) -> Result<[f64; 2], HifiError> {
        if thrust_fraction >= 1.0 {
            return Ok([1.0; 2]);
        }
        if thrust_fraction <= 0.0 {
            return Ok([0.0; 2]);
        }
        let positions = self.positions(thrust_n)?;
        let ch = self.chamber;
        let mr = self.mixture_ratio;
        let flows_at = |pc: f64| {
            let total = pc * ch.throat_area_m2 / (ch.efficiency(pc) * ch.cstar_ideal(mr, 1.0));
            [total / (1.0 + mr), total * mr / (1.0 + mr)]
        };
        let pc = thrust_n / (ch.thrust_coefficient * ch.throat_area_m2);
        let pc_degraded = thrust_fraction * pc;
        let healthy = flows_at(pc);
        let degraded = flows_at(pc_degraded);
        let mut out = [1.0; 2];
        for p in 0..2 {
            let (feed, side) = (self.feeds[p], self.sides[p]);
            let main = (self.engines as f64 - 1.0) * healthy[p] + degraded[p];
            let p_manifold = self.tank_pressure_pa
                - feed.main_resistance * friction_phi(main, feed.main_laminar_kg_s);
            let series = side
                .series_resistance(1.0, positions[p])
                .unwrap_or(f64::INFINITY);
            let r_injector =
                (p_manifold - pc_degraded) / friction_phi(degraded[p], side.laminar_kg_s) - series;
            out[p] = if r_injector > side.injector_resistance {
                (side.injector_resistance / r_injector).sqrt()
            } else {
                1.0
            };
        }
        Ok(out)
    }
}

impl ThrottleTable {
    /// Solves the calibration over `[min_thrust_n, max_thrust_n]`.
    pub fn build(
        at: &CalibrationPoint,
        min_thrust_n: f64,
        max_thrust_n: f64,
    ) -> Result<Self, HifiError> {
        let n = ((max_thrust_n - min_thrust_n).ceil() as usize).max(1);
        let step_n = (max_thrust_n - min_thrust_n) / n as f64;
        let positions = (0..=n)
            .map(|i| at.positions(min_thrust_n + step_n * i as f64))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            min_thrust_n,
            max_thrust_n,
            step_n,
            positions,
        })
    }

    /// Positions `[fuel, ox]` for a thrust command, clamped to the throttle range.
    #[inline]
    pub fn positions(&self, thrust_n: f64) -> [f64; 2] {
        if self.step_n <= 0.0 {
            return self.positions[0];
        }
        let f = thrust_n.clamp(self.min_thrust_n, self.max_thrust_n);
        let u = (f - self.min_thrust_n) / self.step_n;
        let i = (u.floor() as usize).min(self.positions.len() - 2);
        let w = u - i as f64;
        let (a, b) = (self.positions[i], self.positions[i + 1]);
        [a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1])]
    }
}
