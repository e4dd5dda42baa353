//! The throttle valve's calibration, as the surrogate's valve filter uses it: how many
//! newtons of thrust a unit of valve stroke is worth at each throttle level.
//!
//! Why: hifi's TFCV is rate-limited in stroke, and its calibration table is not linear.
//! Near minimum throttle a stroke is worth some 2.4 times more newtons than near full
//! (0.034 of stroke per 40 N at 320 N, 0.081 at 800 N), so the data-sheet rate of a full
//! stroke in 0.15 s is some 7800 N/s of thrust at low throttle and 3300 N/s near full. A
//! filter with one rate in newtons is too slow at one end and too fast at the other.
//! With this map the filter stays in newtons but scales its rate and backlash by the
//! newtons per stroke where the valve is moving.
//!
//! The table is hifi's (commanded thrust to stroke at evenly spaced commands); the step
//! path uses a quadratic in thrust fitted to its slopes (within 0.4 % of every
//! segment's slope for hifi's table). Why not the table itself: the filter in stroke,
//! with the command mapped to stroke and the valve mapped back every step, puts two
//! table lookups on the step's chain of dependent operations; a quadratic is two
//! multiply-adds per engine, and the fitted model was trained with it.
//!
//! "Position newtons" are stroke fraction times `full_stroke_n`, the thrust a full stroke
//! stands for: the filter's `rate_n_per_s` and `backlash_n` are in them. The slope is
//! newtons of thrust per position newton, 1 for a linear valve.

use serde::{Deserialize, Serialize};

/// Most knots a [`StrokeMap`] holds.
pub const STROKE_MAP_MAX_KNOTS: usize = 32;

/// Commanded thrust to stroke at evenly spaced commands, and the slope fitted to it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "StrokeMapSpec", into = "StrokeMapSpec")]
pub struct StrokeMap {
    first_n: f64,
    step_n: f64,
    full_stroke_n: f64,
    knots: usize,
    /// Stroke fraction at each knot (as given).
    stroke: [f64; STROKE_MAP_MAX_KNOTS],
    slope: StrokeSlope,
}

/// Newtons of thrust per position newton, as a quadratic in thrust fitted to a
/// [`StrokeMap`]: all the step path needs of it (small, so the valve filter's state
/// stays compact).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrokeSlope {
    lo_n: f64,
    hi_n: f64,
    /// Lowest power first.
    q: [f64; 3],
}

impl StrokeSlope {
    /// Newtons of thrust per position newton with the valve at `thrust_n` (clamped to
    /// the map's range, as hifi's table clamps commands).
    #[inline(always)]
    pub fn at(&self, thrust_n: f64) -> f64 {
        let t = thrust_n.max(self.lo_n).min(self.hi_n);
        let [q0, q1, q2] = self.q;
        (q2 * t + q1) * t + q0
    }
}

/// A [`StrokeMap`] as written in `train.toml` and model files.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrokeMapSpec {
    /// Commanded thrust at the first knot, N.
    pub first_n: f64,
    /// Commanded thrust between knots, N.
    pub step_n: f64,
    /// The thrust a full stroke stands for, N: the unit of the filter's rate and
    /// backlash.
    pub full_stroke_n: f64,
    /// Valve stroke fraction at each knot, rising.
    pub stroke: Vec<f64>,
}

impl TryFrom<StrokeMapSpec> for StrokeMap {
    type Error = String;

    fn try_from(s: StrokeMapSpec) -> Result<Self, String> {
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        if !s.first_n.is_finite() || !finite_pos(s.step_n) || !finite_pos(s.full_stroke_n) {
            return Err(
                "stroke map: first_n must be finite, step_n and full_stroke_n positive".into(),
            );
        }
        let knots = s.stroke.len();
        if !(3..=STROKE_MAP_MAX_KNOTS).contains(&knots) {
            return Err(format!(
                "stroke map: {knots} knots, needs 3 to {STROKE_MAP_MAX_KNOTS}"
            ));
        }
        if s.stroke.iter().any(|&x| !(0.0..=1.0).contains(&x)) {
            return Err("stroke map: every stroke must be within 0..=1".into());
        }
        if s.stroke.windows(2).any(|w| w[1] <= w[0]) {
            return Err("stroke map: strokes must rise from knot to knot".into());
        }
        let mut m = StrokeMap {
            first_n: s.first_n,
            step_n: s.step_n,
            full_stroke_n: s.full_stroke_n,
            knots,
            stroke: [0.0; STROKE_MAP_MAX_KNOTS],
            slope: StrokeSlope {
                lo_n: s.first_n,
                hi_n: s.first_n + s.step_n * (knots - 1) as f64,
                q: [0.0; 3],
            },
        };
        m.stroke[..knots].copy_from_slice(&s.stroke);
        // Least squares of each segment's slope at its midpoint, in thrust relative to
        // the table's middle (for conditioning), then expanded to powers of thrust.
        let centre_n = 0.5 * (m.first_n + m.last_n());
        let points: Vec<(f64, f64)> = m.segment_slopes().collect();
        let a = nalgebra::DMatrix::from_fn(points.len(), 3, |r, c| {
            (points[r].0 - centre_n).powi(c as i32)
        });
        let b = nalgebra::DVector::from_fn(points.len(), |r, _| points[r].1);
        // nalgebra's SVD panics on a non-finite entry rather than failing.
        if !(a.iter().chain(b.iter()).all(|v| v.is_finite())) {
            return Err(
                "stroke map: its thrust range or full stroke is too large to fit its slope".into(),
            );
        }
        let q = a
            .svd(true, true)
            .solve(&b, 1e-12)
            .map_err(|e| format!("stroke map: cannot fit its slope ({e})"))?;
        m.slope.q = [
            q[0] - q[1] * centre_n + q[2] * centre_n * centre_n,
            q[1] - 2.0 * q[2] * centre_n,
            q[2],
        ];
        let last_n = m.last_n();
        if !(m.slope_at(s.first_n) > 0.0 && m.slope_at(last_n) > 0.0) {
            return Err("stroke map: its fitted slope is not positive over the range".into());
        }
        Ok(m)
    }
}

