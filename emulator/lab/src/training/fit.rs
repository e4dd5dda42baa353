//! From a dataset to coefficients: model variants, design blocks (library terms of scaled
//! features, row by row), block Gram sums, and the warm-started Lasso path that turns them
//! into [`Submodel`]s.

use super::dataset::Dataset;
use super::derive::ValveSpec;
use super::lasso::{lasso_gram, GramStats, LassoSettings, LassoWorkspace, Standardised};
use oils_emulator::propulsion::surrogate::features::{FeatureSpec, Layout, STATE_DIM, STATE_NAMES};
use oils_emulator::propulsion::surrogate::library::Library;
use oils_emulator::propulsion::surrogate::model::{
    active_terms_of, Model, OutputRow, Submodel, Target, Term,
};
use oils_emulator::propulsion::surrogate::valve::ValveFilter;
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};

pub use oils_emulator::propulsion::surrogate::model_file::Variant;

/// Which polynomial phi a submodel's library is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Phi {
    /// Every monomial of the features up to the degree (products included).
    #[default]
    Products,
    /// Each feature's powers alone up to the degree ([`Library::powers`]).
    Powers,
}

/// Polynomial degrees and feature choices of the variants.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VariantConfig {
    /// Degree of the paper model's library (1: K has the paper's stated 7 x (11n+10)).
    pub paper_degree: usize,
    /// The paper model's phi: each feature's powers (`powers`, the reading that keeps
    /// K's blocks of 11n+10) or every product up to the degree (`products`).
    pub paper_phi: Phi,
    /// Degree of the shared per-engine thrust model.
    pub engine_degree: usize,
    /// Degree of the shared-engine variant's pressure and mass model.
    pub system_degree: usize,
    /// Give the per-engine thrust model the ejected-mass histories and lambda.
    pub engine_mass_features: bool,
    /// Beyond the paper: start-phase indicators of the per-engine thrust model (steps
    /// after an engine switches on that get their own indicator; 0 = none, the original
    /// shared-engine features). See [`FeatureSpec::start_steps`].
    pub engine_start_steps: usize,
    /// Beyond the paper: stop-phase indicators (tail-off); 0 = none.
    pub engine_stop_steps: usize,
    /// Degree of library terms with a phase indicator (0: `engine_degree`); 3 makes each
    /// start step a quadratic in the command, as ignition timing depends on it.
    pub engine_phase_degree: usize,
    /// Beyond the paper: give the per-engine thrust model the sum of the four commands
    /// (`T_rsum[t]`, see [`FeatureSpec::command_sum`]).
    pub engine_command_sum: bool,
    /// The shared-engine variant's pressure and mass model is fitted at this multiple of
    /// the penalty `mu` chosen for the variant (1: one penalty for both submodels).
    pub system_mu_scale: f64,
    /// The shared-engine variant's pressure and mass model is fitted at this penalty
    /// whatever `mu` cross-validation tries for the thrust model (overrides
    /// `system_mu_scale`), so CV chooses the thrust's penalty alone instead of moving
    /// both submodels together. The committed value is where the mass rows' CV free-run
    /// errors are lowest (docs/journal/surrogate-history.md, "Penalties and sweeps").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub system_mu: Option<f64>,
    /// Beyond the paper: give the per-engine thrust model the command passed through a
    /// model of the throttle valve's actuator (`T_v`, see [`FeatureSpec::valve`]), as
    /// `train.toml` gives it (`[variants.engine_valve]`): its stroke table and ignition
    /// clock are derived from the reference ([`super::derive`]).
    #[serde(rename = "engine_valve", skip_serializing_if = "Option::is_none")]
    pub engine_valve_spec: Option<ValveSpec>,
    /// The filter the features read: `engine_valve_spec` with what was derived from the
    /// reference ([`super::TrainConfig::resolve`]).
    #[serde(skip)]
    pub engine_valve: Option<ValveFilter>,
    /// Beyond the paper: give the per-engine thrust model how the engines' total draw
    /// changed over the last steps, `dT_vsum[t..t-n]` (see [`FeatureSpec::valve_sum`]).
    /// Needs `engine_valve`.
    pub engine_valve_sum: bool,
}

