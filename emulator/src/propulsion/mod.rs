//! Propulsion models behind one trait: `ideal` (first-order lag), `hifi` (lumped-parameter
//! physics of the pressure-fed system), `surrogate` (the learned sparse polynomial) and
//! `shadow` (hifi drives, the surrogate runs beside it and its divergence is recorded).
//!
//! The plant asks a model to advance by one bench step with the command held, and reads
//! back per-engine thrust and the propellant it ejected. Models own their propellant
//! accounting: the vehicle mass is the initial mass minus what the model reports ejected.

pub mod diagnostics;
pub mod held;
pub mod hifi;
pub mod ideal;
pub mod shadow;
pub mod surrogate;

pub use diagnostics::PropulsionDiagnostics;

use crate::config::PropulsionConfig;
use oils_shared::ENGINE_COUNT;
use std::path::PathBuf;

/// What the propulsion system is told for one step (already sanitised by the link).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EngineCommand {
    /// Commanded thrust per engine, newtons, finite and within `[0, max_thrust_n]`.
    pub thrust_cmd_n: [f64; ENGINE_COUNT],
    /// Engine on/off.
    pub on: [bool; ENGINE_COUNT],
}

/// Everything a propulsion model reports after a step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PropulsionOutput {
    /// Thrust per engine at the end of the step, newtons.
    pub thrust_n: [f64; ENGINE_COUNT],
    /// Time-averaged thrust per engine over the step, newtons: what the rigid body feels
    /// when it integrates the step with thrust held.
    pub mean_thrust_n: [f64; ENGINE_COUNT],
    /// Chamber pressure per engine at the end of the step, pascals.
    pub chamber_pressure_pa: [f64; ENGINE_COUNT],
    /// Helium bottle ("gas") pressure, pascals.
    pub gas_pressure_pa: f64,
    /// Fuel tank ullage pressure, pascals.
    pub fuel_tank_pressure_pa: f64,
    /// Oxidiser tank ullage pressure, pascals.
    pub ox_tank_pressure_pa: f64,
    /// Cumulative fuel ejected through the engines since the start, kilograms.
    pub ejected_fuel_kg: f64,
    /// Cumulative oxidiser ejected since the start, kilograms.
    pub ejected_ox_kg: f64,
    /// Total fuel mass flow at the end of the step, kg/s.
    pub fuel_flow_kg_s: f64,
    /// Total oxidiser mass flow at the end of the step, kg/s.
    pub ox_flow_kg_s: f64,
}

impl PropulsionOutput {
    /// Cumulative propellant ejected, kilograms.
    pub fn ejected_kg(&self) -> f64 {
        self.ejected_fuel_kg + self.ejected_ox_kg
    }
}

/// Internal states of a propulsion model worth logging beside its outputs. A model
/// without such a state reports NaN for it ([`PropulsionInternals::NONE`]), so a log
/// never shows a value the model did not compute.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PropulsionInternals {
    /// Pressure regulator outlet, pascals.
    pub regulator_outlet_pa: f64,
    /// Feed manifold pressure, fuel then oxidiser, pascals.
    pub manifold_pressure_pa: [f64; 2],
    /// Throttle valve position per engine, fuel then oxidiser, 0 (shut) to 1 (open).
    pub valve_position: [[f64; 2]; ENGINE_COUNT],
}

impl PropulsionInternals {
    /// A model with none of these states.
    pub const NONE: Self = Self {
        regulator_outlet_pa: f64::NAN,
        manifold_pressure_pa: [f64::NAN; 2],
        valve_position: [[f64::NAN; 2]; ENGINE_COUNT],
    };
}

impl Default for PropulsionInternals {
    fn default() -> Self {
        Self::NONE
    }
}

/// A failure inside the propulsion system, as a model receives it. Engine-off and
/// engine-stuck faults never reach a model: the plant acts on the command instead, which
/// every model then follows physically.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PropulsionFault {
    /// An engine's thrust degraded to `factor` of what it would be.
    ThrustDegraded {
        /// Engine, 0-based.
        engine: usize,
        /// Remaining fraction, [0, 1).
        factor: f64,
    },
    /// An engine's throttle valves stuck where they are.
    ValveStuck {
        /// Engine, 0-based.
        engine: usize,
    },
    /// An engine's throttle valves move `factor` times as fast as they should.
    ValveSlow {
        /// Engine, 0-based.
        engine: usize,
        /// Speed fraction, (0, 1).
        factor: f64,
    },
    /// The pressure regulator failed wide open.
    RegulatorOpen,
    /// The pressure regulator failed shut.
    RegulatorClosed,
    /// The regulator's set point drifts at this rate, Pa/s.
    RegulatorDrift {
        /// Drift rate, Pa/s.
        rate_pa_s: f64,
    },
    /// Helium leaks from the bottle through this flow area, m^2.
    PressurantLeak {
        /// Leak flow area (Cd A), m^2.
        area_m2: f64,
    },
    /// Propellant leaks from a tank.
    PropellantLeak {
        /// 0 fuel, 1 oxidiser.
        side: usize,
        /// Leak rate while the tank holds liquid, kg/s.
        kg_s: f64,
    },
}

