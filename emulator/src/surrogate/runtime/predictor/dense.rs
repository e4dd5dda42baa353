//! A linear submodel of a few rows (the pressure and ejected masses) as dense
//! coefficients over chunks of four features.

use super::gather::Gather;
use super::terms::PARTIAL_SUMS;

/// Rows of a [`Dense`] submodel, at most: the pressure and the two ejected masses. (At
/// four, the compiler vectorised each feature across the rows, with the coefficients
/// gathered lane by lane, instead of each row across the chunk's four features.)
pub(super) const DENSE_ROWS: usize = 3;

/// See [`super::compiled::CompiledSub::dense`]: the rows' intercepts and their
/// coefficients, laid out for the step. Features come in chunks of four, feature `k` of a
/// chunk into partial sum `k`: each row then costs one vector multiply-add per chunk, and
/// a chunk's four envelope bounds are one read each. (A vector of the rows' coefficients
/// per feature cost a broadcast, a multiply and an add per feature.) Every partial sum
/// adds the same terms in the same order as one feature at a time, so the bits are the
/// same.
#[derive(Debug, Clone)]
pub(super) struct Dense {
    pub(super) intercept: [f64; DENSE_ROWS],
    pub(super) chunks: Vec<DenseChunk>,
    /// The features after the last whole chunk (fewer than four), one at a time:
    /// `(read, coefficient per row)`.
    pub(super) rest: Vec<(Gather, [f64; DENSE_ROWS])>,
}

/// Four features of a [`Dense`] submodel: where each is read, its envelope, and
/// `coef[r][k]`, row `r`'s coefficient of feature `k` (0 for rows past the last).
#[derive(Debug, Clone)]
pub(super) struct DenseChunk {
    pub(super) offset: [usize; PARTIAL_SUMS],
    pub(super) lo: [f64; PARTIAL_SUMS],
    pub(super) hi: [f64; PARTIAL_SUMS],
    pub(super) coef: [[f64; PARTIAL_SUMS]; DENSE_ROWS],
}

impl Dense {
    /// `gather[k]` (clamped, unscaled) and the rows' coefficients `coef[k][r]` of slot k.
    pub(super) fn new(
        intercept: [f64; DENSE_ROWS],
        gather: &[Gather],
        coef: &[[f64; DENSE_ROWS]],
    ) -> Self {
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
    /// `AVX2`: the step runs in its AVX2 build, and the chunks take
    /// [`Dense::chunks_avx2`].
    #[inline(always)]
    pub(super) fn eval<const AVX2: bool>(&self, window: &[f64]) -> ([f64; DENSE_ROWS], bool) {
        // `acc[r][k]`: row r's partial sum k.
        let (mut acc, mut outside) = {
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // SAFETY: the CPU has AVX2 (checked by the caller); reads as below.
                unsafe { self.chunks_avx2(window) }
            } else {
                self.chunks(window)
            }
            #[cfg(not(target_arch = "x86_64"))]
            {
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
    pub(super) fn chunks(
        &self,
        window: &[f64],
    ) -> ([[f64; PARTIAL_SUMS]; DENSE_ROWS], [u64; PARTIAL_SUMS]) {
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
    pub(super) unsafe fn chunks_avx2(
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
