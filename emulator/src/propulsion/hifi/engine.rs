//! Engine module: per engine and propellant a solenoid valve and a throttle flow control
//! valve (TFCV) in the branch line, a dome that must fill before propellant reaches the
//! injector, the injector orifice; per engine a combustion chamber and nozzle.
//!
//! Valve motions are computed exactly (they are piecewise linear or exponential in time
//! for a command held over a bench step), so they add no integration error: the
//! integrator sees their positions at sub-step boundaries.

use super::fluid::orifice_resistance;
use super::params::{EngineParams, EnginePropellantParams};

/// Solenoid valve: after a delay from the command it travels at a constant rate to
/// fully open or closed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Solenoid {
    /// Opening, 0 (closed) to 1 (open).
    pub opening: f64,
    target_open: bool,
    delay_left_s: f64,
}

impl Solenoid {
    /// Energises (`open`) or de-energises the coil; a repeated command changes nothing.
    /// A reversal during a delay restarts the delay; the valve holds meanwhile.
    pub fn command(&mut self, open: bool, open_delay_s: f64, close_delay_s: f64) {
        if open != self.target_open {
            self.target_open = open;
            self.delay_left_s = if open { open_delay_s } else { close_delay_s };
        }
    }

    /// Whether the coil is energised (the valve is opening or open).
    #[inline]
    pub fn commanded_open(&self) -> bool {
        self.target_open
    }

    /// Weight of the post-shutdown dribble: 0 while commanded open, rising to 1 as the
    /// valve closes after a de-energise command.
    #[inline]
    pub fn dribble_gate(&self) -> f64 {
        if self.target_open {
            0.0
        } else {
            1.0 - self.opening
        }
    }

    /// Whether the valve moves at some time in the next `h_s` seconds.
    #[inline]
    pub fn moves_within(&self, h_s: f64) -> bool {
        let unsettled = if self.target_open {
            self.opening < 1.0
        } else {
            self.opening > 0.0
        };
        unsettled && self.delay_left_s < h_s
    }

    /// Advances by `h_s` seconds.
    #[inline]
    pub fn advance(&mut self, h_s: f64, ramp_s: f64) {
        let wait = self.delay_left_s.min(h_s);
        self.delay_left_s -= wait;
        let moving_s = h_s - wait;
        if moving_s > 0.0 {
            let travel = moving_s / ramp_s;
            // Snap the ends: summing sub-step travels leaves round-off (1e-17 open
            // instead of shut), and a shut valve must be exactly shut.
            const SNAP: f64 = 1e-9;
            self.opening = if self.target_open {
                let o = self.opening + travel;
                if o >= 1.0 - SNAP {
                    1.0
                } else {
                    o
                }
            } else {
                let o = self.opening - travel;
                if o <= SNAP {
                    0.0
                } else {
                    o
                }
            };
        }
    }
}

/// TFCV: an actuator with a first-order lag and a rate limit drives the valve through
/// backlash; the position command is quantised.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Tfcv {
    /// Commanded position (quantised), fraction of stroke.
    pub target: f64,
    /// Actuator position, fraction of stroke.
    pub actuator: f64,
    /// Valve position, fraction of stroke: the flow area is proportional to it.
    pub valve: f64,
}

/// Timing constants shared by every TFCV.
#[derive(Debug, Clone, Copy)]
pub struct TfcvDynamics {
    /// Lag time constant, s.
    pub tau_s: f64,
    /// Rate limit, stroke fractions per second.
    pub rate_per_s: f64,
    /// Half the backlash, stroke fraction.
    pub half_backlash: f64,
    /// Command quantum, stroke fraction.
    pub quantum: f64,
}

impl TfcvDynamics {
    /// Quantises a position command (round to the nearest step, within [0, 1]).
    #[inline]
    pub fn quantise(&self, x: f64) -> f64 {
        let q = if self.quantum > 0.0 {
            (x / self.quantum).round() * self.quantum
        } else {
            x
        };
        q.clamp(0.0, 1.0)
    }
}

