//! The every-step and grouped terms of a compiled output row: flat by degree, or
//! factored by a shared first factor, summed in independent partial sums.

use crate::surrogate::runtime::model::OutputRow;

/// Terms compiled for evaluation, split by degree (factor slots into the gathered
/// features, coefficients) in flat arrays, so a linear term costs one read and one
/// multiply-add. Leaving out factors of 1.0 changes no bit.
#[derive(Debug, Clone, Default)]
pub(super) struct Terms {
    pub(super) lin: Vec<([u16; 1], f64)>,
    pub(super) quad: Vec<([u16; 2], f64)>,
    pub(super) cubic: Vec<([u16; 3], f64)>,
}

/// Independent partial sums per lane in [`Factored::add`] and
/// [`super::dense::Dense::eval`]. One running sum would make every term wait for the
/// previous addition (a chain of some 4 cycles per term, most of the step); four sums
/// overlap them. The order of additions differs from library order, which moves the
/// result by rounding only.
pub(super) const PARTIAL_SUMS: usize = 4;

/// Adds `c * x[f0] * x[f1] ...` of each term, per lane, round robin into the partial sums.
#[inline(always)]
pub(super) fn accumulate<const N: usize, const LANES: usize>(
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
    pub(super) fn push(&mut self, f: &[u16], coef: f64) {
        match *f {
            [a] => self.lin.push(([a], coef)),
            [a, b] => self.quad.push(([a, b], coef)),
            [a, b, d] => self.cubic.push(([a, b, d], coef)),
            _ => unreachable!("a term has 1 to 3 factors"),
        }
    }

    /// Adds the terms of one lane to `y` (the few phase terms of one engine).
    #[cold]
    #[inline(never)]
    pub(super) fn add_lane<const LANES: usize>(&self, x: &[[f64; LANES]], e: usize, y: &mut f64) {
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
pub(super) struct Factored {
    /// Linear terms that share no factor with a product term: flat, `c * x_a`.
    pub(super) single: Vec<([u16; 1], f64)>,
    pub(super) groups: Vec<FactorGroup>,
    /// Inner linear terms `c * x_b`, group after group.
    pub(super) lin: Vec<(u16, f64)>,
    /// Inner quadratic terms `c * x_b * x_d` (from cubic terms), group after group.
    pub(super) quad: Vec<([u16; 2], f64)>,
}

/// One group of [`Factored`]: the shared factor, the inner constant and the group's
/// inner terms in `lin` and `quad` (start, end).
#[derive(Debug, Clone, Copy)]
pub(super) struct FactorGroup {
    pub(super) outer: u16,
    pub(super) constant: f64,
    pub(super) lin: [u32; 2],
    pub(super) quad: [u32; 2],
}

impl Factored {
    /// Groups `terms` greedily: the factor shared by most of the remaining terms first,
    /// so few groups carry many terms.
    pub(super) fn new(terms: &Terms) -> Self {
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
    pub(super) fn add<const LANES: usize>(&self, x: &[[f64; LANES]], y: &mut [f64; LANES]) {
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

impl Factored {
    /// [`Factored::add`] for four lanes in AVX2 vectors: the same IEEE operations per
    /// lane in the same order (no fused multiply-add), so the same bits; tested against
    /// the portable path. Written with intrinsics because the compiler's vectorisation
    /// of the portable loops is fragile: a small change to them (four partial sums
    /// instead of two) turned the group sums into scalar code with its sums on the
    /// stack, a step of 310 against 205 ns.
    ///
    /// # Safety
    /// The CPU has AVX2; every slot in the terms is below `x.len()` (as for `add`).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn add_avx2(&self, x: &[[f64; 4]], y: &mut [f64; 4]) {
        use std::arch::x86_64::*;
        let base = x.as_ptr().cast::<f64>();
        // Macros rather than closures: a closure is not compiled with the enclosing
        // function's target features, and the intrinsics would not be inlined into it.
        macro_rules! at {
            ($i:expr) => {
                // SAFETY: the slot is below `x.len()` (the caller's contract), and each
                // slot holds four values.
                unsafe { _mm256_loadu_pd(base.add(usize::from($i) * 4)) }
            };
        }
        macro_rules! term {
            ($c:expr, $x:expr) => {
                _mm256_mul_pd(_mm256_set1_pd($c), $x)
            };
        }
        let mut acc = [_mm256_setzero_pd(); PARTIAL_SUMS];
        let mut chunks = self.single.chunks_exact(PARTIAL_SUMS);
        for chunk in &mut chunks {
            for (a, &([f], c)) in acc.iter_mut().zip(chunk) {
                *a = _mm256_add_pd(*a, term!(c, at!(f)));
            }
        }
        for (a, &([f], c)) in acc.iter_mut().zip(chunks.remainder()) {
            *a = _mm256_add_pd(*a, term!(c, at!(f)));
        }
        let mut groups = _mm256_setzero_pd();
        for g in &self.groups {
            let mut i0 = _mm256_set1_pd(g.constant);
            let (mut i1, mut i2) = (_mm256_setzero_pd(), _mm256_setzero_pd());
            // SAFETY: the group ranges lie within `lin` and `quad` (built together).
            let lin = unsafe { self.lin.get_unchecked(g.lin[0] as usize..g.lin[1] as usize) };
            let mut pairs = lin.chunks_exact(2);
            for p in &mut pairs {
                let ((b0, c0), (b1, c1)) = (p[0], p[1]);
                i0 = _mm256_add_pd(i0, term!(c0, at!(b0)));
                i1 = _mm256_add_pd(i1, term!(c1, at!(b1)));
            }
            for &(b, c) in pairs.remainder() {
                i0 = _mm256_add_pd(i0, term!(c, at!(b)));
            }
            // SAFETY: as for `lin`.
            let quad = unsafe {
                self.quad
                    .get_unchecked(g.quad[0] as usize..g.quad[1] as usize)
            };
            for &([b, d], c) in quad {
                i2 = _mm256_add_pd(i2, term!(c, _mm256_mul_pd(at!(b), at!(d))));
            }
            let inner = _mm256_add_pd(_mm256_add_pd(i0, i1), i2);
            groups = _mm256_add_pd(groups, _mm256_mul_pd(at!(g.outer), inner));
        }
        let singles = _mm256_add_pd(_mm256_add_pd(acc[0], acc[1]), _mm256_add_pd(acc[2], acc[3]));
        // SAFETY: `y` holds four values.
        unsafe {
            let sum = _mm256_add_pd(singles, groups);
            _mm256_storeu_pd(
                y.as_mut_ptr(),
                _mm256_add_pd(_mm256_loadu_pd(y.as_ptr()), sum),
            );
        }
    }
}

/// The coefficients of one output, compiled. Terms with a phase indicator that is
/// exactly 0 outside its phase (uncentred, see `fit::Prepared`) are kept apart, one group
/// per indicator, and evaluated only for an engine in that phase: in steady running no
/// phase term costs anything, and skipping terms that are exactly 0 changes no sum.
///
/// Terms with an ignition feature are kept apart the same way, in one group evaluated
/// for an engine whose ignition clock is in its window (see [`super::gather::Clock`]).
#[derive(Debug, Clone, Default)]
pub(super) struct CompiledRow {
    pub(super) intercept: f64,
    pub(super) terms: Factored,
    pub(super) phase: Vec<Terms>,
    pub(super) clock: Terms,
}

impl CompiledRow {
    /// `group[slot]`: the phase group of a gathered feature, if it is a skippable phase
    /// indicator; `clocked[slot]`: whether it is a skippable ignition feature. (A checked
    /// model has at most one phase or ignition feature per term.)
    pub(super) fn new(
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
