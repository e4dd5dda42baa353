//! The navigation filter's covariance arithmetic in the block form flight filters use,
//! instead of dense 15 x 15 products (`docs/gnc.md`, "Navigation filter", cost).
//!
//! Error state `[δr, δv, δθ, δb_g, δb_a]`, five 3-vectors. Over one IMU period the
//! transition is `Φ = I + A` with six non-zero 3 x 3 blocks of `A` (`Φ` has 54 non-zero
//! entries of 225):
//!
//! ```text
//! A_rv = I dt    A_vr = G dt    A_vθ = -R [Δv]x    A_vba = -R dt    A_θθ = -[Δθ]x    A_θbg = -I dt
//! ```
//!
//! `Φ P Φ^T` is then two passes that each combine whole columns: about 1 300
//! multiplications where the dense form takes 6 750.
//! The samples of one flight-software cycle are combined first ([`Transition::then`]), so the
//! covariance is propagated once a cycle while the strapdown runs at the IMU's rate.
//! The scalar update uses the Joseph form expanded for a rank-one gain, `O(N^2)`. Both are
//! the same matrices as the dense expressions in exact arithmetic (the tests hold them to
//! 1e-12 relative), not in every bit.

use nalgebra::{ArrayStorage, Matrix3, SMatrix};

/// Error-state dimension.
pub const N: usize = 15;
/// First index of the position error block (`mci`, m).
pub const I_R: usize = 0;
/// First index of the velocity error block (`mci`, m/s).
pub const I_V: usize = 3;
/// First index of the attitude error block (body, rad).
pub const I_TH: usize = 6;
/// First index of the gyro bias error block (rad/s).
pub const I_BG: usize = 9;
/// First index of the accelerometer bias error block (m/s^2).
pub const I_BA: usize = 12;

/// A covariance or transition over the error state.
pub type Mat = SMatrix<f64, N, N>;
/// A measurement row over the error state.
pub type Row = SMatrix<f64, 1, N>;
/// A gain or error-state column.
pub type Col = SMatrix<f64, N, 1>;

/// The non-identity blocks of one IMU period's transition `Φ` (the rest of `Φ` is `I`).
#[derive(Debug, Clone, Copy)]
pub struct Transition {
    /// Period, s (`Φ_rv = I dt`, `Φ_θbg = -I dt`).
    pub dt_s: f64,
    /// `Φ_vr = G dt`: the gravity gradient over the period.
    pub v_from_r: Matrix3<f64>,
    /// `Φ_vθ = -R [Δv]x`: a body-frame attitude error turns the velocity increment.
    pub v_from_theta: Matrix3<f64>,
    /// `Φ_vba = -R dt`: an accelerometer bias integrates into velocity.
    pub v_from_ba: Matrix3<f64>,
    /// `Φ_θθ = I - [Δθ]x`.
    pub theta_from_theta: Matrix3<f64>,
}

impl Transition {
    /// The dense `Φ` (what the block products stand for; tests and documentation).
    pub fn dense(&self) -> Mat {
        let dt = self.dt_s;
        let mut f = Mat::identity();
        f.fixed_view_mut::<3, 3>(I_R, I_V)
            .copy_from(&(Matrix3::identity() * dt));
        f.fixed_view_mut::<3, 3>(I_V, I_R).copy_from(&self.v_from_r);
        f.fixed_view_mut::<3, 3>(I_V, I_TH)
            .copy_from(&self.v_from_theta);
        f.fixed_view_mut::<3, 3>(I_V, I_BA)
            .copy_from(&self.v_from_ba);
        f.fixed_view_mut::<3, 3>(I_TH, I_TH)
            .copy_from(&self.theta_from_theta);
        f.fixed_view_mut::<3, 3>(I_TH, I_BG)
            .copy_from(&(-Matrix3::identity() * dt));
        f
    }

