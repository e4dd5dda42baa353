//! Propulsion models behind one trait: `ideal` (first-order lag), `hifi` (lumped-parameter
//! physics of the pressure-fed system), `surrogate` (the learned sparse polynomial) and
//! `shadow` (hifi drives, the surrogate runs beside it and its divergence is recorded).
//!
//! The plant asks a model to advance by one bench step with the command held, and reads
//! back per-engine thrust and the propellant it ejected. Models own their propellant
//! accounting: the vehicle mass is the initial mass minus what the model reports ejected.

pub mod diagnostics;
pub mod hifi;
pub mod ideal;
pub mod shadow;
pub mod surrogate;

pub use diagnostics::PropulsionDiagnostics;

use crate::config::PropulsionConfig;
use oils_shared::ENGINE_COUNT;

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
}

impl PropulsionKind {
    /// Name as on the command line.
    pub fn as_str(&self) -> &'static str {
        match self {
            PropulsionKind::Ideal => "ideal",
            PropulsionKind::Hifi => "hifi",
            PropulsionKind::Surrogate => "surrogate",
            PropulsionKind::Shadow => "shadow",
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
            other => Err(format!(
                "unknown propulsion model `{other}` (expected ideal, hifi, surrogate or shadow)"
            )),
        }
    }
}

/// Files some models load, chosen on the command line. `None`: the defaults (the
/// committed surrogate model compiled in; `HifiParams::default()`, equal to
/// `emulator/config/hifi.toml`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelFiles {
    /// Surrogate model file.
    pub surrogate_model: Option<std::path::PathBuf>,
    /// Hifi parameter TOML.
    pub hifi_params: Option<std::path::PathBuf>,
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
}

/// Builds the model a bench run asked for, checked against the bench step.
/// Allocation happens here, once, before tick 0.
pub fn build_for_bench(
    kind: PropulsionKind,
    cfg: &PropulsionConfig,
    files: &ModelFiles,
    bench_step_ns: u64,
) -> Result<Box<dyn Propulsion>, BuildError> {
    let params = match &files.hifi_params {
        Some(path) => hifi::HifiParams::load(path)?,
        None => hifi::HifiParams::default(),
    };
    build_configured(
        kind,
        cfg,
        files.surrogate_model.as_deref(),
        &params,
        bench_step_ns,
    )
}

/// Builds a model from values: the surrogate model file (none: the committed model)
/// and the hifi parameters (used by `hifi` and `shadow`).
pub fn build_configured(
    kind: PropulsionKind,
    cfg: &PropulsionConfig,
    surrogate_model: Option<&std::path::Path>,
    hifi_params: &hifi::HifiParams,
    bench_step_ns: u64,
) -> Result<Box<dyn Propulsion>, BuildError> {
    let files = ModelFiles {
        surrogate_model: surrogate_model.map(std::path::Path::to_path_buf),
        hifi_params: None,
    };
    let hifi = || hifi::HifiPropulsion::new(hifi_params, cfg);
    Ok(match kind {
        PropulsionKind::Ideal => Box::new(ideal::IdealPropulsion::new(cfg)),
        PropulsionKind::Hifi => Box::new(hifi()?),
        PropulsionKind::Surrogate => Box::new(surrogate_for_bench(cfg, &files, bench_step_ns)?),
        PropulsionKind::Shadow => Box::new(shadow::ShadowPropulsion::new(
            hifi()?,
            surrogate_for_bench(cfg, &files, bench_step_ns)?,
        )),
    })
}

/// The hifi model with the parameter file in `files` (or the defaults).
pub fn hifi_for_bench(
    cfg: &PropulsionConfig,
    files: &ModelFiles,
) -> Result<hifi::HifiPropulsion, BuildError> {
    let params = match &files.hifi_params {
        Some(path) => hifi::HifiParams::load(path)?,
        None => hifi::HifiParams::default(),
    };
    Ok(hifi::HifiPropulsion::new(&params, cfg)?)
}

/// The surrogate with the model file in `files` (or the committed default).
pub fn surrogate_for_bench(
    cfg: &PropulsionConfig,
    files: &ModelFiles,
    bench_step_ns: u64,
) -> Result<crate::propulsion::surrogate::SurrogatePropulsion, BuildError> {
    use crate::propulsion::surrogate::SurrogatePropulsion;
    Ok(match &files.surrogate_model {
        Some(path) => SurrogatePropulsion::from_path(path, cfg, bench_step_ns)?,
        None => SurrogatePropulsion::default_model(cfg, Some(bench_step_ns))?,
    })
}

/// Builds a model with default files, for tests and tools.
///
/// # Panics
/// When the defaults cannot be built for `cfg` (a `hifi` whose default tanks cannot hold
/// the scenario's propellant): use [`build_for_bench`] to get that as an error.
pub fn build(kind: PropulsionKind, cfg: &PropulsionConfig) -> Box<dyn Propulsion> {
    // The committed surrogate's sample time is the default bench step, 10 ms.
    build_for_bench(kind, cfg, &ModelFiles::default(), 10_000_000)
        .unwrap_or_else(|e| panic!("cannot build the {} propulsion model: {e}", kind.as_str()))
}

/// Builds a model with explicit `hifi` parameters (ignored by the other models).
pub fn build_with_hifi_params(
    kind: PropulsionKind,
    cfg: &PropulsionConfig,
    hifi_params: &hifi::HifiParams,
) -> Result<Box<dyn Propulsion>, BuildError> {
    match kind {
        PropulsionKind::Hifi => Ok(Box::new(hifi::HifiPropulsion::new(hifi_params, cfg)?)),
        other => build_for_bench(other, cfg, &ModelFiles::default(), 10_000_000),
    }
}