impl Tfcv {
    /// Advances by `h_s` with the target held. `decay_h` is `exp(-h_s / tau)`, computed
    /// once per bench step by the caller.
    ///
    /// Exact solution of `da/dt = clamp((target - a) / tau, -rate, rate)`: a straight
    /// line at the rate limit until the error is within `rate tau`, then exponential.
    /// The valve follows the actuator through backlash: it moves only when the actuator
    /// pushes it, which is exact here because `a(t)` is monotone for a held target.
    #[inline]
    pub fn advance(&mut self, h_s: f64, dyn_: &TfcvDynamics, decay_h: f64) {
        let err = self.target - self.actuator;
        let band = dyn_.rate_per_s * dyn_.tau_s;
        self.actuator = if err.abs() <= band {
            self.target - err * decay_h
        } else {
            let t_lin = (err.abs() - band) / dyn_.rate_per_s;
            if t_lin >= h_s {
                self.actuator + err.signum() * dyn_.rate_per_s * h_s
            } else {
                self.target - err.signum() * band * (-(h_s - t_lin) / dyn_.tau_s).exp()
            }
        };
        self.valve = self.valve.clamp(
            self.actuator - dyn_.half_backlash,
            self.actuator + dyn_.half_backlash,
        );
    }
}

/// One propellant side of one engine: constants of the branch downstream of the
/// manifold.
#[derive(Debug, Clone, Copy)]
pub struct EngineSide {
    /// Branch inertance (line), 1/m.
    pub inertance: f64,
    /// Branch line resistance, Pa s^2/kg^2.
    pub line_resistance: f64,
    /// `1 / (2 rho (Cd A_open)^2)` of the solenoid valve; divided by opening^2.
    pub solenoid_resistance_open: f64,
    /// `1 / (2 rho (Cd A_max)^2)` of the TFCV; divided by position^2.
    pub tfcv_resistance_full: f64,
    /// Injector resistance, Pa s^2/kg^2.
    pub injector_resistance: f64,
    /// Laminar blend flow, kg/s.
    pub laminar_kg_s: f64,
    /// Liquid mass of a full dome, kg.
    pub dome_full_kg: f64,
    inv_dome_full_kg: f64,
    /// Dome fill fraction at which flow starts to reach the injector.
    pub dome_knee: f64,
    inv_knee_span: f64,
    inv_inertance: f64,
    /// Torricelli drain constant `k` in `dm/dt = -k sqrt(m)`, sqrt(kg)/s.
    pub drain_k: f64,
    /// Solenoid delays, s.
    pub open_delay_s: f64,
    /// Solenoid delays, s.
    pub close_delay_s: f64,
}

/// Flows and rates of one branch at one instant.
#[derive(Debug, Clone, Copy, Default)]
pub struct BranchRates {
    /// Rate of change of the branch flow, (kg/s)/s.
    pub dflow: f64,
    /// Its slope with respect to the flow (implicit diagonal).
    pub dflow_slope: f64,
    /// Flow into the chamber through the injector, kg/s.
    pub injected_kg_s: f64,
}

impl EngineSide {
    /// Constants from parameters.
    pub fn new(
        p: &EnginePropellantParams,
        e: &EngineParams,
        rho: f64,
        inertance: f64,
        line_resistance: f64,
        rated_kg_s: f64,
        laminar_frac: f64,
    ) -> Self {
        let dome_full_kg = p.dome_volume_m3 * rho;
        Self {
            inertance,
            line_resistance,
            solenoid_resistance_open: orifice_resistance(
                rho,
                p.solenoid_discharge_coefficient * p.solenoid_flow_area_m2,
            ),
            tfcv_resistance_full: orifice_resistance(
                rho,
                p.tfcv_discharge_coefficient * p.tfcv_max_area_m2,
            ),
            injector_resistance: orifice_resistance(
                rho,
                p.injector_discharge_coefficient * p.injector_area_m2,
            ),
            laminar_kg_s: laminar_frac * rated_kg_s,
            dome_full_kg,
            inv_dome_full_kg: 1.0 / dome_full_kg,
            dome_knee: e.dome_fill_knee_frac,
            inv_knee_span: 1.0 / (1.0 - e.dome_fill_knee_frac),
            inv_inertance: 1.0 / inertance,
            drain_k: 2.0 * dome_full_kg.sqrt() / e.dome_drain_time_s,
            open_delay_s: p.solenoid_open_delay_s,
            close_delay_s: p.solenoid_close_delay_s,
        }
    }

