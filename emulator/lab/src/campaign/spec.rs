//! The campaign spec: a TOML file naming the cases, the master seed, the base run and
//! the dispersions. `emulator/campaigns/default.toml` is the committed default.

use super::CampaignError;
use oils_emulator::faults::FaultSpec;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::RunConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The committed default campaign (`oils mc run` with no `--spec`).
pub const DEFAULT_CAMPAIGN_TOML: &str = include_str!("../../../campaigns/default.toml");

/// Most cases one campaign may hold (a case result is a file: keep directories sane).
pub const MAX_CASES: u64 = 10_000_000;

/// A campaign.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignSpec {
    /// Name, for reports.
    #[serde(default = "default_name")]
    pub name: String,
    /// Number of cases.
    pub cases: u64,
    /// Master seed: every random number of case `i` comes from (seed, i, dispersion name).
    pub seed: u64,
    /// Wall-time budget of one case, seconds; a case over it is recorded as `timeout`.
    #[serde(default = "default_case_timeout_s")]
    pub case_timeout_s: f64,
    /// The run every case starts from (propulsion, flight software, step, scenario...).
    /// Its `seed` is replaced by each case's own; it always runs in process, lockstep.
    #[serde(default)]
    pub base: RunConfig,
    /// The surrogate's validated error injected as model uncertainty.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_error: Option<ModelErrorSpec>,
    /// Dispersions of configuration values.
    #[serde(default, rename = "dispersion", skip_serializing_if = "Vec::is_empty")]
    pub dispersions: Vec<Dispersion>,
    /// Faults that may strike a case.
    #[serde(default, rename = "fault", skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultDispersion>,
    /// What the results are held against in the figures and the report page.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub requirements: Option<Requirements>,
}

/// Requirements a campaign is judged against (drawn in the figures, counted on the page).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Requirements {
    /// Landing zone: full downrange and crossrange axes of an ellipse about the site
    /// (until the scenario has a site: the nominal case's touchdown point), metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub footprint_m: Option<[f64; 2]>,
}

fn default_name() -> String {
    "campaign".into()
}
fn default_case_timeout_s() -> f64 {
    120.0
}

/// How a drawn number becomes the configuration value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Apply {
    /// nominal + draw.
    #[default]
    Offset,
    /// nominal x draw.
    Scale,
    /// the draw itself.
    Set,
}

/// A distribution to draw from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Distribution {
    /// Normal.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        std: f64,
    },
    /// Normal restricted to [min, max] (redrawn until inside; at most 1000 tries, then
    /// clipped).
    TruncatedNormal {
        /// Mean.
        mean: f64,
        /// Standard deviation.
        std: f64,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
    /// Uniform on [min, max).
    Uniform {
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
    },
    /// One of `values`, with `weights` (equal if absent).
    Choice {
        /// The values.
        values: Vec<f64>,
        /// Relative weights, one per value.
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        weights: Vec<f64>,
    },
}

/// A named dispersion of one or more configuration values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dispersion {
    /// Name: the random stream's name and the results' column.
    pub name: String,
    /// Configuration values it sets, as paths in the run configuration
    /// (`scenario.initial.altitude_m`, `scenario.lander.inertia_wet_kg_m2[0]`,
    /// `hifi.regulator.spring_rate_n_m`). Each target gets its own draw, in order.
    pub targets: Vec<String>,
    /// How the draw is applied.
    #[serde(default)]
    pub apply: Apply,
    /// What is drawn.
    pub dist: Distribution,
    /// One draw for every target instead of one each.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub shared: bool,
    /// Propulsion models it applies to (empty: all).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub models: Vec<PropulsionKind>,
}

/// The surrogate's validated error, injected as the seed paper does.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelErrorSpec {
    /// Statistics file (`oils validate` writes `<model>.uncertainty.json`); absent: the
    /// one beside the run's model (the committed default's for the default model).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<PathBuf>,
    /// Multiplies every standard deviation (1: as validated).
    #[serde(default = "one")]
    pub scale: f64,
    /// Decay time of a transient error, seconds.
    #[serde(default = "default_tau_s")]
    pub transient_tau_s: f64,
    /// Command change within one step that starts a transient, newtons.
    #[serde(default = "default_step_threshold_n")]
    pub step_threshold_n: f64,
    /// Propulsion models it applies to.
    #[serde(default = "surrogate_only")]
    pub models: Vec<PropulsionKind>,
}

fn one() -> f64 {
    1.0
}
fn default_tau_s() -> f64 {
    0.2
}
fn default_step_threshold_n() -> f64 {
    40.0
}
fn surrogate_only() -> Vec<PropulsionKind> {
    vec![PropulsionKind::Surrogate]
}

/// A fault that strikes a case with a probability, at a uniform time in a window.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultDispersion {
    /// Name: the random stream's name and the results' column.
    pub name: String,
    /// The fault without its trigger, in `oils run --fault` syntax (`engine_off:2`,
    /// `thrust_degraded:1,factor=0.8`).
    pub fault: String,
    /// Probability that a case gets it.
    pub probability: f64,
    /// Window of the trigger time, seconds of simulated time.
    #[serde(deserialize_with = "window_s")]
    pub window_s: [f64; 2],
    /// How long it lasts, seconds (absent: to the end).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
    /// Propulsion models it applies to (empty: all).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub models: Vec<PropulsionKind>,
}