    /// This period followed by `next`, to first order in the periods: `Φ2 Φ1 = I + A1 +
    /// A2 + A2 A1`, and `A2 A1` (products of two periods' couplings, such as
    /// `dt [Δv]x` from position to attitude error) is dropped. Over a 10 ms flight-software
    /// cycle of two 5 ms IMU samples these terms are 1e-4 of the ones kept; flight filters
    /// propagate the covariance at such a lower rate than the strapdown.
    pub fn then(&self, next: &Transition) -> Transition {
        let identity = Matrix3::identity();
        Transition {
            dt_s: self.dt_s + next.dt_s,
            v_from_r: self.v_from_r + next.v_from_r,
            v_from_theta: self.v_from_theta + next.v_from_theta,
            v_from_ba: self.v_from_ba + next.v_from_ba,
            theta_from_theta: self.theta_from_theta + next.theta_from_theta - identity,
        }
    }

    /// `Φ P Φ^T` for a symmetric `P`, symmetric by construction.
    ///
    /// `Y = P Φ^T` is a combination of `P`'s columns; as `P` is symmetric, `Y^T = Φ P`, and
    /// `Φ P Φ^T = Y^T Φ^T` combines the columns of `Y^T` the same way. Whole columns are
    /// scaled and added (contiguous in nalgebra's column-major storage), which the compiler
    /// vectorises; nalgebra's strided block views do not.
    pub fn propagate(&self, p: &Mat) -> Mat {
        let y = self.times_phi_transposed(&p.data.0);
        let mut out = self.times_phi_transposed(&transposed(&y));
        mirror_upper(&mut out);
        Mat::from_data(ArrayStorage(out))
    }

    /// `Z Φ^T` for `Z` given by columns: column `j` is `sum_k Φ[j][k] Z[:, k]`.
    fn times_phi_transposed(&self, z: &Columns) -> Columns {
        let dt = self.dt_s;
        // The bias rows of Φ are the identity: those columns are Z's.
        let mut out = *z;
        for j in 0..3 {
            let mut c = z[I_R + j];
            add_scaled(&mut c, dt, &z[I_V + j]);
            out[I_R + j] = c;
        }
        for i in 0..3 {
            let mut c = z[I_V + i];
            for m in 0..3 {
                add_scaled(&mut c, self.v_from_r[(i, m)], &z[I_R + m]);
            }
            for m in 0..3 {
                add_scaled(&mut c, self.v_from_theta[(i, m)], &z[I_TH + m]);
            }
            for m in 0..3 {
                add_scaled(&mut c, self.v_from_ba[(i, m)], &z[I_BA + m]);
            }
            out[I_V + i] = c;
        }
        for i in 0..3 {
            let mut c = [0.0; N];
            for m in 0..3 {
                add_scaled(&mut c, self.theta_from_theta[(i, m)], &z[I_TH + m]);
            }
            add_scaled(&mut c, -dt, &z[I_BG + i]);
            out[I_TH + i] = c;
        }
        out
    }
}

/// A matrix as its columns (nalgebra's storage order).
type Columns = [[f64; N]; N];

#[inline]
fn add_scaled(acc: &mut [f64; N], a: f64, x: &[f64; N]) {
    for (y, x) in acc.iter_mut().zip(x) {
        *y += a * x;
    }
}

fn transposed(z: &Columns) -> Columns {
    let mut t = [[0.0; N]; N];
    for (j, col) in z.iter().enumerate() {
        for (i, v) in col.iter().enumerate() {
            t[i][j] = *v;
        }
    }
    t
}

/// Makes a nearly symmetric matrix symmetric: each pair of mirrored entries becomes
/// their mean.
// Each step reads and writes both `z[j][i]` and `z[i][j]`: indices say it plainly.
#[allow(clippy::needless_range_loop)]
fn mirror_upper(z: &mut Columns) {
    for j in 0..N {
        for i in 0..j {
            let m = 0.5 * (z[j][i] + z[i][j]);
            z[j][i] = m;
            z[i][j] = m;
        }
    }
}

