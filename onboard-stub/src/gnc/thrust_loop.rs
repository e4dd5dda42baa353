//! Acceleration feedback on thrust: the flown system closes a loop on measured
//! acceleration (< 1 % thrust error) over engines that are only +-5 % accurate open
//! loop. Here: a slowly filtered efficiency `eta = measured thrust / expected thrust`,
//! where measured thrust is the accelerometer's specific force times the mass and the
//! expected thrust is the command passed through a first-order lag model of the
//! engines. Commands are divided by `eta`.

use super::GncConfig;

/// The thrust-efficiency estimator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrustLoop {
    lag_model_s: f64,
    filter_s: f64,
    eta_min: f64,
    eta_max: f64,
    min_expected_n: f64,
    expected_n: f64,
    eta: f64,
    last_t_s: Option<f64>,
}

impl ThrustLoop {
    /// An estimator starting at `eta = 1`.
    pub fn new(cfg: &GncConfig) -> Self {
        Self {
            lag_model_s: cfg.thrust_lag_model_s,
            filter_s: cfg.thrust_efficiency_filter_s,
            eta_min: cfg.thrust_efficiency_min,
            eta_max: cfg.thrust_efficiency_max,
            min_expected_n: cfg.max_thrust_n * cfg.throttle_min_frac,
            expected_n: 0.0,
            eta: 1.0,
            last_t_s: None,
        }
    }

    /// Thrust efficiency estimate (1: engines give what they are told).
    pub fn efficiency(&self) -> f64 {
        self.eta
    }

    /// Folds in the measurement at `t_s` (`measured_thrust_n` = specific force times
    /// mass) given the total thrust commanded over the last step.
    pub fn update(&mut self, t_s: f64, measured_thrust_n: f64, last_cmd_total_n: f64) {
        let dt_s = match self.last_t_s {
            Some(t0) if t_s > t0 => t_s - t0,
            Some(_) => return,
            None => {
                self.last_t_s = Some(t_s);
                return;
            }
        };
        self.last_t_s = Some(t_s);
        self.expected_n +=
            (last_cmd_total_n - self.expected_n) * (1.0 - (-dt_s / self.lag_model_s).exp());
        if self.expected_n > self.min_expected_n && measured_thrust_n.is_finite() {
            let ratio = measured_thrust_n / self.expected_n;
            self.eta += (ratio - self.eta) * (dt_s / self.filter_s).min(1.0);
            self.eta = self.eta.clamp(self.eta_min, self.eta_max);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learns_a_five_percent_shortfall() {
        let mut tl = ThrustLoop::new(&GncConfig::default());
        let mut t = 0.0;
        for _ in 0..3000 {
            tl.update(t, 0.95 * 2000.0, 2000.0);
            t += 0.01;
        }
        assert!(
            (tl.efficiency() - 0.95).abs() < 0.005,
            "{}",
            tl.efficiency()
        );
    }

    #[test]
    fn ignores_engines_off() {
        let mut tl = ThrustLoop::new(&GncConfig::default());
        for k in 0..1000 {
            tl.update(k as f64 * 0.01, 0.0, 0.0);
        }
        assert_eq!(tl.efficiency(), 1.0);
    }
}