/// `window_s` at exactly two elements (toml drops extra ones unread; issue #36).
fn window_s<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    oils_emulator::fixed_len::deserialize(d, "fault.window_s")
}

impl FaultDispersion {
    /// The fault with a trigger at `t_s`.
    pub fn at(&self, t_s: f64) -> Result<FaultSpec, String> {
        let mut text = format!("{}@t={t_s}", self.fault);
        if let Some(d) = self.duration_s {
            text.push_str(&format!(",for={d}"));
        }
        text.parse::<FaultSpec>()
    }
}

fn bad(what: impl Into<String>) -> CampaignError {
    CampaignError::Spec(what.into())
}

impl Distribution {
    fn validate(&self, name: &str) -> Result<(), CampaignError> {
        let finite = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
        let ok = match self {
            Distribution::Normal { mean, std } => finite(&[*mean, *std]) && *std >= 0.0,
            Distribution::TruncatedNormal {
                mean,
                std,
                min,
                max,
            } => finite(&[*mean, *std, *min, *max]) && *std >= 0.0 && min < max,
            Distribution::Uniform { min, max } => finite(&[*min, *max]) && min <= max,
            Distribution::Choice { values, weights } => {
                !values.is_empty()
                    && finite(values)
                    && (weights.is_empty()
                        || (weights.len() == values.len()
                            && finite(weights)
                            && weights.iter().all(|w| *w >= 0.0)
                            && weights.iter().sum::<f64>() > 0.0))
            }
        };
        if ok {
            Ok(())
        } else {
            Err(bad(format!(
                "dispersion `{name}`: {self:?} is not a valid distribution (finite numbers, std >= 0, min <= max (< for truncated), choice: values, and one weight >= 0 per value with a positive sum)"
            )))
        }
    }
}

impl CampaignSpec {
    /// The committed default campaign.
    pub fn default_campaign() -> Self {
        Self::parse(
            DEFAULT_CAMPAIGN_TOML,
            Path::new("emulator/campaigns/default.toml"),
        )
        .expect("the committed default campaign is valid (a test checks it)")
    }

