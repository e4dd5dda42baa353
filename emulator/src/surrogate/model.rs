//! A fitted surrogate (what the model file holds) and its free-running predictor (what
//! cross-validation scores and what the runtime steps). One predictor for both, so the
//! model is chosen on exactly the behaviour it has in the loop.

use super::features::{
    command_sum_of, lambda_of, FeatureSpec, History, IgnitionClock, InputVec, Layout, Source,
    StateVec, ValveState, ValveTrack, INPUT_DIM, NOT_IGNITED, STATE_DIM, STATE_MF, STATE_MO,
    STATE_P,
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
            if s.features.start_steps > 64 || s.features.stop_steps > 64 {
                return Err(ctx("start_steps and stop_steps must be 0..=64"));
            }
            if s.features.phase_degree > MAX_DEGREE {
                return Err(ctx("phase_degree must be 0..=3"));
            }
            if s.features.layout == Layout::Mimo && s.features.phase_features() > 0 {
                return Err(ctx("phase indicators are per-engine features only"));
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
            let roles = s.features.roles();
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

/// Terms compiled for evaluation, split by degree (factor slots into the gathered
/// features, coefficients) in flat arrays, so a linear term costs one read and one
/// multiply-add. Leaving out factors of 1.0 changes no bit.
#[derive(Debug, Clone, Default)]
struct Terms {
    lin: Vec<([u16; 1], f64)>,
    quad: Vec<([u16; 2], f64)>,
    cubic: Vec<([u16; 3], f64)>,
}

/// Independent partial sums per lane in [`Factored::add`] and [`Dense::eval`]. One
/// running sum would make every term wait for the previous addition (a chain of some 4
/// cycles per term, most of the step); four sums overlap them. The order of additions
/// differs from library order, which moves the result by rounding only.
const PARTIAL_SUMS: usize = 4;

/// Adds `c * x[f0] * x[f1] ...` of each term, per lane, round robin into the partial sums.
#[inline(always)]
fn accumulate<const N: usize, const LANES: usize>(
    terms: &[([u16; N], f64)],
    x: &[[f64; LANES]],
    acc: &mut [[f64; LANES]; PARTIAL_SUMS],
) {
    // SAFETY: `CompiledSub::compile` maps every factor to a slot below the number of
    // gathered features and `x` has that many entries plus one.
    let at = |i: u16| unsafe { x.get_unchecked(i as usize) };
    let mut add = |k: usize, (f, c): &([u16; N], f64)| {
        for e in 0..LANES {
            let mut p = at(f[0])[e];
            for &i in &f[1..] {
                p *= at(i)[e];
            }
            acc[k][e] += c * p;
        }
    };
    let mut chunks = terms.chunks_exact(PARTIAL_SUMS);
    for chunk in &mut chunks {
        for (k, term) in chunk.iter().enumerate() {
            add(k, term);
        }
    }
    for (k, term) in chunks.remainder().iter().enumerate() {
        add(k, term);
    }
}

impl Terms {
    fn push(&mut self, f: &[u16], coef: f64) {
        match *f {
            [a] => self.lin.push(([a], coef)),
            [a, b] => self.quad.push(([a, b], coef)),
            [a, b, d] => self.cubic.push(([a, b, d], coef)),
            _ => unreachable!("a term has 1 to 3 factors"),
        }
    }

    /// Adds the terms of one lane to `y` (the few phase terms of one engine).
    #[inline(always)]
    fn add_lane<const LANES: usize>(&self, x: &[[f64; LANES]], e: usize, y: &mut f64) {
        let v = |i: u16| x[i as usize][e];
        for &([a], c) in &self.lin {
            *y += c * v(a);
        }
        for &([a, b], c) in &self.quad {
            *y += c * (v(a) * v(b));
        }
        for &([a, b, d], c) in &self.cubic {
            *y += c * (v(a) * v(b) * v(d));
        }
    }
}

/// Every-step terms factored by a shared first factor: `sum_a x_a * (k_a + sum c x_b +
/// sum c x_b x_d)`. A product term then costs one multiplication fewer and one read
/// fewer than as a flat term (the shared factor is read and multiplied once per group),
/// which is most of the step for the thrust row's ~70 quadratic terms. The sum moves by
/// rounding only (tested against the full evaluation).
#[derive(Debug, Clone, Default)]
struct Factored {
    /// Linear terms that share no factor with a product term: flat, `c * x_a`.
    single: Vec<([u16; 1], f64)>,
    groups: Vec<FactorGroup>,
    /// Inner linear terms `c * x_b`, group after group.
    lin: Vec<(u16, f64)>,
    /// Inner quadratic terms `c * x_b * x_d` (from cubic terms), group after group.
    quad: Vec<([u16; 2], f64)>,
}

/// One group of [`Factored`]: the shared factor, the inner constant and the group's
/// inner terms in `lin` and `quad` (start, end).
#[derive(Debug, Clone, Copy)]
struct FactorGroup {
    outer: u16,
    constant: f64,
    lin: [u32; 2],
    quad: [u32; 2],
}

impl Factored {
    /// Groups `terms` greedily: the factor shared by most of the remaining terms first,
    /// so few groups carry many terms.
    fn new(terms: &Terms) -> Self {
        let mut rest: Vec<(Vec<u16>, f64)> = terms
            .lin
            .iter()
            .map(|(f, c)| (f.to_vec(), *c))
            .chain(terms.quad.iter().map(|(f, c)| (f.to_vec(), *c)))
            .chain(terms.cubic.iter().map(|(f, c)| (f.to_vec(), *c)))
            .collect();
        let mut out = Self::default();
        while !rest.is_empty() {
            let mut count: std::collections::BTreeMap<u16, usize> = Default::default();
            for (f, _) in &rest {
                let mut seen = f.clone();
                seen.sort_unstable();
                seen.dedup();
                for a in seen {
                    *count.entry(a).or_default() += 1;
                }
            }
            // Most terms first; ties to the lowest slot (deterministic).
            let (&outer, _) = count
                .iter()
                .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
                .expect("rest is not empty");
            let mut constant = 0.0;
            let (lin_start, quad_start) = (out.lin.len(), out.quad.len());
            let (mine, others): (Vec<_>, Vec<_>) =
                rest.into_iter().partition(|(f, _)| f.contains(&outer));
            rest = others;
            for (mut f, c) in mine {
                let at = f.iter().position(|&a| a == outer).expect("partitioned");
                f.remove(at);
                match f[..] {
                    [] => constant += c,
                    [b] => out.lin.push((b, c)),
                    [b, d] => out.quad.push(([b, d], c)),
                    _ => unreachable!("a term has 1 to 3 factors"),
                }
            }
            let group = FactorGroup {
                outer,
                constant,
                lin: [lin_start as u32, out.lin.len() as u32],
                quad: [quad_start as u32, out.quad.len() as u32],
            };
            if group.lin[0] == group.lin[1] && group.quad[0] == group.quad[1] {
                out.single.push(([outer], constant));
            } else {
                out.groups.push(group);
            }
        }
        out
    }

    /// Adds the terms of every lane (`LANES` = 1 or 4) to `y`.
    #[inline(always)]
    fn add<const LANES: usize>(&self, x: &[[f64; LANES]], y: &mut [f64; LANES]) {
        // SAFETY: as in `accumulate`, every slot is below the number of gathered
        // features, and the group ranges lie within `lin` and `quad` (built together).
        let at = |i: u16| unsafe { x.get_unchecked(i as usize) };
        // One group's `x_a * inner`, the inner sum in three parts (the linear terms in
        // two, the products in one): the chain of additions is the group's latency, and
        // a sum shared by both loops was compiled to lane shuffles.
        let group = |g: &FactorGroup| -> [f64; LANES] {
            let (mut i0, mut i1, mut i2) = ([g.constant; LANES], [0.0; LANES], [0.0; LANES]);
            let lin = unsafe { self.lin.get_unchecked(g.lin[0] as usize..g.lin[1] as usize) };
            let mut pairs = lin.chunks_exact(2);
            for p in &mut pairs {
                let (&(b0, c0), &(b1, c1)) = (&p[0], &p[1]);
                let (x0, x1) = (at(b0), at(b1));
                for e in 0..LANES {
                    i0[e] += c0 * x0[e];
                    i1[e] += c1 * x1[e];
                }
            }
            for &(b, c) in pairs.remainder() {
                let xb = at(b);
                for e in 0..LANES {
                    i0[e] += c * xb[e];
                }
            }
            let quad = unsafe {
                self.quad
                    .get_unchecked(g.quad[0] as usize..g.quad[1] as usize)
            };
            for &([b, d], c) in quad {
                let (xb, xd) = (at(b), at(d));
                for e in 0..LANES {
                    i2[e] += c * (xb[e] * xd[e]);
                }
            }
            let xa = at(g.outer);
            let mut v = [0.0; LANES];
            for e in 0..LANES {
                v[e] = xa[e] * ((i0[e] + i1[e]) + i2[e]);
            }
            v
        };
        let mut acc = [[0.0; LANES]; PARTIAL_SUMS];
        accumulate(&self.single, x, &mut acc);
        // The groups are few (about ten): one running sum, kept in a register, is no
        // longer a chain than the groups' own.
        let mut groups = [0.0; LANES];
        for g in &self.groups {
            let v = group(g);
            for e in 0..LANES {
                groups[e] += v[e];
            }
        }
        for e in 0..LANES {
            y[e] += ((acc[0][e] + acc[1][e]) + (acc[2][e] + acc[3][e])) + groups[e];
        }
    }
}

/// The coefficients of one output, compiled. Terms with a phase indicator that is
/// exactly 0 outside its phase (uncentred, see `fit::Prepared`) are kept apart, one group
/// per indicator, and evaluated only for an engine in that phase: in steady running no
/// phase term costs anything, and skipping terms that are exactly 0 changes no sum.
///
/// Terms with an ignition feature are kept apart the same way, in one group evaluated
/// for an engine whose ignition clock is in its window (see [`Clock`]).
#[derive(Debug, Clone, Default)]
struct CompiledRow {
    intercept: f64,
    terms: Factored,
    phase: Vec<Terms>,
    clock: Terms,
}

impl CompiledRow {
    /// `group[slot]`: the phase group of a gathered feature, if it is a skippable phase
    /// indicator; `clocked[slot]`: whether it is a skippable ignition feature. (A checked
    /// model has at most one phase or ignition feature per term.)
    fn new(
        r: &OutputRow,
        slot: &[u16],
        dim: usize,
        group: &[Option<usize>],
        groups: usize,
        clocked: &[bool],
    ) -> Self {
        let one = slot[dim];
        let mut every = Terms::default();
        let mut row = Self {
            intercept: r.intercept,
            terms: Factored::default(),
            phase: vec![Terms::default(); groups],
            clock: Terms::default(),
        };
        for t in &r.terms {
            // A checked model never has a factor above dim; clamping makes the
            // unchecked reads in `eval` sound for any model.
            let f: Vec<u16> = t
                .factors
                .iter()
                .map(|&f| slot[(f as usize).min(dim)])
                .filter(|&f| f != one)
                .collect();
            let phases: Vec<usize> = f.iter().filter_map(|&s| group[s as usize]).collect();
            match phases[..] {
                [] if f.is_empty() => row.intercept += t.coef,
                [g] => row.phase[g].push(&f, t.coef),
                _ if f.iter().any(|&s| clocked[s as usize]) => row.clock.push(&f, t.coef),
                _ => every.push(&f, t.coef),
            }
        }
        row.terms = Factored::new(&every);
        row
    }
}

/// One feature an active term uses, compiled to a read of the history window (see
/// [`Ring`]) at a fixed `offset`: the record `lag` steps back, component `comp` (for a
/// per-engine feature, engine 0's; the four engines' values follow it), then clamped to
/// the envelope and scaled.
#[derive(Debug, Clone, Copy)]
struct Gather {
    offset: usize,
    scaling: FeatureScaling,
}

/// A phase indicator an active term uses: 1 when the engine's switch is `on` and has been
/// for exactly `run` steps.
#[derive(Debug, Clone, Copy)]
struct PhaseGather {
    slot: usize,
    on: bool,
    run: usize,
    scaling: FeatureScaling,
}

/// An ignition feature an active term uses: the priming indicator (`hat` None) or hat
/// function `hat` of the time since ignition.
#[derive(Debug, Clone, Copy)]
struct ClockGather {
    slot: usize,
    hat: Option<usize>,
    scaling: FeatureScaling,
}

/// The engines' ignition clocks after the step being predicted (see
/// [`crate::surrogate::features::IgnitionClock`]).
#[derive(Debug, Clone, Copy)]
struct Clock {
    since_ignition_s: [f64; ENGINE_COUNT],
    /// Engines whose ignition features may be non-zero: on, and not past the last hat.
    active: [bool; ENGINE_COUNT],
    /// Some engine is active.
    any: bool,
}

impl Clock {
    const IDLE: Self = Self {
        since_ignition_s: [NOT_IGNITED; ENGINE_COUNT],
        active: [false; ENGINE_COUNT],
        any: false,
    };
}

/// A submodel compiled for `LANES` evaluations per step: 1 for a MIMO submodel, 4 (one
/// per engine, evaluated together and vectorised, the same arithmetic per lane as for
/// one) for a per-engine submodel.
#[derive(Debug, Clone)]
struct CompiledSub<const LANES: usize> {
    target: Target,
    outputs: Vec<usize>,
    /// Features the active terms use, and only those (a model of 60 active terms reads
    /// some 20-40 of its ~100 features): read once per step, into slots `0..shared.len()`
    /// ...
    shared: Vec<Gather>,
    /// ... read per engine (per-engine submodels only), into the next slots ...
    lanes: Vec<Gather>,
    /// ... and the phase indicators (per engine) ...
    phases: Vec<PhaseGather>,
    /// ... and the ignition features (per engine), computed from the clock.
    clock: Vec<ClockGather>,
    /// The ignition clock the features read.
    ignition: Option<IgnitionClock>,
    /// The ignition features are exactly 0 outside an engine's window, so their terms
    /// are kept apart and they are gathered only while some engine is in it.
    clock_grouped: bool,
    /// Phase group of "switched on k steps ago" (`[0][k]`) and "off" (`[1][k]`), for
    /// the indicators whose terms are kept apart (see [`CompiledRow`]).
    phase_group: [Vec<Option<usize>>; 2],
    /// Gathered scaled features followed by the constant 1.0, one value per lane.
    x: Vec<[f64; LANES]>,
    /// Linear terms only, their coefficients scaled: the features are gathered clamped
    /// but unscaled.
    folded: bool,
    /// A folded submodel of up to [`DENSE_ROWS`] rows as dense coefficients, four
    /// features at a time: a chunk of four features then costs one vector multiply-add
    /// per row instead of one scalar multiply-add per term.
    dense: Option<Dense>,
    /// The rows' terms, compiled (empty when `dense` evaluates the submodel).
    rows: Vec<CompiledRow>,
}

/// Rows of a [`Dense`] submodel, at most: the pressure and the two ejected masses. (At
/// four, the compiler vectorised each feature across the rows, with the coefficients
/// gathered lane by lane, instead of each row across the chunk's four features.)
const DENSE_ROWS: usize = 3;

/// See [`CompiledSub::dense`]: the rows' intercepts and their coefficients, laid out
/// for the step. Features come in chunks of four, feature `k` of a chunk into partial
/// sum `k`: each row then costs one vector multiply-add per chunk, and a chunk's four
/// envelope bounds are one read each. (A vector of the rows' coefficients per feature
/// cost a broadcast, a multiply and an add per feature.) Every partial sum adds the
/// same terms in the same order as one feature at a time, so the bits are the same.
#[derive(Debug, Clone)]
struct Dense {
    intercept: [f64; DENSE_ROWS],
    chunks: Vec<DenseChunk>,
    /// The features after the last whole chunk (fewer than four), one at a time:
    /// `(read, coefficient per row)`.
    rest: Vec<(Gather, [f64; DENSE_ROWS])>,
}

/// Four features of a [`Dense`] submodel: where each is read, its envelope, and
/// `coef[r][k]`, row `r`'s coefficient of feature `k` (0 for rows past the last).
#[derive(Debug, Clone)]
struct DenseChunk {
    offset: [usize; PARTIAL_SUMS],
    lo: [f64; PARTIAL_SUMS],
    hi: [f64; PARTIAL_SUMS],
    coef: [[f64; PARTIAL_SUMS]; DENSE_ROWS],
}

impl Dense {
    /// `gather[k]` (clamped, unscaled) and the rows' coefficients `coef[k][r]` of slot k.
    fn new(intercept: [f64; DENSE_ROWS], gather: &[Gather], coef: &[[f64; DENSE_ROWS]]) -> Self {
        let chunks = gather
            .chunks_exact(PARTIAL_SUMS)
            .zip(coef.chunks_exact(PARTIAL_SUMS))
            .map(|(g, c)| DenseChunk {
                offset: std::array::from_fn(|k| g[k].offset),
                lo: std::array::from_fn(|k| g[k].scaling.lo),
                hi: std::array::from_fn(|k| g[k].scaling.hi),
                coef: std::array::from_fn(|r| std::array::from_fn(|k| c[k][r])),
            })
            .collect();
        let done = gather.len() / PARTIAL_SUMS * PARTIAL_SUMS;
        let rest = gather[done..]
            .iter()
            .copied()
            .zip(coef[done..].iter().copied())
            .collect();
        Self {
            intercept,
            chunks,
            rest,
        }
    }

    /// Gathers and clamps the features and returns the rows' sums, and whether a
    /// feature was outside its envelope. One pass: a feature is read, clamped and
    /// multiplied into every row while in a register, rather than stored and read back.
    ///
    /// `avx2`: the CPU has AVX2 and the chunks take [`Dense::chunks_avx2`].
    #[inline(always)]
    fn eval(&self, window: &[f64], avx2: bool) -> ([f64; DENSE_ROWS], bool) {
        // `acc[r][k]`: row r's partial sum k.
        let (mut acc, mut outside) = {
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the CPU has AVX2 (checked by the caller); reads as below.
                unsafe { self.chunks_avx2(window) }
            } else {
                self.chunks(window)
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
                let _ = avx2;
                self.chunks(window)
            }
        };
        for (k, (g, c)) in self.rest.iter().enumerate() {
            // SAFETY: `compile` places every read inside the window.
            let (v, out) = g.scaling.clamp(unsafe { *window.get_unchecked(g.offset) });
            outside[k] |= out;
            for r in 0..DENSE_ROWS {
                acc[r][k] += c[r] * v;
            }
        }
        let y = std::array::from_fn(|r| {
            let a = &acc[r];
            self.intercept[r] + ((a[0] + a[1]) + (a[2] + a[3]))
        });
        (y, (outside[0] | outside[1] | outside[2] | outside[3]) != 0)
    }

    /// The whole chunks: each row's partial sums, and per partial sum the bits the clamp
    /// changed (non-zero: a feature was outside its envelope).
    #[inline(always)]
    fn chunks(&self, window: &[f64]) -> ([[f64; PARTIAL_SUMS]; DENSE_ROWS], [u64; PARTIAL_SUMS]) {
        let mut acc = [[0.0; PARTIAL_SUMS]; DENSE_ROWS];
        let mut outside = [0u64; PARTIAL_SUMS];
        for ch in &self.chunks {
            let mut v = [0.0; PARTIAL_SUMS];
            for k in 0..PARTIAL_SUMS {
                // SAFETY: `compile` places every read inside the window.
                let raw = unsafe { *window.get_unchecked(ch.offset[k]) };
                // `FeatureScaling::clamp`, on the chunk's bounds.
                let x = if raw < ch.lo[k] { ch.lo[k] } else { raw };
                v[k] = if x > ch.hi[k] { ch.hi[k] } else { x };
                outside[k] |= v[k].to_bits() ^ raw.to_bits();
            }
            for r in 0..DENSE_ROWS {
                for k in 0..PARTIAL_SUMS {
                    acc[r][k] += ch.coef[r][k] * v[k];
                }
            }
        }
        (acc, outside)
    }

    /// [`Dense::chunks`] in AVX2 vectors, one per row and one for the chunk's features.
    /// Written with intrinsics because the compiler vectorised the portable loop across
    /// the rows, gathering the coefficients lane by lane. The same IEEE operations in
    /// the same order per lane (no fused multiply-add), so the same bits: `max(lo, raw)`
    /// is `raw < lo ? lo : raw` and `min(hi, x)` is `x > hi ? hi : x`, NaN included
    /// (both return the second operand when a comparison fails). Tested against the
    /// portable path.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn chunks_avx2(
        &self,
        window: &[f64],
    ) -> ([[f64; PARTIAL_SUMS]; DENSE_ROWS], [u64; PARTIAL_SUMS]) {
        use std::arch::x86_64::*;
        let mut acc = [_mm256_setzero_pd(); DENSE_ROWS];
        let mut changed = _mm256_setzero_pd();
        for ch in &self.chunks {
            // SAFETY: `compile` places every read inside the window; the arrays hold
            // four values each.
            let w = |k: usize| unsafe { *window.get_unchecked(ch.offset[k]) };
            let raw = _mm256_set_pd(w(3), w(2), w(1), w(0));
            let lo = unsafe { _mm256_loadu_pd(ch.lo.as_ptr()) };
            let hi = unsafe { _mm256_loadu_pd(ch.hi.as_ptr()) };
            let v = _mm256_min_pd(hi, _mm256_max_pd(lo, raw));
            changed = _mm256_or_pd(changed, _mm256_xor_pd(v, raw));
            for (a, c) in acc.iter_mut().zip(&ch.coef) {
                let c = unsafe { _mm256_loadu_pd(c.as_ptr()) };
                *a = _mm256_add_pd(*a, _mm256_mul_pd(c, v));
            }
        }
        let mut sums = [[0.0; PARTIAL_SUMS]; DENSE_ROWS];
        for (s, a) in sums.iter_mut().zip(acc) {
            // SAFETY: four f64 values.
            unsafe { _mm256_storeu_pd(s.as_mut_ptr(), a) };
        }
        let mut bits = [0u64; PARTIAL_SUMS];
        // SAFETY: four 64-bit values (the lanes' bit patterns).
        unsafe { _mm256_storeu_pd(bits.as_mut_ptr().cast(), changed) };
        (sums, bits)
    }
}

