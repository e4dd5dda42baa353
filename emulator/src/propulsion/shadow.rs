//! Shadow mode (`--propulsion shadow`): the truth model (hifi) drives the plant while the
//! surrogate runs beside it, free, on the same commands. Every step the difference of
//! each output is accumulated, so the run report says how far the surrogate strays in
//! closed loop, where the commands depend on the truth model's behaviour.

use super::diagnostics::{DivergenceAccumulator, PropulsionDiagnostics};
use super::hifi::HifiPropulsion;
use super::{EngineCommand, Propulsion, PropulsionOutput};
use crate::propulsion::surrogate::SurrogatePropulsion;

/// A driving model and a shadowing model stepped on the same commands.
///
/// Generic so tests can pair any two models (ideal against ideal gives zero); the bench
/// pairs hifi (truth) with the surrogate.
#[derive(Debug, Clone)]
pub struct ShadowPropulsion<T = HifiPropulsion, M = SurrogatePropulsion> {
    truth: T,
    model: M,
    stats: DivergenceAccumulator,
}

impl<T: Propulsion, M: Propulsion> ShadowPropulsion<T, M> {
    /// `truth` drives; `model` shadows. Both must start from the same initial state (each
    /// model is constructed at rest, so they do).
    pub fn new(truth: T, model: M) -> Self {
        Self {
            truth,
            model,
            stats: DivergenceAccumulator::default(),
        }
    }

    /// The shadowing model's latest outputs.
    pub fn model_output(&self) -> PropulsionOutput {
        self.model.output()
    }
}

impl<T: Propulsion, M: Propulsion> Propulsion for ShadowPropulsion<T, M> {
    fn name(&self) -> &'static str {
        "shadow"
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        let truth = self.truth.step(cmd, dt_ns);
        let model = self.model.step(cmd, dt_ns);
        self.stats.add(&truth, &model);
        truth
    }

    fn output(&self) -> PropulsionOutput {
        self.truth.output()
    }

    fn internals(&self) -> super::PropulsionInternals {
        self.truth.internals()
    }

    fn represents(&self, fault: &super::PropulsionFault) -> bool {
        self.truth.represents(fault)
    }

    fn inject(&mut self, fault: &super::PropulsionFault, active: bool) {
        self.truth.inject(fault, active)
    }

    fn failure(&self) -> Option<&'static str> {
        self.truth.failure()
    }

    fn diagnostics(&self) -> Option<PropulsionDiagnostics> {
        Some(PropulsionDiagnostics {
            out_of_envelope_steps: self
                .model
                .diagnostics()
                .and_then(|d| d.out_of_envelope_steps),
            surrogate_guards: self.model.diagnostics().and_then(|d| d.surrogate_guards),
            hifi_non_finite_rollbacks: self
                .truth
                .diagnostics()
                .and_then(|d| d.hifi_non_finite_rollbacks),
            shadow: Some(self.stats.summary()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PropulsionConfig;
    use crate::propulsion::diagnostics::Divergence;
    use crate::propulsion::ideal::IdealPropulsion;

    fn commands(k: usize) -> EngineCommand {
        EngineCommand {
            thrust_cmd_n: [400.0 + (k % 40) as f64 * 10.0, 600.0, 500.0, 700.0],
            on: [true, true, k % 100 < 50, true],
        }
    }

    #[test]
    fn identical_models_do_not_diverge() {
        let cfg = PropulsionConfig::default();
        let mut s = ShadowPropulsion::new(IdealPropulsion::new(&cfg), IdealPropulsion::new(&cfg));
        for k in 0..300 {
            s.step(&commands(k), 10_000_000);
        }
        let d = s.diagnostics().unwrap().shadow.unwrap();
        assert_eq!(d.steps, 300);
        for t in d.thrust_n {
            assert_eq!(t, Divergence::default());
        }
        assert_eq!(d.total_mass_kg, Divergence::default());
        assert_eq!(d.gas_pressure_pa, Divergence::default());
    }

    #[test]
    fn divergence_matches_a_direct_computation() {
        let cfg = PropulsionConfig::default();
        let slow = PropulsionConfig {
            thrust_lag_s: cfg.thrust_lag_s * 3.0,
            ..cfg.clone()
        };
        let mut s = ShadowPropulsion::new(IdealPropulsion::new(&cfg), IdealPropulsion::new(&slow));
        let (mut a, mut b) = (IdealPropulsion::new(&cfg), IdealPropulsion::new(&slow));
        let (mut max1, mut sq1, mut maxm) = (0.0f64, 0.0, 0.0f64);
        for k in 0..300 {
            let out = s.step(&commands(k), 10_000_000);
            let (ta, tb) = (
                a.step(&commands(k), 10_000_000),
                b.step(&commands(k), 10_000_000),
            );
            assert_eq!(out, ta, "the driving model's output is returned");
            let d = tb.thrust_n[0] - ta.thrust_n[0];
            max1 = max1.max(d.abs());
            sq1 += d * d;
            maxm = maxm.max((ta.ejected_kg() - tb.ejected_kg()).abs());
        }
        let d = s.diagnostics().unwrap().shadow.unwrap();
        assert!(
            max1 > 1.0,
            "the pair must differ for the test to mean anything"
        );
        assert_eq!(d.thrust_n[0].max_abs, max1);
        assert!((d.thrust_n[0].rms - (sq1 / 300.0).sqrt()).abs() < 1e-9);
        assert_eq!(d.total_mass_kg.max_abs, maxm);
    }
}