    /// Series resistance of line, solenoid and TFCV, or `None` when a valve is shut.
    #[inline]
    pub fn series_resistance(&self, solenoid: f64, tfcv: f64) -> Option<f64> {
        if solenoid <= 0.0 || tfcv <= 0.0 {
            return None;
        }
        Some(
            self.line_resistance
                + self.solenoid_resistance_open / (solenoid * solenoid)
                + self.tfcv_resistance_full / (tfcv * tfcv),
        )
    }

    /// Branch dynamics: flow `m` from the manifold at `p_manifold` through the valves
    /// (series resistance `series`, `None` when shut) into the dome (mass `dome_kg`)
    /// and, once the dome is nearly full, through the injector into the chamber at
    /// `p_chamber`.
    ///
    /// While the dome fills, propellant does not reach the injector, so the injector
    /// adds no resistance and nothing burns: the start transient ("priming"). Once the
    /// solenoid shuts, the trapped liquid flashes at its vapour pressure and dribbles
    /// into the chamber by a Torricelli-like drain that ends in finite time: the low
    /// tail of the tail-off. `dribble_gate` (0 while commanded open, `1 - opening`
    /// while closing) brings the dribble in; the injector passes the larger of the fed
    /// flow and the dribble, so the two never add up to more than either.
    ///
    /// `series_jac` is the resistance used for the slope (the integrator's implicit
    /// diagonal): the larger of the sub-step's start and end values, so that a valve
    /// closing within the sub-step is treated as stiff as it is about to become.
    ///
    /// `injector_open_frac` is the fraction of the injector's effective area `Cd A`
    /// left open (1 healthy; less when clogged). A clog acts on the area, so the
    /// injector's resistance `1 / (2 rho (Cd A)^2)` grows as `1 / frac^2` and the flow
    /// in the branch falls with it, the manifold upstream seeing the smaller draw; the
    /// dribble through the narrower orifice falls in proportion to the area.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn rates(
        &self,
        m: f64,
        dome_kg: f64,
        dribble_gate: f64,
        series: Option<f64>,
        series_jac: f64,
        p_manifold: f64,
        p_chamber: f64,
        injector_open_frac: f64,
    ) -> BranchRates {
        let fill = dome_kg * self.inv_dome_full_kg;
        let reach = if fill >= 1.0 {
            1.0
        } else {
            ((fill - self.dome_knee) * self.inv_knee_span).clamp(0.0, 1.0)
        };
        let fed = reach * m.max(0.0);
        let drain = if dribble_gate > 0.0 {
            dribble_gate * injector_open_frac * self.drain_k * dome_kg.max(0.0).sqrt()
        } else {
            0.0
        };
        let (dflow, dflow_slope) = match series {
            None => (0.0, 0.0),
            Some(r) => {
                let ml2 = self.laminar_kg_s * self.laminar_kg_s;
                // friction_phi and its slope, sharing one square root each.
                let s_m = (m * m + ml2).sqrt();
                let mut drop = r * m * s_m;
                let mut slope = series_jac.max(r) * (2.0 * m * m + ml2) / s_m;
                if fed > 0.0 {
                    let injector = if injector_open_frac == 1.0 {
                        self.injector_resistance
                    } else {
                        self.injector_resistance / (injector_open_frac * injector_open_frac)
                    };
                    let s_f = (fed * fed + ml2).sqrt();
                    drop += injector * fed * s_f;
                    slope += injector * reach * (2.0 * fed * fed + ml2) / s_f;
                }
                (
                    (p_manifold - p_chamber - drop) * self.inv_inertance,
                    -slope * self.inv_inertance,
                )
            }
        };
        BranchRates {
            dflow,
            dflow_slope,
            injected_kg_s: fed.max(drain),
        }
    }
}