impl Default for VariantConfig {
    fn default() -> Self {
        Self {
            paper_degree: 1,
            paper_phi: Phi::Powers,
            engine_degree: 2,
            system_degree: 1,
            engine_mass_features: false,
            engine_start_steps: 0,
            engine_stop_steps: 0,
            engine_phase_degree: 0,
            engine_command_sum: false,
            system_mu_scale: 1.0,
            system_mu: None,
            engine_valve_spec: None,
            engine_valve: None,
            engine_valve_sum: false,
        }
    }
}

/// Structure of one submodel before fitting.
#[derive(Debug, Clone, PartialEq)]
pub struct SubSpec {
    /// Features.
    pub features: FeatureSpec,
    /// Library degree.
    pub degree: usize,
    /// Which polynomial of that degree.
    pub phi: Phi,
    /// Target kind.
    pub target: Target,
    /// State indices predicted.
    pub outputs: Vec<usize>,
    /// The penalty this submodel is fitted at, given the variant's.
    pub penalty: Penalty,
}

/// How a submodel's Lasso penalty follows the variant's penalty `mu`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Penalty {
    /// `mu` times this factor (1: the variant's penalty).
    Scaled(f64),
    /// This penalty whatever `mu` is.
    Fixed(f64),
}

impl Penalty {
    /// The submodel's penalty when the variant's is `mu`.
    pub fn at(self, mu: f64) -> f64 {
        match self {
            Penalty::Scaled(k) => mu * k,
            Penalty::Fixed(m) => m,
        }
    }
}

impl SubSpec {
    /// Target columns in the design (one shared column for a per-engine model).
    pub fn target_columns(&self) -> usize {
        match self.features.layout {
            Layout::Mimo => self.outputs.len(),
            Layout::PerEngine => 1,
        }
    }

    /// Rows per time step.
    pub fn evaluations(&self) -> usize {
        match self.features.layout {
            Layout::Mimo => 1,
            Layout::PerEngine => ENGINE_COUNT,
        }
    }
}

/// The submodels of a variant at history length `n`.
pub fn sub_specs(variant: Variant, n: usize, cfg: &VariantConfig) -> Vec<SubSpec> {
    match variant {
        Variant::Paper => vec![SubSpec {
            features: FeatureSpec::paper(n),
            degree: cfg.paper_degree,
            phi: cfg.paper_phi,
            target: Target::Absolute,
            outputs: (0..STATE_DIM).collect(),
            penalty: Penalty::Scaled(1.0),
        }],
        Variant::SharedEngine => vec![
            SubSpec {
                features: FeatureSpec {
                    layout: Layout::PerEngine,
                    history: n,
                    mass_features: cfg.engine_mass_features,
                    start_steps: cfg.engine_start_steps,
                    stop_steps: cfg.engine_stop_steps,
                    phase_degree: cfg.engine_phase_degree,
                    command_sum: cfg.engine_command_sum,
                    valve: cfg.engine_valve,
                    valve_sum: cfg.engine_valve_sum,
                },
                degree: cfg.engine_degree,
                phi: Phi::Products,
                target: Target::Increment,
                outputs: (0..ENGINE_COUNT).collect(),
                penalty: Penalty::Scaled(1.0),
            },
            SubSpec {
                features: FeatureSpec::paper(n),
                degree: cfg.system_degree,
                phi: Phi::Products,
                target: Target::Increment,
                outputs: (ENGINE_COUNT..STATE_DIM).collect(),
                penalty: match cfg.system_mu {
                    Some(m) => Penalty::Fixed(m),
                    None => Penalty::Scaled(cfg.system_mu_scale),
                },
            },
        ],
    }
}

/// Everything fixed about a submodel once the whole dataset is known: scaling, envelope,
/// library, target shift.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Structure.
    pub spec: SubSpec,
    /// Library.
    pub library: Library,
    /// Raw feature means.
    pub mean: Vec<f64>,
    /// Raw feature standard deviations (1 where a feature is constant).
    pub std: Vec<f64>,
    /// Envelope lower bound (widened).
    pub lo: Vec<f64>,
    /// Envelope upper bound (widened).
    pub hi: Vec<f64>,
    /// Mean of each target column over the dataset (the Gram sums are taken about it).
    pub y_shift: Vec<f64>,
}

/// Envelope margin as a share of each feature's training range.
pub const ENVELOPE_MARGIN: f64 = 0.05;

