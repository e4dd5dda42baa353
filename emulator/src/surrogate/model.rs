//! A fitted surrogate (what the model file holds) and its free-running predictor (what
//! cross-validation scores and what the runtime steps). One predictor for both, so the
//! model is chosen on exactly the behaviour it has in the loop.

use super::features::{
    FeatureSpec, History, InputVec, Layout, StateVec, INPUT_DIM, STATE_DIM, STATE_MF, STATE_MO,
    STATE_NAMES, STATE_P,
};
use super::library::{term_name, Term, MAX_DEGREE};
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

/// One non-zero coefficient.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
            if !(1..=MAX_DEGREE).contains(&s.degree) {
                return Err(ctx("degree must be 1..=3"));
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
            let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
            if !finite(&s.feature_mean)
                || !finite(&s.envelope_lo)
                || !finite(&s.envelope_hi)
                || !s.feature_std.iter().all(|x| x.is_finite() && *x > 0.0)
            {
                return Err(ctx(
                    "scaling or envelope has a non-finite or non-positive value",
                ));
            }
            for r in &s.rows {
                if !r.intercept.is_finite() {
                    return Err(ctx(&format!("{}: intercept is not finite", r.output)));
                }
                for t in &r.terms {
                    if !t.coef.is_finite() {
                        return Err(ctx(&format!(
                            "{}: coefficient of {} is not finite",
                            r.output, t.name
                        )));
                    }
                    if t.factors.iter().any(|&f| f as usize > dim) {
                        return Err(ctx(&format!("{}: term {} out of range", r.output, t.name)));
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
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err("on_command_range_n must be finite and ordered".into());
        }
        if !self.initial_state.iter().all(|x| x.is_finite()) {
            return Err("initial state is not finite".into());
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

/// A row compiled for evaluation: factor indices and coefficients in flat arrays.
#[derive(Debug, Clone)]
struct CompiledRow {
    intercept: f64,
    factors: Vec<Term>,
    coefs: Vec<f64>,
}

#[derive(Debug, Clone)]
struct CompiledSub {
    spec: FeatureSpec,
    evaluations: usize,
    target: Target,
    outputs: Vec<usize>,
    /// Per feature: envelope and scaling side by side (one bounds check, one cache line).
    scaling: Vec<FeatureScaling>,
    /// Scaled features followed by the constant 1.0.
    x: Vec<f64>,
    /// Per-engine models: the four engines' scaled features side by side, so every term
    /// is evaluated for the four engines at once (vectorised; same arithmetic per lane).
    x4: Vec<[f64; ENGINE_COUNT]>,
    rows: Vec<CompiledRow>,
}

#[derive(Debug, Clone, Copy)]
struct FeatureScaling {
    lo: f64,
    hi: f64,
    mean: f64,
    inv_std: f64,
}

impl FeatureScaling {
    /// Clamps to the envelope and scales one raw value; reports whether it was outside.
    /// (`max().min()` rather than `clamp`, which asserts lo <= hi on every call; the
    /// model check guarantees it.)
    #[inline(always)]
    fn apply(&self, raw: f64) -> (f64, bool) {
        let v = raw.max(self.lo).min(self.hi);
        ((v - self.mean) * self.inv_std, v != raw)
    }
}

impl CompiledSub {
    fn eval_mimo(&mut self, ring: &Ring, prev: &StateVec, next: &mut StateVec) -> bool {
        let dim = self.spec.dim();
        let mut outside = false;
        let mut x = std::mem::take(&mut self.x);
        self.spec.fill(ring, 0, &mut x[..dim]);
        for (x, sc) in x[..dim].iter_mut().zip(&self.scaling) {
            let (v, out) = sc.apply(*x);
            *x = v;
            outside |= out;
        }
        for (row, &o) in self.rows.iter().zip(&self.outputs) {
            let mut y = row.intercept;
            for (t, c) in row.factors.iter().zip(&row.coefs) {
                // SAFETY: `Predictor::new` clamps every factor to <= dim and `x` has
                // dim + 1 entries, so the three reads are in bounds.
                let term = unsafe {
                    x.get_unchecked(t[0] as usize)
                        * x.get_unchecked(t[1] as usize)
                        * x.get_unchecked(t[2] as usize)
                };
                y += c * term;
            }
            next[o] = match self.target {
                Target::Absolute => y,
                Target::Increment => prev[o] + y,
            };
        }
        self.x = x;
        outside
    }

    fn eval_per_engine(&mut self, ring: &Ring, prev: &StateVec, next: &mut StateVec) -> bool {
        let dim = self.spec.dim();
        let mut outside = false;
        let mut x = std::mem::take(&mut self.x);
        let mut x4 = std::mem::take(&mut self.x4);
        for e in 0..ENGINE_COUNT {
            self.spec.fill(ring, e, &mut x[..dim]);
            for ((x, x4), sc) in x[..dim].iter().zip(x4.iter_mut()).zip(&self.scaling) {
                let (v, out) = sc.apply(*x);
                x4[e] = v;
                outside |= out;
            }
        }
        let row = &self.rows[0];
        let mut y = [row.intercept; ENGINE_COUNT];
        for (t, c) in row.factors.iter().zip(&row.coefs) {
            // SAFETY: as in `eval_mimo`; `x4` has dim + 1 entries.
            let (a, b, d) = unsafe {
                (
                    x4.get_unchecked(t[0] as usize),
                    x4.get_unchecked(t[1] as usize),
                    x4.get_unchecked(t[2] as usize),
                )
            };
            for e in 0..ENGINE_COUNT {
                y[e] += c * (a[e] * b[e] * d[e]);
            }
        }
        for e in 0..ENGINE_COUNT {
            let o = self.outputs[e];
            next[o] = match self.target {
                Target::Absolute => y[e],
                Target::Increment => prev[o] + y[e],
            };
        }
        self.x = x;
        self.x4 = x4;
        outside
    }
}

/// Ring of past inputs and states, seen from the step being predicted (`head`).
#[derive(Debug, Clone)]
struct Ring {
    inputs: Vec<InputVec>,
    states: Vec<StateVec>,
    head: usize,
    /// Length - 1; the length is a power of two so wrapping is a mask, not a division
    /// (the step reads the ring some fifty times).
    mask: usize,
}

impl Ring {
    #[inline]
    fn at(&self, lag: usize) -> usize {
        (self.head + self.inputs.len() - lag) & self.mask
    }
}

impl History for Ring {
    #[inline]
    fn input(&self, lag: usize) -> &InputVec {
        &self.inputs[self.at(lag)]
    }
    #[inline]
    fn state(&self, lag: usize) -> &StateVec {
        &self.states[self.at(lag)]
    }
}

/// Free-running evaluation of a [`Model`]: its own predictions become its history.
/// Every buffer is sized in [`Predictor::new`]; [`Predictor::step`] does not allocate.
#[derive(Debug, Clone)]
pub struct Predictor {
    on_command_range_n: [f64; 2],
    subs: Vec<CompiledSub>,
    ring: Ring,
    out_of_envelope_steps: u64,
}

impl Predictor {
    /// Compiles a model (assumed checked) and starts it from its initial state.
    pub fn new(model: &Model) -> Self {
        let subs: Vec<CompiledSub> = model
            .submodels
            .iter()
            .map(|s| CompiledSub {
                spec: s.features,
                evaluations: s.evaluations(),
                target: s.target,
                outputs: s.outputs.clone(),
                scaling: (0..s.features.dim())
                    .map(|j| FeatureScaling {
                        lo: s.envelope_lo[j],
                        hi: s.envelope_hi[j].max(s.envelope_lo[j]),
                        mean: s.feature_mean[j],
                        inv_std: 1.0 / s.feature_std[j],
                    })
                    .collect(),
                x: vec![1.0; s.features.dim() + 1],
                x4: vec![[1.0; ENGINE_COUNT]; s.features.dim() + 1],
                rows: s
                    .rows
                    .iter()
                    .map(|r| CompiledRow {
                        intercept: r.intercept,
                        // A checked model never has a factor above dim; clamping
                        // makes the unchecked reads in `step` sound for any model.
                        factors: r
                            .terms
                            .iter()
                            .map(|t| t.factors.map(|f| f.min(s.features.dim() as u16)))
                            .collect(),
                        coefs: r.terms.iter().map(|t| t.coef).collect(),
                    })
                    .collect(),
            })
            .collect();
        let depth = subs
            .iter()
            .map(|s| s.spec.max_state_lag())
            .max()
            .unwrap_or(1)
            .saturating_add(1)
            .next_power_of_two();
        let mut p = Self {
            on_command_range_n: model.on_command_range_n,
            subs,
            ring: Ring {
                inputs: vec![[0.0; INPUT_DIM]; depth],
                states: vec![model.initial_state; depth],
                head: 0,
                mask: depth - 1,
            },
            out_of_envelope_steps: 0,
        };
        p.reset_to(&model.initial_state);
        p
    }

    /// Restarts from a state at rest: engines off for all of the history, every past
    /// state equal to `state` (how the reference model is started).
    pub fn reset_to(&mut self, state: &StateVec) {
        self.ring.inputs.fill([0.0; INPUT_DIM]);
        self.ring.states.fill(*state);
        self.ring.head = 0;
        self.out_of_envelope_steps = 0;
    }

    /// Loads a true history (oldest first; the last state is the latest known) so that a
    /// free run can start mid-trajectory, as cross-validation does on a test block.
    pub fn seed_history<H: History>(&mut self, h: &H) {
        let depth = self.ring.inputs.len();
        // Slot `head` is the step about to be predicted; lags 1..depth-1 are the past.
        self.ring.head = 0;
        for lag in 1..depth {
            let i = self.ring.at(lag);
            self.ring.inputs[i] = *h.input(lag);
            self.ring.states[i] = *h.state(lag);
        }
        // One slot back, so the next step() advances onto slot 0.
        self.ring.head = depth - 1;
    }

    /// Number of steps on which some feature was outside the training envelope.
    pub fn out_of_envelope_steps(&self) -> u64 {
        self.out_of_envelope_steps
    }

    /// The latest state.
    pub fn state(&self) -> &StateVec {
        &self.ring.states[self.ring.head]
    }

    /// Predicts the state at the end of a step with `input` held, and makes it history.
    #[inline]
    pub fn step(&mut self, input: &InputVec) -> StateVec {
        let prev = self.ring.states[self.ring.head];
        self.ring.head = (self.ring.head + 1) & self.ring.mask;
        let head = self.ring.head;
        self.ring.inputs[head] = *input;
        let mut outside = false;
        let [lo, hi] = self.on_command_range_n;
        for e in 0..ENGINE_COUNT {
            if self.ring.inputs[head][ENGINE_COUNT + e] > 0.5 {
                let raw = self.ring.inputs[head][e];
                let v = raw.clamp(lo, hi);
                outside |= v != raw;
                self.ring.inputs[head][e] = v;
            }
        }
        // The slot still holds an old state; it is never read (state lags start at 1).
        let mut next = prev;
        for sub in &mut self.subs {
            if sub.evaluations == ENGINE_COUNT {
                outside |= sub.eval_per_engine(&self.ring, &prev, &mut next);
            } else {
                outside |= sub.eval_mimo(&self.ring, &prev, &mut next);
            }
        }
        // Physical guards: thrust and pressure are not negative, ejected mass never
        // falls. A non-finite prediction keeps the previous state (and counts).
        for (o, v) in next.iter_mut().enumerate() {
            if !v.is_finite() {
                *v = prev[o];
                outside = true;
            }
        }
        for v in next.iter_mut().take(ENGINE_COUNT) {
            *v = v.max(0.0);
        }
        next[STATE_P] = next[STATE_P].max(0.0);
        next[STATE_MF] = next[STATE_MF].max(prev[STATE_MF]);
        next[STATE_MO] = next[STATE_MO].max(prev[STATE_MO]);
        self.out_of_envelope_steps += u64::from(outside);
        self.ring.states[head] = next;
        next
    }
}

/// Name of a state output.
pub fn output_name(o: usize) -> &'static str {
    STATE_NAMES[o]
}
