//! The surrogate model file: versioned, self-describing JSON (feature spec, term names,
//! coefficients, scaling, envelope, sample time, provenance, the CV choice). Loading
//! checks it and refuses a wrong format or version, a truncated file, non-finite numbers,
//! an inconsistent structure, or a sample time that does not divide the bench step.
//!
//! JSON because it is readable, diffable and serde_json writes every f64 so it reads
//! back bit for bit (shortest round-trip digits), which the reproduce test relies on.

use super::features::STATE_DIM;
use super::model::Model;
use crate::propulsion::PropulsionOutput;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Value of the `format` field.
pub const FORMAT: &str = "oils-surrogate";
/// The file version this build reads and writes, and the only one: bump it on any
/// change of meaning, and a file of another version is refused with "retrain with
/// `oils train`" rather than read by old rules. Every structure in the file refuses
/// unknown fields, so a field added later is refused by an older build, never ignored.
pub const VERSION: u32 = 8;

/// Where a model came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Provenance {
    /// Reference model that made the data (`hifi`).
    pub reference: String,
    /// BLAKE3 of the reference model's parameters.
    pub reference_param_hash: String,
    /// Seed of the excitation.
    pub excitation_seed: u64,
    /// BLAKE3 of the training configuration.
    pub train_config_hash: String,
    /// Tool and version that trained it.
    pub tool: String,
}

/// What cross-validation chose and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Selection {
    /// History length n.
    pub history: usize,
    /// Penalty mu (scikit-learn's alpha on standardised terms and outputs).
    pub mu: f64,
    /// Mean over folds of the free-run RMSE per output (N, N, N, N, Pa, kg, kg).
    pub cv_free_run_rmse: [f64; STATE_DIM],
    /// Mean over folds of the one-step test RMSE per output.
    pub cv_one_step_test_rmse: [f64; STATE_DIM],
    /// Selection score (mean normalised free-run RMSE).
    pub cv_score: f64,
}

/// Reference outputs the surrogate does not model but reports (held constant).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceOutput {
    /// Fuel tank pressure at the start, pascals.
    pub fuel_tank_pressure_pa: f64,
    /// Oxidiser tank pressure at the start, pascals.
    pub ox_tank_pressure_pa: f64,
}

impl ReferenceOutput {
    /// Taken from the reference model's initial output.
    pub fn of(out: &PropulsionOutput) -> Self {
        Self {
            fuel_tank_pressure_pa: out.fuel_tank_pressure_pa,
            ox_tank_pressure_pa: out.ox_tank_pressure_pa,
        }
    }
}

/// The file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// File version, [`VERSION`].
    pub version: u32,
    /// One paragraph for a human reader.
    pub description: String,
    /// Which model structure.
    pub variant: Variant,
    /// Provenance.
    pub provenance: Provenance,
    /// The cross-validated choice.
    pub selection: Selection,
    /// Held outputs.
    pub reference_output: ReferenceOutput,
    /// Sparsity, percent of library coefficients that are zero.
    pub sparsity_pct: f64,
    /// The model itself.
    pub model: Model,
}

/// Largest model file read, bytes (the committed model is 132 kB): a larger one is
/// refused before it is read (issue #36: 3000 copies of each term, 110 MB, took 1.4 GB).
pub const MAX_MODEL_FILE_BYTES: u64 = 32 << 20;

/// Why a model file was refused.
#[derive(Debug, thiserror::Error)]
pub enum ModelFileError {
    /// The file could not be read.
    #[error("cannot read surrogate model {path}")]
    Io {
        /// Path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The file is larger than [`MAX_MODEL_FILE_BYTES`].
    #[error("surrogate model file {path} is {bytes} bytes; a model file is at most {MAX_MODEL_FILE_BYTES}")]
    TooLarge {
        /// Path (`<text>` for text handed in).
        path: String,
        /// Its size.
        bytes: u64,
    },
    /// The file ends early.
    #[error("surrogate model file is truncated (JSON ends at line {line}, column {column})")]
    Truncated {
        /// Line.
        line: usize,
        /// Column.
        column: usize,
    },
    /// Not JSON of the expected shape.
    #[error("surrogate model file is malformed: {0}")]
    Malformed(String),
    /// Another kind of file.
    #[error("not a surrogate model file (format `{0}`, expected `{FORMAT}`)")]
    WrongFormat(String),
    /// A version this build cannot read.
    #[error("surrogate model file version {found} is not supported (this build reads version {VERSION} only); retrain with `oils train`")]
    WrongVersion {
        /// Version in the file.
        found: u32,
    },
    /// The bench step is not a whole number of model steps.
    #[error("surrogate sample time {sample_ns} ns does not fit the bench step {bench_ns} ns (the bench step must be a whole multiple)")]
    SampleTime {
        /// Model sample time.
        sample_ns: u64,
        /// Bench step.
        bench_ns: u64,
    },
    /// Structure or numbers are wrong (non-finite coefficient, sizes that disagree).
    #[error("surrogate model file is invalid: {0}")]
    Invalid(String),
}

/// The paragraph written into every file.
pub const DESCRIPTION: &str = "Sparse polynomial surrogate of the propulsion system (seed paper Sec. V). \
Each step predicts the state at the end of a step from the command held over it and the known past: \
features are scaled as (raw - feature_mean) / feature_std after clamping to [envelope_lo, envelope_hi]; \
a term is the product of the scaled features named by `factors` (index = feature count means 1.0); \
an output is intercept + sum(coef * term), an increment on the previous value when target = increment. \
See docs/surrogate.md.";

impl ModelFile {
    /// Wraps a fitted model.
    pub fn new(
        variant: Variant,
        model: Model,
        provenance: Provenance,
        selection: Selection,
        reference_output: ReferenceOutput,
    ) -> Self {
        Self {
            format: FORMAT.into(),
            version: VERSION,
            description: DESCRIPTION.into(),
            variant,
            provenance,
            selection,
            reference_output,
            sparsity_pct: model.sparsity_pct(),
            model,
        }
    }

