//! Contiguous-block k-fold cross-validation over history length `n` and penalty `mu`,
//! scored on free-run error.
//!
//! Folds are contiguous blocks of time, never shuffled rows: with lagged features a
//! shuffled fold would hold the neighbours of its test rows in the training set and leak.
//! For every (n, mu) we report one-step RMSE (train and test, from Gram sums) and the
//! free-run RMSE on each test block, where the model starts from the true history at the
//! block's start and then feeds its own predictions back, as in the loop.

use super::dataset::Dataset;
use super::fit::{assemble, fit_path, sse, sub_specs, Prepared, Variant, VariantConfig};
use super::lasso::{mu_grid, GramStats, LassoSettings};
use oils_emulator::propulsion::surrogate::features::STATE_DIM;
use oils_emulator::propulsion::surrogate::predictor::Predictor;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Cross-validation grid and solver settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CvConfig {
    /// Number of contiguous folds k.
    pub folds: usize,
    /// Smallest history length tried.
    pub history_min: usize,
    /// Largest history length tried.
    pub history_max: usize,
    /// Smallest penalty.
    pub mu_min: f64,
    /// Largest penalty.
    pub mu_max: f64,
    /// Log-spaced penalties between them.
    pub mu_count: usize,
    /// Lasso duality-gap tolerance (scikit-learn's `tol`).
    pub tol: f64,
    /// Lasso active-set iterations at most per fit.
    pub max_iter: usize,
    /// Parsimony, beyond-paper variants only: choose the grid point with the fewest
    /// active coefficients among those whose score is within this fraction of the best
    /// (0: the best score, the paper's rule, which the paper variant always uses). Fewer terms cost less per step, and a score a few percent higher is within
    /// the fold-to-fold spread of the estimate.
    pub score_tolerance: f64,
}

impl Default for CvConfig {
    fn default() -> Self {
        Self {
            folds: 5,
            history_min: 1,
            history_max: 10,
            mu_min: 1e-5,
            mu_max: 1.0,
            mu_count: 11,
            tol: 1e-4,
            max_iter: 10_000,
            score_tolerance: 0.0,
        }
    }
}

impl CvConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), String> {
        if self.folds < 2 {
            return Err("cv.folds must be >= 2".into());
        }
        if self.history_min == 0 || self.history_max < self.history_min || self.history_max > 32 {
            return Err("cv: need 1 <= history_min <= history_max <= 32".into());
        }
        let ok = self.mu_min > 0.0
            && self.mu_max >= self.mu_min
            && self.mu_max.is_finite()
            && self.mu_count >= 1;
        if !ok {
            return Err("cv: need 0 < mu_min <= mu_max and mu_count >= 1".into());
        }
        if !(self.tol > 0.0 && self.tol.is_finite()) || self.max_iter == 0 {
            return Err("cv: need tol > 0 and max_iter >= 1".into());
        }
        if !(0.0..=1.0).contains(&self.score_tolerance) {
            return Err("cv: need 0 <= score_tolerance <= 1".into());
        }
        Ok(())
    }

    /// The history lengths searched, for every variant (the paper's n = 1..10 by
    /// default).
    pub fn histories(&self) -> std::ops::RangeInclusive<usize> {
        self.history_min..=self.history_max
    }

    /// The penalties, largest first.
    pub fn mus(&self) -> Vec<f64> {
        mu_grid(self.mu_min, self.mu_max, self.mu_count)
    }

    /// Solver settings.
    pub fn lasso(&self) -> LassoSettings {
        LassoSettings {
            tol: self.tol,
            max_iter: self.max_iter,
        }
    }
}

/// Cross-validated errors of one (n, mu), averaged over folds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GridPoint {
    /// History length.
    pub n: usize,
    /// Penalty (scikit-learn's alpha on the standardised problem).
    pub mu: f64,
    /// One-step RMSE on the training folds, per output.
    pub train_rmse: [f64; STATE_DIM],
    /// One-step RMSE on the test fold, per output.
    pub test_rmse: [f64; STATE_DIM],
    /// Free-run RMSE on the test fold, per output.
    pub free_rmse: [f64; STATE_DIM],
    /// Share of zero coefficients, percent.
    pub sparsity_pct: f64,
    /// Active coefficients, mean over folds.
    pub active_terms: f64,
    /// Selection score: mean over outputs of free-run RMSE / output standard deviation.
    pub score: f64,
    /// Lasso fits whose duality gap ended above the tolerance.
    pub unconverged: usize,
}