impl Prepared {
    /// Scans the dataset once for scaling and envelope.
    pub fn new(spec: SubSpec, data: &Dataset) -> Self {
        let fs = spec.features;
        data.assert_valves_for(&fs);
        let dim = fs.dim();
        let library = match spec.phi {
            Phi::Products => Library::new(dim, spec.degree, &fs.roles(), fs.phase_degree),
            Phi::Powers => Library::powers(dim, spec.degree, &fs.roles()),
        };
        let mut sum = vec![0.0; dim];
        let mut sum2 = vec![0.0; dim];
        let mut lo = vec![f64::INFINITY; dim];
        let mut hi = vec![f64::NEG_INFINITY; dim];
        let mut ysum = vec![0.0; spec.target_columns()];
        let mut x = vec![0.0; dim];
        let mut y = vec![0.0; spec.target_columns()];
        let mut rows = 0.0;
        for t in 0..data.len() {
            for e in 0..spec.evaluations() {
                fs.fill(&data.history_at(t), e, &mut x);
                for j in 0..dim {
                    sum[j] += x[j];
                    sum2[j] += x[j] * x[j];
                    lo[j] = lo[j].min(x[j]);
                    hi[j] = hi[j].max(x[j]);
                }
                targets(&spec, data, t, e, &mut y);
                for (s, v) in ysum.iter_mut().zip(&y) {
                    *s += v;
                }
                rows += 1.0;
            }
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / rows).collect();
        let std: Vec<f64> = (0..dim)
            .map(|j| {
                let v = (sum2[j] / rows - mean[j] * mean[j]).max(0.0).sqrt();
                if v > 1e-12 * (1.0 + mean[j].abs()) {
                    v
                } else {
                    1.0
                }
            })
            .collect();
        for j in 0..dim {
            let margin = ENVELOPE_MARGIN * (hi[j] - lo[j]);
            lo[j] -= margin;
            hi[j] += margin;
        }
        // Phase indicators stay 0 and 1 (not centred): a term with one is then exactly
        // zero outside its phase, and the predictor evaluates it only for an engine in
        // that phase. (The Lasso standardises every term anyway.)
        let (mut mean, mut std) = (mean, std);
        for (j, r) in fs.roles().iter().enumerate() {
            if r.phase {
                mean[j] = 0.0;
                std[j] = 1.0;
            }
        }
        Self {
            spec,
            library,
            mean,
            std,
            lo,
            hi,
            y_shift: ysum.iter().map(|s| s / rows).collect(),
        }
    }

    /// Design rows (library terms, row-major) and shifted targets for steps `a..b`.
    pub fn block(&self, data: &Dataset, a: usize, b: usize) -> (Vec<f64>, Vec<f64>) {
        let order: Vec<usize> = (0..self.library.len()).collect();
        self.block_in(data, a, b, &order)
    }

    /// [`Prepared::block`] with the terms in the order `order` (a permutation).
    fn block_in(
        &self,
        data: &Dataset,
        a: usize,
        b: usize,
        order: &[usize],
    ) -> (Vec<f64>, Vec<f64>) {
        let fs = self.spec.features;
        let dim = fs.dim();
        let p = self.library.len();
        let cols = self.spec.target_columns();
        let rows = (b - a) * self.spec.evaluations();
        let mut xs = vec![0.0; rows * p];
        let mut ys = vec![0.0; rows * cols];
        let mut x = vec![1.0; dim + 1];
        let mut terms = vec![0.0; p];
        let mut r = 0;
        for t in a..b {
            for e in 0..self.spec.evaluations() {
                fs.fill(&data.history_at(t), e, &mut x[..dim]);
                for j in 0..dim {
                    x[j] = (x[j] - self.mean[j]) / self.std[j];
                }
                self.library.eval(&x, &mut terms);
                for (v, &k) in xs[r * p..(r + 1) * p].iter_mut().zip(order) {
                    *v = terms[k];
                }
                let y = &mut ys[r * cols..(r + 1) * cols];
                targets(&self.spec, data, t, e, y);
                for (v, s) in y.iter_mut().zip(&self.y_shift) {
                    *v -= s;
                }
                r += 1;
            }
        }
        (xs, ys)
    }

