//! Training data: the reference propulsion model (hifi) driven by the excitation, one
//! sample per surrogate sample time, and its CSV export for re-fitting elsewhere.

use super::excitation::Excitation;
use oils_emulator::propulsion::surrogate::features::{
    FeatureSpec, InputVec, StateVec, TrajectoryHistory, STATE_DIM, STATE_MF, STATE_MO, STATE_NAMES,
    STATE_P,
};
use oils_emulator::propulsion::surrogate::valve::{ValveFilter, ValveState};
use oils_emulator::propulsion::{EngineCommand, Propulsion, PropulsionOutput};
use oils_shared::ENGINE_COUNT;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

/// The state vector the surrogate models, read from a propulsion output.
pub fn state_of(out: &PropulsionOutput) -> StateVec {
    let mut s = [0.0; STATE_DIM];
    s[..ENGINE_COUNT].copy_from_slice(&out.thrust_n);
    s[STATE_P] = out.gas_pressure_pa;
    s[STATE_MF] = out.ejected_fuel_kg;
    s[STATE_MO] = out.ejected_ox_kg;
    s
}

/// The command a sample's inputs stand for.
pub fn command_of(input: &InputVec) -> EngineCommand {
    EngineCommand {
        thrust_cmd_n: std::array::from_fn(|e| input[e]),
        on: std::array::from_fn(|e| input[ENGINE_COUNT + e] > 0.5),
    }
}

/// A recorded run: inputs of every step and the state at the end of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Sample time, nanoseconds.
    pub sample_time_ns: u64,
    /// State before the first step (the reference model at construction).
    pub initial: StateVec,
    /// Every step's inputs.
    pub inputs: Vec<InputVec>,
    /// State at the end of every step.
    pub states: Vec<StateVec>,
    /// The valve filter tracked over the inputs (`with_valves`), if any.
    pub valve_filter: Option<ValveFilter>,
    /// Its state after every step (empty without a filter).
    pub valves: Vec<ValveState>,
}

impl Dataset {
    /// Drives `model` with the excitation; `on_step` is called after each step (progress).
    pub fn record(model: &mut dyn Propulsion, ex: &Excitation, mut on_step: impl FnMut()) -> Self {
        let initial = state_of(&model.output());
        let mut states = Vec::with_capacity(ex.inputs.len());
        for input in &ex.inputs {
            let out = model.step(&command_of(input), ex.sample_time_ns);
            states.push(state_of(&out));
            on_step();
        }
        Self {
            sample_time_ns: ex.sample_time_ns,
            initial,
            inputs: ex.inputs.clone(),
            states,
            valve_filter: None,
            valves: Vec::new(),
        }
    }

    /// Tracks `filter` over the inputs, for features that read the valve
    /// ([`FeatureSpec::valve`]); `None` clears the track.
    pub fn with_valves(mut self, filter: Option<ValveFilter>) -> Self {
        let dt_s = self.sample_time_ns as f64 * 1e-9;
        self.valves = filter.map_or_else(Vec::new, |f| f.track(&self.inputs, dt_s));
        self.valve_filter = filter;
        self
    }

    /// Panics unless the tracked valve filter is the one `spec` reads (a programming
    /// error: training tracks the configured filter, which every spec gets).
    pub fn assert_valves_for(&self, spec: &FeatureSpec) {
        if spec.valve_features() > 0 {
            assert_eq!(
                spec.valve, self.valve_filter,
                "the dataset tracks another valve filter than the features read"
            );
        }
    }

    /// Number of steps.
    pub fn len(&self) -> usize {
        self.states.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.states.is_empty()
    }

    /// The history as seen from step `t`.
    pub fn history_at(&self, t: usize) -> TrajectoryHistory<'_> {
        TrajectoryHistory {
            inputs: &self.inputs,
            states: &self.states,
            initial: &self.initial,
            valves: &self.valves,
            valve_rest: self
                .valve_filter
                .map_or_else(ValveState::default, |f| f.rest()),
            t,
        }
    }

    /// State at the end of step `t - 1` (the initial state for `t = 0`).
    pub fn previous_state(&self, t: usize) -> &StateVec {
        t.checked_sub(1).map_or(&self.initial, |k| &self.states[k])
    }

    /// Writes `samples.csv` (time series: inputs then states, named columns) and
    /// `features_n{n}.csv` (the paper's raw feature vector for history length `n` and the
    /// seven outputs) into `dir`.
    pub fn export_csv(&self, dir: &Path, spec: &FeatureSpec) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        let dt_s = self.sample_time_ns as f64 * 1e-9;
        let mut w = std::io::BufWriter::new(std::fs::File::create(dir.join("samples.csv"))?);
        let mut line = String::from("t_s,cmd1_n,cmd2_n,cmd3_n,cmd4_n,on1,on2,on3,on4");
        for s in [
            "T_o1_n", "T_o2_n", "T_o3_n", "T_o4_n", "P_pa", "m_f_kg", "m_o_kg",
        ] {
            line.push(',');
            line.push_str(s);
        }
        writeln!(w, "{line}")?;
        for (k, (i, s)) in self.inputs.iter().zip(&self.states).enumerate() {
            line.clear();
            let _ = write!(line, "{}", (k + 1) as f64 * dt_s);
            for v in i.iter().chain(s.iter()) {
                let _ = write!(line, ",{v}");
            }
            writeln!(w, "{line}")?;
        }
        w.flush()?;
        let path = dir.join(format!("features_n{}.csv", spec.history));
        let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
        let mut header = spec.names().join(",");
        for s in STATE_NAMES {
            let _ = write!(header, ",y_{s}[t]");
        }
        writeln!(w, "{header}")?;
        let mut x = vec![0.0; spec.dim()];
        for t in 0..self.len() {
            spec.fill(&self.history_at(t), 0, &mut x);
            line.clear();
            for (j, v) in x.iter().chain(self.states[t].iter()).enumerate() {
                if j > 0 {
                    line.push(',');
                }
                let _ = write!(line, "{v}");
            }
            writeln!(w, "{line}")?;
        }
        w.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::training::excitation::ExcitationConfig;
    use oils_emulator::config::PropulsionConfig;
    use oils_emulator::propulsion::ideal::IdealPropulsion;

    #[test]
    fn records_and_exports() {
        let ex = ExcitationConfig {
            levels: 1,
            sphere_duration_s: 0.5,
            steps: 1,
            ramps: 0,
            switches: 0,
            ..Default::default()
        }
        .generate(10_000_000);
        let mut m = IdealPropulsion::new(&PropulsionConfig::default());
        let mut calls = 0;
        let d = Dataset::record(&mut m, &ex, || calls += 1);
        assert_eq!(calls, ex.inputs.len());
        assert_eq!(d.len(), ex.inputs.len());
        assert_eq!(d.initial[STATE_MF], 0.0);
        assert!(d.states.last().unwrap()[0] > 100.0);
        let dir = std::env::temp_dir().join(format!("oils-dataset-test-{}", std::process::id()));
        let spec = FeatureSpec::paper(2);
        d.export_csv(&dir, &spec).unwrap();
        let f = std::fs::read_to_string(dir.join("features_n2.csv")).unwrap();
        let header = f.lines().next().unwrap();
        assert_eq!(header.split(',').count(), 11 * 2 + 10 + 7);
        assert!(header.starts_with("T_r1[t],"));
        assert_eq!(f.lines().count(), d.len() + 1);
        let s = std::fs::read_to_string(dir.join("samples.csv")).unwrap();
        assert_eq!(s.lines().count(), d.len() + 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
