//! Error statistics of `model - truth`: max |error|, RMS, mean and standard deviation,
//! accumulated one sample at a time (Welford for the variance, so long runs of large
//! values keep their precision).

use serde::{Deserialize, Serialize};

/// Statistics of an error signal.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Samples.
    pub count: u64,
    /// Largest |error|.
    pub max_abs: f64,
    /// Root mean square.
    pub rms: f64,
    /// Mean (the bias).
    pub mean: f64,
    /// Standard deviation about the mean (population).
    pub std: f64,
}

/// Running accumulator for [`ErrorStats`].
#[derive(Debug, Clone, Copy, Default)]
pub struct ErrorAccumulator {
    count: u64,
    max_abs: f64,
    sum_sq: f64,
    mean: f64,
    m2: f64,
}

impl ErrorAccumulator {
    /// Adds one error sample; a non-finite one makes max and RMS infinite.
    pub fn add(&mut self, e: f64) {
        let e = if e.is_finite() { e } else { f64::INFINITY };
        self.count += 1;
        self.max_abs = self.max_abs.max(e.abs());
        self.sum_sq += e * e;
        let d = e - self.mean;
        self.mean += d / self.count as f64;
        self.m2 += d * (e - self.mean);
    }

    /// Merges another accumulator (Chan et al.'s parallel update).
    pub fn merge(&mut self, o: &ErrorAccumulator) {
        if o.count == 0 {
            return;
        }
        if self.count == 0 {
            *self = *o;
            return;
        }
        let n = (self.count + o.count) as f64;
        let d = o.mean - self.mean;
        self.m2 += o.m2 + d * d * self.count as f64 * o.count as f64 / n;
        self.mean += d * o.count as f64 / n;
        self.count += o.count;
        self.sum_sq += o.sum_sq;
        self.max_abs = self.max_abs.max(o.max_abs);
    }

    /// The statistics (all zero without samples).
    pub fn stats(&self) -> ErrorStats {
        if self.count == 0 {
            return ErrorStats::default();
        }
        let n = self.count as f64;
        ErrorStats {
            count: self.count,
            max_abs: self.max_abs,
            rms: (self.sum_sq / n).sqrt(),
            mean: self.mean,
            std: (self.m2 / n).max(0.0).sqrt(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values_and_merge() {
        let xs = [1.0, -2.0, 3.0, 4.0, -5.0];
        let mut all = ErrorAccumulator::default();
        let (mut a, mut b) = (ErrorAccumulator::default(), ErrorAccumulator::default());
        for (i, &x) in xs.iter().enumerate() {
            all.add(x);
            if i < 2 {
                a.add(x)
            } else {
                b.add(x)
            }
        }
        a.merge(&b);
        let s = all.stats();
        assert_eq!(s.count, 5);
        assert_eq!(s.max_abs, 5.0);
        assert!((s.mean - 0.2).abs() < 1e-12);
        assert!((s.rms - (55.0f64 / 5.0).sqrt()).abs() < 1e-12);
        let var = xs.iter().map(|x| (x - 0.2) * (x - 0.2)).sum::<f64>() / 5.0;
        assert!((s.std - var.sqrt()).abs() < 1e-12);
        let m = a.stats();
        assert_eq!(m.count, 5);
        assert!((m.std - s.std).abs() < 1e-12 && (m.mean - s.mean).abs() < 1e-12);
    }
}
