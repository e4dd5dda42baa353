//! The same cases with two propulsion models: per-case differences of the touchdown
//! figures and two-sample Kolmogorov-Smirnov statistics of their distributions
//! (does the surrogate reproduce hifi's closed-loop dispersion?).

use super::case::CaseResult;
use super::summary::{FigureStats, Merged};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Two-sample Kolmogorov-Smirnov test.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct KsTest {
    /// Largest distance between the two empirical distribution functions.
    pub d: f64,
    /// Asymptotic p-value of `d` under "same distribution".
    pub p_value: f64,
    /// Sample sizes.
    pub n: [u64; 2],
}

/// The Kolmogorov distribution's tail Q(lambda) = 2 sum (-1)^(j-1) exp(-2 j^2 lambda^2).
fn kolmogorov_q(lambda: f64) -> f64 {
    if lambda < 1e-3 {
        return 1.0;
    }
    let mut sum = 0.0;
    for j in 1..=100 {
        let j = j as f64;
        let term = (-2.0 * j * j * lambda * lambda).exp();
        sum += if j as u64 % 2 == 1 { term } else { -term };
        if term < 1e-12 {
            break;
        }
    }
    (2.0 * sum).clamp(0.0, 1.0)
}

/// The KS statistic of samples `a` and `b` (non-finite values dropped), with the
/// asymptotic p-value in the small-sample-corrected form of Stephens (1970), as in
/// Numerical Recipes. Twenty lines: no maintained crate offers the two-sample test
/// without pulling in a statistics framework.
pub fn ks_two_sample(a: &[f64], b: &[f64]) -> Option<KsTest> {
    let mut a: Vec<f64> = a.iter().copied().filter(|x| x.is_finite()).collect();
    let mut b: Vec<f64> = b.iter().copied().filter(|x| x.is_finite()).collect();
    if a.is_empty() || b.is_empty() {
        return None;
    }
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let (mut i, mut j, mut d) = (0usize, 0usize, 0.0f64);
    while i < a.len() && j < b.len() {
        let x = a[i].min(b[j]);
        while i < a.len() && a[i] <= x {
            i += 1;
        }
        while j < b.len() && b[j] <= x {
            j += 1;
        }
        d = d.max((i as f64 / na - j as f64 / nb).abs());
    }
    let ne = (na * nb / (na + nb)).sqrt();
    let p_value = kolmogorov_q((ne + 0.12 + 0.11 / ne) * d);
    Some(KsTest {
        d,
        p_value,
        n: [a.len() as u64, b.len() as u64],
    })
}

/// One figure compared.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FigureComparison {
    /// Statistics under each model.
    pub stats: [Option<FigureStats>; 2],
    /// Per-case difference (second model minus first), over cases where both have it.
    pub difference: Option<FigureStats>,
    /// Same distribution?
    pub ks: Option<KsTest>,
}

/// `compare.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// The two models.
    pub models: [String; 2],
    /// Cases.
    pub cases: u64,
    /// Landed fraction under each.
    pub landed_fraction: [f64; 2],
    /// Cases whose outcome differs between the models.
    pub outcome_differs: u64,
    /// Per figure.
    pub figures: BTreeMap<String, FigureComparison>,
}

type Figure = fn(&CaseResult) -> f64;

const FIGURES: [(&str, Figure); 4] = [
    ("vertical_speed_mps", |r| {
        r.touchdown.map_or(f64::NAN, |t| t.vertical_speed_mps)
    }),
    ("horizontal_speed_mps", |r| {
        r.touchdown.map_or(f64::NAN, |t| t.horizontal_speed_mps)
    }),
    ("tilt_deg", |r| r.touchdown.map_or(f64::NAN, |t| t.tilt_deg)),
    ("propellant_used_kg", |r| {
        if r.digest.is_empty() {
            f64::NAN
        } else {
            r.propellant_used_kg
        }
    }),
];

/// Compares two merged campaigns of the same spec under different models.
pub fn compare(a: &Merged, b: &Merged) -> Comparison {
    let mut figures = BTreeMap::new();
    for (name, f) in FIGURES {
        let xa: Vec<f64> = a.results.iter().map(f).collect();
        let xb: Vec<f64> = b.results.iter().map(f).collect();
        let diff = a
            .results
            .iter()
            .zip(&b.results)
            .filter(|(ra, rb)| ra.index == rb.index)
            .map(|(ra, rb)| f(rb) - f(ra));
        figures.insert(
            name.to_string(),
            FigureComparison {
                stats: [
                    FigureStats::of(xa.iter().copied()),
                    FigureStats::of(xb.iter().copied()),
                ],
                difference: FigureStats::of(diff),
                ks: ks_two_sample(&xa, &xb),
            },
        );
    }
    Comparison {
        models: [a.summary.propulsion.clone(), b.summary.propulsion.clone()],
        cases: a.results.len().min(b.results.len()) as u64,
        landed_fraction: [a.summary.landed_fraction, b.summary.landed_fraction],
        outcome_differs: a
            .results
            .iter()
            .zip(&b.results)
            .filter(|(ra, rb)| ra.outcome != rb.outcome)
            .count() as u64,
        figures,
    }
}

/// `compare.csv`: per case, each figure under both models and the difference.
pub fn compare_csv(a: &Merged, b: &Merged) -> String {
    let (ma, mb) = (&a.summary.propulsion, &b.summary.propulsion);
    let mut out = format!("index,outcome_{ma},outcome_{mb}");
    for (name, _) in FIGURES {
        let _ = write!(out, ",{name}_{ma},{name}_{mb},{name}_diff");
    }
    out.push('\n');
    let num = |x: f64| {
        if x.is_finite() {
            format!("{x}")
        } else {
            String::new()
        }
    };
    for (ra, rb) in a.results.iter().zip(&b.results) {
        let _ = write!(
            out,
            "{},{},{}",
            ra.index.map_or(String::new(), |i| i.to_string()),
            ra.outcome,
            rb.outcome
        );
        for (_, f) in FIGURES {
            let (x, y) = (f(ra), f(rb));
            let _ = write!(out, ",{},{},{}", num(x), num(y), num(y - x));
        }
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn ks_of_a_sample_with_itself_is_zero_and_of_disjoint_samples_one() {
        let a: Vec<f64> = (0..100).map(f64::from).collect();
        let t = ks_two_sample(&a, &a).unwrap();
        assert_eq!(t.d, 0.0);
        assert!(t.p_value > 0.99);
        let b: Vec<f64> = (200..300).map(f64::from).collect();
        let t = ks_two_sample(&a, &b).unwrap();
        assert_eq!(t.d, 1.0);
        assert!(t.p_value < 1e-10);
    }

    #[test]
    fn ks_tells_a_shifted_normal_from_the_same_one() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut normal = |shift: f64| -> Vec<f64> {
            (0..500)
                .map(|_| rng.sample::<f64, _>(rand_distr::StandardNormal) + shift)
                .collect()
        };
        let (a, b, c) = (normal(0.0), normal(0.0), normal(0.5));
        let same = ks_two_sample(&a, &b).unwrap();
        let shifted = ks_two_sample(&a, &c).unwrap();
        assert!(same.p_value > 0.01, "{same:?}");
        assert!(shifted.p_value < 1e-6, "{shifted:?}");
        // D for a 0.5-sigma shift of large samples: about Phi(0.25) - Phi(-0.25) = 0.197.
        assert!((shifted.d - 0.197).abs() < 0.06, "{shifted:?}");
    }
}