impl GridPoint {
    /// Mean over the four engines of a per-output thrust RMSE.
    pub fn thrust(v: &[f64; STATE_DIM]) -> f64 {
        v[..4].iter().sum::<f64>() / 4.0
    }
}

/// The cross-validation of one variant.
#[derive(Debug, Clone)]
pub struct CvResult {
    /// Which variant.
    pub variant: Variant,
    /// Every grid point, by n then mu (largest first).
    pub points: Vec<GridPoint>,
    /// Index of the chosen point (lowest finite score, or with `score_tolerance` the
    /// fewest active terms within it of the lowest).
    pub best: usize,
}

impl CvResult {
    /// The chosen point.
    pub fn chosen(&self) -> &GridPoint {
        &self.points[self.best]
    }

    /// The chosen penalty is the grid's largest or smallest: the score may fall further
    /// beyond it, and the grid should be widened.
    pub fn mu_at_grid_end(&self) -> bool {
        let mu = self.chosen().mu;
        let (lo, hi) = self
            .points
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
                (lo.min(p.mu), hi.max(p.mu))
            });
        mu <= lo || mu >= hi
    }
}

/// Contiguous fold boundaries over `len` steps.
pub fn fold_bounds(len: usize, folds: usize) -> Vec<(usize, usize)> {
    (0..folds)
        .map(|k| (k * len / folds, (k + 1) * len / folds))
        .collect()
}

/// Standard deviation of each state output over the dataset (score normalisation).
pub fn output_std(data: &Dataset) -> [f64; STATE_DIM] {
    let n = data.len().max(1) as f64;
    std::array::from_fn(|o| {
        let m = data.states.iter().map(|s| s[o]).sum::<f64>() / n;
        let v = data.states.iter().map(|s| (s[o] - m).powi(2)).sum::<f64>() / n;
        v.sqrt().max(1e-12)
    })
}

/// The Gram sums cross-validation and the final fit take every history length's from:
/// each submodel at the longest history searched, summed over each fold block. A shorter
/// history's library is a subset of the longest's ([`Prepared::nested`]), so its sums are
/// a selection of these: the costly products over the data are taken once per variant,
/// not once per history length.
#[derive(Debug, Clone)]
pub struct NestedSums {
    variant: Variant,
    /// The submodels at the longest history.
    preps: Vec<Prepared>,
    /// Per submodel, the sums of each fold block.
    blocks: Vec<Vec<GramStats>>,
    /// Per submodel, the sums over all the data (the blocks added in order).
    totals: Vec<GramStats>,
}

/// A submodel at one history length, with where its terms are in [`NestedSums`].
struct Nested {
    prep: Prepared,
    index: Vec<usize>,
}

impl NestedSums {
    /// Sums of `variant`'s submodels at history `n_max` over the fold blocks of `cv`.
    /// The blocks are summed in parallel, each in two halves, added in a fixed order (same
    /// bits on any number of threads). `tick` is called once per block done.
    pub fn new(
        variant: Variant,
        n_max: usize,
        data: &Dataset,
        cv: &CvConfig,
        vcfg: &VariantConfig,
        tick: &(dyn Fn() + Sync),
    ) -> Self {
        let bounds = fold_bounds(data.len(), cv.folds);
        let preps: Vec<Prepared> = sub_specs(variant, n_max, vcfg)
            .into_iter()
            .map(|s| Prepared::new(s, data))
            .collect();
        let per_block: Vec<Vec<GramStats>> = bounds
            .par_iter()
            .map(|&(a, b)| {
                let sums = preps
                    .iter()
                    .map(|prep| {
                        let mid = a + (b - a) / 2;
                        let (mut first, second) =
                            rayon::join(|| prep.stats(data, a, mid), || prep.stats(data, mid, b));
                        first.accumulate(&second, 1.0);
                        first
                    })
                    .collect();
                tick();
                sums
            })
            .collect();
        let blocks: Vec<Vec<GramStats>> = (0..preps.len())
            .map(|s| per_block.iter().map(|b| b[s].clone()).collect())
            .collect();
        let totals = blocks
            .iter()
            .zip(&preps)
            .map(|(bl, prep)| {
                let mut t = GramStats::zeros(prep.library.len(), prep.spec.target_columns());
                for b in bl {
                    t.accumulate(b, 1.0);
                }
                t
            })
            .collect();
        Self {
            variant,
            preps,
            blocks,
            totals,
        }
    }