    /// Reads and checks a spec file.
    pub fn load(path: &Path) -> Result<Self, CampaignError> {
        const MAX_BYTES: u64 = 4 << 20;
        let meta = std::fs::metadata(path).map_err(|source| CampaignError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        if meta.len() > MAX_BYTES {
            return Err(bad(format!(
                "{}: {} bytes; a campaign spec is at most {MAX_BYTES}",
                path.display(),
                meta.len()
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|source| CampaignError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks spec text (`path` only names it in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Self, CampaignError> {
        let spec: Self = toml::from_str(text)
            .map_err(|e| bad(format!("{}: {}", path.display(), e.message())))?;
        spec.validate()?;
        Ok(spec)
    }

    /// The spec as TOML (what `DIR/campaign.toml` holds).
    pub fn to_toml(&self) -> Result<String, CampaignError> {
        toml::to_string(self).map_err(|e| bad(format!("cannot write the spec as TOML: {e}")))
    }

    /// Checks everything that can be checked without running a case.
    pub fn validate(&self) -> Result<(), CampaignError> {
        if !(1..=MAX_CASES).contains(&self.cases) {
            return Err(bad(format!("cases = {} (1-{MAX_CASES})", self.cases)));
        }
        if !(self.case_timeout_s.is_finite() && self.case_timeout_s > 0.0) {
            return Err(bad(format!(
                "case_timeout_s = {} (> 0 seconds)",
                self.case_timeout_s
            )));
        }
        let mut base = self.base.clone();
        base.link = oils_emulator::run_config::LinkKind::Inproc;
        base.validate().map_err(|e| bad(format!("base: {e}")))?;
        if base.propulsion == PropulsionKind::Fmu {
            return Err(bad(
                "base.propulsion = \"fmu\": a campaign builds each case's model in its worker, which has no FMU loader; fly the FMU with `oils run --propulsion fmu:PATH`, or campaign on hifi, surrogate or ideal",
            ));
        }
        if matches!(base.fsw, oils_onboard_stub::fsw::FswSpec::External) {
            return Err(bad(
                "base.fsw = \"external\": a campaign runs its flight software in process (gnc, playback or c:PATH)",
            ));
        }
        let mut names = std::collections::BTreeSet::new();
        let mut unique = |name: &str| {
            if name.is_empty()
                || !name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                return Err(bad(format!(
                    "name `{name}`: use letters, digits, `_` and `-` (it names a results column)"
                )));
            }
            if RESERVED.contains(&name) || !names.insert(name.to_string()) {
                return Err(bad(format!(
                    "name `{name}` is used twice or is reserved ({})",
                    RESERVED.join(", ")
                )));
            }
            Ok(())
        };
        for d in &self.dispersions {
            unique(&d.name)?;
            if d.targets.is_empty() {
                return Err(bad(format!("dispersion `{}`: no targets", d.name)));
            }
            d.dist.validate(&d.name)?;
        }
        if let Some(m) = &self.model_error {
            unique("model_error")?;
            let ok = m.scale.is_finite()
                && (0.0..=100.0).contains(&m.scale)
                && m.transient_tau_s.is_finite()
                && m.transient_tau_s > 0.0
                && m.step_threshold_n.is_finite()
                && m.step_threshold_n > 0.0;
            if !ok {
                return Err(bad(
                    "model_error: scale in [0, 100], transient_tau_s > 0, step_threshold_n > 0",
                ));
            }
        }
        for f in &self.faults {
            unique(&f.name)?;
            let w = f.window_s;
            if !(f.probability.is_finite() && (0.0..=1.0).contains(&f.probability)) {
                return Err(bad(format!(
                    "fault `{}`: probability = {} (0-1)",
                    f.name, f.probability
                )));
            }
            if !(w[0].is_finite() && w[1].is_finite() && 0.0 <= w[0] && w[0] <= w[1]) {
                return Err(bad(format!(
                    "fault `{}`: window_s = {w:?} (0 <= start <= end)",
                    f.name
                )));
            }
            let spec = f
                .at(w[0])
                .map_err(|e| bad(format!("fault `{}`: {e}", f.name)))?;
            spec.validate()
                .map_err(|e| bad(format!("fault `{}`: {e}", f.name)))?;
        }
        if let Some(zone) = self.requirements.and_then(|r| r.footprint_m) {
            if !zone.iter().all(|x| x.is_finite() && *x > 0.0) {
                return Err(bad(format!(
                    "requirements.footprint_m = {zone:?} (two lengths > 0 metres)"
                )));
            }
        }
        Ok(())
    }

    /// Whether `models` (empty: all) includes the campaign's propulsion model.
    pub fn applies(&self, models: &[PropulsionKind]) -> bool {
        models.is_empty() || models.contains(&self.base.propulsion)
    }
}

/// Names a dispersion may not take (they are streams or columns of their own).
pub const RESERVED: &[&str] = &[
    "seed",
    "index",
    "outcome",
    "outcome_reason",
    "digest",
    "nominal",
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_default_campaign_is_valid() {
        let spec = CampaignSpec::default_campaign();
        assert!(spec.cases >= 100);
        assert!(!spec.dispersions.is_empty());
        assert!(spec.model_error.is_some());
        assert!(!spec.faults.is_empty());
    }

    #[test]
    fn a_spec_survives_toml_both_ways() {
        let spec = CampaignSpec::default_campaign();
        let text = spec.to_toml().unwrap();
        let back = CampaignSpec::parse(&text, Path::new("x")).unwrap();
        assert_eq!(back, spec);
    }

    #[test]
    fn bad_specs_are_refused_with_the_reason() {
        let bad = |text: &str| {
            CampaignSpec::parse(text, Path::new("t.toml"))
                .unwrap_err()
                .to_string()
        };
        assert!(bad("cases = 0\nseed = 1\n").contains("cases = 0"));
        assert!(bad("cases = 5\nseed = 1\nbogus = 2\n").contains("bogus"));
        let e = bad("cases = 5\nseed = 1\n[[dispersion]]\nname = \"a\"\ntargets = [\"x\"]\ndist = { kind = \"normal\", mean = 0.0, std = -1.0 }\n");
        assert!(e.contains("dispersion `a`"), "{e}");
        let e = bad("cases = 5\nseed = 1\n[[dispersion]]\nname = \"seed\"\ntargets = [\"x\"]\ndist = { kind = \"uniform\", min = 0.0, max = 1.0 }\n");
        assert!(e.contains("reserved"), "{e}");
        let e = bad("cases = 5\nseed = 1\n[[fault]]\nname = \"f\"\nfault = \"engine_off:9\"\nprobability = 0.5\nwindow_s = [1.0, 2.0]\n");
        assert!(e.contains("fault `f`"), "{e}");
        let e = bad("cases = 5\nseed = 1\n[requirements]\nfootprint_m = [0.0, 1.0]\n");
        assert!(e.contains("footprint_m"), "{e}");
        let e = bad("cases = 5\nseed = 1\n[base]\ndt_ms = 0\n");
        assert!(e.contains("dt_ms"), "{e}");
        // Issue #36: a third window element was dropped silently.
        let e = bad("cases = 5\nseed = 1\n[[fault]]\nname = \"f\"\nfault = \"engine_off:1\"\nprobability = 0.5\nwindow_s = [1.0, 2.0, \"x\"]\n");
        assert!(
            e.contains("`fault.window_s` has 3 elements, expected 2"),
            "{e}"
        );
        let e = bad("cases = 5\nseed = 1\n[base.scenario.lander]\nengine_thrust_scale = [1.0, 1.0, 1.0, 1.0, 1.0]\n");
        assert!(
            e.contains("`lander.engine_thrust_scale` has 5 elements, expected 4"),
            "{e}"
        );
    }
}