#[derive(Debug, Clone, Copy)]
struct FeatureScaling {
    lo: f64,
    hi: f64,
    mean: f64,
    inv_std: f64,
}

impl FeatureScaling {
    /// Clamps to the envelope and scales one raw value; the second value is non-zero when
    /// it was outside. (Comparisons rather than `clamp`, which asserts lo <= hi on every
    /// call, or `max`/`min`, which spend instructions on NaN. A NaN feature stays NaN,
    /// makes the prediction non-finite, and the step's guard keeps the previous state and
    /// counts the step. "Outside" is "the clamp changed a bit": an integer OR to collect,
    /// cheaper than a floating comparison.)
    #[inline(always)]
    fn apply(&self, raw: f64) -> (f64, u64) {
        let (v, out) = self.clamp(raw);
        ((v - self.mean) * self.inv_std, out)
    }

    /// Clamps only (for a submodel whose coefficients hold the scaling).
    #[inline(always)]
    fn clamp(&self, raw: f64) -> (f64, u64) {
        let v = if raw < self.lo { self.lo } else { raw };
        let v = if v > self.hi { self.hi } else { v };
        (v, v.to_bits() ^ raw.to_bits())
    }
}

/// Per-engine switch phase at the latest step: the switch and how many consecutive steps
/// it has had that value, saturated at `cap + 1`. Kept incrementally so the phase
/// indicators cost a comparison; equal to scanning the history (`features::phase_age`).
#[derive(Debug, Clone, Copy)]
struct Phases {
    on: [bool; ENGINE_COUNT],
    run: [usize; ENGINE_COUNT],
    cap: usize,
}

