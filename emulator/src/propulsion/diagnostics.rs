//! What a propulsion model reports about itself at the end of a run (beside its outputs):
//! how often the surrogate left its training envelope, and, in shadow mode, how far the
//! surrogate strayed from the model that drove the plant.
//!
//! Accumulation happens in fixed fields (running maximum, sum of squares, count), so a
//! model can update it on every step without allocating.

use super::PropulsionOutput;
use oils_shared::ENGINE_COUNT;
use serde::Serialize;

/// Largest absolute and root-mean-square difference of one output over a run.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Divergence {
    /// Largest |model - truth| over the run.
    pub max_abs: f64,
    /// Root mean square of (model - truth) over the run.
    pub rms: f64,
}

/// Per-output divergence of a shadowing model from the model that drove the plant.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ShadowDivergence {
    /// Steps compared.
    pub steps: u64,
    /// Thrust at the end of each step, per engine, newtons.
    pub thrust_n: [Divergence; ENGINE_COUNT],
    /// Helium bottle ("gas") pressure, pascals.
    pub gas_pressure_pa: Divergence,
    /// Cumulative ejected fuel, kilograms.
    pub ejected_fuel_kg: Divergence,
    /// Cumulative ejected oxidiser, kilograms.
    pub ejected_ox_kg: Divergence,
    /// Total module mass (initial mass minus everything ejected), kilograms.
    pub total_mass_kg: Divergence,
}

/// Diagnostics of a propulsion model, filled in at the end of a run.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct PropulsionDiagnostics {
    /// Steps on which a surrogate input left the training envelope and was clamped
    /// (`None`: the model has no envelope).
    pub out_of_envelope_steps: Option<u64>,
    /// Steps on which the surrogate's physical guards acted: a prediction that was not
    /// finite (the previous value was kept) or not physical (a negative thrust or
    /// pressure set to 0, an ejected mass that would fall held). `None`: not a surrogate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub surrogate_guards: Option<SurrogateGuards>,
    /// Hifi: steps whose state became non-finite and was rolled back (the quarantine;
    /// the run then ends aborted). `None`: not hifi.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hifi_non_finite_rollbacks: Option<u64>,
    /// Shadow mode: divergence of the shadowing surrogate from the driving model.
    pub shadow: Option<ShadowDivergence>,
}

/// How often the surrogate's guards acted, in steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct SurrogateGuards {
    /// Steps with a command of an engine that is on outside the on-range (clamped).
    pub clamped_commands: u64,
    /// Steps with a prediction that was not finite (the previous value was kept).
    pub non_finite_predictions: u64,
    /// Steps with a prediction clamped to be physical (thrust and pressure >= 0,
    /// ejected masses never falling).
    pub clamped_predictions: u64,
    /// Steps with a prediction beyond its physical bound, clamped to it (thrust above
    /// `MAX_THRUST_OVER_RATING` x `max_thrust_n`, gas pressure above
    /// `MAX_GAS_PRESSURE_PA`; `propulsion::surrogate::model`): a model that is not
    /// physical. `MAX_BOUNDED_STEPS` of them end the run aborted.
    pub bounded_predictions: u64,
}

/// Number of outputs a [`DivergenceAccumulator`] tracks: 4 thrusts, gas pressure, ejected
/// fuel, ejected oxidiser, total mass.
const TRACKED: usize = ENGINE_COUNT + 4;

/// Running per-output maximum and sum of squares of `model - truth`; no allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DivergenceAccumulator {
    steps: u64,
    max_abs: [f64; TRACKED],
    sum_sq: [f64; TRACKED],
}

impl Default for DivergenceAccumulator {
    fn default() -> Self {
        Self {
            steps: 0,
            max_abs: [0.0; TRACKED],
            sum_sq: [0.0; TRACKED],
        }
    }
}

impl DivergenceAccumulator {
    /// Adds one step's pair of outputs.
    pub fn add(&mut self, truth: &PropulsionOutput, model: &PropulsionOutput) {
        let mut d = [0.0; TRACKED];
        for (d, (m, t)) in d.iter_mut().zip(model.thrust_n.iter().zip(&truth.thrust_n)) {
            *d = m - t;
        }
        d[ENGINE_COUNT] = model.gas_pressure_pa - truth.gas_pressure_pa;
        d[ENGINE_COUNT + 1] = model.ejected_fuel_kg - truth.ejected_fuel_kg;
        d[ENGINE_COUNT + 2] = model.ejected_ox_kg - truth.ejected_ox_kg;
        // Same initial mass, so the mass difference is minus the ejected difference.
        d[ENGINE_COUNT + 3] = truth.ejected_kg() - model.ejected_kg();
        for (i, v) in d.iter().enumerate() {
            // A NaN difference is a divergence without bound: keep it visible.
            let a = if v.is_finite() {
                v.abs()
            } else {
                f64::INFINITY
            };
            if a > self.max_abs[i] {
                self.max_abs[i] = a;
            }
            self.sum_sq[i] += a * a;
        }
        self.steps += 1;
    }

    /// The summary so far.
    pub fn summary(&self) -> ShadowDivergence {
        let n = self.steps.max(1) as f64;
        let at = |i: usize| Divergence {
            max_abs: self.max_abs[i],
            rms: (self.sum_sq[i] / n).sqrt(),
        };
        ShadowDivergence {
            steps: self.steps,
            thrust_n: std::array::from_fn(at),
            gas_pressure_pa: at(ENGINE_COUNT),
            ejected_fuel_kg: at(ENGINE_COUNT + 1),
            ejected_ox_kg: at(ENGINE_COUNT + 2),
            total_mass_kg: at(ENGINE_COUNT + 3),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_and_rms_of_known_differences() {
        let mut acc = DivergenceAccumulator::default();
        let truth = PropulsionOutput::default();
        for d in [3.0, -4.0] {
            let mut m = PropulsionOutput::default();
            m.thrust_n[2] = d;
            m.gas_pressure_pa = 10.0 * d;
            m.ejected_fuel_kg = d;
            m.ejected_ox_kg = d;
            acc.add(&truth, &m);
        }
        let s = acc.summary();
        assert_eq!(s.steps, 2);
        assert_eq!(s.thrust_n[2].max_abs, 4.0);
        assert!((s.thrust_n[2].rms - (12.5f64).sqrt()).abs() < 1e-12);
        assert_eq!(s.thrust_n[0], Divergence::default());
        assert_eq!(s.gas_pressure_pa.max_abs, 40.0);
        assert_eq!(s.total_mass_kg.max_abs, 8.0);
        assert!((s.total_mass_kg.rms - (50.0f64).sqrt()).abs() < 1e-12);
    }
}
