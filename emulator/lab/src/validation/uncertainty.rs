//! The surrogate's validated error as model uncertainty (seed paper, Section VI: "model
//! error is fed as model uncertainty to carry out Monte Carlo simulation"). `oils
//! validate` writes it beside the model file (`<model>.uncertainty.json`); a Monte Carlo
//! loads it with [`ModelUncertainty::load`] and draws, e.g., a per-engine thrust error
//! `N(mean, std)` of the regime it flies (transient after a throttle step, steady
//! otherwise), bounded by `max_abs`.

use super::cases::WindowKind;
use super::compare::{Trace, GAS, MASS, OUTPUT_NAMES};
use super::report::accumulate;
use super::stats::{ErrorAccumulator, ErrorStats};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `format` of the file.
pub const FORMAT: &str = "oils-surrogate-uncertainty";
/// `version` of the file.
pub const VERSION: u32 = 1;

/// Thrust error (surrogate - hifi, per engine, pooled over the four) by regime.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ThrustUncertainty {
    /// In the transient windows after steps and engine starts.
    pub transient: ErrorStats,
    /// In steady holds and sine sweeps.
    pub steady: ErrorStats,
    /// Over full descent (and user) profiles.
    pub descent: ErrorStats,
    /// Everything.
    pub all: ErrorStats,
}

/// Error statistics of one validation case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaseUncertainty {
    /// Case name.
    pub name: String,
    /// Per output (`thrust1_n` ... `total_mass_kg`).
    pub outputs: BTreeMap<String, ErrorStats>,
}

/// The file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelUncertainty {
    /// Always [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The model these errors belong to (path or `committed default`).
    pub model: String,
    /// BLAKE3 of the model file's bytes: a Monte Carlo can refuse stale statistics.
    pub model_blake3: String,
    /// The truth model.
    pub truth: String,
    /// Bench step of the validation, milliseconds.
    pub dt_ms: f64,
    /// Thrust error by regime.
    pub thrust_n: ThrustUncertainty,
    /// Gas pressure error over every case, pascals.
    pub gas_pressure_pa: ErrorStats,
    /// Total module mass error over every case, kilograms.
    pub total_mass_kg: ErrorStats,
    /// Per case.
    pub cases: Vec<CaseUncertainty>,
}

/// The file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum UncertaintyError {
    /// I/O.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// Not the expected JSON.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
}

impl ModelUncertainty {
    /// Statistics of `traces` for the model whose file bytes are `model_bytes`.
    pub fn from_traces(
        traces: &[Trace],
        model: &str,
        model_bytes: &[u8],
        truth: &str,
        dt_ms: f64,
    ) -> Self {
        let mut thrust: BTreeMap<WindowKind, ErrorAccumulator> = BTreeMap::new();
        let mut thrust_all = ErrorAccumulator::default();
        let mut gas = ErrorAccumulator::default();
        let mut mass = ErrorAccumulator::default();
        let mut cases = Vec::new();
        for t in traces {
            let (all, by_kind) = accumulate(t);
            for (kind, acc) in &by_kind {
                let regime = match kind {
                    WindowKind::Sine => WindowKind::Steady,
                    k => *k,
                };
                thrust.entry(regime).or_default().merge(&acc.thrust);
            }
            thrust_all.merge(&all.thrust);
            gas.merge(&all.outputs[GAS]);
            mass.merge(&all.outputs[MASS]);
            cases.push(CaseUncertainty {
                name: t.case.name.clone(),
                outputs: OUTPUT_NAMES
                    .iter()
                    .zip(&all.outputs)
                    .map(|(n, a)| (n.to_string(), a.stats()))
                    .collect(),
            });
        }
        let of = |k| thrust.get(&k).map(|a| a.stats()).unwrap_or_default();
        Self {
            format: FORMAT.into(),
            version: VERSION,
            model: model.into(),
            model_blake3: blake3::hash(model_bytes).to_hex().to_string(),
            truth: truth.into(),
            dt_ms,
            thrust_n: ThrustUncertainty {
                transient: of(WindowKind::Transient),
                steady: of(WindowKind::Steady),
                descent: of(WindowKind::Descent),
                all: thrust_all.stats(),
            },
            gas_pressure_pa: gas.stats(),
            total_mass_kg: mass.stats(),
            cases,
        }
    }

    /// Where the statistics of the model at `model_path` live: `x.json` ->
    /// `x.uncertainty.json`.
    pub fn path_beside(model_path: &Path) -> PathBuf {
        let stem = model_path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "model".into());
        model_path.with_file_name(format!("{stem}.uncertainty.json"))
    }

    /// Writes pretty JSON.
    pub fn save(&self, path: &Path) -> Result<(), UncertaintyError> {
        let io = |source| UncertaintyError::Io {
            path: path.display().to_string(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let text = serde_json::to_string_pretty(self).map_err(|e| UncertaintyError::Format {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(path, text + "\n").map_err(io)
    }

    /// Loads and checks a file written by [`ModelUncertainty::save`].
    pub fn load(path: &Path) -> Result<Self, UncertaintyError> {
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| UncertaintyError::Io {
            path: shown.clone(),
            source,
        })?;
        Self::parse(&text).map_err(|message| UncertaintyError::Format {
            path: shown,
            message,
        })
    }

    /// Parses and checks the JSON text.
    pub fn parse(text: &str) -> Result<Self, String> {
        let u: Self = serde_json::from_str(text).map_err(|e| e.to_string())?;
        if u.format != FORMAT || u.version != VERSION {
            return Err(format!(
                "expected format `{FORMAT}` version {VERSION}, found `{}` version {}",
                u.format, u.version
            ));
        }
        let t = &u.thrust_n;
        for s in [
            t.transient,
            t.steady,
            t.descent,
            t.all,
            u.gas_pressure_pa,
            u.total_mass_kg,
        ] {
            if ![s.max_abs, s.rms, s.mean, s.std]
                .iter()
                .all(|v| v.is_finite())
            {
                return Err("non-finite statistic".into());
            }
        }
        Ok(u)
    }

    /// Whether these statistics were computed for the model file with these bytes.
    pub fn matches_model(&self, model_bytes: &[u8]) -> bool {
        self.model_blake3 == blake3::hash(model_bytes).to_hex().to_string()
    }
}
