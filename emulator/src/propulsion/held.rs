//! Sample-and-hold around a propulsion model that runs at its own sample time (the
//! surrogate's trained 10 ms) under a plant that integrates faster (1 ms): the command
//! is latched at each sample's start and held over the sample; the model is stepped once
//! per sample; between samples its outputs are held: the sample's mean thrust and flows
//! over every plant step inside it, the ejected masses advancing with those flows (so the
//! impulse and propellant of a sample equal the model's own), and the instantaneous
//! thrust and pressures moving along the straight line the model assumes between its two
//! end points (its mean thrust is that line's trapezoid).
//!
//! The plant is unchanged: it steps this wrapper as any model. Nothing here allocates.

use super::{
    EngineCommand, Propulsion, PropulsionDiagnostics, PropulsionFault, PropulsionInternals,
    PropulsionOutput,
};

/// A model stepped every `sample_ns`, under plant steps that divide it.
pub struct Held<P: Propulsion> {
    inner: P,
    sample_ns: u64,
    /// Time into the current sample, nanoseconds (0: a sample starts with the next step).
    phase_ns: u64,
    /// The model's output at the start and the end of the current sample.
    start: PropulsionOutput,
    end: PropulsionOutput,
    /// What this wrapper reported last.
    last: PropulsionOutput,
}

impl<P: Propulsion> Held<P> {
    /// Holds `inner`, which must be stepped by whole samples of `sample_ns`.
    pub fn new(inner: P, sample_ns: u64) -> Self {
        let out = inner.output();
        Self {
            inner,
            sample_ns,
            phase_ns: 0,
            start: out,
            end: out,
            last: out,
        }
    }

    /// The held model.
    pub fn inner(&self) -> &P {
        &self.inner
    }
}

fn lerp(a: f64, b: f64, f: f64) -> f64 {
    a + (b - a) * f
}

impl<P: Propulsion> Propulsion for Held<P> {
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        if self.phase_ns == 0 {
            // A sample starts: latch the command, step the model over the whole sample.
            self.start = self.end;
            self.end = self.inner.step(cmd, self.sample_ns);
        }
        self.phase_ns = (self.phase_ns + dt_ns).min(self.sample_ns);
        let f = self.phase_ns as f64 / self.sample_ns as f64;
        let (s, e) = (&self.start, &self.end);
        let mut o = *e;
        for i in 0..o.thrust_n.len() {
            o.thrust_n[i] = lerp(s.thrust_n[i], e.thrust_n[i], f);
            o.chamber_pressure_pa[i] = lerp(s.chamber_pressure_pa[i], e.chamber_pressure_pa[i], f);
        }
        o.gas_pressure_pa = lerp(s.gas_pressure_pa, e.gas_pressure_pa, f);
        o.fuel_tank_pressure_pa = lerp(s.fuel_tank_pressure_pa, e.fuel_tank_pressure_pa, f);
        o.ox_tank_pressure_pa = lerp(s.ox_tank_pressure_pa, e.ox_tank_pressure_pa, f);
        o.ejected_fuel_kg = lerp(s.ejected_fuel_kg, e.ejected_fuel_kg, f);
        o.ejected_ox_kg = lerp(s.ejected_ox_kg, e.ejected_ox_kg, f);
        if self.phase_ns >= self.sample_ns {
            self.phase_ns = 0;
        }
        self.last = o;
        o
    }

    fn output(&self) -> PropulsionOutput {
        self.last
    }

    fn diagnostics(&self) -> Option<PropulsionDiagnostics> {
        self.inner.diagnostics()
    }

    fn internals(&self) -> PropulsionInternals {
        self.inner.internals()
    }

    fn represents(&self, fault: &PropulsionFault) -> bool {
        self.inner.represents(fault)
    }

    fn inject(&mut self, fault: &PropulsionFault, active: bool) {
        self.inner.inject(fault, active);
    }

    fn failure(&self) -> Option<&'static str> {
        self.inner.failure()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PropulsionConfig;
    use crate::propulsion::surrogate::SurrogatePropulsion;

    #[test]
    #[allow(clippy::needless_range_loop)] // four engines side by side
    fn ten_held_steps_of_1_ms_give_the_impulse_and_propellant_of_one_10_ms_step() {
        let cfg = PropulsionConfig::default();
        let mut one = SurrogatePropulsion::default_model(&cfg, None).unwrap();
        let mut held = Held::new(
            SurrogatePropulsion::default_model(&cfg, None).unwrap(),
            10_000_000,
        );
        let mut cmd = EngineCommand::default();
        for k in 0..300u64 {
            cmd.on = [k >= 10; 4];
            cmd.thrust_cmd_n = [300.0 + k as f64, 500.0, 200.0, 700.0];
            let a = one.step(&cmd, 10_000_000);
            let mut impulse = [0.0; 4];
            let mut b = PropulsionOutput::default();
            for _ in 0..10 {
                b = held.step(&cmd, 1_000_000);
                for e in 0..4 {
                    impulse[e] += b.mean_thrust_n[e] * 1e-3;
                }
            }
            for e in 0..4 {
                assert!(
                    (impulse[e] - a.mean_thrust_n[e] * 1e-2).abs() < 1e-9,
                    "step {k}"
                );
                assert_eq!(b.thrust_n[e], a.thrust_n[e], "step {k}");
            }
            assert_eq!(b.ejected_kg(), a.ejected_kg(), "step {k}");
        }
    }
}