    /// The variant's submodels at history `n`.
    fn at(&self, n: usize, vcfg: &VariantConfig) -> Vec<Nested> {
        sub_specs(self.variant, n, vcfg)
            .into_iter()
            .zip(&self.preps)
            .map(|(spec, longest)| {
                let (prep, index) = longest.nested(spec);
                Nested { prep, index }
            })
            .collect()
    }
}

/// Runs the grid for one variant on its sums. `tick` is called once per (n, fold) done.
pub fn cross_validate(
    sums: &NestedSums,
    data: &Dataset,
    cv: &CvConfig,
    vcfg: &VariantConfig,
    tick: &(dyn Fn() + Sync),
) -> CvResult {
    let variant = sums.variant;
    let mus = cv.mus();
    let bounds = fold_bounds(data.len(), cv.folds);
    let ostd = output_std(data);
    let per_n: Vec<Vec<GridPoint>> = cv
        .histories()
        .into_par_iter()
        .map(|n| grid_for_n(sums, n, data, cv, vcfg, &mus, &bounds, &ostd, tick))
        .collect();
    let points: Vec<GridPoint> = per_n.into_iter().flatten().collect();
    // The paper's model is chosen by the paper's rule, the lowest score.
    let tolerance = match variant {
        Variant::Paper => 0.0,
        Variant::SharedEngine => cv.score_tolerance,
    };
    let best = select(&points, tolerance);
    CvResult {
        variant,
        points,
        best,
    }
}

/// The chosen grid point: the lowest score, or with a tolerance the fewest active terms
/// among the points within `tolerance` of the lowest score (ties: the lower score).
pub fn select(points: &[GridPoint], tolerance: f64) -> usize {
    let lowest = (0..points.len())
        .min_by(|&a, &b| points[a].score.total_cmp(&points[b].score))
        .unwrap_or(0);
    if tolerance <= 0.0 {
        return lowest;
    }
    let limit = points[lowest].score * (1.0 + tolerance);
    (0..points.len())
        .filter(|&i| points[i].score <= limit)
        .min_by(|&a, &b| {
            points[a]
                .active_terms
                .total_cmp(&points[b].active_terms)
                .then(points[a].score.total_cmp(&points[b].score))
        })
        .unwrap_or(lowest)
}

#[allow(clippy::too_many_arguments)]
fn grid_for_n(
    sums: &NestedSums,
    n: usize,
    data: &Dataset,
    cv: &CvConfig,
    vcfg: &VariantConfig,
    mus: &[f64],
    bounds: &[(usize, usize)],
    ostd: &[f64; STATE_DIM],
    tick: &(dyn Fn() + Sync),
) -> Vec<GridPoint> {
    let nested = sums.at(n, vcfg);
    let preps: Vec<&Prepared> = nested.iter().map(|s| &s.prep).collect();
    // A training set is the total minus its test block.
    let blocks: Vec<Vec<GramStats>> = nested
        .iter()
        .zip(&sums.blocks)
        .map(|(s, bl)| bl.iter().map(|b| b.select(&s.index)).collect())
        .collect();
    let totals: Vec<GramStats> = nested
        .iter()
        .zip(&sums.totals)
        .map(|(s, t)| t.select(&s.index))
        .collect();
    let m = mus.len();
    let folds = bounds.len() as f64;
    let mut acc = vec![Acc::default(); m];
    for (k, &(a, b)) in bounds.iter().enumerate() {
        let mut fold_fits = Vec::new();
        for (s, prep) in preps.iter().enumerate() {
            let mut train = totals[s].clone();
            train.accumulate(&blocks[s][k], -1.0);
            let path = fit_path(prep, &train, mus, &cv.lasso());
            fold_fits.push((train, path));
        }
        for (i, acc) in acc.iter_mut().enumerate() {
            let mut subs = Vec::new();
            let mut active = 0usize;
            let mut total = 0usize;
            for (s, prep) in preps.iter().enumerate() {
                let (train, path) = &fold_fits[s];
                let coefs = &path.coefs[i];
                acc.unconverged += path.unconverged[i];
                for (c, (w, b0)) in coefs.iter().enumerate() {
                    let tr = (sse(train, c, w, *b0, prep.y_shift[c]) / train.n).sqrt();
                    let test = &blocks[s][k];
                    let te = (sse(test, c, w, *b0, prep.y_shift[c]) / test.n).sqrt();
                    let outs: Vec<usize> =
                        if prep.spec.target_columns() == 1 && prep.spec.evaluations() > 1 {
                            prep.spec.outputs.clone()
                        } else {
                            vec![prep.spec.outputs[c]]
                        };
                    for o in outs {
                        acc.train[o] += tr / folds;
                        acc.test[o] += te / folds;
                    }
                    active += w.iter().filter(|v| **v != 0.0).count();
                    total += w.len();
                }
                subs.push(prep.submodel(coefs));
            }
            acc.sparsity += 100.0 * (1.0 - active as f64 / total.max(1) as f64) / folds;
            acc.active += active as f64 / folds;
            let model = assemble(data, subs);
            let free = free_run_rmse(&model, data, a, b);
            for o in 0..STATE_DIM {
                acc.free[o] += free[o] / folds;
            }
        }
        tick();
    }
    acc.into_iter()
        .zip(mus)
        .map(|(a, &mu)| {
            let score = (0..STATE_DIM).map(|o| a.free[o] / ostd[o]).sum::<f64>() / STATE_DIM as f64;
            GridPoint {
                n,
                mu,
                train_rmse: a.train,
                test_rmse: a.test,
                free_rmse: a.free,
                sparsity_pct: a.sparsity,
                active_terms: a.active,
                score: if score.is_finite() {
                    score
                } else {
                    f64::INFINITY
                },
                unconverged: a.unconverged,
            }
        })
        .collect()
}

