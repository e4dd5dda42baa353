//! The Cholesky factor of a Gram matrix restricted to a set of terms that grows and
//! shrinks one term at a time (the Lasso's active set), kept up to date in O(m^2) per
//! change instead of refactorised in O(m^3).

/// `L` with `L L' = Q_AA`, lower triangular, for the `m` terms of the set in the order
/// they were added. Storage is sized once for `capacity` terms.
#[derive(Debug, Clone)]
pub struct ActiveCholesky {
    capacity: usize,
    m: usize,
    /// Row-major, row stride `capacity`; row `i` holds `L[i][0..=i]`.
    l: Vec<f64>,
    /// Rotations of a column removal.
    cos: Vec<f64>,
    sin: Vec<f64>,
    removed: Vec<f64>,
}

/// Why a term could not join the set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dependent {
    /// Its pivot relative to its diagonal: how much of its column lies outside the span of
    /// the set's columns (squared, as a share of its squared norm).
    pub relative_pivot: f64,
}

impl ActiveCholesky {
    /// An empty factor with room for `capacity` terms.
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            m: 0,
            l: vec![0.0; capacity * capacity],
            cos: vec![0.0; capacity],
            sin: vec![0.0; capacity],
            removed: vec![0.0; capacity],
        }
    }

    /// Terms in the set.
    pub fn len(&self) -> usize {
        self.m
    }

    /// True when the set is empty.
    pub fn is_empty(&self) -> bool {
        self.m == 0
    }

    /// Empties the set.
    pub fn clear(&mut self) {
        self.m = 0;
    }

    #[inline]
    fn row(&self, i: usize) -> &[f64] {
        &self.l[i * self.capacity..i * self.capacity + i + 1]
    }

    /// Solves `L v = b` in place (`b` of length `len()`).
    pub fn forward(&self, b: &mut [f64]) {
        for i in 0..self.m {
            let row = self.row(i);
            let s = super::lasso::dot(&row[..i], &b[..i]);
            b[i] = (b[i] - s) / row[i];
        }
    }

    /// Solves `L' x = y` in place (`y` of length `len()`).
    pub fn backward(&self, y: &mut [f64]) {
        for i in (0..self.m).rev() {
            let row = self.row(i);
            let x = y[i] / row[i];
            y[i] = x;
            for (yk, lik) in y[..i].iter_mut().zip(&row[..i]) {
                *yk -= lik * x;
            }
        }
    }

    /// Solves `Q_AA x = b` in place.
    pub fn solve(&self, b: &mut [f64]) {
        self.forward(b);
        self.backward(b);
    }

    /// Appends a term whose Gram entries with the set's terms are `cross` (length `len()`,
    /// overwritten with `L^-1 cross`) and whose own is `diag`. Refused when its column is
    /// (numerically) in the span of the set's: the squared pivot below `min_pivot * diag`.
    pub fn push(&mut self, cross: &mut [f64], diag: f64, min_pivot: f64) -> Result<(), Dependent> {
        let m = self.m;
        assert!(m < self.capacity && cross.len() == m);
        self.forward(cross);
        let d2 = diag - super::lasso::dot(cross, cross);
        // NaN is refused too.
        if d2.is_nan() || d2 <= min_pivot * diag {
            return Err(Dependent {
                relative_pivot: d2 / diag,
            });
        }
        let start = m * self.capacity;
        self.l[start..start + m].copy_from_slice(cross);
        self.l[start + m] = d2.sqrt();
        self.m += 1;
        Ok(())
    }

    /// Removes the term at position `k` (later ones move up by one).
    pub fn remove(&mut self, k: usize) {
        let m = self.m;
        assert!(k < m);
        let cap = self.capacity;
        // The removed column below the diagonal.
        for i in k + 1..m {
            self.removed[i - 1 - k] = self.l[i * cap + k];
        }
        // Rows below k move up one, without column k.
        for i in k + 1..m {
            let (src, dst) = (i * cap, (i - 1) * cap);
            self.l.copy_within(src..src + k, dst);
            self.l.copy_within(src + k + 1..src + i + 1, dst + k);
        }
        self.m -= 1;
        // The trailing block T (rows and columns k..) must now satisfy T T' = T0 T0' + c c'
        // with c the removed column: a rank-one update by Givens rotations, row by row so
        // every access is along a row.
        for i in k..self.m {
            let mut c = self.removed[i - k];
            let row = &mut self.l[i * cap..i * cap + i + 1];
            for j in k..i {
                let lij = (row[j] + self.sin[j] * c) / self.cos[j];
                c = self.cos[j] * c - self.sin[j] * lij;
                row[j] = lij;
            }
            let lii = row[i];
            let r = lii.hypot(c);
            self.cos[i] = r / lii;
            self.sin[i] = c / lii;
            row[i] = r;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive definite matrix with some strongly correlated columns.
    fn spd(p: usize) -> Vec<f64> {
        let rows = 3 * p;
        // A fixed pseudo-random draw plus a component every column shares.
        let mut state = 12345u64;
        let x: Vec<f64> = (0..rows * p)
            .map(|k| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let r = k / p;
                (state >> 11) as f64 / (1u64 << 53) as f64 + 3.0 * (r as f64 * 0.05).cos()
            })
            .collect();
        let mut q = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                q[i * p + j] = (0..rows).map(|r| x[r * p + i] * x[r * p + j]).sum();
            }
        }
        q
    }

    /// Solves Q_AA x = b through the factor and checks the residual.
    fn residual(f: &ActiveCholesky, q: &[f64], p: usize, set: &[usize]) -> f64 {
        let b: Vec<f64> = (0..set.len()).map(|i| 1.0 + i as f64).collect();
        let mut x = b.clone();
        f.solve(&mut x);
        let mut worst = 0.0f64;
        for (i, &a) in set.iter().enumerate() {
            let qx: f64 = set.iter().zip(&x).map(|(&c, x)| q[a * p + c] * x).sum();
            worst = worst.max((qx - b[i]).abs() / b[i]);
        }
        worst
    }

    #[test]
    fn pushes_and_removals_keep_the_factor_of_the_set() {
        let p = 12;
        let q = spd(p);
        let mut f = ActiveCholesky::new(p);
        let mut set: Vec<usize> = Vec::new();
        let push = |f: &mut ActiveCholesky, set: &mut Vec<usize>, j: usize| {
            let mut cross: Vec<f64> = set.iter().map(|&a| q[a * p + j]).collect();
            f.push(&mut cross, q[j * p + j], 1e-12).unwrap();
            set.push(j);
        };
        for j in [3, 0, 7, 5, 11, 2, 9] {
            push(&mut f, &mut set, j);
        }
        assert!(residual(&f, &q, p, &set) < 1e-9);
        for k in [2, 0, 4] {
            f.remove(k);
            set.remove(k);
            assert_eq!(f.len(), set.len());
            assert!(
                residual(&f, &q, p, &set) < 1e-9,
                "after removing position {k}"
            );
        }
        push(&mut f, &mut set, 7);
        push(&mut f, &mut set, 1);
        assert!(residual(&f, &q, p, &set) < 1e-9);
    }

    #[test]
    fn a_column_in_the_span_of_the_set_is_refused() {
        // Columns 0, 1 and their sum.
        let p = 3;
        let x = [[1.0, 0.0], [0.5, 2.0], [1.0, 1.0], [0.0, 1.0]];
        let col = |r: &[f64; 2], j: usize| if j < 2 { r[j] } else { r[0] + r[1] };
        let mut q = vec![0.0; p * p];
        for i in 0..p {
            for j in 0..p {
                q[i * p + j] = x.iter().map(|r| col(r, i) * col(r, j)).sum();
            }
        }
        let mut f = ActiveCholesky::new(p);
        f.push(&mut [], q[0], 1e-12).unwrap();
        f.push(&mut [q[1]], q[4], 1e-12).unwrap();
        let refused = f.push(&mut [q[2], q[5]], q[8], 1e-12).unwrap_err();
        assert!(refused.relative_pivot.abs() < 1e-12);
        assert_eq!(f.len(), 2);
    }
}
