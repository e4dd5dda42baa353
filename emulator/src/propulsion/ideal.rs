//! The `ideal` propulsion model: each engine follows its clamped command through a
//! first-order lag; propellant flows at thrust / (Isp g0), split by the mixture ratio;
//! pressures are constant. Quick tests and GNC tuning, not truth.

use super::{EngineCommand, Propulsion, PropulsionOutput};
use crate::config::PropulsionConfig;
use oils_shared::ENGINE_COUNT;

/// Standard gravity for Isp, m/s^2.
pub const G0_M_S2: f64 = 9.80665;

/// First-order-lag propulsion.
#[derive(Debug, Clone)]
pub struct IdealPropulsion {
    cfg: PropulsionConfig,
    out: PropulsionOutput,
}

impl IdealPropulsion {
    /// A model at rest with full tanks.
    pub fn new(cfg: &PropulsionConfig) -> Self {
        let out = PropulsionOutput {
            gas_pressure_pa: cfg.gas_pressure_pa,
            fuel_tank_pressure_pa: cfg.tank_pressure_pa,
            ox_tank_pressure_pa: cfg.tank_pressure_pa,
            ..Default::default()
        };
        Self {
            cfg: cfg.clone(),
            out,
        }
    }

    /// Thrust an engine settles at for a command: off is zero; on is clamped to the
    /// throttle range; nothing once the propellant is gone.
    fn target_thrust_n(&self, cmd_n: f64, on: bool) -> f64 {
        if !on || self.out.ejected_kg() >= self.cfg.propellant_kg {
            return 0.0;
        }
        let max = self.cfg.max_thrust_n;
        cmd_n.clamp(self.cfg.throttle_min_frac * max, max)
    }
}

impl Propulsion for IdealPropulsion {
    fn name(&self) -> &'static str {
        "ideal"
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        let dt_s = dt_ns as f64 * 1e-9;
        // Exact discretisation of dF/dt = (F* - F) / tau over a step with F* held.
        let decay = (-dt_s / self.cfg.thrust_lag_s).exp();
        let mean_gain = self.cfg.thrust_lag_s / dt_s * (1.0 - decay);
        let mut total_mean_n = 0.0;
        let mut total_end_n = 0.0;
        for i in 0..ENGINE_COUNT {
            let target = self.target_thrust_n(cmd.thrust_cmd_n[i], cmd.on[i]);
            let start = self.out.thrust_n[i];
            let end = target + (start - target) * decay;
            let mean = target + (start - target) * mean_gain;
            self.out.thrust_n[i] = end;
            self.out.mean_thrust_n[i] = mean;
            total_mean_n += mean;
            total_end_n += end;
        }
        let exhaust_m_s = self.cfg.isp_s * G0_M_S2;
        let mr = self.cfg.mixture_ratio;
        let ejected_kg = (total_mean_n / exhaust_m_s * dt_s)
            .min(self.cfg.propellant_kg - self.out.ejected_kg())
            .max(0.0);
        self.out.ejected_ox_kg += ejected_kg * mr / (1.0 + mr);
        self.out.ejected_fuel_kg += ejected_kg / (1.0 + mr);
        let flow_kg_s = total_end_n / exhaust_m_s;
        self.out.ox_flow_kg_s = flow_kg_s * mr / (1.0 + mr);
        self.out.fuel_flow_kg_s = flow_kg_s / (1.0 + mr);
        for i in 0..ENGINE_COUNT {
            self.out.chamber_pressure_pa[i] =
                self.out.thrust_n[i] / self.cfg.max_thrust_n * self.cfg.chamber_pressure_max_pa;
        }
        self.out
    }

    fn output(&self) -> PropulsionOutput {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on_at(thrust_n: f64) -> EngineCommand {
        EngineCommand {
            thrust_cmd_n: [thrust_n; 4],
            on: [true; 4],
        }
    }

    #[test]
    fn settles_at_command_with_lag() {
        let cfg = PropulsionConfig::default();
        let mut p = IdealPropulsion::new(&cfg);
        let dt_ns = 10_000_000;
        let out = p.step(&on_at(600.0), dt_ns);
        // After one step of a lag tau: 600 (1 - e^{-dt/tau}).
        let expect = 600.0 * (1.0 - (-0.01 / cfg.thrust_lag_s).exp());
        assert!(
            (out.thrust_n[0] - expect).abs() < 1e-9,
            "{} vs {expect}",
            out.thrust_n[0]
        );
        assert!(out.mean_thrust_n[0] < out.thrust_n[0]);
        for _ in 0..500 {
            p.step(&on_at(600.0), dt_ns);
        }
        assert!((p.output().thrust_n[2] - 600.0).abs() < 1e-6);
    }

    #[test]
    fn clamps_to_throttle_range_and_off_is_zero() {
        let cfg = PropulsionConfig::default();
        let mut p = IdealPropulsion::new(&cfg);
        let mut cmd = on_at(10.0);
        cmd.thrust_cmd_n[1] = 5000.0;
        cmd.on[3] = false;
        for _ in 0..1000 {
            p.step(&cmd, 10_000_000);
        }
        let out = p.output();
        assert!((out.thrust_n[0] - cfg.throttle_min_frac * cfg.max_thrust_n).abs() < 1e-6);
        assert!((out.thrust_n[1] - cfg.max_thrust_n).abs() < 1e-6);
        assert_eq!(out.thrust_n[3], 0.0);
    }

    #[test]
    fn mass_flow_matches_rocket_equation_rate() {
        // Steady 4 x 800 N for 10 s ejects F t / (Isp g0), split by the mixture ratio.
        let cfg = PropulsionConfig {
            thrust_lag_s: 1e-4,
            ..Default::default()
        };
        let mut p = IdealPropulsion::new(&cfg);
        for _ in 0..1000 {
            p.step(&on_at(800.0), 10_000_000);
        }
        let out = p.output();
        let expect = 3200.0 * 10.0 / (cfg.isp_s * G0_M_S2);
        assert!(
            (out.ejected_kg() - expect).abs() / expect < 1e-4,
            "{}",
            out.ejected_kg()
        );
        let mr = out.ejected_ox_kg / out.ejected_fuel_kg;
        assert!((mr - cfg.mixture_ratio).abs() < 1e-12);
    }

    #[test]
    fn stops_when_propellant_is_gone() {
        let cfg = PropulsionConfig {
            propellant_kg: 1.0,
            ..Default::default()
        };
        let mut p = IdealPropulsion::new(&cfg);
        for _ in 0..2000 {
            p.step(&on_at(800.0), 10_000_000);
        }
        assert!((p.output().ejected_kg() - 1.0).abs() < 1e-12);
        assert!(p.output().thrust_n[0] < 1e-6);
    }
}
