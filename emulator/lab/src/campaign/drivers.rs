//! What drives the failures: for each applied value (a dispersion's column, a fault, the
//! model error per engine), its Spearman rank correlation with failure and with each
//! touchdown figure, ranked. Rank correlation because the question is "does more of
//! this make it worse", monotonic but rarely linear, and because one crash at 100 m/s
//! must not outweigh a thousand landings as it does in a Pearson coefficient.

use super::case::CaseResult;
use super::spec::CampaignSpec;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// The touchdown figures a driver is correlated with, by their `summary.json` name.
pub const FIGURES: [&str; 5] = [
    "vertical_speed_mps",
    "horizontal_speed_mps",
    "tilt_deg",
    "site_error_m",
    "propellant_used_kg",
];

/// One applied value and how it moves the results.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Driver {
    /// The applied column (`altitude_m`, `engine_thrust_scale[2]`, `engine_out`).
    pub name: String,
    /// `dispersion`, `fault` (enters as struck 1 / not struck 0) or `model_error`.
    pub kind: String,
    /// Rank correlation with failure (1: did not land, 0: landed) over the cases that
    /// flew (not `invalid`, `error` or `timeout`); absent when every case ended alike.
    pub failure_rho: Option<f64>,
    /// Two-sided p-value of `failure_rho` under "no association" (Fisher z with the
    /// Fieller-Hartley-Pearson variance 1.06 / (n - 3)).
    pub failure_p: Option<f64>,
    /// Cases in `failure_rho`.
    pub cases: u64,
    /// Rank correlation with each touchdown figure ([`FIGURES`]) over the cases that
    /// touched down (absent where the value or the figure is constant).
    pub figures: BTreeMap<String, f64>,
}

impl Driver {
    /// The largest |rho| over the touchdown figures (0 without any).
    pub fn strongest_figure_rho(&self) -> f64 {
        self.figures.values().fold(0.0, |m, r| m.max(r.abs()))
    }
}

/// Whether a case flew to an end the GNC is answerable for.
pub fn flew(r: &CaseResult) -> bool {
    !matches!(r.outcome.as_str(), "invalid" | "error" | "timeout")
}

/// A driver's value in case `r`: a fault's column is its trigger time when it struck,
/// so it enters as struck (1) or not (0); other columns as applied (absent: `None`).
pub fn value(r: &CaseResult, name: &str, fault: bool) -> Option<f64> {
    if fault {
        Some(if r.applied.contains_key(name) {
            1.0
        } else {
            0.0
        })
    } else {
        r.applied.get(name).copied().filter(|x| x.is_finite())
    }
}

/// A touchdown figure of `r` (`site_error_m`: distance from the scenario's site).
pub fn figure(r: &CaseResult, _nominal: &CaseResult, name: &str) -> Option<f64> {
    let td = r.touchdown?;
    let v = match name {
        "vertical_speed_mps" => td.vertical_speed_mps,
        "horizontal_speed_mps" => td.horizontal_speed_mps,
        "tilt_deg" => td.tilt_deg,
        "site_error_m" => r.downrange_m?.hypot(r.crossrange_m?),
        "propellant_used_kg" => r.propellant_used_kg,
        _ => return None,
    };
    v.is_finite().then_some(v)
}

/// Ranks of `xs` from 1, ties sharing their mean rank.
pub fn ranks(xs: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..xs.len()).collect();
    order.sort_by(|&a, &b| xs[a].total_cmp(&xs[b]));
    let mut r = vec![0.0; xs.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && xs[order[j + 1]] == xs[order[i]] {
            j += 1;
        }
        let mean = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            r[k] = mean;
        }
        i = j + 1;
    }
    r
}

/// Spearman's rank correlation of paired samples; `None` with fewer than 3 pairs or a
/// constant side.
pub fn spearman(pairs: &[(f64, f64)]) -> Option<f64> {
    if pairs.len() < 3 {
        return None;
    }
    let a = ranks(&pairs.iter().map(|p| p.0).collect::<Vec<_>>());
    let b = ranks(&pairs.iter().map(|p| p.1).collect::<Vec<_>>());
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(&b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        return None;
    }
    Some((sab / (saa * sbb).sqrt()).clamp(-1.0, 1.0))
}