    /// The terms with no phase or ignition factor (in library order), then those with one,
    /// which are zero outside a start or a stop; and how many come first.
    fn sparse_last(&self) -> (Vec<usize>, usize) {
        let roles = self.spec.features.roles();
        let sparse = |k: usize| {
            self.library.terms[k]
                .iter()
                .any(|&f| roles.get(f as usize).is_some_and(|r| r.phase))
        };
        let p = self.library.len();
        let mut order: Vec<usize> = (0..p).filter(|&k| !sparse(k)).collect();
        let dense = order.len();
        order.extend((0..p).filter(|&k| sparse(k)));
        (order, dense)
    }

    /// Gram sums of steps `a..b`, built in chunks so the design never has to fit in
    /// memory whole.
    pub fn stats(&self, data: &Dataset, a: usize, b: usize) -> GramStats {
        const CHUNK_STEPS: usize = 1024;
        let p = self.library.len();
        let cols = self.spec.target_columns();
        let (order, dense) = self.sparse_last();
        let mut total = GramStats::zeros(p, cols);
        let mut start = a;
        while start < b {
            let end = (start + CHUNK_STEPS).min(b);
            let (xs, ys) = self.block_in(data, start, end, &order);
            total.add_rows(&xs, &ys, dense);
            start = end;
        }
        total.mirror();
        // Back to library order.
        let mut position = vec![0; p];
        for (i, &k) in order.iter().enumerate() {
            position[k] = i;
        }
        total.select(&position)
    }

    /// The same submodel at a shorter history, `spec`, taken from this one: its features
    /// are a subset of these (the first lags of the same signals; found by name), scaled
    /// alike, so its library is a subset of this library. Returns it and, for each of its
    /// terms, the index of the same term here (for [`GramStats::select`]).
    pub fn nested(&self, spec: SubSpec) -> (Self, Vec<usize>) {
        let here = &self.spec;
        assert!(
            spec.degree == here.degree
                && spec.phi == here.phi
                && spec.target == here.target
                && spec.outputs == here.outputs
                && spec.penalty == here.penalty
                && spec.features.history <= here.features.history,
            "not a shorter history of the same submodel"
        );
        let fs = spec.features;
        let names = self.spec.features.names();
        let feature: Vec<usize> = fs
            .names()
            .iter()
            .map(|n| {
                names
                    .iter()
                    .position(|m| m == n)
                    .unwrap_or_else(|| panic!("feature {n} not in the longer history"))
            })
            .collect();
        let library = match spec.phi {
            Phi::Products => Library::new(fs.dim(), spec.degree, &fs.roles(), fs.phase_degree),
            Phi::Powers => Library::powers(fs.dim(), spec.degree, &fs.roles()),
        };
        let here_term: std::collections::BTreeMap<Term, usize> = self
            .library
            .terms
            .iter()
            .enumerate()
            .map(|(k, t)| (*t, k))
            .collect();
        let (one, here_one) = (fs.dim(), self.spec.features.dim());
        let index = library
            .terms
            .iter()
            .map(|t| {
                let mut u = t.map(|f| {
                    let f = f as usize;
                    (if f == one { here_one } else { feature[f] }) as u16
                });
                u.sort_unstable();
                here_term[&u]
            })
            .collect();
        let pick = |v: &[f64]| feature.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let nested = Self {
            library,
            mean: pick(&self.mean),
            std: pick(&self.std),
            lo: pick(&self.lo),
            hi: pick(&self.hi),
            y_shift: self.y_shift.clone(),
            spec,
        };
        (nested, index)
    }

    /// A submodel from raw-term coefficients (one vector and intercept per column).
    pub fn submodel(&self, coefs: &[(Vec<f64>, f64)]) -> Submodel {
        let fs = self.spec.features;
        let names = fs.names();
        let rows = coefs
            .iter()
            .enumerate()
            .map(|(c, (w, b))| OutputRow {
                output: match fs.layout {
                    Layout::Mimo => STATE_NAMES[self.spec.outputs[c]].to_string(),
                    Layout::PerEngine => "T_o".to_string(),
                },
                intercept: *b,
                terms: active_terms_of(&self.library.terms, w, fs.dim(), &names),
            })
            .collect();
        Submodel {
            features: fs,
            degree: self.spec.degree,
            library_size: self.library.len(),
            target: self.spec.target,
            outputs: self.spec.outputs.clone(),
            feature_names: names,
            feature_mean: self.mean.clone(),
            feature_std: self.std.clone(),
            envelope_lo: self.lo.clone(),
            envelope_hi: self.hi.clone(),
            rows,
        }
    }
}