/// A propulsion model the plant can step.
///
/// Contract: `step` does not allocate, lock, log or read the clock; the same sequence of
/// commands gives bit-identical outputs.
pub trait Propulsion: Send {
    /// Short name used in reports (`ideal`, `hifi`, `surrogate`).
    fn name(&self) -> &'static str;
    /// Advances the model by `dt_ns` with `cmd` held; returns the outputs at the end.
    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput;
    /// The outputs now, without stepping (at construction: the initial state).
    fn output(&self) -> PropulsionOutput;
    /// What the model reports about itself (envelope exits, shadow divergence); read at
    /// the end of a run, not per step. `None`: nothing to report.
    fn diagnostics(&self) -> Option<PropulsionDiagnostics> {
        None
    }
    /// Internal states for the log, at the current step boundary (no allocation).
    fn internals(&self) -> PropulsionInternals {
        PropulsionInternals::NONE
    }
    /// Whether the model represents `fault` physically (checked before tick 0).
    fn represents(&self, _fault: &PropulsionFault) -> bool {
        false
    }
    /// Starts (`active`) or clears a fault the model represents; a no-op otherwise.
    fn inject(&mut self, _fault: &PropulsionFault, _active: bool) {}
    /// Why the model can no longer step (its state became non-finite and was rolled
    /// back, ...), naming the quantity; `None` while it is sound. Checked after every
    /// step (no allocation): the scheduler ends the run aborted on the first failure.
    fn failure(&self) -> Option<&'static str> {
        None
    }
}

/// Which propulsion model a run uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PropulsionKind {
    /// First-order thrust lag; quick tests.
    Ideal,
    /// Lumped-parameter physics of the pressure-fed system: the truth model.
    Hifi,
    /// The learned sparse surrogate (seed paper); the committed default model unless a
    /// model file is given.
    Surrogate,
    /// Hifi drives the plant; the surrogate runs beside it on the same commands and its
    /// per-output divergence is reported.
    Shadow,
    /// The user's model as an FMU (`propulsion_fmu` in the run configuration): built by
    /// the program that runs the bench (the `oils` binary, through the lab's FMU
    /// import) and handed to the session, never by [`build`]: the core has no FMU loader.
    Fmu,
}

impl PropulsionKind {
    /// Name as on the command line.
    pub fn as_str(&self) -> &'static str {
        match self {
            PropulsionKind::Ideal => "ideal",
            PropulsionKind::Hifi => "hifi",
            PropulsionKind::Surrogate => "surrogate",
            PropulsionKind::Shadow => "shadow",
            PropulsionKind::Fmu => "fmu",
        }
    }
}

impl std::str::FromStr for PropulsionKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ideal" => Ok(PropulsionKind::Ideal),
            "hifi" => Ok(PropulsionKind::Hifi),
            "surrogate" => Ok(PropulsionKind::Surrogate),
            "shadow" => Ok(PropulsionKind::Shadow),
            "fmu" => Ok(PropulsionKind::Fmu),
            other => Err(format!(
                "unknown propulsion model `{other}` (expected ideal, hifi, surrogate, shadow or fmu:PATH)"
            )),
        }
    }
}

/// A propulsion model as a run names it: which model, the engines it drives, and the
/// files and parameters it loads. [`build`] makes the model from it; every caller (the
/// session, training, validation, tools and tests) goes through that one builder.
#[derive(Debug, Clone)]
pub struct PropulsionSpec {
    /// Which model.
    pub kind: PropulsionKind,
    /// The engines (rating, chamber pressure, propellant, lag).
    pub engines: PropulsionConfig,
    /// The surrogate's model file (`surrogate`, `shadow`); `None`: the committed model
    /// compiled in.
    pub surrogate_model: Option<PathBuf>,
    /// The hifi model's parameters (`hifi`, `shadow`); default: `emulator/config/hifi.toml`.
    pub hifi: hifi::HifiParams,
    /// The period at which the plant will step the model, nanoseconds, checked against
    /// the surrogate's sample time; `None`: the model's own sample time.
    pub step_ns: Option<u64>,
}