impl From<StrokeMap> for StrokeMapSpec {
    fn from(m: StrokeMap) -> Self {
        StrokeMapSpec {
            first_n: m.first_n,
            step_n: m.step_n,
            full_stroke_n: m.full_stroke_n,
            stroke: m.strokes().to_vec(),
        }
    }
}

impl StrokeMap {
    /// Newtons of thrust per position newton with the valve at `thrust_n` (the fitted
    /// quadratic, [`StrokeSlope::at`]).
    pub fn slope_at(&self, thrust_n: f64) -> f64 {
        self.slope.at(thrust_n)
    }

    /// The fitted slope.
    pub fn slope(&self) -> StrokeSlope {
        self.slope
    }

    /// Commanded thrust at the first knot, N.
    pub fn first_n(&self) -> f64 {
        self.first_n
    }

    /// Commanded thrust at the last knot, N.
    pub fn last_n(&self) -> f64 {
        self.first_n + self.step_n * (self.knots - 1) as f64
    }

    /// Commanded thrust between knots, N.
    pub fn step_n(&self) -> f64 {
        self.step_n
    }

    /// Stroke fraction at each knot.
    pub fn strokes(&self) -> &[f64] {
        &self.stroke[..self.knots]
    }

    /// Each segment's slope, newtons per position newton (what the quadratic is fitted
    /// to), at its midpoint's thrust.
    pub fn segment_slopes(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.strokes().windows(2).enumerate().map(|(i, w)| {
            (
                self.first_n + self.step_n * (i as f64 + 0.5),
                self.step_n / ((w[1] - w[0]) * self.full_stroke_n),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(stroke: Vec<f64>) -> StrokeMapSpec {
        StrokeMapSpec {
            first_n: 320.0,
            step_n: 40.0,
            full_stroke_n: 1000.0,
            stroke,
        }
    }

    #[test]
    fn a_linear_valve_has_slope_one_and_a_curved_one_its_segments_slopes() {
        // 40 N per 0.04 stroke of a 1000 N stroke: one newton per position newton.
        let m = StrokeMap::try_from(spec(vec![0.32, 0.36, 0.40, 0.44])).unwrap();
        for t in [320.0, 350.0, 440.0] {
            assert!((m.slope_at(t) - 1.0).abs() < 1e-12, "{}", m.slope_at(t));
        }
        // Segment slopes on a line in thrust are fitted exactly, and the ends clamp.
        let strokes: Vec<f64> = (0..5)
            .scan(0.2, |s, k| {
                let at = *s;
                *s += 40.0 / (1000.0 * (2.0 - 0.25 * f64::from(k)));
                Some(at)
            })
            .collect();
        let m = StrokeMap::try_from(spec(strokes)).unwrap();
        for (t, want) in m.segment_slopes() {
            assert!((m.slope_at(t) - want).abs() < 1e-9, "{t}: {want}");
        }
        assert_eq!(m.slope_at(0.0), m.slope_at(320.0));
        assert_eq!(m.slope_at(1e9), m.slope_at(480.0));
    }

    #[test]
    fn bad_maps_are_refused_with_a_reason() {
        for (s, want) in [
            (spec(vec![0.2, 0.3]), "knots"),
            (spec(vec![0.2, 0.2, 0.3]), "rise"),
            (spec(vec![0.3, 0.2, 0.4]), "rise"),
            (spec(vec![0.2, 0.3, 1.2]), "within"),
            (spec(vec![0.2, 0.3, f64::NAN]), "within"),
            (
                StrokeMapSpec {
                    step_n: 0.0,
                    ..spec(vec![0.2, 0.3, 0.4])
                },
                "positive",
            ),
            (spec(vec![0.1; 40]), "knots"),
            (
                StrokeMapSpec {
                    step_n: 1e300,
                    ..spec(vec![0.2, 0.3, 0.4])
                },
                "too large",
            ),
        ] {
            let e = StrokeMap::try_from(s).unwrap_err();
            assert!(e.contains(want), "{e}");
        }
    }

    #[test]
    fn round_trips_through_its_spec() {
        let m = StrokeMap::try_from(spec(vec![0.2, 0.25, 0.4])).unwrap();
        let text = serde_json::to_string(&m).unwrap();
        assert_eq!(serde_json::from_str::<StrokeMap>(&text).unwrap(), m);
        assert!(text.contains("\"stroke\":[0.2,0.25,0.4]"), "{text}");
    }
}
