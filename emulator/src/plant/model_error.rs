//! Injected propulsion model error ([`ModelErrorConfig`]): how a Monte Carlo campaign
//! feeds the surrogate's validated error back into the loop as model uncertainty (seed
//! paper, Section VI).
//!
//! Each firing engine's delivered thrust gets a steady bias plus a transient error. A
//! transient starts at an engine start or at a command step larger than the threshold
//! (the regimes `oils validate` measures separately), with an amplitude drawn from the
//! transient statistics, and decays exponentially. The draws come from one ChaCha8
//! stream seeded by the configuration, so a case repeats bit for bit.

use crate::config::ModelErrorConfig;
use crate::propulsion::{EngineCommand, PropulsionOutput};
use oils_shared::ENGINE_COUNT;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// ChaCha stream id of the model-error draws.
pub const MODEL_ERROR_STREAM: u64 = 0x6d6f_645f_6572_7200; // "mod_err"

/// The injector's state.
#[derive(Debug, Clone)]
pub struct ModelError {
    cfg: ModelErrorConfig,
    rng: ChaCha8Rng,
    /// Current transient error of each engine, newtons.
    transient_n: [f64; ENGINE_COUNT],
    last_cmd_n: [f64; ENGINE_COUNT],
    last_on: [bool; ENGINE_COUNT],
    /// Transients started so far (reported).
    transients: u64,
    /// The step length the decay factor was worked out for, and the factor: the plant
    /// steps at one length, so `exp` runs once a run, not once a step (the same
    /// argument gives the same factor).
    decay_for: (f64, f64),
}

impl ModelError {
    /// An injector for a validated configuration.
    pub fn new(cfg: &ModelErrorConfig) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        rng.set_stream(MODEL_ERROR_STREAM);
        Self {
            cfg: cfg.clone(),
            rng,
            transient_n: [0.0; ENGINE_COUNT],
            last_cmd_n: [0.0; ENGINE_COUNT],
            last_on: [false; ENGINE_COUNT],
            transients: 0,
            decay_for: (f64::NAN, f64::NAN),
        }
    }

    /// Transients started so far.
    pub fn transients(&self) -> u64 {
        self.transients
    }

    /// Adds the error to what the model delivered for the step just taken with
    /// `engines`, lasting `dt_s`. No allocation.
    pub fn apply(&mut self, engines: &EngineCommand, out: &mut PropulsionOutput, dt_s: f64) {
        if self.decay_for.0 != dt_s {
            self.decay_for = (dt_s, (-dt_s / self.cfg.transient_tau_s).exp());
        }
        let decay = self.decay_for.1;
        for e in 0..ENGINE_COUNT {
            let on = engines.on[e];
            let cmd_n = engines.thrust_cmd_n[e];
            let started = on && !self.last_on[e];
            let stepped = on && (cmd_n - self.last_cmd_n[e]).abs() > self.cfg.step_threshold_n;
            if started || stepped {
                let n: f64 = self.rng.sample(StandardNormal);
                let max = self.cfg.transient_max_abs_n;
                self.transient_n[e] =
                    (self.cfg.transient_mean_n + n * self.cfg.transient_std_n).clamp(-max, max);
                self.transients += 1;
            } else {
                self.transient_n[e] *= decay;
            }
            self.last_on[e] = on;
            self.last_cmd_n[e] = cmd_n;
            if out.thrust_n[e] > 0.0 || out.mean_thrust_n[e] > 0.0 {
                let error_n = self.cfg.bias_n[e] + self.transient_n[e];
                out.thrust_n[e] = (out.thrust_n[e] + error_n).max(0.0);
                out.mean_thrust_n[e] = (out.mean_thrust_n[e] + error_n).max(0.0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn firing(thrust_n: f64) -> (EngineCommand, PropulsionOutput) {
        let engines = EngineCommand {
            thrust_cmd_n: [thrust_n; ENGINE_COUNT],
            on: [true; ENGINE_COUNT],
        };
        let out = PropulsionOutput {
            thrust_n: [thrust_n; ENGINE_COUNT],
            mean_thrust_n: [thrust_n; ENGINE_COUNT],
            ..PropulsionOutput::default()
        };
        (engines, out)
    }

    #[test]
    fn bias_is_added_and_a_transient_decays_to_it() {
        let cfg = ModelErrorConfig {
            enabled: true,
            bias_n: [1.0, -2.0, 0.5, 0.0],
            transient_mean_n: 10.0,
            transient_std_n: 0.0,
            transient_max_abs_n: 50.0,
            transient_tau_s: 0.1,
            step_threshold_n: 40.0,
            seed: 7,
        };
        let mut m = ModelError::new(&cfg);
        let (engines, mut out) = firing(500.0);
        m.apply(&engines, &mut out, 0.01);
        // Engine start: bias + the full transient amplitude (std 0: exactly the mean).
        assert_eq!(out.thrust_n[0], 500.0 + 1.0 + 10.0);
        assert_eq!(m.transients(), 4);
        for _ in 0..100 {
            let (_, mut o) = firing(500.0);
            m.apply(&engines, &mut o, 0.01);
            out = o;
        }
        // One second later (10 tau) only the bias is left.
        assert!((out.thrust_n[1] - 498.0).abs() < 1e-3);
        assert_eq!(m.transients(), 4);
    }

    #[test]
    fn off_engines_get_nothing_and_thrust_stays_non_negative() {
        let cfg = ModelErrorConfig {
            enabled: true,
            bias_n: [-30.0; 4],
            ..ModelErrorConfig::default()
        };
        let mut m = ModelError::new(&cfg);
        let (mut engines, mut out) = firing(10.0);
        engines.on[3] = false;
        out.thrust_n[3] = 0.0;
        out.mean_thrust_n[3] = 0.0;
        m.apply(&engines, &mut out, 0.01);
        assert_eq!(out.thrust_n[0], 0.0);
        assert_eq!(out.thrust_n[3], 0.0);
    }

    #[test]
    fn the_same_seed_gives_the_same_draws() {
        let cfg = ModelErrorConfig {
            enabled: true,
            transient_std_n: 3.0,
            transient_max_abs_n: 70.0,
            seed: 11,
            ..ModelErrorConfig::default()
        };
        let run = || {
            let mut m = ModelError::new(&cfg);
            let (engines, mut out) = firing(400.0);
            m.apply(&engines, &mut out, 0.01);
            out.thrust_n
        };
        assert_eq!(run(), run());
        let mut other = cfg.clone();
        other.seed = 12;
        let mut m = ModelError::new(&other);
        let (engines, mut out) = firing(400.0);
        m.apply(&engines, &mut out, 0.01);
        assert_ne!(out.thrust_n, run());
    }
}
