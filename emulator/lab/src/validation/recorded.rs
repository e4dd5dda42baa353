//! Validation on recorded runs (`oils validate --data`): the recording is the truth. A
//! [`Playback`] model hands back the recorded outputs step by step while the surrogate
//! runs free on the recorded commands; each run is judged like a user profile, as a
//! whole against the paper's descent bounds.

use super::cases::{Case, CaseKind, Window, WindowKind};
use crate::training::recorded::RecordedRun;
use oils_emulator::propulsion::surrogate::features::{StateVec, STATE_MF, STATE_MO, STATE_P};
use oils_emulator::propulsion::{EngineCommand, Propulsion, PropulsionOutput};
use oils_shared::profile::{ProfileError, ProfileRow, ThrustProfile};
use oils_shared::ENGINE_COUNT;

/// A recorded run played back as a propulsion model: each step returns the next
/// recorded state whatever the command (the case feeds the recorded commands); past
/// the end it holds the last state.
#[derive(Debug, Clone)]
pub struct Playback {
    initial: StateVec,
    states: Vec<StateVec>,
    tanks_pa: [f64; 2],
    next: usize,
    last: PropulsionOutput,
}

impl Playback {
    /// The run's samples, from its initial state.
    pub fn new(run: &RecordedRun) -> Self {
        let mut p = Self {
            initial: run.dataset.initial,
            states: run.dataset.states.clone(),
            tanks_pa: [
                run.reference_output.fuel_tank_pressure_pa,
                run.reference_output.ox_tank_pressure_pa,
            ],
            next: 0,
            last: PropulsionOutput::default(),
        };
        p.last = p.output_of(&p.initial, &p.initial, 0.0);
        p
    }

    fn output_of(&self, prev: &StateVec, now: &StateVec, per_s: f64) -> PropulsionOutput {
        let mut o = PropulsionOutput {
            gas_pressure_pa: now[STATE_P],
            fuel_tank_pressure_pa: self.tanks_pa[0],
            ox_tank_pressure_pa: self.tanks_pa[1],
            ejected_fuel_kg: now[STATE_MF],
            ejected_ox_kg: now[STATE_MO],
            fuel_flow_kg_s: (now[STATE_MF] - prev[STATE_MF]) * per_s,
            ox_flow_kg_s: (now[STATE_MO] - prev[STATE_MO]) * per_s,
            ..Default::default()
        };
        for e in 0..ENGINE_COUNT {
            o.thrust_n[e] = now[e];
            o.mean_thrust_n[e] = 0.5 * (prev[e] + now[e]);
        }
        o
    }
}

impl Propulsion for Playback {
    fn name(&self) -> &'static str {
        "recorded"
    }

    fn step(&mut self, _cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        let prev = match self.next {
            0 => self.initial,
            k => self.states[(k - 1).min(self.states.len() - 1)],
        };
        let now = self.states[self.next.min(self.states.len() - 1)];
        self.next += 1;
        let per_s = if dt_ns > 0 { 1e9 / dt_ns as f64 } else { 0.0 };
        self.last = self.output_of(&prev, &now, per_s);
        self.last
    }

    fn output(&self) -> PropulsionOutput {
        self.last
    }
}

/// The case of a recorded run: its commands, one row per sample, run for its length,
/// one window judged against the descent bound. Named `data-<file stem>`.
pub fn case_of(run: &RecordedRun) -> Result<Case, ProfileError> {
    let d = &run.dataset;
    let dt = d.sample_time_ns as i64;
    let rows = d
        .inputs
        .iter()
        .enumerate()
        .map(|(k, v)| ProfileRow {
            t_ns: k as i64 * dt,
            thrust_cmd_n: std::array::from_fn(|e| v[e]),
            on: std::array::from_fn(|e| v[ENGINE_COUNT + e] > 0.5),
        })
        .collect();
    let duration_ns = d.len() as i64 * dt;
    let stem = run
        .path
        .file_stem()
        .map_or_else(|| "run".into(), |s| s.to_string_lossy().into_owned());
    Ok(Case {
        name: format!("data-{stem}"),
        kind: CaseKind::Profile,
        profile: ThrustProfile::from_rows(rows)?,
        duration_ns,
        windows: vec![Window {
            kind: WindowKind::Descent,
            start_ns: 0,
            end_ns: duration_ns,
        }],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::training::recorded;
    use crate::validation::compare::run_case;
    use oils_emulator::config::PropulsionConfig;
    use oils_emulator::propulsion::ideal::IdealPropulsion;

    #[test]
    fn a_recording_of_a_model_validates_that_model_with_no_error() {
        // Record the ideal model on a few commands, then validate the ideal model on the
        // recording: every output agrees exactly.
        let mut m = IdealPropulsion::new(&PropulsionConfig::default());
        let mut csv = recorded::REQUIRED_COLUMNS.join(",") + "\n";
        let line = |t: f64, c: &EngineCommand, o: &PropulsionOutput| {
            let mut l = format!("{t}");
            for v in c.thrust_cmd_n {
                l.push_str(&format!(",{v}"));
            }
            for v in c.on {
                l.push_str(&format!(",{}", u8::from(v)));
            }
            for v in o.thrust_n {
                l.push_str(&format!(",{v}"));
            }
            l + &format!(
                ",{},{},{}\n",
                o.gas_pressure_pa, o.ejected_fuel_kg, o.ejected_ox_kg
            )
        };
        let cmd = |k: usize| EngineCommand {
            thrust_cmd_n: [400.0 + k as f64; 4],
            on: [true, !k.is_multiple_of(7), true, true],
        };
        csv.push_str(&line(0.0, &cmd(1), &m.output()));
        for k in 1..300 {
            let c = cmd(k);
            let o = m.step(&c, 10_000_000);
            csv.push_str(&line(k as f64 * 0.01, &c, &o));
        }
        let run = recorded::read(csv.as_bytes(), "rec.csv".as_ref(), 10_000_000).unwrap();
        let case = case_of(&run).unwrap();
        assert_eq!(case.name, "data-rec");
        let mut truth = Playback::new(&run);
        let mut model = IdealPropulsion::new(&PropulsionConfig::default());
        let trace = run_case(&case, &mut truth, &mut model, 10_000_000, 1750.0).unwrap();
        assert_eq!(trace.samples.len(), 300);
        for s in &trace.samples {
            assert_eq!(s.truth, s.model, "at {} ns", s.t_ns);
        }
    }
}