/// Components of a ring record: the step's inputs, its command sum and the four
/// valve-filtered commands after it, then the state at its end and lambda of that state
/// (each computed once when stored, not per read).
const REC_SUM: usize = INPUT_DIM;
const REC_VALVE: usize = INPUT_DIM + 1;
const REC_STATE: usize = REC_VALVE + ENGINE_COUNT;
const REC_LAMBDA: usize = REC_STATE + STATE_DIM;
const REC_DIM: usize = REC_LAMBDA + 1;

impl<const LANES: usize> CompiledSub<LANES> {
    /// `depth`: the ring's depth (every lag the submodel reads is below it).
    fn compile(s: &Submodel, depth: usize) -> Self {
        let dim = s.features.dim();
        let sources = s.features.sources();
        let per_engine = s.features.layout == Layout::PerEngine;
        assert_eq!(
            LANES,
            s.evaluations(),
            "compiled with the submodel's lane count"
        );
        let mut used = vec![false; dim + 1];
        for r in &s.rows {
            for t in &r.terms {
                for &f in &t.factors {
                    // A checked model never has a factor above dim; clamping makes the
                    // unchecked reads in `eval` sound for any model.
                    used[(f as usize).min(dim)] = true;
                }
            }
        }
        let scaling = |j: usize| FeatureScaling {
            lo: s.envelope_lo[j],
            hi: s.envelope_hi[j].max(s.envelope_lo[j]),
            mean: s.feature_mean[j],
            inv_std: 1.0 / s.feature_std[j],
        };
        let read = |j: usize, lag: usize, comp: usize| {
            assert!(lag < depth, "the ring holds every lag read");
            Gather {
                offset: Ring::offset(depth, lag, comp),
                scaling: scaling(j),
            }
        };
        // Sort the used features into shared reads, lane reads and phase indicators,
        // remembering which feature each read is.
        let (mut shared, mut lanes) = (Vec::new(), Vec::new());
        let mut phase_js = Vec::new();
        let mut clock_js = Vec::new();
        for j in (0..dim).filter(|&j| used[j]) {
            let lane = |p: bool| per_engine && p;
            match sources[j] {
                Source::Input {
                    lag,
                    comp,
                    per_engine: p,
                } => (if lane(p) { &mut lanes } else { &mut shared }).push((j, read(j, lag, comp))),
                Source::State {
                    lag,
                    comp,
                    per_engine: p,
                } => (if lane(p) { &mut lanes } else { &mut shared })
                    .push((j, read(j, lag, REC_STATE + comp))),
                Source::Lambda => shared.push((j, read(j, 1, REC_LAMBDA))),
                Source::CommandSum => shared.push((j, read(j, 0, REC_SUM))),
                Source::Valve { lag } => lanes.push((j, read(j, lag, REC_VALVE))),
                Source::Start(_) | Source::Stop(_) => phase_js.push(j),
                Source::Priming | Source::Ignition(..) => clock_js.push(j),
            }
        }
        // `slot[j]`: feature j's place in `x`, in the order gathered; `dim` maps to the
        // 1.0 slot.
        let mut slot = vec![0u16; dim + 1];
        let mut count = 0;
        for &j in shared
            .iter()
            .chain(&lanes)
            .map(|(j, _)| j)
            .chain(&phase_js)
            .chain(&clock_js)
        {
            slot[j] = count as u16;
            count += 1;
        }
        slot[dim] = count as u16;
        let mut phases: Vec<PhaseGather> = phase_js
            .iter()
            .map(|&j| PhaseGather {
                slot: slot[j] as usize,
                on: matches!(sources[j], Source::Start(_)),
                run: match sources[j] {
                    Source::Start(k) | Source::Stop(k) => k + 1,
                    _ => unreachable!("only phase indicators are listed"),
                },
                scaling: scaling(j),
            })
            .collect();
        // Phase indicators that are exactly 0 outside their phase get a term group.
        let mut group = vec![None; count + 1];
        let mut phase_group = [Vec::new(), Vec::new()];
        let mut groups = 0;
        let mut constant = Vec::new();
        phases.retain(|g| {
            let sc = g.scaling;
            // 0 scales to exactly 0 and neither 0 nor 1 is ever clamped: then every term
            // with the indicator is 0 outside the phase (not evaluated) and sees the
            // indicator's in-phase value inside it, a constant set here once.
            let skippable = sc.mean == 0.0 && sc.lo <= 0.0 && sc.hi >= 1.0;
            if skippable {
                group[g.slot] = Some(groups);
                let table = &mut phase_group[usize::from(!g.on)];
                if table.len() < g.run {
                    table.resize(g.run, None);
                }
                table[g.run - 1] = Some(groups);
                groups += 1;
                constant.push((g.slot, sc.apply(1.0).0));
            }
            !skippable
        });
        let clock: Vec<ClockGather> = clock_js
            .iter()
            .map(|&j| ClockGather {
                slot: slot[j] as usize,
                hat: match sources[j] {
                    Source::Ignition(k, _) => Some(k),
                    _ => None,
                },
                scaling: scaling(j),
            })
            .collect();
        // As for the phase indicators: 0 must scale to exactly 0, unclamped.
        let clock_grouped = clock
            .iter()
            .all(|g| g.scaling.mean == 0.0 && g.scaling.lo <= 0.0 && g.scaling.hi >= 0.0);
        let mut clocked = vec![false; count + 1];
        if clock_grouped {
            for g in &clock {
                clocked[g.slot] = true;
            }
        }
        let mut x = vec![[1.0; LANES]; count + 1];
        for (slot, v) in constant {
            x[slot] = [v; LANES];
        }
        // A submodel of linear terms only (the pressure and mass rows) has the scaling
        // folded into its coefficients: `c * (v - mean) / std` is `(c / std) * v` plus a
        // constant, so a feature costs a clamp rather than a clamp, a subtraction and a
        // multiplication. The sum moves by rounding only.
        let folded = phase_js.is_empty()
            && clock_js.is_empty()
            && s.rows.iter().all(|r| {
                r.terms
                    .iter()
                    .all(|t| t.factors.iter().filter(|&&f| f as usize != dim).count() <= 1)
            });
        let rows: Vec<CompiledRow> = s
            .rows
            .iter()
            .map(|r| {
                if !folded {
                    return CompiledRow::new(r, &slot, dim, &group, groups, &clocked);
                }
                let mut r = r.clone();
                for t in &mut r.terms {
                    if let Some(&j) = t.factors.iter().find(|&&f| (f as usize) < dim) {
                        let j = j as usize;
                        t.coef /= s.feature_std[j];
                        r.intercept -= t.coef * s.feature_mean[j];
                    }
                }
                CompiledRow::new(&r, &slot, dim, &group, groups, &clocked)
            })
            .collect();
        let unscaled = |(_, g): (usize, Gather)| {
            if folded {
                Gather {
                    scaling: FeatureScaling {
                        mean: 0.0,
                        inv_std: 1.0,
                        ..g.scaling
                    },
                    ..g
                }
            } else {
                g
            }
        };
        let shared: Vec<Gather> = shared.into_iter().map(unscaled).collect();
        let dense = (folded && LANES == 1 && rows.len() <= DENSE_ROWS).then(|| {
            let mut intercept = [0.0; DENSE_ROWS];
            let mut coef = vec![[0.0; DENSE_ROWS]; count];
            for (r, row) in rows.iter().enumerate() {
                intercept[r] = row.intercept;
                // Folded rows are linear: every term is a single factor (checked here,
                // once, so that no term could be dropped silently).
                assert!(
                    row.terms.groups.is_empty(),
                    "a folded row has only linear terms"
                );
                for &([a], c) in &row.terms.single {
                    coef[a as usize][r] += c;
                }
            }
            // A dense submodel reads shared features only: its slots are `shared`'s.
            assert_eq!(
                count,
                shared.len(),
                "a dense submodel has shared reads only"
            );
            Dense::new(intercept, &shared, &coef)
        });
        // The dense coefficients replace the rows.
        let rows = if dense.is_some() { Vec::new() } else { rows };
        Self {
            dense,
            phase_group,
            target: s.target,
            outputs: s.outputs.clone(),
            x,
            folded,
            shared,
            lanes: lanes.into_iter().map(unscaled).collect(),
            phases,
            clock,
            ignition: s.features.ignition(),
            clock_grouped,
            rows,
        }
    }

