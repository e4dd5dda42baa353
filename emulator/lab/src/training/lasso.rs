//! Lasso on a precomputed Gram matrix by an active-set method with exact solves, with
//! scikit-learn's duality gap as the stopping test, and a warm-started path over the
//! penalty.
//!
//! Written by hand: no pure-Rust crate offers Gram-based Lasso with warm starts and
//! scikit-learn's duality gap (linfa-elasticnet works on the design matrix and pulls in
//! ndarray/BLAS plumbing). It solves scikit-learn's problem, which the test
//! `lasso_matches_sklearn` checks on a committed fixture.
//!
//! Why not coordinate descent (scikit-learn's solver, and this module's until issue #23):
//! on the surrogate's polynomial terms, strongly correlated (a command, its valve-filtered
//! value and their histories), cyclic coordinate descent creeps, and at small penalties
//! 20 000 sweeps stopped far from the optimum. The active-set method
//! (Osborne, Presnell and Turlach 2000; the "feature-sign search" of Lee et al. 2007)
//! holds the signs of the active coefficients, minimises the then quadratic objective on
//! them exactly through a Cholesky factor kept up to date as terms join and leave
//! ([`super::cholesky`]), steps towards that minimiser until a coefficient reaches zero,
//! and admits the terms that break the optimality conditions; it ends at the conditions,
//! up to rounding, in a number of solves of the order of the active terms.
//!
//! Scaling, stated once. scikit-learn minimises `(1/(2N)) ||y - Xw - b||^2 + alpha ||w||_1`.
//! [`lasso_gram`] solves exactly that problem (`alpha` is scikit-learn's), given the Gram
//! matrix of the centred design. The training pipeline calls it on standardised terms and
//! standardised outputs and names the penalty `mu`: `mu` is scikit-learn's `alpha` on the
//! standardised problem, and the paper's `(1/2) sum(...) + mu_paper ||K||_1` has
//! `mu_paper = N * mu` (N training rows).

use super::cholesky::ActiveCholesky;
use nalgebra::{Dyn, MatrixView, MatrixViewMut};

/// A view of a slice with any strides.
type Strided<'a> = MatrixView<'a, f64, Dyn, Dyn, Dyn, Dyn>;
/// A mutable view of a slice with any strides.
type StridedMut<'a> = MatrixViewMut<'a, f64, Dyn, Dyn, Dyn, Dyn>;

/// Columns `j0..j0 + w` of the first `r` rows of a row-major matrix with row stride
/// `stride`, as an r x w view.
fn cols(x: &[f64], j0: usize, w: usize, r: usize, stride: usize) -> Strided<'_> {
    Strided::from_slice_with_strides(&x[j0..], r, w, stride, 1)
}

/// The transpose of [`cols`], a w x r view.
fn cols_t(x: &[f64], j0: usize, w: usize, r: usize, stride: usize) -> Strided<'_> {
    Strided::from_slice_with_strides(&x[j0..], w, r, 1, stride)
}

/// Stopping and iteration limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LassoSettings {
    /// A fit has converged when its duality gap is below `tol * ||y_centred||^2`
    /// (scikit-learn's rule and default).
    pub tol: f64,
    /// Active-set iterations at most (each one solve on the active set).
    pub max_iter: usize,
}

impl Default for LassoSettings {
    fn default() -> Self {
        Self {
            tol: 1e-4,
            max_iter: 10_000,
        }
    }
}

/// How a fit ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LassoReport {
    /// Active-set iterations done.
    pub iterations: usize,
    /// Final duality gap (same scaling as scikit-learn's `dual_gap_ * N`).
    pub gap: f64,
    /// The gap fell below the tolerance.
    pub converged: bool,
    /// Largest violation of the optimality conditions, relative to the penalty:
    /// `max_j |x_j'(y - Xw)| / (alpha N) - 1` over inactive terms, 0 when none.
    pub kkt_violation: f64,
}

/// A Lasso problem in Gram form, unnormalised like scikit-learn's `cd_fast`:
/// `q = Xc' X c` (p x p, row-major), `xty = Xc' yc`, `yty = yc' yc`, `n_samples = N`.
#[derive(Debug, Clone, Copy)]
pub struct GramProblem<'a> {
    /// Centred Gram matrix, p x p row-major.
    pub gram: &'a [f64],
    /// Centred design times centred target, p.
    pub xty: &'a [f64],
    /// Squared norm of the centred target.
    pub yty: f64,
    /// Number of rows N.
    pub n_samples: f64,
}

/// Position of a term outside the active set.
const INACTIVE: usize = usize::MAX;
/// A term joins only if its column has at least this share of its squared norm outside
/// the span of the active columns; below it, it swaps with an active term instead.
const MIN_PIVOT: f64 = 1e-12;
/// Terms admitted at most per iteration (the batch doubles from 1 while admissions
/// succeed and falls back to 1 when one of them would leave zero the wrong way).
const MAX_BATCH: usize = 64;
/// Relative slack on the optimality conditions: rounding, not a violation.
const KKT_SLACK: f64 = 1e-9;