#[derive(Debug, Clone, Default)]
struct Acc {
    train: [f64; STATE_DIM],
    test: [f64; STATE_DIM],
    free: [f64; STATE_DIM],
    sparsity: f64,
    active: f64,
    unconverged: usize,
}

/// Free-run RMSE per output over steps `a..b`: the model starts from the true history at
/// `a` and then runs on its own predictions.
pub fn free_run_rmse(
    model: &oils_emulator::propulsion::surrogate::model::Model,
    data: &Dataset,
    a: usize,
    b: usize,
) -> [f64; STATE_DIM] {
    let mut pred = Predictor::new(model);
    pred.seed_history(&data.history_at(a));
    let mut se = [0.0; STATE_DIM];
    for t in a..b {
        let y = pred.step(&data.inputs[t]);
        for o in 0..STATE_DIM {
            se[o] += (y[o] - data.states[t][o]).powi(2);
        }
    }
    se.map(|s| (s / (b - a).max(1) as f64).sqrt())
}

/// Fits the chosen (n, mu) on all the data.
pub fn fit_final(
    sums: &NestedSums,
    n: usize,
    mu: f64,
    data: &Dataset,
    cv: &CvConfig,
    vcfg: &VariantConfig,
) -> oils_emulator::propulsion::surrogate::model::Model {
    // Walk the grid's path down to mu for the warm start, then mu itself.
    let mut mus: Vec<f64> = cv.mus().into_iter().filter(|m| *m > mu).collect();
    mus.push(mu);
    let subs = sums
        .at(n, vcfg)
        .into_iter()
        .zip(&sums.totals)
        .map(|(s, total)| {
            let path = fit_path(&s.prep, &total.select(&s.index), &mus, &cv.lasso());
            s.prep
                .submodel(path.coefs.last().map_or(&[][..], |c| &c[..]))
        })
        .collect();
    assemble(data, subs)
}

