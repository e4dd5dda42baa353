//! The learned sparse surrogate of the propulsion system (seed paper, Sections III-V) as
//! it runs in the loop: the model file, the fitted model, the features, the valve filter
//! and ignition clock, the predictor, and `SurrogatePropulsion`. Training, which makes
//! the model file, is the lab's (`oils_lab::training`); nothing here depends on it.
//!
//! `SurrogatePropulsion`: the learned model in the loop. It runs free (its own predictions
//! are its history), starts from the state the reference model starts from, evaluates
//! only active terms, and allocates nothing per step. Inputs outside the training
//! envelope are clamped and counted ([`SurrogatePropulsion::out_of_envelope_steps`]).

// Index loops read like the equations in this numerical code.
#![allow(clippy::needless_range_loop)]

pub mod features;
pub mod library;
pub mod model;
pub mod model_file;
pub mod predictor;
pub mod stroke_map;
pub mod valve;

use self::features::{InputVec, StateVec, INPUT_DIM, STATE_MF, STATE_MO, STATE_P};
use self::model_file::{ModelFile, ModelFileError};
use self::predictor::Predictor;
use crate::config::PropulsionConfig;
use crate::propulsion::{EngineCommand, Propulsion, PropulsionOutput};
use oils_shared::ENGINE_COUNT;
use std::path::Path;

/// The committed default model (`emulator/models/surrogate-default.json`), built into the
/// binary so the bench runs without training.
pub const DEFAULT_MODEL_JSON: &str = include_str!("../../../models/surrogate-default.json");

/// The surrogate propulsion model.
#[derive(Debug, Clone)]
pub struct SurrogatePropulsion {
    predictor: Predictor,
    sample_time_ns: u64,
    /// `1 / sample time`, per second: the flows of a step at the model's sample time
    /// without a division on the step path.
    per_sample_s: f64,
    /// Chamber pressure per newton of thrust (the model predicts thrust only).
    chamber_pa_per_n: f64,
    held: self::model_file::ReferenceOutput,
    /// What the latest step was, for [`Propulsion::output`].
    last: LastStep,
}

/// The latest step, as far as [`Propulsion::output`] needs it. Kept instead of the
/// 152-byte output itself, whose copy per step (just written value by value, then read
/// back wide) cost more than the wrapper's arithmetic; and for a step of one sample,
/// the loop's case, nothing at all: its start is the predictor's previous state.
#[derive(Debug, Clone, Copy)]
enum LastStep {
    /// No step yet: no flows, the mean thrust is the thrust.
    None,
    /// One step at the model's sample time.
    Sample,
    /// A step of several samples: the state at its start, 1 / its length in seconds
    /// (0 for a step of length 0) and its mean thrust.
    Substeps {
        start: StateVec,
        per_s: f64,
        mean_thrust_n: [f64; ENGINE_COUNT],
    },
}

impl SurrogatePropulsion {
    /// From a checked model file, for a bench stepping every `bench_step_ns`.
    pub fn new(
        file: &ModelFile,
        cfg: &PropulsionConfig,
        bench_step_ns: u64,
    ) -> Result<Self, ModelFileError> {
        file.check_step(bench_step_ns)?;
        let mut predictor = Predictor::new(&file.model);
        predictor.set_limits(predictor::Limits::of_rating(cfg.max_thrust_n));
        Ok(Self {
            predictor,
            sample_time_ns: file.model.sample_time_ns,
            per_sample_s: 1e9 / file.model.sample_time_ns as f64,
            chamber_pa_per_n: cfg.chamber_pressure_max_pa / cfg.max_thrust_n,
            held: file.reference_output,
            last: LastStep::None,
        })
    }

    /// Loads the model at `path`.
    pub fn from_path(
        path: &Path,
        cfg: &PropulsionConfig,
        bench_step_ns: u64,
    ) -> Result<Self, ModelFileError> {
        Self::new(&ModelFile::load(path)?, cfg, bench_step_ns)
    }

    /// The committed default model; `bench_step_ns` defaults to its sample time.
    pub fn default_model(
        cfg: &PropulsionConfig,
        bench_step_ns: Option<u64>,
    ) -> Result<Self, ModelFileError> {
        let file = ModelFile::parse(DEFAULT_MODEL_JSON)?;
        let step = bench_step_ns.unwrap_or(file.model.sample_time_ns);
        Self::new(&file, cfg, step)
    }

    /// The committed default model's sample time, nanoseconds.
    pub fn default_sample_time_ns() -> Result<u64, ModelFileError> {
        // Parsed once per process: a campaign asks once per case.
        static SAMPLE_NS: std::sync::OnceLock<u64> = std::sync::OnceLock::new();
        if let Some(ns) = SAMPLE_NS.get() {
            return Ok(*ns);
        }
        let ns = ModelFile::parse(DEFAULT_MODEL_JSON)?.model.sample_time_ns;
        Ok(*SAMPLE_NS.get_or_init(|| ns))
    }