    /// Gathers, clamps and scales the used features of the history `window` into `x`;
    /// true when one was outside its envelope. `avx2`: as in [`CompiledSub::eval`].
    #[inline(always)]
    fn gather(&mut self, window: &[f64], phases: &Phases, clock: &Clock, avx2: bool) -> bool {
        let mut outside = 0;
        // SAFETY: `compile` places every read (and the engines after it) inside a window
        // of the ring's depth, which is the length of `window`.
        let at = |i: usize| unsafe { *window.get_unchecked(i) };
        debug_assert!(self.lanes.iter().all(|g| g.offset + LANES <= window.len()));
        debug_assert!(self.shared.iter().all(|g| g.offset < window.len()));
        let (x_shared, x_rest) = self.x.split_at_mut(self.shared.len());
        if self.folded {
            for (g, x) in self.shared.iter().zip(x_shared) {
                let (v, out) = g.scaling.clamp(at(g.offset));
                *x = [v; LANES];
                outside |= out;
            }
        } else {
            for (g, x) in self.shared.iter().zip(x_shared) {
                let (v, out) = g.scaling.apply(at(g.offset));
                *x = [v; LANES];
                outside |= out;
            }
        }
        #[cfg(target_arch = "x86_64")]
        let lanes_done = if avx2 && LANES == ENGINE_COUNT {
            // SAFETY: `[f64; LANES]` is `[f64; 4]` here; the CPU has AVX2 (the caller
            // checked); reads as above.
            let x4 = unsafe {
                std::slice::from_raw_parts_mut(x_rest.as_mut_ptr().cast::<[f64; 4]>(), x_rest.len())
            };
            outside |= unsafe { gather_lanes_avx2(&self.lanes, window, x4) };
            true
        } else {
            false
        };
        #[cfg(not(target_arch = "x86_64"))]
        let lanes_done = {
            let _ = avx2;
            false
        };
        if !lanes_done {
            for (g, x) in self.lanes.iter().zip(x_rest) {
                for (e, x) in x.iter_mut().enumerate() {
                    let (v, out) = g.scaling.apply(at(g.offset + e));
                    *x = v;
                    outside |= out;
                }
            }
        }
        for g in &self.phases {
            let x = &mut self.x[g.slot];
            for (e, x) in x.iter_mut().enumerate() {
                let hit = phases.on[e] == g.on && phases.run[e] == g.run;
                let (v, out) = g.scaling.apply(f64::from(u8::from(hit)));
                *x = v;
                outside |= out;
            }
        }
        if let Some(c) = &self.ignition {
            if clock.any || !self.clock_grouped {
                for g in &self.clock {
                    let x = &mut self.x[g.slot];
                    for (e, x) in x.iter_mut().enumerate() {
                        let since = clock.since_ignition_s[e];
                        let raw = match g.hat {
                            None => IgnitionClock::priming(phases.on[e], since),
                            Some(j) => c.hat(since, j),
                        };
                        let (v, out) = g.scaling.apply(raw);
                        *x = v;
                        outside |= out;
                    }
                }
            }
        }
        outside != 0
    }

