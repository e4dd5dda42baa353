//! Lasso by cyclic coordinate descent on a precomputed Gram matrix, with scikit-learn's
//! duality-gap stopping rule, and a warm-started path over the penalty.
//!
//! Written by hand: no pure-Rust crate offers Gram-based Lasso with a duality-gap rule and
//! warm starts (linfa-elasticnet works on the design matrix and pulls in ndarray/BLAS
//! plumbing); the algorithm is fifty lines and must match scikit-learn, which the test
//! `lasso_matches_sklearn` checks on a committed fixture.
//!
//! Scaling, stated once. scikit-learn minimises `(1/(2N)) ||y - Xw - b||^2 + alpha ||w||_1`.
//! [`lasso_gram`] solves exactly that problem (`alpha` is scikit-learn's), given the Gram
//! matrix of the centred design. The training pipeline calls it on standardised terms and
//! standardised outputs and names the penalty `mu`: `mu` is scikit-learn's `alpha` on the
//! standardised problem, and the paper's `(1/2) sum(...) + mu_paper ||K||_1` has
//! `mu_paper = N * mu` (N training rows).

use matrixmultiply::dgemm;

/// Stopping and iteration limits, scikit-learn's meaning and defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LassoSettings {
    /// Stop when the duality gap is below `tol * ||y_centred||^2`.
    pub tol: f64,
    /// Full sweeps at most.
    pub max_iter: usize,
}

impl Default for LassoSettings {
    fn default() -> Self {
        Self {
            tol: 1e-4,
            max_iter: 1000,
        }
    }
}

/// How a fit ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LassoReport {
    /// Full sweeps done.
    pub sweeps: usize,
    /// Final duality gap (same scaling as scikit-learn's `dual_gap_ * N`).
    pub gap: f64,
    /// The gap fell below the tolerance.
    pub converged: bool,
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

/// Solves the Lasso at penalty `alpha` (scikit-learn's scaling), starting from `w`
/// (warm start) and leaving the solution there. `h` is scratch of length p.
pub fn lasso_gram(
    prob: &GramProblem,
    alpha: f64,
    settings: &LassoSettings,
    w: &mut [f64],
    h: &mut [f64],
) -> LassoReport {
    let p = prob.xty.len();
    let q = prob.gram;
    let l1 = alpha * prob.n_samples;
    let tol = settings.tol * prob.yty;
    // h = Q w.
    for i in 0..p {
        h[i] = dot(&q[i * p..(i + 1) * p], w);
    }
    let mut gap = f64::INFINITY;
    for sweep in 0..settings.max_iter {
        let mut w_max = 0.0f64;
        let mut d_w_max = 0.0f64;
        for j in 0..p {
            let qjj = q[j * p + j];
            if qjj <= 0.0 {
                continue;
            }
            let w_old = w[j];
            // Correlation of feature j with the residual that leaves j out.
            let rho = prob.xty[j] - h[j] + qjj * w_old;
            let w_new = soft_threshold(rho, l1) / qjj;
            if w_new != w_old {
                axpy(w_new - w_old, &q[j * p..(j + 1) * p], h);
                w[j] = w_new;
            }
            d_w_max = d_w_max.max((w_new - w_old).abs());
            w_max = w_max.max(w_new.abs());
        }
        let last = sweep + 1 == settings.max_iter;
        if w_max == 0.0 || d_w_max / w_max < settings.tol || last {
            gap = duality_gap(prob, l1, w, h);
            // `<=`: a constant output has yty = 0 and a zero gap at w = 0.
            if gap <= tol {
                return LassoReport {
                    sweeps: sweep + 1,
                    gap,
                    converged: true,
                };
            }
        }
    }
    LassoReport {
        sweeps: settings.max_iter,
        gap,
        converged: false,
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
fn soft_threshold(x: f64, t: f64) -> f64 {
    if x > t {
        x - t
    } else if x < -t {
        x + t
    } else {
        0.0
    }
}

#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
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
        let rows = x.len() / p.max(1);
        let mut s = Self::zeros(p, outputs);
        s.n = rows as f64;
        let p_i = p as isize;
        let o_i = outputs as isize;
        // SAFETY: dimensions and strides describe exactly the slices passed.
        unsafe {
            // X' X: A = X' (p x rows), B = X (rows x p).
            dgemm(
                p,
                rows,
                p,
                1.0,
                x.as_ptr(),
                1,
                p_i,
                x.as_ptr(),
                p_i,
                1,
                0.0,
                s.xtx.as_mut_ptr(),
                p_i,
                1,
            );
            dgemm(
                p,
                rows,
                outputs,
                1.0,
                x.as_ptr(),
                1,
                p_i,
                y.as_ptr(),
                o_i,
                1,
                0.0,
                s.xty.as_mut_ptr(),
                o_i,
                1,
            );
        }
        for r in 0..rows {
            for (a, v) in s.sum_x.iter_mut().zip(&x[r * p..(r + 1) * p]) {
                *a += v;
            }
            for o in 0..outputs {
                let v = y[r * outputs + o];
                s.sum_y[o] += v;
                s.yty[o] += v * v;
            }
        }
        s
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
        let mut h = vec![0.0; p];
        let settings = LassoSettings {
            tol: 1e-14,
            max_iter: 100_000,
        };
        let r = lasso_gram(&prob, 1e-12, &settings, &mut w, &mut h);
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
        let mut h = vec![0.0; p];
        lasso_gram(
            &prob,
            alpha_max * 1.001,
            &LassoSettings::default(),
            &mut w,
            &mut h,
        );
        assert_eq!(w, vec![0.0; p]);
        let mut w = vec![0.0; p];
        lasso_gram(
            &prob,
            alpha_max * 0.5,
            &LassoSettings::default(),
            &mut w,
            &mut h,
        );
        assert!(w.iter().any(|v| *v != 0.0));
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
