//! A fixed-step explicit Runge-Kutta integrator whose Butcher tableau is data.
//!
//! Hand-written because the bench needs a fixed step aligned on the integer-nanosecond
//! clock, stack-only stage buffers (no allocation per step) and bit-identical results;
//! the ODE crates on crates.io are adaptive, allocate per call, or both. The classic
//! four-stage tableau is ~30 lines, and keeping it as data makes it easy to check.

use nalgebra::SVector;

/// An explicit Runge-Kutta tableau with `S` stages.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ButcherTableau<const S: usize> {
    /// Stage times as fractions of the step.
    pub c: [f64; S],
    /// Stage coefficients, strictly lower triangular.
    pub a: [[f64; S]; S],
    /// Weights of the stage derivatives in the update.
    pub b: [f64; S],
}

/// The classic fourth-order Runge-Kutta method.
pub const RK4: ButcherTableau<4> = ButcherTableau {
    c: [0.0, 0.5, 0.5, 1.0],
    a: [
        [0.0, 0.0, 0.0, 0.0],
        [0.5, 0.0, 0.0, 0.0],
        [0.0, 0.5, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ],
    b: [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0],
};

impl<const S: usize> ButcherTableau<S> {
    /// One step of length `h_s` from `x0` at time `t0_s` (seconds since the step's
    /// reference time) of `dx/dt = f(t, x)`. Stage buffers live on the stack.
    pub fn step<const N: usize>(
        &self,
        t0_s: f64,
        h_s: f64,
        x0: &SVector<f64, N>,
        f: impl Fn(f64, &SVector<f64, N>) -> SVector<f64, N>,
    ) -> SVector<f64, N> {
        let mut k = [SVector::<f64, N>::zeros(); S];
        for i in 0..S {
            let mut xi = *x0;
            for (kj, &aij) in k.iter().zip(self.a[i].iter()).take(i) {
                if aij != 0.0 {
                    xi += kj * (h_s * aij);
                }
            }
            k[i] = f(t0_s + self.c[i] * h_s, &xi);
        }
        let mut x1 = *x0;
        for (ki, &bi) in k.iter().zip(self.b.iter()) {
            x1 += ki * (h_s * bi);
        }
        x1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector1;

    #[test]
    fn tableau_is_consistent() {
        // Row sums of A equal c; weights sum to one (order >= 1 conditions).
        for i in 0..4 {
            let row: f64 = RK4.a[i].iter().sum();
            assert!((row - RK4.c[i]).abs() < 1e-15);
        }
        assert!((RK4.b.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn exponential_decay_is_fourth_order() {
        // dx/dt = -x over 1 s: the global error must fall ~16x when h halves.
        let err = |n: usize| {
            let h = 1.0 / n as f64;
            let mut x = Vector1::new(1.0);
            for i in 0..n {
                x = RK4.step(i as f64 * h, h, &x, |_, x| -x);
            }
            (x[0] - (-1.0f64).exp()).abs()
        };
        let ratio = err(8) / err(16);
        assert!((14.0..18.0).contains(&ratio), "ratio {ratio}");
    }

    #[test]
    fn time_dependent_rhs_uses_stage_times() {
        // dx/dt = 3 t^2 is integrated exactly by a 4th-order method.
        let x = RK4.step(1.0, 0.5, &Vector1::new(0.0), |t, _| {
            Vector1::new(3.0 * t * t)
        });
        assert!((x[0] - (1.5f64.powi(3) - 1.0)).abs() < 1e-14);
    }
}
