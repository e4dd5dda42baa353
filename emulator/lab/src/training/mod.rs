//! The surrogate's training pipeline (seed paper, Sections III-V): excitation, data from
//! the reference model, history features, polynomial library, Lasso, cross-validation on
//! free-run error, held-out runs, reports and figures. It writes a model file that
//! [`oils_emulator::propulsion::surrogate`] reads; nothing here runs in the loop.
//!
//! `train()` runs the whole pipeline against any reference model given as a factory, so
//! it is tested on the `ideal` model and run on `hifi`.

// Index loops read like the equations in this numerical code.
#![allow(clippy::needless_range_loop)]

pub mod cholesky;
pub mod cv;
pub mod dataset;
pub mod derive;
pub mod excitation;
pub mod figures;
pub mod fit;
pub mod holdout;
pub mod lasso;
pub mod recorded;
pub mod report;
pub mod user;

use cv::{cross_validate, fit_final, CvConfig, CvResult, NestedSums};
use dataset::Dataset;
use excitation::{Excitation, ExcitationConfig};
use fit::{Variant, VariantConfig};
use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::surrogate::model_file::{self, ModelFile, Provenance, Selection};
use oils_emulator::propulsion::{Propulsion, PropulsionKind, PropulsionSpec};
use serde::{Deserialize, Serialize};

/// Which variant goes into the model file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Deploy {
    /// Whichever has the lower cross-validated free-run score.
    Best,
    /// The paper-faithful model.
    Paper,
    /// The shared per-engine model.
    SharedEngine,
}

/// Everything `oils train` does, as plain numbers (committed as `emulator/config/train.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Reference model the data comes from (the source: `hifi`).
    pub reference: PropulsionKind,
    /// Parameters of the reference model.
    pub propulsion: PropulsionConfig,
    /// `hifi` parameter file (TOML, any subset of fields); none: `HifiParams::default()`,
    /// which equals the committed `emulator/config/hifi.toml`.
    pub hifi_params: Option<std::path::PathBuf>,
    /// Surrogate sample time, nanoseconds (the bench step, 10 ms, by default; the bench
    /// step must be a whole multiple of it).
    pub sample_time_ns: u64,
    /// Excitation.
    pub excitation: ExcitationConfig,
    /// Cross-validation grid and solver.
    pub cv: CvConfig,
    /// Variant structure.
    pub variants: VariantConfig,
    /// Variants to cross-validate (the paper's is always among them).
    pub train_variants: Vec<Variant>,
    /// Which one to write as the model file.
    pub deploy: Deploy,
    /// Terms per output printed in the report.
    pub top_terms: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            reference: PropulsionKind::Hifi,
            propulsion: PropulsionConfig::default(),
            hifi_params: None,
            sample_time_ns: 10_000_000,
            excitation: ExcitationConfig::default(),
            cv: CvConfig::default(),
            variants: VariantConfig::default(),
            train_variants: vec![Variant::Paper, Variant::SharedEngine],
            deploy: Deploy::Best,
            top_terms: 8,
        }
    }
}

/// A training configuration is unusable.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("invalid training configuration: {0}")]
pub struct TrainConfigError(pub String);