/// The active-set solver's factor and scratch, sized once for `p` terms; reused from fit
/// to fit.
#[derive(Debug, Clone)]
pub struct LassoWorkspace {
    p: usize,
    chol: ActiveCholesky,
    /// Active terms in the factor's order.
    active: Vec<usize>,
    /// The sign each active coefficient is held to.
    sign: Vec<f64>,
    /// Active terms admitted at zero since the last optimal point.
    fresh: Vec<bool>,
    /// Each term's position in `active`, or `INACTIVE`.
    pos: Vec<usize>,
    /// Terms refused for the rest of a fit.
    blocked: Vec<bool>,
    /// `Q w`.
    qw: Vec<f64>,
    z: Vec<f64>,
    cross: Vec<f64>,
    violators: Vec<(f64, usize)>,
}

impl LassoWorkspace {
    /// A workspace for problems of `p` terms.
    pub fn new(p: usize) -> Self {
        Self {
            p,
            chol: ActiveCholesky::new(p),
            active: Vec::with_capacity(p),
            sign: Vec::with_capacity(p),
            fresh: Vec::with_capacity(p),
            pos: vec![INACTIVE; p],
            blocked: vec![false; p],
            qw: vec![0.0; p],
            z: vec![0.0; p],
            cross: vec![0.0; p],
            violators: Vec::with_capacity(p),
        }
    }

    fn reset(&mut self) {
        self.chol.clear();
        self.active.clear();
        self.sign.clear();
        self.fresh.clear();
        self.pos.fill(INACTIVE);
        self.blocked.fill(false);
    }

    /// Admits term `j` with sign `s`; on refusal (its column in the active columns'
    /// span) `cross` holds `L^-1 Q_Aj`.
    fn join(&mut self, q: &[f64], j: usize, s: f64, fresh: bool) -> bool {
        let p = self.p;
        let m = self.active.len();
        for (c, &a) in self.cross[..m].iter_mut().zip(&self.active) {
            *c = q[j * p + a];
        }
        if self
            .chol
            .push(&mut self.cross[..m], q[j * p + j], MIN_PIVOT)
            .is_err()
        {
            return false;
        }
        self.pos[j] = m;
        self.active.push(j);
        self.sign.push(s);
        self.fresh.push(fresh);
        true
    }

    /// Removes the active term at position `k`.
    fn leave(&mut self, k: usize) {
        self.chol.remove(k);
        self.pos[self.active[k]] = INACTIVE;
        self.active.remove(k);
        self.sign.remove(k);
        self.fresh.remove(k);
        for (i, &a) in self.active.iter().enumerate().skip(k) {
            self.pos[a] = i;
        }
    }

    /// `qw = Q w` over the active terms (w is zero elsewhere).
    fn update_qw(&mut self, q: &[f64], w: &[f64]) {
        let p = self.p;
        self.qw.fill(0.0);
        for &a in &self.active {
            axpy(w[a], &q[a * p..(a + 1) * p], &mut self.qw);
        }
    }
}