/// The complementary error function (Numerical Recipes' `erfcc`, fractional error
/// below 1.2e-7 everywhere).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Two-sided p-value of a Spearman `rho` over `n` pairs under independence.
pub fn p_value(rho: f64, n: usize) -> Option<f64> {
    if n < 4 {
        return None;
    }
    let z = rho.clamp(-0.999_999_999, 0.999_999_999).atanh() * ((n as f64 - 3.0) / 1.06).sqrt();
    Some(erfc(z.abs() / std::f64::consts::SQRT_2).clamp(0.0, 1.0))
}

/// Every applied column of the campaign's results, ranked: strongest correlation with
/// failure first, then the strongest with a touchdown figure, then by name.
pub fn rank(spec: &CampaignSpec, results: &[CaseResult], nominal: &CaseResult) -> Vec<Driver> {
    let faults: BTreeSet<&str> = spec.faults.iter().map(|f| f.name.as_str()).collect();
    let mut columns: BTreeSet<&str> = results
        .iter()
        .flat_map(|r| r.applied.keys().map(String::as_str))
        .collect();
    // A fault that struck no case is a driver of nothing, but it is in the campaign.
    columns.extend(spec.faults.iter().map(|f| f.name.as_str()));
    let flown: Vec<&CaseResult> = results.iter().filter(|r| flew(r)).collect();
    let mut drivers: Vec<Driver> = columns
        .into_iter()
        .map(|name| {
            let fault = faults.contains(name);
            let failure: Vec<(f64, f64)> = flown
                .iter()
                .filter_map(|r| {
                    let failed = if r.outcome == "landed" { 0.0 } else { 1.0 };
                    value(r, name, fault).map(|v| (v, failed))
                })
                .collect();
            let failure_rho = spearman(&failure);
            let figures = FIGURES
                .iter()
                .filter_map(|f| {
                    let pairs: Vec<(f64, f64)> = results
                        .iter()
                        .filter_map(|r| Some((value(r, name, fault)?, figure(r, nominal, f)?)))
                        .collect();
                    spearman(&pairs).map(|rho| (f.to_string(), rho))
                })
                .collect();
            Driver {
                name: name.to_string(),
                kind: if fault {
                    "fault"
                } else if name.starts_with("model_error") {
                    "model_error"
                } else {
                    "dispersion"
                }
                .into(),
                failure_rho,
                failure_p: failure_rho.and_then(|r| p_value(r, failure.len())),
                cases: failure.len() as u64,
                figures,
            }
        })
        .collect();
    drivers.sort_by(|a, b| {
        let f = |d: &Driver| d.failure_rho.map_or(-1.0, f64::abs);
        f(b).total_cmp(&f(a))
            .then(
                b.strongest_figure_rho()
                    .total_cmp(&a.strongest_figure_rho()),
            )
            .then(a.name.cmp(&b.name))
    });
    drivers
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::case::{Touchdown, Trace};
    use rand::{Rng, SeedableRng};

    #[test]
    fn ties_share_their_mean_rank() {
        assert_eq!(ranks(&[3.0, 1.0, 3.0, 2.0]), [3.5, 1.0, 3.5, 2.0]);
    }

    #[test]
    fn spearman_is_one_for_any_increasing_relation_and_undefined_for_a_constant() {
        let up: Vec<(f64, f64)> = (0..20).map(|i| (i as f64, (i as f64).exp())).collect();
        assert_eq!(spearman(&up), Some(1.0));
        let down: Vec<(f64, f64)> = (0..20).map(|i| (i as f64, -(i as f64).powi(3))).collect();
        assert_eq!(spearman(&down), Some(-1.0));
        let flat: Vec<(f64, f64)> = (0..20).map(|i| (i as f64, 2.0)).collect();
        assert_eq!(spearman(&flat), None);
        // A textbook value: ranks (1,2,3,4,5) against (2,1,4,3,5): 1 - 6*4/(5*24) = 0.8.
        let t = [(1.0, 2.0), (2.0, 1.0), (3.0, 4.0), (4.0, 3.0), (5.0, 5.0)];
        assert!((spearman(&t).unwrap() - 0.8).abs() < 1e-12);
    }

    #[test]
    fn p_values_are_small_for_strong_and_large_for_no_association() {
        assert!(p_value(0.5, 200).unwrap() < 1e-10);
        assert!(p_value(0.0, 200).unwrap() > 0.999);
        // z = 1.96 gives p = 0.05.
        let n = 103;
        let rho = (1.96 * (1.06 / (n as f64 - 3.0)).sqrt()).tanh();
        assert!((p_value(rho, n).unwrap() - 0.05).abs() < 1e-4);
        assert!((erfc(0.0) - 1.0).abs() < 1e-7);
        assert!((erfc(-1.0) - 1.842_700_79).abs() < 1e-6);
    }

    fn result(index: u64, applied: &[(&str, f64)], landed: bool, vz: f64) -> CaseResult {
        CaseResult {
            index: Some(index),
            seed: index,
            outcome: if landed { "landed" } else { "crashed" }.into(),
            outcome_reason: None,
            error: None,
            digest: "d".into(),
            steps: 1,
            sim_time_s: 1.0,
            touchdown: Some(Touchdown {
                slope_deg: 0.0,
                roughness_m: 0.0,
                t_s: 1.0,
                vertical_speed_mps: vz,
                horizontal_speed_mps: 0.1,
                tilt_deg: 1.0,
            }),
            propellant_used_kg: 900.0,
            downrange_m: Some(0.0),
            crossrange_m: Some(0.0),
            nav_error: None,
            nav_error_50m: None,
            nav_horizontal_by_altitude: Vec::new(),
            fault_events: 0,
            faults: vec![],
            out_of_envelope: None,
            applied: applied.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            trace: Trace::default(),
            wall_s: 0.0,
        }
    }

    #[test]
    fn the_dispersion_that_causes_the_failures_ranks_first() {
        let spec = CampaignSpec::parse(
            "cases = 300\nseed = 1\n[[fault]]\nname = \"engine_out\"\nfault = \"engine-off:2\"\nprobability = 0.1\nwindow_s = [1.0, 2.0]\n",
            std::path::Path::new("t.toml"),
        )
        .unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let nominal = result(0, &[], true, 1.0);
        let results: Vec<CaseResult> = (0..300)
            .map(|i| {
                let cause: f64 = rng.gen_range(0.0..1.0);
                let noise: f64 = rng.gen_range(0.0..1.0);
                let other: f64 = rng.gen_range(0.0..1.0);
                let struck = rng.gen_bool(0.05);
                let mut applied = vec![("cause", cause), ("noise", noise), ("other", other)];
                if struck {
                    // A fault that strikes rarely and never matters.
                    applied.push(("engine_out", 100.0));
                }
                // Failures when the cause is high; the vertical speed follows the noise.
                result(i, &applied, cause < 0.8, 1.0 + noise)
            })
            .collect();
        let d = rank(&spec, &results, &nominal);
        let names: Vec<&str> = d.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(names[0], "cause", "{d:#?}");
        assert!(names.contains(&"engine_out"));
        assert!(d[0].failure_rho.unwrap() > 0.6, "{:?}", d[0]);
        assert!(d[0].failure_p.unwrap() < 1e-10);
        assert_eq!(d[0].cases, 300);
        let noise = d.iter().find(|d| d.name == "noise").unwrap();
        assert!(noise.failure_rho.unwrap().abs() < 0.2);
        assert!((noise.figures["vertical_speed_mps"] - 1.0).abs() < 1e-12);
        // Constant figures give no coefficient.
        assert!(!noise.figures.contains_key("tilt_deg"));
        let fault = d.iter().find(|d| d.name == "engine_out").unwrap();
        assert_eq!(fault.kind, "fault");
    }
}