    /// Steps on which some feature left the training envelope (and was clamped).
    pub fn out_of_envelope_steps(&self) -> u64 {
        self.predictor.out_of_envelope_steps()
    }

    /// The output after a step from `prev` to `now`; `per_s` is 1 / the step's length in
    /// seconds (0 before any step: no flows).
    #[inline(always)]
    fn output_of(&self, prev: &StateVec, now: &StateVec, per_s: f64) -> PropulsionOutput {
        let mut o = PropulsionOutput {
            gas_pressure_pa: now[STATE_P],
            fuel_tank_pressure_pa: self.held.fuel_tank_pressure_pa,
            ox_tank_pressure_pa: self.held.ox_tank_pressure_pa,
            ejected_fuel_kg: now[STATE_MF],
            ejected_ox_kg: now[STATE_MO],
            ..Default::default()
        };
        for e in 0..ENGINE_COUNT {
            o.thrust_n[e] = now[e];
            // Trapezoid over the step: the model only knows the end points.
            o.mean_thrust_n[e] = 0.5 * (prev[e] + now[e]);
            o.chamber_pressure_pa[e] = now[e] * self.chamber_pa_per_n;
        }
        o.fuel_flow_kg_s = (now[STATE_MF] - prev[STATE_MF]) * per_s;
        o.ox_flow_kg_s = (now[STATE_MO] - prev[STATE_MO]) * per_s;
        o
    }
}

/// The model's input for one step of `cmd`: the four commands (0 for an engine that is
/// off) and the four switches.
pub fn input_of(cmd: &EngineCommand) -> InputVec {
    let mut v = [0.0; INPUT_DIM];
    for e in 0..ENGINE_COUNT {
        v[e] = if cmd.on[e] { cmd.thrust_cmd_n[e] } else { 0.0 };
        v[ENGINE_COUNT + e] = f64::from(u8::from(cmd.on[e]));
    }
    v
}

impl Propulsion for SurrogatePropulsion {
    fn name(&self) -> &'static str {
        "surrogate"
    }

    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        debug_assert!(
            dt_ns.is_multiple_of(self.sample_time_ns),
            "checked at construction"
        );
        let input = input_of(cmd);
        // The bench steps at the model's sample time: one prediction, its trapezoid is the
        // mean thrust, no divisions (the same bits as the general path below). Its start
        // is read back from the predictor's history rather than kept across the step.
        if dt_ns == self.sample_time_ns {
            let now = self.predictor.step(&input);
            self.last = LastStep::Sample;
            return self.output_of(&self.predictor.previous_state(), &now, self.per_sample_s);
        }
        let start = self.predictor.state();
        let substeps = (dt_ns / self.sample_time_ns).max(1);
        let mut sum_mean = [0.0; ENGINE_COUNT];
        let mut prev = start;
        for _ in 0..substeps {
            let now = self.predictor.step(&input);
            for e in 0..ENGINE_COUNT {
                sum_mean[e] += 0.5 * (prev[e] + now[e]);
            }
            prev = now;
        }
        let per_s = if dt_ns > 0 { 1e9 / dt_ns as f64 } else { 0.0 };
        let mut out = self.output_of(&start, &prev, per_s);
        for e in 0..ENGINE_COUNT {
            out.mean_thrust_n[e] = sum_mean[e] / substeps as f64;
        }
        self.last = LastStep::Substeps {
            start,
            per_s,
            mean_thrust_n: out.mean_thrust_n,
        };
        out
    }

    fn output(&self) -> PropulsionOutput {
        let now = self.predictor.state();
        match self.last {
            LastStep::None => self.output_of(&now, &now, 0.0),
            LastStep::Sample => {
                self.output_of(&self.predictor.previous_state(), &now, self.per_sample_s)
            }
            LastStep::Substeps {
                start,
                per_s,
                mean_thrust_n,
            } => PropulsionOutput {
                mean_thrust_n,
                ..self.output_of(&start, &now, per_s)
            },
        }
    }

    /// A model that keeps predicting beyond its physical bounds is not one to fly on.
    fn failure(&self) -> Option<&'static str> {
        (self.predictor.guards().bounded_predictions >= self::model::MAX_BOUNDED_STEPS).then_some(
            "the surrogate predicted thrust above 2 x max_thrust_n or gas pressure above 1e8 Pa on 10 steps (clamped each time): the model is not physical",
        )
    }

    fn diagnostics(&self) -> Option<crate::propulsion::PropulsionDiagnostics> {
        Some(crate::propulsion::PropulsionDiagnostics {
            out_of_envelope_steps: Some(self.out_of_envelope_steps()),
            surrogate_guards: Some(self.predictor.guards()),
            hifi_non_finite_rollbacks: None,
            shadow: None,
        })
    }
}