/// Wall-clock time of the final fit's two parts for one variant at (n, mu): building the
/// Gram sums from the data, and the Lasso from zero at `mu` alone (the problem
/// scikit-learn's `Lasso(alpha=mu, precompute=True).fit` solves). For the timing report
/// only; nothing in a model reads the clock.
pub fn time_final_fit(
    variant: Variant,
    n: usize,
    mu: f64,
    data: &Dataset,
    cv: &CvConfig,
    vcfg: &VariantConfig,
) -> (f64, f64) {
    let mut gram_s = 0.0;
    let mut fit_s = 0.0;
    for spec in sub_specs(variant, n, vcfg) {
        let t0 = std::time::Instant::now();
        let prep = Prepared::new(spec, data);
        let stats = prep.stats(data, 0, data.len());
        gram_s += t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        let path = fit_path(&prep, &stats, &[mu], &cv.lasso());
        fit_s += t1.elapsed().as_secs_f64();
        std::hint::black_box(path);
    }
    (gram_s, fit_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(score: f64, active_terms: f64) -> GridPoint {
        GridPoint {
            n: 1,
            mu: 1.0,
            train_rmse: [0.0; STATE_DIM],
            test_rmse: [0.0; STATE_DIM],
            free_rmse: [0.0; STATE_DIM],
            sparsity_pct: 0.0,
            active_terms,
            score,
            unconverged: 0,
        }
    }

    /// A short recording of the `ideal` model with the valve filter tracked.
    fn short_dataset() -> (Dataset, VariantConfig) {
        use crate::training::excitation::ExcitationConfig;
        use oils_emulator::config::PropulsionConfig;
        use oils_emulator::propulsion::ideal::IdealPropulsion;
        use oils_emulator::propulsion::surrogate::valve::TEST_VALVE;
        let ex = ExcitationConfig {
            levels: 1,
            sphere_duration_s: 1.0,
            steps: 1,
            ramps: 1,
            switches: 2,
            ..Default::default()
        }
        .generate(10_000_000);
        let mut m = IdealPropulsion::new(&PropulsionConfig::default());
        let data = Dataset::record(&mut m, &ex, || {}).with_valves(Some(TEST_VALVE));
        let vcfg = VariantConfig {
            paper_degree: 2,
            engine_stop_steps: 3,
            engine_phase_degree: 3,
            engine_command_sum: true,
            engine_valve: Some(TEST_VALVE),
            engine_valve_sum: true,
            ..VariantConfig::default()
        };
        (data, vcfg)
    }

    #[test]
    fn a_shorter_history_is_a_selection_of_the_longest() {
        let (data, vcfg) = short_dataset();
        for variant in [Variant::Paper, Variant::SharedEngine] {
            for (s, spec) in sub_specs(variant, 4, &vcfg).into_iter().enumerate() {
                let longest = Prepared::new(spec, &data);
                let sums = longest.stats(&data, 0, data.len());
                for n in 1..=4 {
                    let spec = sub_specs(variant, n, &vcfg).swap_remove(s);
                    let direct = Prepared::new(spec.clone(), &data);
                    let (nested, index) = longest.nested(spec);
                    assert_eq!(nested.library, direct.library);
                    assert_eq!(
                        (
                            &nested.mean,
                            &nested.std,
                            &nested.lo,
                            &nested.hi,
                            &nested.y_shift
                        ),
                        (
                            &direct.mean,
                            &direct.std,
                            &direct.lo,
                            &direct.hi,
                            &direct.y_shift
                        ),
                        "{variant:?} submodel {s} n = {n}: scaling"
                    );
                    let want = direct.stats(&data, 0, data.len());
                    let got = sums.select(&index);
                    let scale = want.xtx.iter().fold(1.0f64, |m, v| m.max(v.abs()));
                    for (a, b) in got
                        .xtx
                        .iter()
                        .zip(&want.xtx)
                        .chain(got.xty.iter().zip(&want.xty))
                        .chain(got.sum_x.iter().zip(&want.sum_x))
                        .chain(got.sum_y.iter().zip(&want.sum_y))
                        .chain(got.yty.iter().zip(&want.yty))
                    {
                        assert!(
                            (a - b).abs() <= 1e-12 * scale,
                            "{variant:?} n = {n}: {a} vs {b}"
                        );
                    }
                    assert_eq!(got.n, want.n);
                }
            }
        }
    }

    #[test]
    fn a_penalty_at_either_end_of_the_grid_is_told() {
        let at = |mu: f64| GridPoint {
            mu,
            ..point(1.0, 1.0)
        };
        let result = |best: usize| CvResult {
            variant: Variant::Paper,
            points: vec![at(1.0), at(1e-3), at(1e-6), at(1.0), at(1e-3), at(1e-6)],
            best,
        };
        assert!(result(0).mu_at_grid_end() && result(3).mu_at_grid_end());
        assert!(result(2).mu_at_grid_end() && result(5).mu_at_grid_end());
        assert!(!result(1).mu_at_grid_end() && !result(4).mu_at_grid_end());
    }

    #[test]
    fn selection_is_lowest_score_or_fewest_terms_within_tolerance() {
        let pts = [point(1.00, 300.0), point(1.04, 100.0), point(1.01, 200.0)];
        assert_eq!(select(&pts, 0.0), 0);
        assert_eq!(select(&pts, 0.02), 2);
        assert_eq!(select(&pts, 0.05), 1);
    }
}