    /// Predicts this submodel's outputs into `next`; true when a feature was outside its
    /// envelope. `avx2`: the step runs in its AVX2 build (see [`Predictor::step`]).
    #[inline(always)]
    fn eval(
        &mut self,
        window: &[f64],
        phases: &Phases,
        clock: &Clock,
        prev: &StateVec,
        next: &mut StateVec,
        avx2: bool,
    ) -> bool {
        if let Some(d) = &self.dense {
            debug_assert!(self.lanes.is_empty() && self.phases.is_empty() && self.clock.is_empty());
            let (y, outside) = d.eval(window, avx2);
            for (&o, y) in self.outputs.iter().zip(y) {
                next[o] = self.target.apply(prev[o], y);
            }
            return outside;
        }
        let outside = self.gather(window, phases, clock, avx2);
        if LANES == 1 {
            for (row, &o) in self.rows.iter().zip(&self.outputs) {
                let mut y = [row.intercept; LANES];
                row.terms.add(&self.x, &mut y);
                next[o] = self.target.apply(prev[o], y[0]);
            }
        } else {
            // One shared row for the engines, plus each engine's phase terms.
            let row = &self.rows[0];
            let mut y = [row.intercept; LANES];
            row.terms.add(&self.x, &mut y);
            for (e, y) in y.iter_mut().enumerate() {
                let table = &self.phase_group[usize::from(!phases.on[e])];
                if let Some(&Some(g)) = table.get(phases.run[e] - 1) {
                    row.phase[g].add_lane(&self.x, e, y);
                }
                if self.clock_grouped && clock.active[e] {
                    row.clock.add_lane(&self.x, e, y);
                }
            }
            for (&o, y) in self.outputs.iter().zip(y) {
                next[o] = self.target.apply(prev[o], y);
            }
        }
        outside
    }
}

/// The per-engine reads of [`CompiledSub::gather`] in AVX2 vectors: a feature's four
/// engines are adjacent in the window, so each is one read, one clamp and one scaling.
/// Written with intrinsics because the compiler vectorised the portable loop across
/// four features at a time and transposed them back. The same IEEE operations per lane
/// as [`FeatureScaling::apply`] (see [`Dense::chunks_avx2`] for the clamp), so the same
/// bits; tested against the portable path. Returns the bits the clamps changed.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn gather_lanes_avx2(lanes: &[Gather], window: &[f64], x: &mut [[f64; 4]]) -> u64 {
    use std::arch::x86_64::*;
    let mut changed = _mm256_setzero_pd();
    for (g, x) in lanes.iter().zip(x) {
        debug_assert!(g.offset + 4 <= window.len());
        // SAFETY: `compile` places every read and the engines after it in the window.
        let raw = unsafe { _mm256_loadu_pd(window.as_ptr().add(g.offset)) };
        let sc = g.scaling;
        let v = _mm256_min_pd(
            _mm256_set1_pd(sc.hi),
            _mm256_max_pd(_mm256_set1_pd(sc.lo), raw),
        );
        changed = _mm256_or_pd(changed, _mm256_xor_pd(v, raw));
        let scaled = _mm256_mul_pd(
            _mm256_sub_pd(v, _mm256_set1_pd(sc.mean)),
            _mm256_set1_pd(sc.inv_std),
        );
        // SAFETY: `x` holds four values.
        unsafe { _mm256_storeu_pd(x.as_mut_ptr(), scaled) };
    }
    let mut bits = [0u64; 4];
    // SAFETY: four 64-bit values.
    unsafe { _mm256_storeu_pd(bits.as_mut_ptr().cast(), changed) };
    bits[0] | bits[1] | bits[2] | bits[3]
}