impl TrainConfig {
    /// Checks every field before anything runs.
    pub fn validate(&self) -> Result<(), TrainConfigError> {
        let e = TrainConfigError;
        if self.sample_time_ns == 0 || self.sample_time_ns > 1_000_000_000 {
            return Err(e("sample_time_ns must be in (0, 1 s]".into()));
        }
        self.excitation.validate().map_err(e)?;
        self.cv.validate().map_err(e)?;
        let v = &self.variants;
        for (name, d) in [
            ("paper_degree", v.paper_degree),
            ("engine_degree", v.engine_degree),
            ("system_degree", v.system_degree),
        ] {
            if !(1..=oils_emulator::propulsion::surrogate::library::MAX_DEGREE).contains(&d) {
                return Err(e(format!("variants.{name} = {d}: must be 1..=3")));
            }
        }
        if !(v.system_mu_scale.is_finite() && v.system_mu_scale > 0.0) {
            return Err(e(format!(
                "variants.system_mu_scale = {}: must be a positive number",
                v.system_mu_scale
            )));
        }
        if let Some(m) = v.system_mu {
            if !(m.is_finite() && m > 0.0) {
                return Err(e(format!(
                    "variants.system_mu = {m}: must be a positive number"
                )));
            }
        }
        if let Some(f) = &v.engine_valve_spec {
            f.validate()
                .map_err(|m| e(format!("variants.engine_valve: {m}")))?;
        }
        if v.engine_valve_sum && v.engine_valve_spec.is_none() {
            return Err(e(
                "variants.engine_valve_sum = true needs a [variants.engine_valve] filter".into(),
            ));
        }
        if v.engine_phase_degree > oils_emulator::propulsion::surrogate::library::MAX_DEGREE {
            return Err(e(format!(
                "variants.engine_phase_degree = {}: must be 0..=3",
                v.engine_phase_degree
            )));
        }
        if v.engine_start_steps > 64 || v.engine_stop_steps > 64 {
            return Err(e(
                "variants.engine_start_steps and engine_stop_steps must be 0..=64".into(),
            ));
        }
        if !self.train_variants.contains(&Variant::Paper) {
            return Err(e("train_variants must include `paper`".into()));
        }
        let wanted = match self.deploy {
            Deploy::Best | Deploy::Paper => Variant::Paper,
            Deploy::SharedEngine => Variant::SharedEngine,
        };
        if !self.train_variants.contains(&wanted) {
            return Err(e(format!(
                "deploy {:?} needs that variant trained",
                self.deploy
            )));
        }
        let steps = self.excitation.duration_s() * 1e9 / self.sample_time_ns as f64;
        if steps < 20.0 * self.cv.folds as f64 * (self.cv.history_max + 2) as f64 {
            return Err(e(
                "the excitation is too short for the folds and history".into()
            ));
        }
        Ok(())
    }