/// Solves the Lasso at penalty `alpha` (scikit-learn's scaling), starting from `w`
/// (warm start: its support is the first active set) and leaving the solution there.
pub fn lasso_gram(
    prob: &GramProblem,
    alpha: f64,
    settings: &LassoSettings,
    w: &mut [f64],
    ws: &mut LassoWorkspace,
) -> LassoReport {
    let p = prob.xty.len();
    assert_eq!(ws.p, p, "workspace sized for another problem");
    let q = prob.gram;
    let l1 = alpha * prob.n_samples;
    let xty_max = prob.xty.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // Above this a term breaks the optimality conditions.
    let bound = l1 * (1.0 + KKT_SLACK) + 1e-14 * xty_max;
    ws.reset();
    for j in 0..p {
        if w[j] != 0.0 && !(q[j * p + j] > 0.0 && ws.join(q, j, w[j].signum(), false)) {
            w[j] = 0.0;
        }
    }
    let mut batch = 1;
    let mut iterations = 0;
    while iterations < settings.max_iter {
        iterations += 1;
        let m = ws.active.len();
        // The minimiser of the objective with the active signs held: Q_AA z = X_A'y - l1 s.
        for k in 0..m {
            ws.z[k] = prob.xty[ws.active[k]] - l1 * ws.sign[k];
        }
        ws.chol.solve(&mut ws.z[..m]);
        // A term admitted at zero whose minimiser has the other sign gains nothing: out
        // again (alone, it is refused for this fit: in exact arithmetic it cannot happen).
        let fresh = ws.fresh.iter().filter(|f| **f).count();
        let mut refused = false;
        for k in (0..m).rev() {
            if ws.fresh[k] && ws.z[k] * ws.sign[k] <= 0.0 {
                if fresh == 1 {
                    ws.blocked[ws.active[k]] = true;
                }
                ws.leave(k);
                refused = true;
            }
        }
        if refused {
            batch = 1;
            continue;
        }
        // Step towards z until the first coefficient reaches zero.
        let mut t = 1.0;
        let mut first = None;
        for k in 0..m {
            let (wk, zk) = (w[ws.active[k]], ws.z[k]);
            if zk * ws.sign[k] <= 0.0 {
                let tk = wk / (wk - zk);
                if tk < t {
                    t = tk;
                    first = Some(k);
                }
            }
        }
        if let Some(first) = first {
            for k in 0..m {
                let a = ws.active[k];
                w[a] += t * (ws.z[k] - w[a]);
                ws.fresh[k] = false;
            }
            w[ws.active[first]] = 0.0;
            for k in (0..m).rev() {
                let a = ws.active[k];
                if w[a] * ws.sign[k] <= 0.0 {
                    w[a] = 0.0;
                    ws.leave(k);
                }
            }
            continue;
        }
        for k in 0..m {
            w[ws.active[k]] = ws.z[k];
            ws.fresh[k] = false;
        }
        // Optimal on the active set; every other term must satisfy |x_j'r| <= l1.
        ws.update_qw(q, w);
        ws.violators.clear();
        for j in 0..p {
            if ws.pos[j] == INACTIVE && !ws.blocked[j] && q[j * p + j] > 0.0 {
                let g = prob.xty[j] - ws.qw[j];
                if g.abs() > bound {
                    ws.violators.push((g.abs(), j));
                }
            }
        }
        if ws.violators.is_empty() {
            break;
        }
        let mut violators = std::mem::take(&mut ws.violators);
        violators.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut admitted = 0;
        for &(_, j) in violators.iter().take(batch) {
            let s = (prob.xty[j] - ws.qw[j]).signum();
            if ws.join(q, j, s, true) {
                admitted += 1;
            } else if admitted == 0 {
                // Its column lies in the active columns' span: swap it in for one of them.
                swap_in(prob, l1, j, s, w, ws);
                break;
            }
        }
        ws.violators = violators;
        batch = (batch * 2).min(MAX_BATCH);
    }
    ws.update_qw(q, w);
    let mut worst = 0.0f64;
    for j in 0..p {
        if ws.pos[j] == INACTIVE && q[j * p + j] > 0.0 && l1 > 0.0 {
            worst = worst.max((prob.xty[j] - ws.qw[j]).abs() / l1 - 1.0);
        }
    }
    let gap = duality_gap(prob, l1, w, &ws.qw);
    LassoReport {
        iterations,
        gap,
        // `<=`: a constant output has yty = 0 and a zero gap at w = 0.
        converged: gap <= settings.tol * prob.yty,
        kkt_violation: worst,
    }
}

/// Term `j` breaks the optimality conditions at an optimal point of the active set but
/// its column is a combination `X_A c` of the active ones (`ws.cross` holds `L^-1 Q_Aj`).
/// Moving `w_j` up by `tau s` and `w_A` down by `tau s c` keeps the fit and lowers the
/// penalty at the rate `|x_j'r| / l1 - 1`, until an active coefficient reaches zero; that
/// term leaves and `j` joins. Refused for this fit when nothing lowers the objective.
fn swap_in(prob: &GramProblem, l1: f64, j: usize, s: f64, w: &mut [f64], ws: &mut LassoWorkspace) {
    let m = ws.active.len();
    ws.chol.backward(&mut ws.cross[..m]);
    let mut tau = f64::INFINITY;
    let mut out = None;
    for k in 0..m {
        let d = -s * ws.cross[k];
        let wk = w[ws.active[k]];
        if d * wk < 0.0 {
            let tk = -wk / d;
            if tk < tau {
                tau = tk;
                out = Some(k);
            }
        }
    }
    let rate: f64 = 1.0 - s * (0..m).map(|k| ws.sign[k] * ws.cross[k]).sum::<f64>();
    let Some(out) = out.filter(|_| rate < 0.0 && l1 > 0.0) else {
        ws.blocked[j] = true;
        return;
    };
    for k in 0..m {
        w[ws.active[k]] -= tau * s * ws.cross[k];
    }
    w[ws.active[out]] = 0.0;
    ws.leave(out);
    if ws.join(prob.gram, j, s, false) {
        w[j] = tau * s;
    } else {
        ws.blocked[j] = true;
    }
}