impl PropulsionSpec {
    /// `kind` on `engines` with the default files, stepped at its own sample time.
    pub fn new(kind: PropulsionKind, engines: &PropulsionConfig) -> Self {
        Self {
            kind,
            engines: engines.clone(),
            surrogate_model: None,
            hifi: hifi::HifiParams::default(),
            step_ns: None,
        }
    }
}

/// A propulsion model could not be built for the bench.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// The surrogate model file was refused.
    #[error(transparent)]
    Surrogate(#[from] crate::propulsion::surrogate::model_file::ModelFileError),
    /// The hifi parameters were refused.
    #[error(transparent)]
    Hifi(#[from] hifi::HifiError),
    /// A model the core does not build ([`PropulsionKind::Fmu`]): the caller's builder
    /// refused it, or none was handed in.
    #[error("{0}")]
    External(String),
}

/// Builds the model `spec` names. Allocation happens here, once, before tick 0.
pub fn build(spec: &PropulsionSpec) -> Result<Box<dyn Propulsion>, BuildError> {
    Ok(match spec.kind {
        PropulsionKind::Ideal => Box::new(ideal::IdealPropulsion::new(&spec.engines)),
        PropulsionKind::Hifi => Box::new(build_hifi(spec)?),
        PropulsionKind::Surrogate => build_surrogate_held(spec)?,
        PropulsionKind::Shadow => Box::new(shadow::ShadowPropulsion::new(
            build_hifi(spec)?,
            build_surrogate(spec)?,
        )),
        PropulsionKind::Fmu => {
            return Err(BuildError::External(
                "an FMU (propulsion = \"fmu\") is built by the program that runs the bench: `oils run --propulsion fmu:PATH` imports it; the run core has no FMU loader".into(),
            ))
        }
    })
}

/// The hifi model of `spec` (whatever its kind), for callers that need the concrete type.
pub fn build_hifi(spec: &PropulsionSpec) -> Result<hifi::HifiPropulsion, BuildError> {
    Ok(hifi::HifiPropulsion::new(&spec.hifi, &spec.engines)?)
}

/// The surrogate for the bench step of `spec`: stepped directly when the step is a whole
/// number of its samples, else (a plant step that divides its sample time, as 1 ms under
/// a 10 ms model) sampled and held ([`held::Held`]).
fn build_surrogate_held(spec: &PropulsionSpec) -> Result<Box<dyn Propulsion>, BuildError> {
    use surrogate::model_file::ModelFile;
    let sample_ns = match &spec.surrogate_model {
        Some(path) => ModelFile::load(path)?.model.sample_time_ns,
        None => surrogate::SurrogatePropulsion::default_sample_time_ns()?,
    };
    match spec.step_ns {
        Some(step) if step > 0 && step < sample_ns && sample_ns.is_multiple_of(step) => {
            let mut at_sample = spec.clone();
            at_sample.step_ns = Some(sample_ns);
            Ok(Box::new(held::Held::new(
                build_surrogate(&at_sample)?,
                sample_ns,
            )))
        }
        _ => Ok(Box::new(build_surrogate(spec)?)),
    }
}

/// The propulsion model's own period for a bench step of `step_ns`, nanoseconds: the
/// surrogate's sample time (held under a faster plant, sub-stepped under a slower one),
/// the bench step for the others (hifi sub-steps internally, ideal is exact).
pub fn model_period_ns(spec: &PropulsionSpec) -> Result<u64, BuildError> {
    let step = spec.step_ns.unwrap_or(10_000_000);
    Ok(match spec.kind {
        PropulsionKind::Surrogate | PropulsionKind::Shadow => match &spec.surrogate_model {
            Some(path) => {
                surrogate::model_file::ModelFile::load(path)?
                    .model
                    .sample_time_ns
            }
            None => surrogate::SurrogatePropulsion::default_sample_time_ns()?,
        },
        PropulsionKind::Ideal | PropulsionKind::Hifi | PropulsionKind::Fmu => step,
    })
}

/// The surrogate of `spec` (whatever its kind), for callers that need the concrete type.
pub fn build_surrogate(
    spec: &PropulsionSpec,
) -> Result<surrogate::SurrogatePropulsion, BuildError> {
    use surrogate::SurrogatePropulsion;
    Ok(match (&spec.surrogate_model, spec.step_ns) {
        (Some(path), step) => {
            let file = surrogate::model_file::ModelFile::load(path)?;
            let step = step.unwrap_or(file.model.sample_time_ns);
            SurrogatePropulsion::new(&file, &spec.engines, step)?
        }
        (None, step) => SurrogatePropulsion::default_model(&spec.engines, step)?,
    })
}