    /// Serialises (pretty JSON, trailing newline).
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self).unwrap_or_default();
        s.push('\n');
        s
    }

    /// Parses and checks a file's text (the sample time is checked by [`Self::check_step`]).
    pub fn parse(text: &str) -> Result<Self, ModelFileError> {
        if text.len() as u64 > MAX_MODEL_FILE_BYTES {
            return Err(ModelFileError::TooLarge {
                path: "<text>".into(),
                bytes: text.len() as u64,
            });
        }
        // Look at the header first so a wrong version is named as such even when the
        // rest of the layout changed.
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| json_error(e, text))?;
        let format = value.get("format").and_then(|v| v.as_str()).unwrap_or("");
        if format != FORMAT {
            return Err(ModelFileError::WrongFormat(format.to_string()));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if version != u64::from(VERSION) {
            return Err(ModelFileError::WrongVersion {
                found: u32::try_from(version).unwrap_or(u32::MAX),
            });
        }
        let file: Self = serde_json::from_value(value).map_err(|e| json_error(e, text))?;
        file.model.check().map_err(ModelFileError::Invalid)?;
        if file.model.sample_time_ns == 0 {
            return Err(ModelFileError::Invalid("sample_time_ns is 0".into()));
        }
        file.check_nominal_steps()?;
        Ok(file)
    }

    /// Steps a predictor from the model's initial state with every engine off, then
    /// at the top of the on-range, then at its bottom: every state must stay finite
    /// (bounded numbers make that likely, this makes it certain for the nominal path),
    /// and within the physical bounds of an engine rated at the top of the on-range
    /// (the rating training commands up to; [`super::predictor::Limits::of_rating`]).
    fn check_nominal_steps(&self) -> Result<(), ModelFileError> {
        use super::features::INPUT_DIM;
        use oils_shared::ENGINE_COUNT;
        let mut p = super::predictor::Predictor::new(&self.model);
        let [lo, hi] = self.model.on_command_range_n;
        let limits = super::predictor::Limits::of_rating(hi);
        let mut on = [0.0; INPUT_DIM];
        for e in 0..ENGINE_COUNT {
            on[ENGINE_COUNT + e] = 1.0;
        }
        let (mut at_hi, mut at_lo) = (on, on);
        for e in 0..ENGINE_COUNT {
            at_hi[e] = hi;
            at_lo[e] = lo;
        }
        let phases = [
            ([0.0; INPUT_DIM], "engines off"),
            (at_hi, "engines on at the top of the on-range"),
            (at_lo, "engines on at the bottom of the on-range"),
        ];
        for (input, what) in phases {
            for step in 0..20 {
                let state = p.step(&input);
                if let Some(i) = (0..STATE_DIM).find(|&i| !state[i].is_finite()) {
                    return Err(ModelFileError::Invalid(format!(
                        "the prediction of state {i} is not finite after {} nominal steps ({what})",
                        step + 1
                    )));
                }
                let thrust_n = state[..ENGINE_COUNT].iter().fold(0.0f64, |m, t| m.max(*t));
                let gas_pa = state[super::features::STATE_P];
                if thrust_n > limits.thrust_n || gas_pa > limits.gas_pressure_pa {
                    return Err(ModelFileError::Invalid(format!(
                        "after {} nominal steps ({what}) the model predicts {thrust_n:.6e} N of thrust and {gas_pa:.6e} Pa of gas pressure: beyond {} x the top of its on-range ({hi} N) or {:e} Pa, not physical",
                        step + 1,
                        super::model::MAX_THRUST_OVER_RATING,
                        super::model::MAX_GAS_PRESSURE_PA,
                    )));
                }
            }
        }
        Ok(())
    }

    /// Reads and checks a file.
    pub fn load(path: &Path) -> Result<Self, ModelFileError> {
        let io = |source| ModelFileError::Io {
            path: path.display().to_string(),
            source,
        };
        let bytes = std::fs::metadata(path).map_err(io)?.len();
        if bytes > MAX_MODEL_FILE_BYTES {
            return Err(ModelFileError::TooLarge {
                path: path.display().to_string(),
                bytes,
            });
        }
        let text = std::fs::read_to_string(path).map_err(io)?;
        Self::parse(&text)
    }

    /// Model steps per bench step, or an error if the bench step is not a whole multiple.
    pub fn check_step(&self, bench_step_ns: u64) -> Result<u64, ModelFileError> {
        let sample_ns = self.model.sample_time_ns;
        if bench_step_ns == 0 || !bench_step_ns.is_multiple_of(sample_ns) {
            return Err(ModelFileError::SampleTime {
                sample_ns,
                bench_ns: bench_step_ns,
            });
        }
        Ok(bench_step_ns / sample_ns)
    }
}