/// A scalar measurement update `y = h δx + v`, `var(v) = r`: the gain `K`, the
/// innovation variance `s` and the covariance after, by the Joseph form
/// `(I - K h) P (I - K h)^T + K r K^T` expanded for a rank-one gain (`b = P h^T`,
/// `s = h b + r`): `P - K b^T - b K^T + s K K^T`, entry by entry on one half and mirrored.
/// `p` must be symmetric (the filter keeps it so).
pub fn scalar_update(p: &Mat, h: &Row, r: f64) -> (Col, f64, Mat) {
    let b = p * h.transpose();
    let s = (h * b)[(0, 0)] + r;
    let k = b / s;
    let mut z = p.data.0;
    for j in 0..N {
        for i in 0..=j {
            let v = z[j][i] - k[i] * b[j] - b[i] * k[j] + s * k[i] * k[j];
            z[j][i] = v;
            z[i][j] = v;
        }
    }
    (k, s, Mat::from_data(ArrayStorage(z)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
        Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
    }

    fn covariance(rng: &mut ChaCha8Rng) -> Mat {
        let l = Mat::from_fn(|_, _| rng.gen_range(-1.0..1.0));
        let mut z = (l * l.transpose() + Mat::identity() * 1e-3).data.0;
        mirror_upper(&mut z);
        Mat::from_data(ArrayStorage(z))
    }

    fn transition(rng: &mut ChaCha8Rng) -> Transition {
        let dt = 0.005;
        let m3 = |rng: &mut ChaCha8Rng, s: f64| Matrix3::from_fn(|_, _| rng.gen_range(-s..s));
        let dv = Vector3::from_fn(|_, _| rng.gen_range(-0.1..0.1));
        let dth = Vector3::from_fn(|_, _| rng.gen_range(-1e-3..1e-3));
        let rot = m3(rng, 1.0);
        Transition {
            dt_s: dt,
            v_from_r: m3(rng, 1e-6),
            v_from_theta: -rot * skew(&dv),
            v_from_ba: -rot * dt,
            theta_from_theta: Matrix3::identity() - skew(&dth),
        }
    }

    fn assert_close(a: &Mat, b: &Mat) {
        let scale = b.amax();
        for (x, y) in a.iter().zip(b.iter()) {
            assert!((x - y).abs() <= 1e-12 * scale, "{x:e} against {y:e}");
        }
    }

    #[test]
    fn block_propagation_equals_the_dense_sandwich() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let p = covariance(&mut rng);
            let f = transition(&mut rng);
            let dense = f.dense() * p * f.dense().transpose();
            let block = f.propagate(&p);
            assert_close(&block, &dense);
            assert_eq!(block, block.transpose());
        }
    }

    /// Two 5 ms periods summed are the product of their transitions but for exactly the
    /// dropped `A2 A1`, under 1e-3 in every entry of a `Φ` whose diagonal is 1, with
    /// velocity increments of up to 0.1 m/s a period (20 m/s^2, five times the lander's
    /// largest acceleration).
    #[test]
    fn two_periods_combine_to_first_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..100 {
            let (a, b) = (transition(&mut rng), transition(&mut rng));
            let exact = b.dense() * a.dense();
            let combined = a.then(&b).dense();
            let dropped = (exact - combined).amax();
            assert!(dropped <= 1e-3, "{dropped:e}");
            let second_order = (b.dense() - Mat::identity()) * (a.dense() - Mat::identity());
            assert!((exact - combined - second_order).amax() <= 1e-14);
        }
    }

    #[test]
    fn expanded_joseph_update_equals_the_joseph_form() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..200 {
            let p = covariance(&mut rng);
            let mut h = Row::zeros();
            for c in [0, 1, 2, 6, 7] {
                h[(0, c)] = rng.gen_range(-1.0..1.0);
            }
            let r = rng.gen_range(0.01..10.0);
            let (k, s, after) = scalar_update(&p, &h, r);
            let b = p * h.transpose();
            assert!((s - ((h * b)[(0, 0)] + r)).abs() <= 1e-12 * s);
            let ikh = Mat::identity() - k * h;
            let joseph = ikh * p * ikh.transpose() + k * k.transpose() * r;
            assert_close(&after, &joseph);
            // The optimal gain's covariance is also the short form P - K h P.
            assert_close(&after, &(p - k * h * p));
        }
    }
}
