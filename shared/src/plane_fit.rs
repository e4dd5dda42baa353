//! A least-squares plane `z = a + b x + c y` through scattered heights, by its normal
//! equations (Cramer's rule on the 3 x 3 system: no allocation, no linear-algebra
//! crate). Shared by the emulator's judgement of the ground under a touchdown and the
//! reference flight software's hazard map, so the two measure slope and roughness the
//! same way.

/// The running sums of the normal equations.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PlaneFit {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    sz: f64,
    sxz: f64,
    syz: f64,
}

impl PlaneFit {
    /// Adds the point `(x, y, z)`.
    pub fn add(&mut self, x: f64, y: f64, z: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.sxy += x * y;
        self.syy += y * y;
        self.sz += z;
        self.sxz += x * z;
        self.syz += y * z;
    }

    /// Points added.
    pub fn count(&self) -> usize {
        self.n as usize
    }

    /// `[a, b, c]` of the plane; `None` with fewer than three points not on a line.
    pub fn solve(&self) -> Option<[f64; 3]> {
        let m = [
            [self.n, self.sx, self.sy],
            [self.sx, self.sxx, self.sxy],
            [self.sy, self.sxy, self.syy],
        ];
        let r = [self.sz, self.sxz, self.syz];
        let det3 = |m: &[[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let d = det3(&m);
        let scale = self.n * self.sxx.max(self.syy).max(1e-300);
        if !(d.is_finite() && d.abs() > 1e-12 * scale * scale.max(1.0)) {
            return None;
        }
        let mut out = [0.0; 3];
        for (k, o) in out.iter_mut().enumerate() {
            let mut mk = m;
            for row in 0..3 {
                mk[row][k] = r[row];
            }
            *o = det3(&mk) / d;
        }
        Some(out)
    }

    /// The plane's tilt from horizontal, degrees, for `[a, b, c]`.
    pub fn slope_deg(plane: &[f64; 3]) -> f64 {
        plane[1].hypot(plane[2]).atan().to_degrees()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exact_plane_comes_back_and_a_line_is_refused() {
        let mut f = PlaneFit::default();
        for i in -3..=3 {
            for j in -3..=3 {
                let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
                f.add(x, y, 1.5 + 0.2 * x - 0.1 * y);
            }
        }
        let p = f.solve().unwrap();
        assert!(
            (p[0] - 1.5).abs() < 1e-12 && (p[1] - 0.2).abs() < 1e-12 && (p[2] + 0.1).abs() < 1e-12
        );
        assert!((PlaneFit::slope_deg(&p) - 0.05f64.sqrt().atan().to_degrees()).abs() < 1e-9);
        let mut line = PlaneFit::default();
        for i in 0..5 {
            line.add(i as f64, 2.0 * i as f64, 1.0);
        }
        assert!(line.solve().is_none());
    }
}