/// The history: the last `depth` records, each stored twice (at `i` and `i + depth`), so
/// that the records from `depth - 1` steps back to the latest always lie in one
/// contiguous window. A feature is then a fixed offset into the window, found when the
/// model is compiled, instead of a wrap-around computation per read.
#[derive(Debug, Clone)]
struct Ring {
    buf: Vec<f64>,
    depth: usize,
    /// Record index of the step being predicted, `0..depth`.
    head: usize,
}

impl Ring {
    fn new(depth: usize) -> Self {
        Self {
            buf: vec![0.0; 2 * depth * REC_DIM],
            depth,
            head: 0,
        }
    }

    /// Where component `comp` of the record `lag` steps back lies in the window.
    fn offset(depth: usize, lag: usize, comp: usize) -> usize {
        (depth - 1 - lag) * REC_DIM + comp
    }

    /// The window: record `head - depth + 1` (wrapped) first, `head` last.
    #[inline(always)]
    fn window(&self) -> &[f64] {
        let start = (self.head + 1) * REC_DIM;
        &self.buf[start..start + self.depth * REC_DIM]
    }

    /// The record `lag` steps back.
    fn rec(&self, lag: usize) -> &[f64] {
        let i = self.head + self.depth - lag;
        &self.buf[i * REC_DIM..(i + 1) * REC_DIM]
    }

    /// Moves `head` on by one record (a compare, not the division of `%`, on the step
    /// path) and returns it.
    #[inline(always)]
    fn advance(&mut self) -> usize {
        self.head += 1;
        if self.head == self.depth {
            self.head = 0;
        }
        self.head
    }

    /// Index of the record `lag` steps back.
    fn index(&self, lag: usize) -> usize {
        (self.head + self.depth - lag) % self.depth
    }

    /// Writes `values` from component `comp` of record `i`, in both copies, then
    /// `last` after them. Value by value rather than through an assembled array: the
    /// values were just computed one by one, and a wide read of them would wait for
    /// the narrow writes (a store-forwarding stall: in a profile of the step, those
    /// wide reads were among its hottest instructions). `N` is a constant so that the
    /// copy is a few moves: over a slice of run-time length it compiled to a call to
    /// `memcpy`, some 5 % of the step.
    #[inline(always)]
    fn write<const N: usize>(
        &mut self,
        i: usize,
        comp: usize,
        values: &[f64; N],
        last: Option<f64>,
    ) {
        for copy in [i, i + self.depth] {
            let at = copy * REC_DIM + comp;
            let r: &mut [f64; N] = (&mut self.buf[at..at + N])
                .try_into()
                .expect("a slice of N values");
            *r = *values;
            if let Some(v) = last {
                self.buf[at + N] = v;
            }
        }
    }

    fn set_state(&mut self, i: usize, s: &StateVec) {
        let lambda = lambda_of(s[STATE_MF], s[STATE_MO]);
        self.write(i, REC_STATE, s, Some(lambda));
    }

    fn set_valve(&mut self, i: usize, valve_n: &[f64; ENGINE_COUNT]) {
        self.write(i, REC_VALVE, valve_n, None);
    }

    fn set_input(&mut self, i: usize, u: &InputVec) {
        self.write(i, 0, u, Some(command_sum_of(u)));
    }

    /// The latest state.
    fn state(&self) -> StateVec {
        let r = self.rec(0);
        std::array::from_fn(|k| r[REC_STATE + k])
    }
}

