//! Fixed-step second-order Rosenbrock-W integration (ROS2, Verwer et al. 1999) with a
//! diagonal Jacobian.
//!
//! Why this scheme: the model mixes slow thermodynamics (seconds to minutes) with
//! ~1 ms feed-line, chamber and regulator dynamics, and becomes truly stiff where a
//! valve closes (the branch resistance goes to infinity as the solenoid shuts). An
//! explicit method would need tiny steps near every shutdown; a fully implicit one
//! would need Newton iterations and linear solves. ROS2 is linearly implicit: each
//! stage divides by `1 - gamma h J_ii`, where `J_ii` is the state's own damping
//! (friction slope of a flow, chamber outflow, poppet damping). It is second order for
//! any choice of that matrix (a W-method), L-stable for the diagonal stiffness, and
//! costs two right-hand-side evaluations per sub-step. States with `J_ii = 0` reduce
//! to Heun's method; every mass inventory is kept at `J_ii = 0`, so each inventory is
//! updated with exactly the flows its neighbours see and mass is conserved to
//! round-off by construction.

/// `gamma = 1 + 1/sqrt(2)`: the L-stable choice.
const GAMMA: f64 = 1.0 + std::f64::consts::FRAC_1_SQRT_2;

/// A right-hand side `dy/dt = f(y)` over a sub-step.
pub trait Rhs<const N: usize> {
    /// Evaluates `f` at the start (`end = false`) or end (`end = true`) of the current
    /// sub-step (time-dependent inputs such as valve positions differ). Writes the
    /// diagonal of the Jacobian approximation into `jdiag` when given.
    fn eval(&mut self, end: bool, y: &[f64; N], dydt: &mut [f64; N], jdiag: Option<&mut [f64; N]>);
}

/// Stage buffers of the integrator, allocated once.
#[derive(Debug, Clone)]
pub struct Ros2<const N: usize> {
    f: [f64; N],
    jdiag: [f64; N],
    k1: [f64; N],
    y2: [f64; N],
}

impl<const N: usize> Default for Ros2<N> {
    fn default() -> Self {
        Self {
            f: [0.0; N],
            jdiag: [0.0; N],
            k1: [0.0; N],
            y2: [0.0; N],
        }
    }
}

impl<const N: usize> Ros2<N> {
    /// Advances `y` by `h` seconds.
    #[inline]
    // Five arrays advance in lockstep: an index reads plainer than a zip of five.
    #[allow(clippy::needless_range_loop)]
    pub fn step(&mut self, y: &mut [f64; N], h: f64, rhs: &mut impl Rhs<N>) {
        rhs.eval(false, y, &mut self.f, Some(&mut self.jdiag));
        for i in 0..N {
            // Stage divisor, reused for both stages.
            self.jdiag[i] = 1.0 / (1.0 - GAMMA * h * self.jdiag[i]);
            self.k1[i] = self.f[i] * self.jdiag[i];
            self.y2[i] = y[i] + h * self.k1[i];
        }
        rhs.eval(true, &self.y2, &mut self.f, None);
        for i in 0..N {
            let k2 = (self.f[i] - 2.0 * self.k1[i]) * self.jdiag[i];
            y[i] += h * (1.5 * self.k1[i] + 0.5 * k2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Damped oscillator plus a stiff decaying mode: x'' = -w^2 x - c x', z' = -1e6 (z - 1).
    struct Test;
    impl Rhs<3> for Test {
        fn eval(&mut self, _end: bool, y: &[f64; 3], d: &mut [f64; 3], j: Option<&mut [f64; 3]>) {
            let (w2, c, k) = (100.0, 1.0, 1e6);
            d[0] = y[1];
            d[1] = -w2 * y[0] - c * y[1];
            d[2] = -k * (y[2] - 1.0);
            if let Some(j) = j {
                *j = [0.0, -c, -k];
            }
        }
    }

    fn run(h: f64) -> [f64; 3] {
        let mut y = [1.0, 0.0, 0.0];
        let mut r = Ros2::default();
        let n = (1.0 / h).round() as usize;
        for _ in 0..n {
            r.step(&mut y, h, &mut Test);
        }
        y
    }

    #[test]
    fn second_order_and_stable_on_stiff_mode() {
        // Exact: underdamped oscillator at t = 1.
        let (w2, c): (f64, f64) = (100.0, 1.0);
        let wd = (w2 - c * c / 4.0).sqrt();
        let a = -c / 2.0;
        let exact = (a * 1.0).exp() * ((wd * 1.0).cos() - a / wd * (wd * 1.0).sin());
        let e1 = (run(1e-3)[0] - exact).abs();
        let e2 = (run(5e-4)[0] - exact).abs();
        let ratio = e1 / e2;
        assert!(ratio > 3.5 && ratio < 4.5, "order ratio {ratio}");
        // The stiff mode (h k = 1000) settles without oscillation.
        assert!((run(1e-3)[2] - 1.0).abs() < 1e-12);
    }
}