/// Combustion chamber and nozzle: constants.
#[derive(Debug, Clone, Copy)]
pub struct Chamber {
    /// Throat area, m^2.
    pub throat_area_m2: f64,
    /// Vacuum thrust coefficient.
    pub thrust_coefficient: f64,
    /// `Gamma^2 / V_c`, where `Gamma` is the Vandenkerckhove function: with
    /// `R T_c = (Gamma c*)^2` the chamber equation becomes
    /// `dPc/dt = Gamma^2 c* / V_c (c* m_in - Pc A_t)`.
    gamma_sq_over_volume: f64,
    cstar_peak: f64,
    cstar_floor: f64,
    mr_peak: f64,
    eff_rated: f64,
    eff_slope_per_throttle: f64,
    /// Chamber pressure at rated thrust, Pa.
    pub rated_pc_pa: f64,
}

impl Chamber {
    /// Constants; `rated_thrust_n` and `min_throttle` from the scenario.
    pub fn new(e: &EngineParams, rated_thrust_n: f64, min_throttle: f64) -> Self {
        let g = e.chamber_gamma;
        let gamma_fn = g.sqrt() * (2.0 / (g + 1.0)).powf((g + 1.0) / (2.0 * (g - 1.0)));
        let volume = e.characteristic_length_m * e.throat_area_m2;
        Self {
            throat_area_m2: e.throat_area_m2,
            thrust_coefficient: e.thrust_coefficient,
            gamma_sq_over_volume: gamma_fn * gamma_fn / volume,
            cstar_peak: e.cstar_ideal_peak_m_s,
            cstar_floor: e.cstar_floor_m_s,
            mr_peak: e.cstar_peak_mixture_ratio,
            eff_rated: e.cstar_efficiency_rated,
            eff_slope_per_throttle: e.cstar_efficiency_drop_at_min / (1.0 - min_throttle),
            rated_pc_pa: rated_thrust_n / (e.thrust_coefficient * e.throat_area_m2),
        }
    }

    /// Ideal c* for the oxidiser and fuel flows entering, m/s: a bell in the mixture
    /// ratio `r = ox / fuel`, `floor + (peak - floor) 4 r r_p / (r + r_p)^2`, which is
    /// the peak at `r_p`, falls off symmetrically in `ln r` and tends to the unburnt
    /// floor when one propellant is missing (start, shutdown).
    #[inline]
    pub fn cstar_ideal(&self, ox_kg_s: f64, fuel_kg_s: f64) -> f64 {
        let denom = ox_kg_s + self.mr_peak * fuel_kg_s;
        if denom <= 0.0 {
            return self.cstar_floor;
        }
        let bell = 4.0 * self.mr_peak * ox_kg_s.max(0.0) * fuel_kg_s.max(0.0) / (denom * denom);
        self.cstar_floor + (self.cstar_peak - self.cstar_floor) * bell
    }

    /// c* efficiency at a chamber pressure: lower at low throttle.
    #[inline]
    pub fn efficiency(&self, pc_pa: f64) -> f64 {
        let throttle = (pc_pa / self.rated_pc_pa).clamp(0.0, 1.0);
        self.eff_rated - self.eff_slope_per_throttle * (1.0 - throttle)
    }

    /// Delivered c*, m/s.
    #[inline]
    pub fn cstar(&self, ox_kg_s: f64, fuel_kg_s: f64, pc_pa: f64) -> f64 {
        self.efficiency(pc_pa) * self.cstar_ideal(ox_kg_s, fuel_kg_s)
    }