fn json_error(e: serde_json::Error, text: &str) -> ModelFileError {
    let msg = e.to_string();
    if e.is_eof() {
        ModelFileError::Truncated {
            line: e.line(),
            column: e.column(),
        }
    } else if msg.contains("number out of range")
        || msg.contains("null, expected f64")
        || text.contains("NaN")
        || text.contains("Infinity")
    {
        // JSON has no NaN or infinity: serde_json writes them as null, other tools as
        // bare words or overflowing numbers. Name the real problem.
        ModelFileError::Invalid(format!("non-finite number (NaN or infinity): {msg}"))
    } else {
        ModelFileError::Malformed(msg)
    }
}
/// Which model structure a file holds (and training fits).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Variant {
    /// The paper as written: one MIMO model, `11n+10` features, seven absolute outputs.
    Paper,
    /// Beyond the paper: one per-engine thrust model with coefficients shared by the
    /// four engines (trained on all four engines' rows) predicting thrust increments,
    /// plus a MIMO model of the increments of gas pressure and ejected masses.
    SharedEngine,
}

impl Variant {
    /// Name in reports and the model file.
    pub fn as_str(&self) -> &'static str {
        match self {
            Variant::Paper => "paper",
            Variant::SharedEngine => "shared-engine",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::PropulsionConfig;
    use crate::propulsion::surrogate::model::{
        MAX_BOUNDED_STEPS, MAX_GAS_PRESSURE_PA, MAX_THRUST_OVER_RATING,
    };
    use crate::propulsion::surrogate::{SurrogatePropulsion, DEFAULT_MODEL_JSON};
    use crate::propulsion::{EngineCommand, Propulsion};

    fn committed() -> serde_json::Value {
        serde_json::from_str(DEFAULT_MODEL_JSON).unwrap()
    }

    fn refused(v: &serde_json::Value) -> String {
        match ModelFile::parse(&v.to_string()) {
            Err(e @ ModelFileError::Invalid(_)) => e.to_string(),
            other => panic!("not refused as invalid: {other:?}"),
        }
    }

    /// Issue #36: a model of 3000 copies of each term (110 MB, 1.4 GB resident) flew.
    #[test]
    fn a_term_given_twice_is_refused() {
        let mut v = committed();
        let terms = &mut v["model"]["submodels"][0]["rows"][0]["terms"];
        let first = terms[0].clone();
        terms.as_array_mut().unwrap().push(first);
        let e = refused(&v);
        assert!(e.contains("appears twice"), "{e}");
        // The same monomial with its factors in another order is the same term.
        let mut v = committed();
        let terms = &mut v["model"]["submodels"][1]["rows"][0]["terms"];
        let mut t = terms[0].clone();
        let f = t["factors"].as_array_mut().unwrap();
        f.reverse();
        terms.as_array_mut().unwrap().push(t);
        let e = refused(&v);
        assert!(e.contains("appears twice"), "{e}");
    }

    #[test]
    fn a_model_file_above_the_size_bound_is_refused_before_it_is_read() {
        let dir = std::env::temp_dir().join(format!("oils-model-size-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("huge.json");
        // Sparse: nothing of it is ever read.
        std::fs::File::create(&path)
            .unwrap()
            .set_len(MAX_MODEL_FILE_BYTES + 1)
            .unwrap();
        let e = ModelFile::load(&path).unwrap_err();
        assert!(matches!(e, ModelFileError::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("at most 33554432"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
        let text = DEFAULT_MODEL_JSON.to_string() + &" ".repeat(MAX_MODEL_FILE_BYTES as usize);
        let e = ModelFile::parse(&text).unwrap_err();
        assert!(matches!(e, ModelFileError::TooLarge { .. }), "{e}");
        ModelFile::load(Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/models/surrogate-default.json"
        )))
        .unwrap();
    }

    /// Issue #36: a coefficient of 1e11 (inside the 1e12 bound of each number) flew to
    /// COMPLETED at 1.08e13 N per engine, no guard counted. At load, the nominal steps
    /// must stay within the physical bounds.
    #[test]
    fn a_model_beyond_its_physical_bounds_on_the_nominal_steps_is_refused() {
        for (row, intercept) in [(0, 1e9), (0, 2000.0)] {
            let mut v = committed();
            v["model"]["submodels"][0]["rows"][row]["intercept"] = serde_json::json!(intercept);
            let e = refused(&v);
            assert!(e.contains("not physical"), "{e}");
        }
        let mut v = committed();
        // Gas pressure rising 100 bar a step from 280 bar.
        v["model"]["submodels"][1]["rows"][0]["intercept"] = serde_json::json!(1e7);
        let e = refused(&v);
        assert!(e.contains("Pa of gas pressure"), "{e}");
    }

    /// What the load check cannot see (a term outside the nominal steps' phases) the
    /// runtime bounds: clamped, counted, and after MAX_BOUNDED_STEPS the model fails.
    #[test]
    fn predictions_beyond_the_physical_bounds_are_clamped_counted_and_end_the_run() {
        let mut file = ModelFile::parse(DEFAULT_MODEL_JSON).unwrap();
        file.model.submodels[0].rows[0].intercept = 1e9;
        let cfg = PropulsionConfig::default();
        let mut s = SurrogatePropulsion::new(&file, &cfg, file.model.sample_time_ns).unwrap();
        let cmd = EngineCommand {
            thrust_cmd_n: [600.0; 4],
            on: [true; 4],
        };
        for _ in 0..MAX_BOUNDED_STEPS {
            assert_eq!(s.failure(), None);
            let out = s.step(&cmd, file.model.sample_time_ns);
            assert!(out
                .thrust_n
                .iter()
                .all(|&t| t == MAX_THRUST_OVER_RATING * cfg.max_thrust_n));
        }
        let why = s.failure().expect("the model failed");
        let guards = s.diagnostics().unwrap().surrogate_guards.unwrap();
        assert_eq!(guards.bounded_predictions, MAX_BOUNDED_STEPS);
        // The message states the bounds as the constants have them.
        for part in [
            format!("above {MAX_THRUST_OVER_RATING} x max_thrust_n"),
            format!("above {MAX_GAS_PRESSURE_PA:e} Pa"),
            format!("on {MAX_BOUNDED_STEPS} steps"),
        ] {
            assert!(why.contains(&part), "{why}: {part}");
        }
        // The committed model, the same commands: nothing bounded.
        let mut s = SurrogatePropulsion::default_model(&cfg, None).unwrap();
        for _ in 0..500 {
            s.step(&cmd, file.model.sample_time_ns);
        }
        let guards = s.diagnostics().unwrap().surrogate_guards.unwrap();
        assert_eq!((guards.bounded_predictions, s.failure()), (0, None));
    }

    /// Found by the bound (tests/link_faults.rs, garbage commands): engine 4 toggled
    /// every few steps beside engine 3 at its minimum drives the committed model out of
    /// its envelope until it predicts 285 kN on engines 1 and 2, which are off. The
    /// run then ends with the model failed instead of flying on that.
    #[test]
    fn the_committed_model_run_away_out_of_its_envelope_is_bounded_and_fails() {
        let cfg = PropulsionConfig::default();
        let mut s = SurrogatePropulsion::default_model(&cfg, None).unwrap();
        let mut failed_at = None;
        for k in 0..300u64 {
            let cmd = EngineCommand {
                thrust_cmd_n: [0.0, 0.0, 0.0, if k % 2 == 0 { 800.0 } else { 500.0 }],
                on: [false, false, true, k % 3 != 0],
            };
            let out = s.step(&cmd, 10_000_000);
            assert!(out
                .thrust_n
                .iter()
                .all(|&t| t <= MAX_THRUST_OVER_RATING * cfg.max_thrust_n));
            if s.failure().is_some() {
                failed_at.get_or_insert(k);
            }
        }
        assert!(failed_at.is_some_and(|k| k < 100), "{failed_at:?}");
    }
}