/// scikit-learn's duality gap for the Lasso in Gram form (`enet_coordinate_descent_gram`
/// with `beta = 0`), with `h = Q w` and `l1 = alpha N`.
fn duality_gap(prob: &GramProblem, l1: f64, w: &[f64], h: &[f64]) -> f64 {
    let mut dual_norm = 0.0f64;
    for (xty, h) in prob.xty.iter().zip(h) {
        dual_norm = dual_norm.max((xty - h).abs());
    }
    let q_dot_w = dot(prob.xty, w);
    let r_norm2 = (prob.yty + dot(w, h) - 2.0 * q_dot_w).max(0.0);
    let (scale, mut gap) = if dual_norm > l1 {
        let c = l1 / dual_norm;
        (c, 0.5 * r_norm2 * (1.0 + c * c))
    } else {
        (1.0, r_norm2)
    };
    let w_l1: f64 = w.iter().map(|x| x.abs()).sum();
    gap += l1 * w_l1 - scale * prob.yty + scale * q_dot_w;
    gap
}

#[inline]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    // Four accumulators so the compiler can vectorise; the order is fixed, so the result
    // is the same on every run.
    let mut acc = [0.0f64; 4];
    let chunks = a.len() / 4;
    for c in 0..chunks {
        for k in 0..4 {
            acc[k] += a[4 * c + k] * b[4 * c + k];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for i in 4 * chunks..a.len() {
        s += a[i] * b[i];
    }
    s
}

#[inline]
fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += alpha * x;
    }
}

/// Sums over rows that make the Gram matrix: kept uncentred about a fixed `shift` (the
/// global mean), so blocks add and subtract exactly-enough and the centring done later
/// loses no digits to cancellation.
#[derive(Debug, Clone, PartialEq)]
pub struct GramStats {
    /// Terms p.
    pub p: usize,
    /// Outputs.
    pub outputs: usize,
    /// Rows.
    pub n: f64,
    /// Sum of shifted terms, p.
    pub sum_x: Vec<f64>,
    /// Sum of shifted outputs.
    pub sum_y: Vec<f64>,
    /// Sum of x x', p x p.
    pub xtx: Vec<f64>,
    /// Sum of x y', p x outputs.
    pub xty: Vec<f64>,
    /// Sum of y^2 per output.
    pub yty: Vec<f64>,
}

impl GramStats {
    /// Empty sums.
    pub fn zeros(p: usize, outputs: usize) -> Self {
        Self {
            p,
            outputs,
            n: 0.0,
            sum_x: vec![0.0; p],
            sum_y: vec![0.0; outputs],
            xtx: vec![0.0; p * p],
            xty: vec![0.0; p * outputs],
            yty: vec![0.0; outputs],
        }
    }

    /// Sums of a block of rows: `x` is rows x p and `y` rows x outputs, both row-major and
    /// already shifted.
    pub fn from_block(x: &[f64], y: &[f64], p: usize, outputs: usize) -> Self {
        Self::from_block_split(x, y, p, outputs, p)
    }

    /// [`GramStats::from_block`] for a design whose columns from `dense` on are zero in
    /// most rows (see [`GramStats::add_rows`]).
    pub fn from_block_split(x: &[f64], y: &[f64], p: usize, outputs: usize, dense: usize) -> Self {
        let mut s = Self::zeros(p, outputs);
        s.add_rows(x, y, dense);
        s.mirror();
        s
    }

