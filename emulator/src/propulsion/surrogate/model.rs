//! A fitted surrogate: what the model file holds (submodels, their active terms,
//! feature scaling and training envelope) and the checks a model must pass before
//! [`super::predictor::Predictor`] steps it.

use super::features::{FeatureSpec, Layout, StateVec, STATE_DIM};
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};

/// What a row of coefficients predicts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// The output itself, `y[t]` (the paper).
    Absolute,
    /// The change over the step, `y[t] - y[t-1]`: the penalty then shrinks towards
    /// "nothing changes" rather than towards zero, and cumulative masses never appear as
    /// a level the polynomial must reproduce.
    Increment,
}

impl Target {
    /// The fitted quantity for an output that was `prev` and is `now` (training).
    #[inline]
    pub fn of(self, prev: f64, now: f64) -> f64 {
        match self {
            Target::Absolute => now,
            Target::Increment => now - prev,
        }
    }

    /// The output from its previous value and a prediction `y` of the fitted quantity.
    #[inline]
    pub fn apply(self, prev: f64, y: f64) -> f64 {
        match self {
            Target::Absolute => y,
            Target::Increment => prev + y,
        }
    }
}

/// One non-zero coefficient.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActiveTerm {
    /// Readable name, e.g. `T_o1[t-2]*P[t-1]` (of scaled features).
    pub name: String,
    /// Indices into the scaled feature vector extended by a 1.0 slot (index = `dim`).
    pub factors: Term,
    /// Coefficient.
    pub coef: f64,
}

/// The coefficients of one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputRow {
    /// Output name (`T_o1` .. `m_o`; `T_o` for the shared per-engine row).
    pub output: String,
    /// Intercept.
    pub intercept: f64,
    /// Active terms only, in library order.
    pub terms: Vec<ActiveTerm>,
}

/// A block of outputs predicted from one feature layout.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Submodel {
    /// Feature layout and history length.
    pub features: FeatureSpec,
    /// Polynomial degree of the library.
    pub degree: usize,
    /// Number of terms in the full library (the active ones are in `rows`).
    pub library_size: usize,
    /// Absolute or increment targets.
    pub target: Target,
    /// State indices predicted. For [`Layout::PerEngine`] these are the four thrusts and
    /// `rows` holds one shared row applied to each engine.
    pub outputs: Vec<usize>,
    /// Feature names, in order.
    pub feature_names: Vec<String>,
    /// Feature scaling: scaled = (raw - mean) / std.
    pub feature_mean: Vec<f64>,
    /// See `feature_mean`.
    pub feature_std: Vec<f64>,
    /// Training envelope of each raw feature (widened by a margin): values outside are
    /// counted and clamped, never extrapolated.
    pub envelope_lo: Vec<f64>,
    /// See `envelope_lo`.
    pub envelope_hi: Vec<f64>,
    /// Coefficients.
    pub rows: Vec<OutputRow>,
}

/// A whole surrogate: every state output predicted by exactly one submodel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Sample time, nanoseconds.
    pub sample_time_ns: u64,
    /// State the runtime starts from (the reference model at construction).
    pub initial_state: StateVec,
    /// Range of thrust commands seen for engines that are on, newtons: the per-feature
    /// envelope cannot tell "on at 50 N" from "off" (0 N), this can.
    pub on_command_range_n: [f64; 2],
    /// The submodels.
    pub submodels: Vec<Submodel>,
}

impl Submodel {
    /// Number of evaluations per step (four for a per-engine model).
    pub fn evaluations(&self) -> usize {
        match self.features.layout {
            Layout::Mimo => 1,
            Layout::PerEngine => ENGINE_COUNT,
        }
    }

    /// Active terms over all rows.
    pub fn active_terms(&self) -> usize {
        self.rows.iter().map(|r| r.terms.len()).sum()
    }
}