/// Target values of step `t` (engine `e` for a per-engine model), unshifted.
fn targets(spec: &SubSpec, data: &Dataset, t: usize, e: usize, y: &mut [f64]) {
    let now = &data.states[t];
    let prev = data.previous_state(t);
    let value = |o: usize| spec.target.of(prev[o], now[o]);
    match spec.features.layout {
        Layout::Mimo => {
            for (c, &o) in spec.outputs.iter().enumerate() {
                y[c] = value(o);
            }
        }
        Layout::PerEngine => y[0] = value(spec.outputs[e]),
    }
}

/// Coefficients of every target column along the penalty path.
#[derive(Debug, Clone)]
pub struct PathFit {
    /// `coefs[mu_index][column]` = (raw-term coefficients, intercept in shifted units
    /// plus shift, i.e. the real intercept).
    pub coefs: Vec<Vec<(Vec<f64>, f64)>>,
    /// Per penalty: fits whose duality gap ended above the tolerance.
    pub unconverged: Vec<usize>,
}

/// Lasso path over `mus` (descending; each through the submodel's [`Penalty`]),
/// warm-started, on the standardised problem of `stats`. Returned coefficients apply to
/// unscaled library terms.
pub fn fit_path(
    prep: &Prepared,
    stats: &GramStats,
    mus: &[f64],
    settings: &LassoSettings,
) -> PathFit {
    let std = Standardised::new(stats.centred());
    let p = prep.library.len();
    let zero_shift = vec![0.0; p];
    let mut coefs = vec![Vec::with_capacity(std.outputs()); mus.len()];
    let mut unconverged = vec![0; mus.len()];
    let mut ws = LassoWorkspace::new(p);
    for c in 0..std.outputs() {
        let prob = std.problem(c);
        let mut w = vec![0.0; p];
        for (i, &mu) in mus.iter().enumerate() {
            let r = lasso_gram(&prob, prep.spec.penalty.at(mu), settings, &mut w, &mut ws);
            unconverged[i] += usize::from(!r.converged);
            coefs[i].push(std.unscale(c, &w, &zero_shift, prep.y_shift[c]));
        }
    }
    PathFit { coefs, unconverged }
}

/// Sum of squared one-step errors of column `c` over the rows summed in `s`, for
/// coefficients `w` and intercept `b` (real units; `y_shift` is what the sums were
/// shifted by). Only active terms are visited.
pub fn sse(s: &GramStats, c: usize, w: &[f64], b: f64, y_shift: f64) -> f64 {
    let p = s.p;
    let o = s.outputs;
    let active: Vec<usize> = (0..p).filter(|&j| w[j] != 0.0).collect();
    let b = b - y_shift;
    let mut wxx = 0.0;
    for &i in &active {
        let mut acc = 0.0;
        for &j in &active {
            acc += s.xtx[i * p + j] * w[j];
        }
        wxx += w[i] * acc;
    }
    let wxy: f64 = active.iter().map(|&j| w[j] * s.xty[j * o + c]).sum();
    let wx: f64 = active.iter().map(|&j| w[j] * s.sum_x[j]).sum();
    let v = s.yty[c] - 2.0 * b * s.sum_y[c] - 2.0 * wxy + s.n * b * b + 2.0 * b * wx + wxx;
    v.max(0.0)
}

/// Assembles a model from fitted submodels.
pub fn assemble(data: &Dataset, subs: Vec<Submodel>) -> Model {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for i in &data.inputs {
        for e in 0..ENGINE_COUNT {
            if i[ENGINE_COUNT + e] > 0.5 {
                lo = lo.min(i[e]);
                hi = hi.max(i[e]);
            }
        }
    }
    if lo > hi {
        (lo, hi) = (0.0, 0.0);
    }
    Model {
        sample_time_ns: data.sample_time_ns,
        initial_state: data.initial,
        on_command_range_n: [lo, hi],
        submodels: subs,
    }
}