    /// Adds a block of rows (`x` rows x p, `y` rows x outputs, row-major, shifted) to the
    /// sums, but only to one triangle of `xtx`: call [`GramStats::mirror`] once all rows
    /// are in. The columns from `dense` on are zero in most rows (the terms of the phase
    /// and ignition features, zero outside a start or a stop): their products are taken
    /// over the rows where one of them is not, the rest over every row, in panels.
    pub fn add_rows(&mut self, x: &[f64], y: &[f64], dense: usize) {
        /// Panel width of the dense product.
        const PANEL: usize = 256;
        let (p, outputs) = (self.p, self.outputs);
        let rows = x.len() / p.max(1);
        assert!(dense <= p && x.len() == rows * p && y.len() == rows * outputs);
        self.n += rows as f64;
        if rows == 0 || p == 0 {
            return;
        }
        // Column-major views of the row-major buffers: `xtx` as such is its transpose,
        // which does not matter once mirrored.
        let mut xtx = StridedMut::from_slice_with_strides_mut(&mut self.xtx, p, p, 1, p);
        let mut xty =
            StridedMut::from_slice_with_strides_mut(&mut self.xty, p, outputs, outputs, 1);
        for i0 in (0..dense).step_by(PANEL) {
            let bi = PANEL.min(dense - i0);
            let a = cols_t(x, i0, bi, rows, p);
            for j0 in (i0..dense).step_by(PANEL) {
                let bj = PANEL.min(dense - j0);
                xtx.view_mut((i0, j0), (bi, bj))
                    .gemm(1.0, &a, &cols(x, j0, bj, rows, p), 1.0);
            }
            xty.view_mut((i0, 0), (bi, outputs)).gemm(
                1.0,
                &a,
                &cols(y, 0, outputs, rows, outputs),
                1.0,
            );
        }
        for r in 0..rows {
            for (a, v) in self.sum_x[..dense].iter_mut().zip(&x[r * p..r * p + dense]) {
                *a += v;
            }
            for o in 0..outputs {
                let v = y[r * outputs + o];
                self.sum_y[o] += v;
                self.yty[o] += v * v;
            }
        }
        if dense == p {
            return;
        }
        // The rows where a sparse column is not zero, gathered.
        let mut xs = Vec::new();
        let mut ys = Vec::new();
        for r in 0..rows {
            let row = &x[r * p..(r + 1) * p];
            if row[dense..].iter().any(|v| *v != 0.0) {
                xs.extend_from_slice(row);
                ys.extend_from_slice(&y[r * outputs..(r + 1) * outputs]);
            }
        }
        let k = xs.len() / p;
        if k == 0 {
            return;
        }
        let w = p - dense;
        xtx.view_mut((0, dense), (p, w)).gemm(
            1.0,
            &cols_t(&xs, 0, p, k, p),
            &cols(&xs, dense, w, k, p),
            1.0,
        );
        xty.view_mut((dense, 0), (w, outputs)).gemm(
            1.0,
            &cols_t(&xs, dense, w, k, p),
            &cols(&ys, 0, outputs, k, outputs),
            1.0,
        );
        for r in 0..k {
            for (a, v) in self.sum_x[dense..]
                .iter_mut()
                .zip(&xs[r * p + dense..(r + 1) * p])
            {
                *a += v;
            }
        }
    }

    /// Completes `xtx` from the triangle [`GramStats::add_rows`] fills.
    pub fn mirror(&mut self) {
        let p = self.p;
        // Row-major, the filled triangle is the lower one (j <= i).
        for i in 0..p {
            for j in i + 1..p {
                self.xtx[i * p + j] = self.xtx[j * p + i];
            }
        }
    }

    /// The sums of the terms at `index` (in that order): the sums of a library that is a
    /// subset of this one.
    pub fn select(&self, index: &[usize]) -> Self {
        let (p, o) = (self.p, self.outputs);
        let q = index.len();
        let mut xtx = vec![0.0; q * q];
        for (a, &i) in index.iter().enumerate() {
            for (b, &j) in index.iter().enumerate() {
                xtx[a * q + b] = self.xtx[i * p + j];
            }
        }
        Self {
            p: q,
            outputs: o,
            n: self.n,
            sum_x: index.iter().map(|&i| self.sum_x[i]).collect(),
            sum_y: self.sum_y.clone(),
            xtx,
            xty: index
                .iter()
                .flat_map(|&i| self.xty[i * o..(i + 1) * o].iter().copied())
                .collect(),
            yty: self.yty.clone(),
        }
    }

    /// Adds (`sign` = 1) or removes (`sign` = -1) another block's sums.
    pub fn accumulate(&mut self, other: &Self, sign: f64) {
        self.n += sign * other.n;
        let add = |a: &mut [f64], b: &[f64]| {
            for (a, b) in a.iter_mut().zip(b) {
                *a += sign * b;
            }
        };
        add(&mut self.sum_x, &other.sum_x);
        add(&mut self.sum_y, &other.sum_y);
        add(&mut self.xtx, &other.xtx);
        add(&mut self.xty, &other.xty);
        add(&mut self.yty, &other.yty);
    }

    /// The centred problem: (Gram, X'y per output column-major-by-output, y'y per output,
    /// mean of shifted x, mean of shifted y).
    pub fn centred(&self) -> Centred {
        let p = self.p;
        let n = self.n;
        let mx: Vec<f64> = self.sum_x.iter().map(|s| s / n).collect();
        let my: Vec<f64> = self.sum_y.iter().map(|s| s / n).collect();
        let mut gram = self.xtx.clone();
        for i in 0..p {
            for j in 0..p {
                gram[i * p + j] -= n * mx[i] * mx[j];
            }
        }
        let mut xty = vec![0.0; p * self.outputs];
        for o in 0..self.outputs {
            for i in 0..p {
                xty[o * p + i] = self.xty[i * self.outputs + o] - n * mx[i] * my[o];
            }
        }
        let yty = (0..self.outputs)
            .map(|o| (self.yty[o] - n * my[o] * my[o]).max(0.0))
            .collect();
        Centred {
            p,
            n,
            gram,
            xty,
            yty,
            mean_x: mx,
            mean_y: my,
        }
    }
}