impl Model {
    /// Checks the structure (every output covered once, sizes consistent, finite
    /// numbers). Returns a description of the first problem.
    pub fn check(&self) -> Result<(), String> {
        let mut covered = [0usize; STATE_DIM];
        for (i, s) in self.submodels.iter().enumerate() {
            let dim = s.features.dim();
            let ctx = |m: &str| format!("submodel {i}: {m}");
            if s.features.history == 0 || s.features.history > 64 {
                return Err(ctx("history length must be 1..=64"));
            }
            if dim > MAX_FEATURES {
                return Err(ctx(&format!(
                    "{dim} features: a submodel may have at most {MAX_FEATURES}"
                )));
            }
            if !(1..=MAX_DEGREE).contains(&s.degree) {
                return Err(ctx("degree must be 1..=3"));
            }
            if s.features.start_steps > 64 || s.features.stop_steps > 64 {
                return Err(ctx("start_steps and stop_steps must be 0..=64"));
            }
            if s.features.phase_degree > MAX_DEGREE {
                return Err(ctx("phase_degree must be 0..=3"));
            }
            if s.features.layout == Layout::Mimo && s.features.phase_features() > 0 {
                return Err(ctx("phase indicators are per-engine features only"));
            }
            if s.features.valve_sum
                && (s.features.layout != Layout::PerEngine || s.features.valve.is_none())
            {
                return Err(ctx(
                    "valve_sum needs a per-engine layout with a valve filter",
                ));
            }
            if let Some(f) = &s.features.valve {
                f.validate().map_err(|m| ctx(&m))?;
                let other = self.submodels.iter().filter_map(|o| o.features.valve);
                if other.into_iter().any(|o| o != *f) {
                    return Err(ctx("every submodel must read the same valve filter"));
                }
            }
            for (name, v) in [
                ("feature_names", s.feature_names.len()),
                ("feature_mean", s.feature_mean.len()),
                ("feature_std", s.feature_std.len()),
                ("envelope_lo", s.envelope_lo.len()),
                ("envelope_hi", s.envelope_hi.len()),
            ] {
                if v != dim {
                    return Err(ctx(&format!("{name} has {v} entries, features need {dim}")));
                }
            }
            let expect_rows = match s.features.layout {
                Layout::Mimo => s.outputs.len(),
                Layout::PerEngine => {
                    if s.outputs != (0..ENGINE_COUNT).collect::<Vec<_>>() {
                        return Err(ctx("a per-engine submodel predicts the four thrusts"));
                    }
                    1
                }
            };
            if s.rows.len() != expect_rows {
                return Err(ctx("one coefficient row per output expected"));
            }
            for &o in &s.outputs {
                if o >= STATE_DIM {
                    return Err(ctx("output index out of range"));
                }
                covered[o] += 1;
            }
            let finite = |v: &[f64]| v.iter().all(|x| bounded(*x));
            if !finite(&s.feature_mean)
                || !finite(&s.envelope_lo)
                || !finite(&s.envelope_hi)
                || !s
                    .feature_std
                    .iter()
                    .all(|x| bounded(*x) && *x >= MIN_FEATURE_STD)
            {
                return Err(ctx(&format!(
                    "scaling or envelope has a value that is not finite, above {MAX_MAGNITUDE:e} in magnitude, or (feature_std) below {MIN_FEATURE_STD:e}"
                )));
            }
            if s.envelope_lo
                .iter()
                .zip(&s.envelope_hi)
                .any(|(lo, hi)| lo > hi)
            {
                return Err(ctx("envelope_lo is above envelope_hi"));
            }
            let roles = s.features.roles();
            for r in &s.rows {
                if !bounded(r.intercept) {
                    return Err(ctx(&format!(
                        "{}: intercept {} is not finite or above {MAX_MAGNITUDE:e} in magnitude",
                        r.output, r.intercept
                    )));
                }
                for t in &r.terms {
                    if !bounded(t.coef) {
                        return Err(ctx(&format!(
                            "{}: coefficient of {} is {}: not finite or above {MAX_MAGNITUDE:e} in magnitude",
                            r.output, t.name, t.coef
                        )));
                    }
                    if t.factors.iter().any(|&f| f as usize > dim) {
                        return Err(ctx(&format!("{}: term {} out of range", r.output, t.name)));
                    }
                    // The predictor evaluates a phase or ignition term only in its phase
                    // or window, which needs one such feature per term (the library
                    // never makes two).
                    let phased = t
                        .factors
                        .iter()
                        .filter(|&&f| (f as usize) < dim && roles[f as usize].phase)
                        .count();
                    if phased > 1 {
                        return Err(ctx(&format!(
                            "{}: term {} has more than one phase or ignition feature",
                            r.output, t.name
                        )));
                    }
                }
                // Each monomial once (issue #36: 3000 copies of every term loaded).
                if r.terms.len() > s.library_size {
                    return Err(ctx(&format!(
                        "{}: {} active terms, more than the library's {}",
                        r.output,
                        r.terms.len(),
                        s.library_size
                    )));
                }
                let mut seen = std::collections::HashSet::with_capacity(r.terms.len());
                for t in &r.terms {
                    let mut monomial = t.factors;
                    monomial.sort_unstable();
                    if !seen.insert(monomial) {
                        return Err(ctx(&format!(
                            "{}: term {} appears twice (a library has each term once)",
                            r.output, t.name
                        )));
                    }
                }
            }
        }
        if covered.iter().any(|&c| c != 1) {
            return Err(format!(
                "every output must be predicted exactly once (counts {covered:?})"
            ));
        }
        let [lo, hi] = self.on_command_range_n;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi && hi <= 1e6) {
            return Err("on_command_range_n must be finite, ordered and in [0, 1e6] N".into());
        }
        if !self.initial_state.iter().all(|x| bounded(*x)) {
            return Err(format!(
                "initial state is not finite or above {MAX_MAGNITUDE:e} in magnitude"
            ));
        }
        Ok(())
    }

    /// Total active terms.
    pub fn active_terms(&self) -> usize {
        self.submodels.iter().map(Submodel::active_terms).sum()
    }

    /// Size of the full libraries (rows x library), for sparsity.
    pub fn total_terms(&self) -> usize {
        self.submodels
            .iter()
            .map(|s| s.rows.len() * s.library_size)
            .sum()
    }

    /// Sparsity: share of library coefficients that are zero, percent.
    pub fn sparsity_pct(&self) -> f64 {
        100.0 * (1.0 - self.active_terms() as f64 / self.total_terms().max(1) as f64)
    }

    /// The model printed by name: each output's intercept and its `top` largest terms
    /// (by |coefficient|, all features being scaled to unit variance).
    pub fn describe(&self, top: usize) -> String {
        let mut s = String::new();
        for sub in &self.submodels {
            s.push_str(&format!(
                "submodel {:?} n={} degree={} target={:?}: {} of {} terms active\n",
                sub.features.layout,
                sub.features.history,
                sub.degree,
                sub.target,
                sub.active_terms(),
                sub.rows.len() * sub.library_size
            ));
            for r in &sub.rows {
                s.push_str(&format!(
                    "  {} = {:+.6e}  ({} active)\n",
                    r.output,
                    r.intercept,
                    r.terms.len()
                ));
                let mut idx: Vec<usize> = (0..r.terms.len()).collect();
                idx.sort_by(|&a, &b| r.terms[b].coef.abs().total_cmp(&r.terms[a].coef.abs()));
                for &i in idx.iter().take(top) {
                    let t = &r.terms[i];
                    s.push_str(&format!("      {:+.6e} * {}\n", t.coef, t.name));
                }
            }
        }
        s
    }
}