    /// Parses TOML and validates it.
    pub fn from_toml(text: &str) -> Result<Self, TrainConfigError> {
        let cfg: Self = toml::from_str(text).map_err(|err| TrainConfigError(err.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The configuration with its valve filter complete: the stroke table and ignition
    /// clock derived from hifi with `hifi` (when the reference is hifi), or the filter as
    /// given when it asks for neither. Already resolved: returned as it is.
    pub fn resolve(
        &self,
        hifi: Option<&HifiParams>,
    ) -> Result<(Self, Option<derive::ClockFit>), TrainConfigError> {
        let mut cfg = self.clone();
        let v = &mut cfg.variants;
        let Some(spec) = v.engine_valve_spec.filter(|_| v.engine_valve.is_none()) else {
            return Ok((cfg, None));
        };
        let dt_s = self.sample_time_ns as f64 * 1e-9;
        let err = |m: String| TrainConfigError(format!("variants.engine_valve: {m}"));
        let (filter, fit) = match (self.reference, hifi) {
            (PropulsionKind::Hifi, Some(h)) => {
                spec.derive(h, &self.propulsion, dt_s).map_err(err)?
            }
            _ => (spec.plain().map_err(err)?, None),
        };
        v.engine_valve = Some(filter);
        Ok((cfg, fit))
    }

    /// A BLAKE3 hash of the configuration (provenance).
    pub fn hash_hex(&self) -> String {
        let text = serde_json::to_string(self).unwrap_or_default();
        blake3::hash(text.as_bytes()).to_hex().to_string()
    }
}

/// What the reference model is, for provenance.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceInfo {
    /// Model name (`hifi`, `ideal`).
    pub name: String,
    /// Hash of its parameters (a BLAKE3 hex digest of their canonical JSON form: the
    /// scenario's `PropulsionConfig`, and for `hifi` every `HifiParams` field as used).
    pub param_hash: String,
}

impl ReferenceInfo {
    /// Name and parameter hash of a reference model; `hifi` is the hifi parameter set
    /// actually used (only read when `kind` is `Hifi`).
    pub fn new(kind: PropulsionKind, propulsion: &PropulsionConfig, hifi: &HifiParams) -> Self {
        let text = match kind {
            PropulsionKind::Hifi => serde_json::to_string(&(kind, propulsion, hifi)),
            _ => serde_json::to_string(&(kind, propulsion)),
        }
        .unwrap_or_default();
        Self {
            name: kind.as_str().to_string(),
            param_hash: blake3::hash(text.as_bytes()).to_hex().to_string(),
        }
    }

    /// Name and parameter hash of the configured reference model with default hifi
    /// parameters (what the committed configuration uses).
    pub fn of(cfg: &TrainConfig) -> Self {
        Self::new(cfg.reference, &cfg.propulsion, &HifiParams::default())
    }
}

/// The hifi parameters a configuration names (its file, or the defaults).
pub fn hifi_params_of(cfg: &TrainConfig) -> Result<HifiParams, TrainConfigError> {
    match &cfg.hifi_params {
        Some(path) => HifiParams::load(path).map_err(|e| TrainConfigError(e.to_string())),
        None => Ok(HifiParams::default()),
    }
}

/// The reference model a training configuration names, with the hifi parameters it
/// trains on, stepped at the surrogate's sample time.
pub fn reference_spec(cfg: &TrainConfig, hifi: &HifiParams) -> PropulsionSpec {
    PropulsionSpec {
        hifi: hifi.clone(),
        step_ns: Some(cfg.sample_time_ns),
        ..PropulsionSpec::new(cfg.reference, &cfg.propulsion)
    }
}

/// Runs [`train`] with the reference model the configuration names.
pub fn train_configured(
    cfg: &TrainConfig,
    progress: &dyn Progress,
) -> Result<TrainOutcome, TrainConfigError> {
    cfg.propulsion
        .validate()
        .map_err(|e| TrainConfigError(e.to_string()))?;
    let hifi = hifi_params_of(cfg)?;
    let spec = reference_spec(cfg, &hifi);
    // Build once up front so a bad parameter set is an error, not a panic in the factory.
    oils_emulator::propulsion::build(&spec).map_err(|e| TrainConfigError(e.to_string()))?;
    let factory = || {
        oils_emulator::propulsion::build(&spec)
            .unwrap_or_else(|e| unreachable!("built once already: {e}"))
    };
    let info = ReferenceInfo::new(cfg.reference, &cfg.propulsion, &hifi);
    cfg.validate()?;
    // What is derived from hifi (the valve's stroke table and the ignition clock) and the
    // training data do not depend on each other: both at once.
    let excitation = cfg.excitation.generate(cfg.sample_time_ns);
    progress.begin("data, derive", excitation.inputs.len() as u64);
    let (resolved, recorded) = rayon::join(
        || cfg.resolve(Some(&hifi)),
        || Dataset::record(factory().as_mut(), &excitation, || progress.tick()),
    );
    progress.finish();
    let (resolved, clock_fit) = resolved?;
    let initial = model_file::ReferenceOutput::of(&factory().output());
    let mut outcome = train_recorded(&resolved, excitation, recorded, initial, &info, progress)?;
    outcome.clock_fit = clock_fit;
    Ok(outcome)
}

/// Progress reporting hooks (the CLI draws bars; tests pass [`Quiet`]).
pub trait Progress: Sync {
    /// A phase with `total` units of work begins.
    fn begin(&self, phase: &str, total: u64);
    /// One unit done.
    fn tick(&self);
    /// The phase is over.
    fn finish(&self);
}

/// No progress output.
pub struct Quiet;

impl Progress for Quiet {
    fn begin(&self, _: &str, _: u64) {}
    fn tick(&self) {}
    fn finish(&self) {}
}

/// Everything a training run produced.
#[derive(Debug, Clone)]
pub struct TrainOutcome {
    /// The excitation.
    pub excitation: Excitation,
    /// The recorded data.
    pub dataset: Dataset,
    /// Cross-validation of each variant, in `train_variants` order.
    pub cv: Vec<CvResult>,
    /// The final model file of each variant, same order.
    pub models: Vec<ModelFile>,
    /// Index of the deployed one.
    pub deployed: usize,
    /// The valve filter the features read, with what was derived from the reference.
    pub valve: Option<oils_emulator::propulsion::surrogate::valve::ValveFilter>,
    /// How the derived ignition clock fits the reference's ignitions.
    pub clock_fit: Option<derive::ClockFit>,
}

impl TrainOutcome {
    /// The model file to write.
    pub fn deployed_model(&self) -> &ModelFile {
        &self.models[self.deployed]
    }
}

/// Runs the pipeline: excitation, data from `reference`, cross-validation of each variant,
/// final fits, model files. Deterministic: same config and reference, same bits.
pub fn train(
    cfg: &TrainConfig,
    reference: &dyn Fn() -> Box<dyn Propulsion>,
    info: &ReferenceInfo,
    progress: &dyn Progress,
) -> Result<TrainOutcome, TrainConfigError> {
    cfg.validate()?;
    let (cfg, _) = &cfg.resolve(None)?;
    let excitation = cfg.excitation.generate(cfg.sample_time_ns);
    let mut model = reference();
    progress.begin("data", excitation.inputs.len() as u64);
    let recorded = Dataset::record(model.as_mut(), &excitation, || progress.tick());
    progress.finish();
    let initial = model_file::ReferenceOutput::of(&reference().output());
    train_recorded(cfg, excitation, recorded, initial, info, progress)
}

/// [`train`] from the data recorded with `excitation` (its valve filter not yet
/// tracked) from a reference whose held outputs are `initial_output`, with a resolved
/// configuration.
pub(crate) fn train_recorded(
    cfg: &TrainConfig,
    excitation: Excitation,
    recorded: Dataset,
    initial_output: model_file::ReferenceOutput,
    info: &ReferenceInfo,
    progress: &dyn Progress,
) -> Result<TrainOutcome, TrainConfigError> {
    let dataset = recorded.with_valves(cfg.variants.engine_valve);
    let mut results = Vec::new();
    let mut models = Vec::new();
    for &variant in &cfg.train_variants {
        let range = cfg.cv.histories();
        progress.begin(&format!("sums {}", variant.as_str()), cfg.cv.folds as u64);
        let sums = NestedSums::new(
            variant,
            *range.end(),
            &dataset,
            &cfg.cv,
            &cfg.variants,
            &|| progress.tick(),
        );
        progress.finish();
        let span = range.count() * cfg.cv.folds;
        progress.begin(&format!("cv {}", variant.as_str()), span as u64);
        let res = cross_validate(&sums, &dataset, &cfg.cv, &cfg.variants, &|| progress.tick());
        progress.finish();
        let chosen = res.chosen().clone();
        let fitted = fit_final(&sums, chosen.n, chosen.mu, &dataset, &cfg.cv, &cfg.variants);
        models.push(ModelFile::new(
            variant,
            fitted,
            Provenance {
                reference: info.name.clone(),
                reference_param_hash: info.param_hash.clone(),
                excitation_seed: cfg.excitation.seed,
                train_config_hash: cfg.hash_hex(),
                tool: format!("oils-emulator {}", env!("CARGO_PKG_VERSION")),
            },
            Selection {
                history: chosen.n,
                mu: chosen.mu,
                cv_free_run_rmse: chosen.free_rmse,
                cv_one_step_test_rmse: chosen.test_rmse,
                cv_score: chosen.score,
            },
            initial_output,
        ));
        results.push(res);
    }
    let index_of = |v: Variant| cfg.train_variants.iter().position(|x| *x == v);
    let deployed = match cfg.deploy {
        Deploy::Paper => index_of(Variant::Paper),
        Deploy::SharedEngine => index_of(Variant::SharedEngine),
        Deploy::Best => (0..results.len()).min_by(|&a, &b| {
            results[a]
                .chosen()
                .score
                .total_cmp(&results[b].chosen().score)
        }),
    }
    .unwrap_or(0);
    Ok(TrainOutcome {
        excitation,
        dataset,
        cv: results,
        models,
        deployed,
        valve: cfg.variants.engine_valve,
        clock_fit: None,
    })
}