/// A centred least-squares problem for several outputs sharing one design.
#[derive(Debug, Clone, PartialEq)]
pub struct Centred {
    /// Terms.
    pub p: usize,
    /// Rows.
    pub n: f64,
    /// Xc' Xc, p x p.
    pub gram: Vec<f64>,
    /// Xc' yc, output-major: `xty[o * p + i]`.
    pub xty: Vec<f64>,
    /// yc' yc per output.
    pub yty: Vec<f64>,
    /// Column means of x (in the shifted coordinates the sums were taken in).
    pub mean_x: Vec<f64>,
    /// Means of y (shifted).
    pub mean_y: Vec<f64>,
}

/// The standardised problem the penalty `mu` is defined on: every term and every output
/// scaled to unit variance over the training rows, so one `mu` means the same for every
/// term and output.
#[derive(Debug, Clone)]
pub struct Standardised {
    /// The centred problem it came from.
    pub centred: Centred,
    /// Standard deviation of each term (0: constant term, never selected).
    pub x_std: Vec<f64>,
    /// Standard deviation of each output (1 for a constant output).
    pub y_std: Vec<f64>,
    gram: Vec<f64>,
    xty: Vec<f64>,
}

impl Standardised {
    /// Scales a centred problem.
    pub fn new(centred: Centred) -> Self {
        let p = centred.p;
        let n = centred.n;
        let x_std: Vec<f64> = (0..p)
            .map(|j| {
                let v = centred.gram[j * p + j] / n;
                if v > 1e-24 {
                    v.sqrt()
                } else {
                    0.0
                }
            })
            .collect();
        let y_std: Vec<f64> = centred
            .yty
            .iter()
            // A constant output keeps scale 1: its problem is all zeros and converges at once.
            .map(|v| if *v > 0.0 { (v / n).sqrt() } else { 1.0 })
            .collect();
        let inv = |s: f64| if s > 0.0 { 1.0 / s } else { 0.0 };
        let mut gram = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                gram[i * p + j] = centred.gram[i * p + j] * inv(x_std[i]) * inv(x_std[j]);
            }
        }
        let outputs = centred.yty.len();
        let mut xty = vec![0.0; p * outputs];
        for o in 0..outputs {
            for i in 0..p {
                xty[o * p + i] = centred.xty[o * p + i] * inv(x_std[i]) / y_std[o];
            }
        }
        Self {
            centred,
            x_std,
            y_std,
            gram,
            xty,
        }
    }

    /// Number of outputs.
    pub fn outputs(&self) -> usize {
        self.y_std.len()
    }

    /// The Gram problem of one output.
    pub fn problem(&self, output: usize) -> GramProblem<'_> {
        let p = self.centred.p;
        let n = self.centred.n;
        let yty = self.centred.yty[output] / (self.y_std[output] * self.y_std[output]);
        GramProblem {
            gram: &self.gram,
            xty: &self.xty[output * p..(output + 1) * p],
            yty,
            n_samples: n,
        }
    }

    /// Coefficients on the unscaled (shifted) terms and the intercept, from standardised
    /// coefficients `w_std` of `output`. `shift_x`/`shift_y` undo the shift the sums were
    /// taken in.
    pub fn unscale(
        &self,
        output: usize,
        w_std: &[f64],
        shift_x: &[f64],
        shift_y: f64,
    ) -> (Vec<f64>, f64) {
        let ys = self.y_std[output];
        let w: Vec<f64> = w_std
            .iter()
            .zip(&self.x_std)
            .map(|(w, s)| if *s > 0.0 { w * ys / s } else { 0.0 })
            .collect();
        // y = mean_y + sum w (x - mean_x), in shifted coordinates; back to raw terms.
        let mut b = self.centred.mean_y[output] + shift_y;
        for j in 0..w.len() {
            b -= w[j] * (self.centred.mean_x[j] + shift_x[j]);
        }
        (w, b)
    }
}