/// Builds the named active terms of a coefficient vector over a library.
pub fn active_terms_of(
    terms: &[Term],
    coefs: &[f64],
    dim: usize,
    names: &[String],
) -> Vec<ActiveTerm> {
    terms
        .iter()
        .zip(coefs)
        .filter(|(_, c)| **c != 0.0)
        .map(|(t, c)| ActiveTerm {
            name: term_name(t, dim, names),
            factors: *t,
            coef: *c,
        })
        .collect()
}
/// The library terms: a term is stored as three factor indices into the feature vector
/// extended by one slot that always holds 1.0; lower-degree terms are padded with that slot.
/// Highest supported polynomial degree.
pub const MAX_DEGREE: usize = 3;
/// The most features a submodel may have (the widest the other limits allow: 714 for a
/// MIMO submodel, 648 per engine, at a history of 64). The predictor keeps its feature buffers at a fixed `MAX_FEATURES + 1`
/// slots, which lets it read a term's factors without a bounds check each.
pub const MAX_FEATURES: usize = 1023;

/// Largest magnitude of any number in a model (coefficients, intercepts, scaling,
/// envelope, initial state). With features clamped to the envelope and scaled, and terms
/// of degree at most [`MAX_DEGREE`], every prediction then stays finite.
pub const MAX_MAGNITUDE: f64 = 1e12;
/// Smallest feature standard deviation (training writes 1.0 for a constant feature).
pub const MIN_FEATURE_STD: f64 = 1e-15;

/// The most thrust a prediction may give, as a multiple of the engine's rating
/// (`max_thrust_n`; the committed model peaks at 0.996 of it over the default descent):
/// beyond it a model is not physical (issue #36: a coefficient of 1e11, inside
/// [`MAX_MAGNITUDE`], flew 1.08e13 N per engine to COMPLETED). Such a prediction is
/// clamped and counted.
pub const MAX_THRUST_OVER_RATING: f64 = 2.0;
/// The most gas pressure a prediction may give, pascals (1000 bar, the bound of every
/// pressure the bench reads; the bottle starts at 280).
pub const MAX_GAS_PRESSURE_PA: f64 = 1e8;
/// Steps with a prediction beyond those bounds after which a run ends aborted.
pub const MAX_BOUNDED_STEPS: u64 = 10;

fn bounded(x: f64) -> bool {
    x.is_finite() && x.abs() <= MAX_MAGNITUDE
}

/// One monomial: the product of three entries of the extended feature vector.
pub type Term = [u16; MAX_DEGREE];

/// Product of a term's factors.
#[inline(always)]
pub fn eval_term(t: &Term, x_ext: &[f64]) -> f64 {
    x_ext[t[0] as usize] * x_ext[t[1] as usize] * x_ext[t[2] as usize]
}

/// Name of a term, see [`Library::term_name`].
pub fn term_name(term: &Term, dim: usize, feature_names: &[String]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    let f: Vec<usize> = term
        .iter()
        .map(|&x| x as usize)
        .filter(|&x| x < dim)
        .collect();
    while i < f.len() {
        let mut j = i;
        while j < f.len() && f[j] == f[i] {
            j += 1;
        }
        let name = feature_names.get(f[i]).map_or("?", String::as_str);
        if j - i == 1 {
            parts.push(name.to_string());
        } else {
            parts.push(format!("{name}^{}", j - i));
        }
        i = j;
    }
    parts.join("*")
}