    /// Chamber pressure rate, Pa/s, and its slope with respect to Pc (implicit diagonal).
    #[inline]
    pub fn pressure_rate(&self, ox_kg_s: f64, fuel_kg_s: f64, pc_pa: f64) -> (f64, f64) {
        let cstar = self.cstar(ox_kg_s, fuel_kg_s, pc_pa);
        let k = self.gamma_sq_over_volume * cstar;
        (
            k * (cstar * (ox_kg_s + fuel_kg_s) - pc_pa * self.throat_area_m2),
            -k * self.throat_area_m2,
        )
    }

    /// Thrust, N: `Cf Pc At`.
    #[inline]
    pub fn thrust_n(&self, pc_pa: f64) -> f64 {
        self.thrust_coefficient * pc_pa.max(0.0) * self.throat_area_m2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solenoid_waits_then_ramps() {
        let mut s = Solenoid::default();
        s.command(true, 0.004, 0.003);
        s.advance(0.003, 0.02);
        assert_eq!(s.opening, 0.0);
        s.advance(0.002, 0.02); // 1 ms past the delay
        assert!((s.opening - 0.05).abs() < 1e-12);
        s.advance(0.1, 0.02);
        assert_eq!(s.opening, 1.0);
        s.command(false, 0.004, 0.003);
        s.advance(0.003 + 0.01, 0.02);
        assert!((s.opening - 0.5).abs() < 1e-12);
    }

    #[test]
    fn tfcv_rate_limit_then_lag_then_backlash() {
        let d = TfcvDynamics {
            tau_s: 0.015,
            rate_per_s: 1.0 / 0.15,
            half_backlash: 0.0025,
            quantum: 0.001,
        };
        let mut v = Tfcv {
            target: 0.8,
            actuator: 0.2,
            valve: 0.2,
        };
        // Rate-limited: 10 ms moves 1/15 of the stroke.
        let h = 0.01;
        v.advance(h, &d, (-h / d.tau_s).exp());
        assert!((v.actuator - (0.2 + 0.01 / 0.15)).abs() < 1e-12);
        assert!((v.valve - (v.actuator - d.half_backlash)).abs() < 1e-12);
        // Sub-stepping gives the same result as one long step (exactness).
        let mut a = v;
        let mut b = v;
        a.advance(0.1, &d, (-0.1 / d.tau_s).exp());
        for _ in 0..1000 {
            b.advance(1e-4, &d, (-1e-4 / d.tau_s).exp());
        }
        assert!((a.actuator - b.actuator).abs() < 1e-12, "{a:?} {b:?}");
        // Reversal: the valve does not move until the backlash is taken up.
        let mut c = Tfcv {
            target: 0.5,
            actuator: 0.5,
            valve: 0.5 - d.half_backlash,
        };
        c.target = 0.497;
        c.advance(0.1, &d, (-0.1 / d.tau_s).exp());
        assert_eq!(c.valve, 0.5 - d.half_backlash);
        assert_eq!(d.quantise(0.12345), 0.123);
    }

    #[test]
    fn cstar_peaks_at_peak_ratio_and_falls_to_floor() {
        let e = EngineParams::default();
        let c = Chamber::new(&e, 800.0, 0.4);
        let at = |mr: f64| c.cstar_ideal(mr, 1.0);
        assert!((at(e.cstar_peak_mixture_ratio) - e.cstar_ideal_peak_m_s).abs() < 1e-9);
        assert!((at(1.65) - 1738.0).abs() < 1.0, "{}", at(1.65));
        assert!(at(1.0) < at(1.65) && at(3.0) < at(1.9));
        assert_eq!(c.cstar_ideal(0.1, 0.0), e.cstar_floor_m_s);
        assert_eq!(c.cstar_ideal(0.0, 0.0), e.cstar_floor_m_s);
        assert!(c.efficiency(c.rated_pc_pa * 0.4) < c.efficiency(c.rated_pc_pa));
    }
}