/// Log-spaced penalties from `hi` down to `lo` (the order a warm-started path runs).
pub fn mu_grid(lo: f64, hi: f64, count: usize) -> Vec<f64> {
    if count <= 1 {
        return vec![hi];
    }
    let (a, b) = (hi.log10(), lo.log10());
    (0..count)
        .map(|i| 10f64.powf(a + (b - a) * i as f64 / (count - 1) as f64))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a small problem with a known sparse answer.
    fn toy() -> (Vec<f64>, Vec<f64>, usize) {
        let p = 3;
        let mut x = Vec::new();
        let mut y = Vec::new();
        for i in 0..50 {
            let t = i as f64;
            let row = [t.sin(), (0.7 * t).cos(), (1.3 * t).sin() * 0.5];
            y.push(2.0 * row[0] - 1.0 * row[2] + 3.0);
            x.extend_from_slice(&row);
        }
        (x, y, p)
    }

    #[test]
    fn tiny_penalty_recovers_least_squares() {
        let (x, y, p) = toy();
        let stats = GramStats::from_block(&x, &y, p, 1);
        let c = stats.centred();
        let prob = GramProblem {
            gram: &c.gram,
            xty: &c.xty,
            yty: c.yty[0],
            n_samples: c.n,
        };
        let mut w = vec![0.0; p];
        let mut ws = LassoWorkspace::new(p);
        let settings = LassoSettings {
            tol: 1e-14,
            max_iter: 100_000,
        };
        let r = lasso_gram(&prob, 1e-12, &settings, &mut w, &mut ws);
        assert!(r.converged);
        assert!((w[0] - 2.0).abs() < 1e-8 && w[1].abs() < 1e-8 && (w[2] + 1.0).abs() < 1e-8);
    }

    #[test]
    fn large_penalty_gives_zero_and_gap_is_tiny_at_optimum() {
        let (x, y, p) = toy();
        let c = GramStats::from_block(&x, &y, p, 1).centred();
        let prob = GramProblem {
            gram: &c.gram,
            xty: &c.xty,
            yty: c.yty[0],
            n_samples: c.n,
        };
        // alpha_max = max |X'y| / N: at or above it every coefficient is zero.
        let alpha_max = c.xty.iter().fold(0.0f64, |m, v| m.max(v.abs())) / c.n;
        let mut w = vec![0.5; p];
        let mut ws = LassoWorkspace::new(p);
        lasso_gram(
            &prob,
            alpha_max * 1.001,
            &LassoSettings::default(),
            &mut w,
            &mut ws,
        );
        assert_eq!(w, vec![0.0; p]);
        let mut w = vec![0.0; p];
        lasso_gram(
            &prob,
            alpha_max * 0.5,
            &LassoSettings::default(),
            &mut w,
            &mut ws,
        );
        assert!(w.iter().any(|v| *v != 0.0));
    }

    /// A problem like the surrogate's: every product up to degree 2 of the last few
    /// samples of a slowly varying signal (strongly correlated terms), standardised; the
    /// target the signal's next increment.
    fn lagged_products() -> Standardised {
        let lags = 6;
        let rows = 4000;
        let mut state = 7u64;
        let mut draw = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (mut level, mut s) = (0.0, 0.0);
        let mut signal = Vec::new();
        for t in 0..rows + lags + 1 {
            if t % 40 == 0 {
                level = draw();
            }
            s += 0.1 * (level - s) + 0.05 * s * s;
            signal.push(s + 1e-3 * draw());
        }
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for t in lags..lags + rows {
            let f: Vec<f64> = (0..=lags).map(|k| signal[t - k]).collect();
            x.extend_from_slice(&f);
            for i in 0..f.len() {
                for j in i..f.len() {
                    x.push(f[i] * f[j]);
                }
            }
            y.push(signal[t + 1] - signal[t]);
        }
        let p = x.len() / rows;
        Standardised::new(GramStats::from_block(&x, &y, p, 1).centred())
    }

    /// Cyclic coordinate descent on the Gram form (scikit-learn's `cd_fast`, this
    /// module's solver before issue #23), for comparison.
    fn coordinate_descent(prob: &GramProblem, l1: f64, sweeps: usize, w: &mut [f64]) {
        let p = w.len();
        let q = prob.gram;
        let mut h: Vec<f64> = (0..p).map(|i| dot(&q[i * p..(i + 1) * p], w)).collect();
        for _ in 0..sweeps {
            for j in 0..p {
                let qjj = q[j * p + j];
                if qjj <= 0.0 {
                    continue;
                }
                let rho = prob.xty[j] - h[j] + qjj * w[j];
                let new = rho.signum() * (rho.abs() - l1).max(0.0) / qjj;
                axpy(new - w[j], &q[j * p..(j + 1) * p], &mut h);
                w[j] = new;
            }
        }
    }

    /// `(1/2) w'Qw - w'X'y + l1 |w|_1`: the objective up to a constant, times N.
    fn objective(prob: &GramProblem, l1: f64, w: &[f64]) -> f64 {
        let p = w.len();
        let quad: f64 = (0..p)
            .map(|i| w[i] * dot(&prob.gram[i * p..(i + 1) * p], w))
            .sum();
        0.5 * quad - dot(prob.xty, w) + l1 * w.iter().map(|v| v.abs()).sum::<f64>()
    }

    #[test]
    fn small_penalties_reach_the_optimum_where_coordinate_descent_stalls() {
        let std = lagged_products();
        let prob = std.problem(0);
        let p = prob.xty.len();
        let settings = LassoSettings {
            tol: 1e-9,
            max_iter: 10_000,
        };
        let mut w = vec![0.0; p];
        let mut ws = LassoWorkspace::new(p);
        let mut iterations = 0;
        for alpha in mu_grid(1e-8, 1e-1, 15) {
            let r = lasso_gram(&prob, alpha, &settings, &mut w, &mut ws);
            assert!(
                r.converged && r.kkt_violation < 1e-8,
                "alpha {alpha}: {r:?}"
            );
            iterations += r.iterations;
        }
        assert!(iterations < 20 * p, "{iterations} iterations for {p} terms");
        // The smallest penalty from zero, by coordinate descent with the sweep limit the
        // training had.
        let l1 = 1e-8 * prob.n_samples;
        let mut w_cd = vec![0.0; p];
        coordinate_descent(&prob, l1, 20_000, &mut w_cd);
        let h: Vec<f64> = (0..p)
            .map(|i| dot(&prob.gram[i * p..(i + 1) * p], &w_cd))
            .collect();
        let gap_cd = duality_gap(&prob, l1, &w_cd, &h);
        // The problem is hard enough to tell the solvers apart ...
        assert!(
            gap_cd > 1e-4 * prob.yty,
            "coordinate descent converged: gap {:e} of {:e}",
            gap_cd,
            prob.yty
        );
        // ... and the active-set answer is the better one.
        assert!(objective(&prob, l1, &w) < objective(&prob, l1, &w_cd));
    }

    /// Sums by their definition, one row at a time.
    fn naive(x: &[f64], y: &[f64], p: usize, o: usize) -> GramStats {
        let mut s = GramStats::zeros(p, o);
        for (r, row) in x.chunks(p).enumerate() {
            s.n += 1.0;
            for i in 0..p {
                s.sum_x[i] += row[i];
                for j in 0..p {
                    s.xtx[i * p + j] += row[i] * row[j];
                }
                for c in 0..o {
                    s.xty[i * o + c] += row[i] * y[r * o + c];
                }
            }
            for c in 0..o {
                s.sum_y[c] += y[r * o + c];
                s.yty[c] += y[r * o + c] * y[r * o + c];
            }
        }
        s
    }

    fn assert_close(a: &GramStats, b: &GramStats) {
        assert_eq!((a.p, a.outputs, a.n), (b.p, b.outputs, b.n));
        let pairs = [
            (&a.sum_x, &b.sum_x),
            (&a.sum_y, &b.sum_y),
            (&a.xtx, &b.xtx),
            (&a.xty, &b.xty),
            (&a.yty, &b.yty),
        ];
        for (u, v) in pairs {
            assert_eq!(u.len(), v.len());
            for (x, y) in u.iter().zip(v.iter()) {
                assert!((x - y).abs() <= 1e-12 * (1.0 + x.abs()), "{x} vs {y}");
            }
        }
    }

    #[test]
    fn split_panelled_sums_are_the_sums() {
        // 600 dense columns (three panels, the last partial) and 20 sparse ones that are
        // zero but in every 37th row; two outputs.
        let (p, dense, o, rows) = (620, 600, 2, 300);
        let mut x = vec![0.0; rows * p];
        let mut y = vec![0.0; rows * o];
        for r in 0..rows {
            for j in 0..p {
                if j < dense || r % 37 == 0 {
                    x[r * p + j] = ((r * 31 + j * 17) % 101) as f64 / 50.0 - 1.0;
                }
            }
            for c in 0..o {
                y[r * o + c] = ((r * 7 + c) % 13) as f64 - 6.0;
            }
        }
        let want = naive(&x, &y, p, o);
        assert_close(&GramStats::from_block_split(&x, &y, p, o, dense), &want);
        assert_close(&GramStats::from_block(&x, &y, p, o), &want);
        // A selection is the sums of the selected columns.
        let index = [617, 3, 256, 599, 600, 42];
        let sub: Vec<f64> = (0..rows)
            .flat_map(|r| index.iter().map(move |&j| (r, j)))
            .map(|(r, j)| x[r * p + j])
            .collect();
        assert_close(&want.select(&index), &naive(&sub, &y, index.len(), o));
    }

    #[test]
    fn block_sums_add_up_to_the_whole() {
        let (x, y, p) = toy();
        let whole = GramStats::from_block(&x, &y, p, 1);
        let mut parts = GramStats::from_block(&x[..20 * p], &y[..20], p, 1);
        parts.accumulate(&GramStats::from_block(&x[20 * p..], &y[20..], p, 1), 1.0);
        for (a, b) in whole.xtx.iter().zip(&parts.xtx) {
            assert!((a - b).abs() < 1e-9);
        }
        assert_eq!(whole.n, parts.n);
    }

    #[test]
    fn grid_runs_high_to_low() {
        let g = mu_grid(1e-5, 1.0, 6);
        assert_eq!(g.len(), 6);
        assert!((g[0] - 1.0).abs() < 1e-12 && (g[5] - 1e-5).abs() < 1e-15);
        assert!(g.windows(2).all(|w| w[1] < w[0]));
    }
}