#[cfg(target_arch = "x86_64")]
fn avx2_detected() -> bool {
    std::is_x86_feature_detected!("avx2")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_detected() -> bool {
    false
}

/// Free-running evaluation of a [`Model`]: its own predictions become its history.
/// Every buffer is sized in [`Predictor::new`]; [`Predictor::step`] does not allocate.
#[derive(Debug, Clone)]
pub struct Predictor {
    on_command_range_n: [f64; 2],
    mimo: Vec<CompiledSub<1>>,
    per_engine: Vec<CompiledSub<ENGINE_COUNT>>,
    ring: Ring,
    phases: Phases,
    /// The valve filter some submodel reads, and its state after the latest step.
    valve: Option<ValveTrack>,
    /// The ignition clocks after the step (idle without one).
    clock: Clock,
    out_of_envelope_steps: u64,
    /// Step with the AVX2 build of the same code (x86-64 CPUs that have it).
    avx2: bool,
}

impl Predictor {
    /// Compiles a model (assumed checked) and starts it from its initial state.
    pub fn new(model: &Model) -> Self {
        // The phase indicators are kept incrementally, so the ring only has to hold the
        // lags the features read directly.
        let depth = model
            .submodels
            .iter()
            .map(|s| s.features.max_state_lag())
            .max()
            .unwrap_or(1)
            .saturating_add(1);
        let cap = model
            .submodels
            .iter()
            .map(|s| s.features.start_steps.max(s.features.stop_steps))
            .max()
            .unwrap_or(0);
        let of_layout = |l: Layout| {
            model
                .submodels
                .iter()
                .filter(move |s| s.features.layout == l)
        };
        let mut p = Self {
            on_command_range_n: model.on_command_range_n,
            mimo: of_layout(Layout::Mimo)
                .map(|s| CompiledSub::compile(s, depth))
                .collect(),
            per_engine: of_layout(Layout::PerEngine)
                .map(|s| CompiledSub::compile(s, depth))
                .collect(),
            ring: Ring::new(depth),
            phases: Phases {
                on: [false; ENGINE_COUNT],
                run: [cap + 1; ENGINE_COUNT],
                cap,
            },
            valve: model
                .submodels
                .iter()
                .filter(|s| s.features.valve_features() > 0)
                .find_map(|s| s.features.valve)
                .map(|f| ValveTrack::new(f, model.sample_time_ns as f64 * 1e-9)),
            clock: Clock::IDLE,
            out_of_envelope_steps: 0,
            avx2: cfg!(target_arch = "x86_64") && avx2_detected(),
        };
        p.reset_to(&model.initial_state);
        p
    }

    /// Restarts from a state at rest: engines off for all of the history, every past
    /// state equal to `state` (how the reference model is started).
    pub fn reset_to(&mut self, state: &StateVec) {
        let rest = self.valve.as_mut().map_or(ValveState::default(), |v| {
            v.reset();
            v.state
        });
        for i in 0..self.ring.depth {
            self.ring.set_input(i, &[0.0; INPUT_DIM]);
            self.ring.set_valve(i, &rest.valve_n);
            self.ring.set_state(i, state);
        }
        self.ring.head = 0;
        self.phases.on = [false; ENGINE_COUNT];
        self.phases.run = [self.phases.cap + 1; ENGINE_COUNT];
        self.clock = Clock::IDLE;
        self.out_of_envelope_steps = 0;
    }

    /// Loads a true history (oldest first; the last state is the latest known) so that a
    /// free run can start mid-trajectory, as cross-validation does on a test block.
    pub fn seed_history<H: History>(&mut self, h: &H) {
        // Slot `head` is the step about to be predicted; lags 1..depth-1 are the past.
        self.ring.head = 0;
        for lag in 1..self.ring.depth {
            let i = self.ring.index(lag);
            self.ring.set_input(i, h.input(lag));
            if self.valve.is_some() {
                self.ring.set_valve(i, &h.valve(lag).valve_n);
            }
            self.ring.set_state(i, h.state(lag));
        }
        if let Some(v) = &mut self.valve {
            v.state = *h.valve(1);
        }
        // One slot back, so the next step() advances onto slot 0.
        self.ring.head = self.ring.depth - 1;
        // The switch phase at the latest known step, read from the history (which may
        // reach further back than the ring).
        let cap = self.phases.cap;
        for e in 0..ENGINE_COUNT {
            let sw = |lag: usize| h.input(lag)[ENGINE_COUNT + e] > 0.5;
            let on = sw(1);
            self.phases.on[e] = on;
            self.phases.run[e] = (1..=cap).find(|&k| sw(k + 1) != on).unwrap_or(cap + 1);
        }
    }

    /// Number of steps on which some used feature was outside the training envelope.
    pub fn out_of_envelope_steps(&self) -> u64 {
        self.out_of_envelope_steps
    }

    /// The latest state.
    pub fn state(&self) -> StateVec {
        self.ring.state()
    }

    /// Predicts the state at the end of a step with `input` held, and makes it history.
    #[inline]
    pub fn step(&mut self, input: &InputVec) -> StateVec {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: the CPU has AVX2 (checked in `new`).
            return unsafe { self.step_avx2(input) };
        }
        self.step_portable(input)
    }

    /// [`Predictor::step`] compiled for AVX2: the four engines' lanes in one vector
    /// instead of two. Bit for bit the same results: each lane is the same IEEE operation
    /// in the same order, and without fused multiply-add (which would round differently,
    /// and so is not enabled) nothing else changes. Tested against the portable path.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn step_avx2(&mut self, input: &InputVec) -> StateVec {
        self.step_portable(input)
    }

    #[inline(always)]
    fn step_portable(&mut self, input: &InputVec) -> StateVec {
        let prev = self.ring.state();
        let head = self.ring.advance();
        let mut u = *input;
        let mut outside = false;
        let [lo, hi] = self.on_command_range_n;
        for e in 0..ENGINE_COUNT {
            let on = u[ENGINE_COUNT + e] > 0.5;
            if on {
                let raw = u[e];
                let v = raw.clamp(lo, hi);
                outside |= v != raw;
                u[e] = v;
            }
            let ph = &mut self.phases;
            ph.run[e] = if on == ph.on[e] {
                (ph.run[e] + 1).min(ph.cap + 1)
            } else {
                1
            };
            ph.on[e] = on;
        }
        // The model sees the commands after the on-range clamp above. The record's state
        // is still an old one; it is never read (state lags start at 1).
        self.ring.set_input(head, &u);
        if let Some(v) = &mut self.valve {
            let ignition = v.ignition();
            let s = v.advance(&u);
            self.ring.set_valve(head, &s.valve_n);
            if let Some(c) = ignition {
                // The switches are the phases' (already updated for this step).
                let window_s = c.window_s();
                let k = &mut self.clock;
                k.any = false;
                for e in 0..ENGINE_COUNT {
                    let since = s.since_ignition_s[e];
                    k.since_ignition_s[e] = since;
                    k.active[e] = self.phases.on[e] && since < window_s;
                    k.any |= k.active[e];
                }
            }
        }
        let mut next = prev;
        let window = self.ring.window();
        let avx2 = self.avx2;
        for sub in &mut self.per_engine {
            outside |= sub.eval(window, &self.phases, &self.clock, &prev, &mut next, avx2);
        }
        for sub in &mut self.mimo {
            outside |= sub.eval(window, &self.phases, &self.clock, &prev, &mut next, avx2);
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
        self.ring.set_state(head, &next);
        next
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::surrogate::features::{TrajectoryHistory, ValveFilter};
    use crate::surrogate::library::Library;

    /// A valve filter for the test models (hifi's TFCV figures in newtons).
    pub(crate) const TEST_VALVE: ValveFilter = ValveFilter {
        time_constant_s: 0.015,
        rate_n_per_s: 6000.0,
        backlash_n: 4.7,
        park_n: 320.0,
        ignition: Some(TEST_IGNITION),
    };

    /// An ignition clock for the test models (with sag, so the engines' clocks depend
    /// on each other).
    pub(crate) const TEST_IGNITION: IgnitionClock = IgnitionClock {
        fill_n_s: 20.0,
        drain_time_s: 0.6,
        full: 1.1,
        lead_s: 0.01,
        knot_spacing_s: 0.005,
        knots: 6,
        sag_per_n: 6e-5,
    };

    /// The valve track of `inputs` for `model` (empty when no submodel reads it).
    fn valves_of(model: &Model, inputs: &[InputVec]) -> (Vec<ValveState>, ValveState) {
        let dt_s = model.sample_time_ns as f64 * 1e-9;
        match model.submodels.iter().find_map(|s| s.features.valve) {
            Some(f) => (f.track(inputs, dt_s), f.rest()),
            None => (Vec::new(), ValveState::default()),
        }
    }

    /// A model with every library term active (pseudo-random coefficients), so every
    /// feature, phase indicator and term degree is exercised. With `mimo_degree` 1 the
    /// MIMO submodel is linear, and compiled with its scaling folded.
    fn dense_model(mimo_degree: usize) -> Model {
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let specs = [
            (
                FeatureSpec {
                    layout: Layout::PerEngine,
                    history: 2,
                    mass_features: true,
                    start_steps: 5,
                    stop_steps: 3,
                    phase_degree: 0,
                    command_sum: true,
                    valve: Some(TEST_VALVE),
                },
                3,
                (0..ENGINE_COUNT).collect::<Vec<_>>(),
            ),
            (
                FeatureSpec {
                    layout: Layout::Mimo,
                    history: 1,
                    mass_features: true,
                    start_steps: 0,
                    stop_steps: 0,
                    phase_degree: 0,
                    command_sum: false,
                    valve: None,
                },
                mimo_degree,
                (ENGINE_COUNT..STATE_DIM).collect(),
            ),
        ];
        let submodels = specs
            .into_iter()
            .map(|(features, degree, outputs)| {
                let dim = features.dim();
                let names = features.names();
                let lib = Library::new(dim, degree, &features.roles(), features.phase_degree);
                let rows = match features.layout {
                    Layout::PerEngine => 1,
                    Layout::Mimo => outputs.len(),
                };
                Submodel {
                    features,
                    degree,
                    library_size: lib.len(),
                    target: Target::Increment,
                    feature_names: names.clone(),
                    // Start indicators uncentred, as training leaves them (their terms are
                    // then evaluated only in their phase); the others centred, which the
                    // predictor must handle too.
                    feature_mean: names
                        .iter()
                        .map(|n| if n.starts_with("start") { 0.0 } else { rnd() })
                        .collect(),
                    feature_std: (0..dim).map(|_| 1.0 + rnd()).collect(),
                    envelope_lo: vec![-1e9; dim],
                    envelope_hi: vec![1e9; dim],
                    rows: (0..rows)
                        .map(|o| OutputRow {
                            output: format!("y{o}"),
                            intercept: rnd(),
                            terms: lib
                                .terms
                                .iter()
                                .map(|t| ActiveTerm {
                                    name: lib.term_name(t, &names),
                                    factors: *t,
                                    coef: 1e-16 * rnd(),
                                })
                                .collect(),
                        })
                        .collect(),
                    outputs,
                }
            })
            .collect();
        Model {
            sample_time_ns: 10_000_000,
            initial_state: [0.0, 0.0, 0.0, 0.0, 2.8e7, 0.0, 0.0],
            on_command_range_n: [320.0, 800.0],
            submodels,
        }
    }

    /// The straightforward evaluation: every feature by `fill`, every term in library
    /// order. The compiled predictor must agree to rounding (it sums the phase terms of
    /// an engine in a phase after the others).
    #[test]
    fn compiled_step_equals_full_evaluation() {
        for mimo_degree in [1, 2] {
            compiled_step_equals_full_evaluation_of(&dense_model(mimo_degree));
        }
    }

    /// A term with two phase or ignition features would be evaluated in one's window
    /// with the other's in-phase constant: refused.
    #[test]
    fn a_term_with_two_phase_features_is_refused() {
        let mut m = dense_model(1);
        m.check().unwrap();
        let s = &mut m.submodels[0];
        let names = s.features.names();
        let at = |n: &str| names.iter().position(|x| x == n).unwrap() as u16;
        let one = s.features.dim() as u16;
        s.rows[0].terms.push(ActiveTerm {
            name: "priming[t]*stop0[t]".into(),
            factors: [at("priming[t]"), at("stop0[t]"), one],
            coef: 1.0,
        });
        let e = m.check().unwrap_err();
        assert!(e.contains("more than one phase or ignition feature"), "{e}");
    }

    /// The AVX2 build of the step gives the same bits as the portable one (on a CPU
    /// without AVX2 both runs take the portable path).
    #[test]
    fn avx2_and_portable_steps_agree_bit_for_bit() {
        let committed = crate::surrogate::model_file::ModelFile::parse(
            crate::surrogate::runtime::DEFAULT_MODEL_JSON,
        )
        .unwrap()
        .model;
        let (cmds, _) = crate::surrogate::features::source_tests::switching_trajectory(400);
        // The same switching at 2.5 times the thrust: commands beyond the on-range,
        // clamped and counted.
        let wild: Vec<InputVec> = cmds
            .iter()
            .map(|u| std::array::from_fn(|k| if k < ENGINE_COUNT { 2.5 * u[k] } else { u[k] }))
            .collect();
        // The committed model with every envelope narrowed to its middle third: the
        // features are clamped from both sides in every path.
        let mut narrowed = committed.clone();
        for s in &mut narrowed.submodels {
            for (lo, hi) in s.envelope_lo.iter_mut().zip(&mut s.envelope_hi) {
                let third = (*hi - *lo) / 3.0;
                (*lo, *hi) = (*lo + third, *hi - third);
            }
        }
        for model in [dense_model(1), dense_model(2), committed, narrowed] {
            for cmds in [&cmds, &wild] {
                let mut fast = Predictor::new(&model);
                let mut portable = Predictor::new(&model);
                portable.avx2 = false;
                for (t, cmd) in cmds.iter().enumerate() {
                    let (a, b) = (fast.step(cmd), portable.step(cmd));
                    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "step {t}");
                }
                assert_eq!(
                    fast.out_of_envelope_steps(),
                    portable.out_of_envelope_steps()
                );
            }
        }
    }

    /// The straightforward prediction of step `t` from the true history: `inputs` up to
    /// and including step `t` (as the model sees them), `states` up to step `t - 1`.
    fn full_step(model: &Model, inputs: &[InputVec], states: &[StateVec], t: usize) -> StateVec {
        let prev = states[..t].last().copied().unwrap_or(model.initial_state);
        let (valves, valve_rest) = valves_of(model, &inputs[..=t]);
        let mut want = prev;
        for s in &model.submodels {
            let dim = s.features.dim();
            let mut x = vec![1.0; dim + 1];
            for (e, &o) in s.outputs.iter().enumerate() {
                let h = TrajectoryHistory {
                    inputs,
                    states,
                    initial: &model.initial_state,
                    valves: &valves,
                    valve_rest,
                    t,
                };
                s.features.fill(&h, e, &mut x[..dim]);
                for j in 0..dim {
                    let v = x[j].max(s.envelope_lo[j]).min(s.envelope_hi[j]);
                    x[j] = (v - s.feature_mean[j]) * (1.0 / s.feature_std[j]);
                }
                let row = &s.rows[if s.rows.len() == 1 { 0 } else { e }];
                let mut y = row.intercept;
                for term in &row.terms {
                    let f = term.factors.map(|f| x[f as usize]);
                    y += term.coef * (f[0] * f[1] * f[2]);
                }
                want[o] = prev[o] + y;
            }
        }
        for v in want.iter_mut().take(ENGINE_COUNT) {
            *v = v.max(0.0);
        }
        want[STATE_P] = want[STATE_P].max(0.0);
        want[STATE_MF] = want[STATE_MF].max(prev[STATE_MF]);
        want[STATE_MO] = want[STATE_MO].max(prev[STATE_MO]);
        want
    }

    /// One step at a time from a true history, so that coefficients of ordinary size
    /// stay bounded (a free run of an all-active model needs tiny ones, which would hide
    /// a wrong intercept or scale in the folded linear submodel).
    #[test]
    fn one_step_from_history_equals_full_evaluation() {
        for mimo_degree in [1, 2] {
            let mut model = dense_model(mimo_degree);
            for r in &mut model.submodels[1].rows {
                for t in &mut r.terms {
                    t.coef *= 1e16;
                }
            }
            let (inputs, states) =
                crate::surrogate::features::source_tests::switching_trajectory(60);
            let (valves, valve_rest) = valves_of(&model, &inputs);
            let mut p = Predictor::new(&model);
            for t in 4..inputs.len() {
                p.seed_history(&TrajectoryHistory {
                    inputs: &inputs,
                    states: &states,
                    initial: &model.initial_state,
                    valves: &valves,
                    valve_rest,
                    t,
                });
                let got = p.step(&inputs[t]);
                let want = full_step(&model, &inputs, &states, t);
                for o in 0..STATE_DIM {
                    let tol = 1e-12 * (1.0 + want[o].abs());
                    assert!(
                        (got[o] - want[o]).abs() <= tol,
                        "degree {mimo_degree} step {t} output {o}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    fn compiled_step_equals_full_evaluation_of(model: &Model) {
        model.check().unwrap();
        let mut p = Predictor::new(model);
        let (cmds, _) = crate::surrogate::features::source_tests::switching_trajectory(150);
        let mut inputs: Vec<InputVec> = Vec::new();
        let mut states: Vec<StateVec> = Vec::new();
        let mut clocked_steps = 0;
        for (t, cmd) in cmds.iter().enumerate() {
            let got = p.step(cmd);
            clocked_steps += usize::from(p.clock.any);
            let mut u = *cmd;
            for e in 0..ENGINE_COUNT {
                if u[ENGINE_COUNT + e] > 0.5 {
                    u[e] = u[e].clamp(320.0, 800.0);
                }
            }
            inputs.push(u);
            let want = full_step(model, &inputs, &states, t);
            for o in 0..STATE_DIM {
                let tol = 1e-12 * (1.0 + want[o].abs());
                assert!(
                    (got[o] - want[o]).abs() <= tol,
                    "step {t} output {o}: {got:?} vs {want:?}"
                );
            }
            states.push(got);
        }
        // The run does go through ignition windows (their terms are evaluated apart).
        let clocked = model
            .submodels
            .iter()
            .any(|s| s.features.ignition().is_some());
        assert!(
            !clocked || clocked_steps > 20,
            "{clocked_steps} steps in a window"
        );
        // Seeding from the recorded history mid-run continues identically.
        let mut q = Predictor::new(model);
        let t0 = 77;
        let (valves, valve_rest) = valves_of(model, &inputs);
        q.seed_history(&TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &model.initial_state,
            valves: &valves,
            valve_rest,
            t: t0,
        });
        for t in t0..cmds.len() {
            assert_eq!(q.step(&cmds[t]), states[t], "seeded step {t}");
        }
    }
}
