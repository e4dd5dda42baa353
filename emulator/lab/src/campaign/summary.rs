//! Merging a campaign: `cases.csv` (one row per case) and `summary.json` (statistics),
//! byte-identical for the same spec whichever backend, worker count or shards ran it
//! (every number is a function of the case results, and wall times stay out).

use super::case::CaseResult;
use super::spec::CampaignSpec;
use super::store::{write_atomic, Store};
use super::CampaignError;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

/// Statistics of one figure over the cases that have it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FigureStats {
    /// Cases with a value.
    pub count: u64,
    /// Mean.
    pub mean: f64,
    /// Standard deviation (sample, n - 1).
    pub std: f64,
    /// Smallest.
    pub min: f64,
    /// 1st percentile (linear interpolation between order statistics).
    pub p1: f64,
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

/// The `p`-quantile (0-1) of sorted `xs`, linear between order statistics.
pub fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = p * (sorted.len() - 1) as f64;
    let lo = h.floor() as usize;
    let hi = (lo + 1).min(sorted.len() - 1);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

impl FigureStats {
    /// Statistics of the finite values of `xs`; `None` if there are none.
    pub fn of(xs: impl IntoIterator<Item = f64>) -> Option<Self> {
        let mut v: Vec<f64> = xs.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = if v.len() > 1 {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Some(Self {
            count: v.len() as u64,
            mean,
            std: var.sqrt(),
            min: v[0],
            p1: quantile(&v, 0.01),
            p50: quantile(&v, 0.5),
            p99: quantile(&v, 0.99),
            max: v[v.len() - 1],
        })
    }
}

/// The 3-sigma ellipse of the touchdown footprint about its mean.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ellipse {
    /// Centre, downrange and crossrange from the landing site, metres.
    pub centre_m: [f64; 2],
    /// Semi-major axis (3 sigma), metres.
    pub semi_major_m: f64,
    /// Semi-minor axis (3 sigma), metres.
    pub semi_minor_m: f64,
    /// Angle of the major axis from the downrange axis, degrees.
    pub angle_deg: f64,
}

impl Ellipse {
    /// The 3-sigma ellipse of `points` (at least 3).
    pub fn of(points: &[(f64, f64)]) -> Option<Self> {
        if points.len() < 3 {
            return None;
        }
        let n = points.len() as f64;
        let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
        let my = points.iter().map(|p| p.1).sum::<f64>() / n;
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for (x, y) in points {
            sxx += (x - mx) * (x - mx);
            syy += (y - my) * (y - my);
            sxy += (x - mx) * (y - my);
        }
        let (sxx, syy, sxy) = (sxx / (n - 1.0), syy / (n - 1.0), sxy / (n - 1.0));
        // Eigenvalues of the 2x2 covariance.
        let mid = 0.5 * (sxx + syy);
        let d = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
        let (l1, l2) = (mid + d, (mid - d).max(0.0));
        Some(Self {
            centre_m: [mx, my],
            semi_major_m: 3.0 * l1.sqrt(),
            semi_minor_m: 3.0 * l2.sqrt(),
            angle_deg: (0.5 * (2.0 * sxy).atan2(sxx - syy)).to_degrees(),
        })
    }

    /// Points on the ellipse, for drawing.
    pub fn outline(&self, n: usize) -> Vec<(f64, f64)> {
        let a = self.angle_deg.to_radians();
        (0..=n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                let (u, v) = (self.semi_major_m * t.cos(), self.semi_minor_m * t.sin());
                (
                    self.centre_m[0] + u * a.cos() - v * a.sin(),
                    self.centre_m[1] + u * a.sin() + v * a.cos(),
                )
            })
            .collect()
    }
}

/// A case that did not land.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// Case index.
    pub index: u64,
    /// Its outcome.
    pub outcome: String,
    /// Why it crashed (`tip-over`, `slope`...), when it touched down.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outcome_reason: Option<String>,
    /// Why, if known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// Campaign name.
    pub name: String,
    /// Cases in the campaign.
    pub cases: u64,
    /// Cases with a result (equal to `cases` unless merged with `--partial`).
    pub merged: u64,
    /// Master seed.
    pub seed: u64,
    /// Propulsion model.
    pub propulsion: String,
    /// Cases that landed.
    pub landed: u64,
    /// landed / merged.
    pub landed_fraction: f64,
    /// Cases by outcome.
    pub outcomes: BTreeMap<String, u64>,
    /// Crashed cases by the reason (`tip-over`, `slope`, `vertical-speed`...).
    pub crash_reasons: BTreeMap<String, u64>,
    /// Cases that touched down unsafe, by cause: a crash's reason, or `rock` (landed
    /// with a rock or hole over [`HAZARD_CLEARANCE_M`] under the footprint).
    #[serde(default)]
    pub unsafe_touchdowns: BTreeMap<String, u64>,
    /// Cases and landed cases by the faults they were given: `none` (fault-free), or
    /// the fault kinds joined with `+` (`thrust-degraded`, `engine-off+telemetry-drop`).
    pub landed_by_faults: BTreeMap<String, LandedCount>,
    /// The nominal run (no dispersions).
    pub nominal: NominalSummary,
    /// Statistics per figure (touchdown figures over the cases that touched down).
    pub figures: BTreeMap<String, FigureStats>,
    /// The landed cases' touchdown footprint's 3-sigma ellipse, about the scenario's
    /// landing site (downrange, crossrange).
    pub footprint_3sigma: Option<Ellipse>,
    /// Worst cases by figure: indices, worst first (5 each).
    pub worst: BTreeMap<String, Vec<u64>>,
    /// Cases that did not land (first 200 by index).
    pub failures: Vec<Failure>,
    /// Cases that did not land, in all.
    pub failure_count: u64,
    /// Indices without a result (only with `--partial`).
    pub missing: Vec<u64>,
    /// What drives the failures: each applied value's rank correlation with failure
    /// and with the touchdown figures, strongest first ([`super::drivers`]).
    pub drivers: Vec<super::drivers::Driver>,
}

/// Cases and how many of them landed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LandedCount {
    /// Cases.
    pub cases: u64,
    /// Of which landed.
    pub landed: u64,
}

/// The fault kinds of a case (`none` without faults): what comes before `:` or `@` in
/// each fault, sorted, joined with `+`.
pub fn fault_kinds(faults: &[String]) -> String {
    let mut kinds: Vec<&str> = faults
        .iter()
        .map(|f| f.split([':', '@']).next().unwrap_or(f).trim())
        .collect();
    kinds.sort_unstable();
    kinds.dedup();
    if kinds.is_empty() {
        "none".into()
    } else {
        kinds.join("+")
    }
}

/// The nominal run in the summary.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NominalSummary {
    /// Outcome.
    pub outcome: String,
    /// Digest.
    pub digest: String,
    /// Touchdown vertical speed, m/s.
    pub vertical_speed_mps: Option<f64>,
    /// Propellant used, kg.
    pub propellant_used_kg: f64,
}

/// The body's clearance above the footpads, m: a rock or hole under the footprint
/// beyond it makes a landing unsafe (assumed, as the reference GNC's hazard limit,
/// `docs/gnc.md`).
pub const HAZARD_CLEARANCE_M: f64 = 0.3;

/// Why a case's touchdown was unsafe (`None`: safe). A case that never touched down
/// gives its outcome.
pub fn touchdown_hazard(r: &CaseResult) -> Option<String> {
    let Some(td) = &r.touchdown else {
        return Some(r.outcome.clone());
    };
    if let Some(why) = &r.outcome_reason {
        return Some(why.clone());
    }
    if r.outcome != "landed" {
        return Some(r.outcome.clone());
    }
    (td.roughness_m > HAZARD_CLEARANCE_M).then(|| "rock".to_string())
}

/// Per-case figures derived at merge time: the end point about the scenario's site.
struct Derived {
    downrange_error_m: f64,
    crossrange_error_m: f64,
    site_error_m: f64,
}

fn derived(r: &CaseResult, _nominal: &CaseResult) -> Derived {
    let nan = |x: Option<f64>| x.unwrap_or(f64::NAN);
    let dx = nan(r.downrange_m);
    let dy = nan(r.crossrange_m);
    Derived {
        downrange_error_m: dx,
        crossrange_error_m: dy,
        site_error_m: dx.hypot(dy),
    }
}

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        String::new()
    }
}

fn opt(x: Option<f64>) -> String {
    x.map_or(String::new(), num)
}

fn text(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\"").replace(['\n', '\r'], " "))
    } else {
        s.to_string()
    }
}

/// The fixed columns of `cases.csv`, before the applied dispersion values.
pub const CSV_COLUMNS: [&str; 24] = [
    "index",
    "seed",
    "outcome",
    "outcome_reason",
    "touchdown_t_s",
    "vertical_speed_mps",
    "horizontal_speed_mps",
    "tilt_deg",
    "downrange_m",
    "crossrange_m",
    "downrange_error_m",
    "crossrange_error_m",
    "site_error_m",
    "propellant_used_kg",
    "fault_events",
    "faults",
    "digest",
    "nav_error_m",
    "nav_horizontal_error_m",
    "nav_altitude_error_m",
    "nav_horizontal_error_50m_m",
    "touchdown_safe",
    "touchdown_hazard",
    "touchdown_roughness_m",
];

/// `cases.csv` text.
pub fn cases_csv(results: &[CaseResult], nominal: &CaseResult) -> String {
    let applied: BTreeSet<&str> = results
        .iter()
        .flat_map(|r| r.applied.keys().map(String::as_str))
        .collect();
    let mut out = CSV_COLUMNS.join(",");
    for a in &applied {
        out.push_str(",applied_");
        out.push_str(&text(a));
    }
    out.push_str(",out_of_envelope,error\n");
    for r in results {
        let d = derived(r, nominal);
        let td = r.touchdown;
        let _ = write!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.index.map_or(String::new(), |i| i.to_string()),
            r.seed,
            r.outcome,
            text(r.outcome_reason.as_deref().unwrap_or("")),
            opt(td.map(|t| t.t_s)),
            opt(td.map(|t| t.vertical_speed_mps)),
            opt(td.map(|t| t.horizontal_speed_mps)),
            opt(td.map(|t| t.tilt_deg)),
            opt(r.downrange_m),
            opt(r.crossrange_m),
            num(d.downrange_error_m),
            num(d.crossrange_error_m),
            num(d.site_error_m),
            num(r.propellant_used_kg),
            r.fault_events,
            text(&r.faults.join(";")),
            r.digest,
            opt(r.nav_error.map(|e| e.position_m)),
            opt(r.nav_error.map(|e| e.horizontal_m)),
            opt(r.nav_error.map(|e| e.altitude_m)),
            opt(r.nav_error_50m.map(|e| e.horizontal_m)),
            touchdown_hazard(r).is_none(),
            text(touchdown_hazard(r).as_deref().unwrap_or("")),
            opt(td.map(|t| t.roughness_m)),
        );
        for a in &applied {
            out.push(',');
            out.push_str(&r.applied.get(*a).map_or(String::new(), |x| num(*x)));
        }
        let _ = writeln!(
            out,
            ",{},{}",
            r.out_of_envelope.map_or(String::new(), |n| n.to_string()),
            text(r.error.as_deref().unwrap_or(""))
        );
    }
    out
}

/// The summary of `results` (sorted by index) against the `nominal` run.
pub fn summarise(
    spec: &CampaignSpec,
    results: &[CaseResult],
    nominal: &CaseResult,
    missing: Vec<u64>,
) -> Summary {
    let mut outcomes = BTreeMap::new();
    for r in results {
        *outcomes.entry(r.outcome.clone()).or_insert(0) += 1;
    }
    let landed = outcomes.get("landed").copied().unwrap_or(0);
    let mut crash_reasons = BTreeMap::new();
    for r in results {
        if let Some(why) = &r.outcome_reason {
            *crash_reasons.entry(why.clone()).or_insert(0) += 1;
        }
    }
    let mut unsafe_touchdowns = BTreeMap::new();
    for r in results.iter().filter(|r| !r.digest.is_empty()) {
        if let Some(why) = touchdown_hazard(r) {
            *unsafe_touchdowns.entry(why).or_insert(0) += 1;
        }
    }
    let mut landed_by_faults: BTreeMap<String, LandedCount> = BTreeMap::new();
    for r in results {
        let c = landed_by_faults.entry(fault_kinds(&r.faults)).or_default();
        c.cases += 1;
        c.landed += u64::from(r.outcome == "landed");
    }
    let touched: Vec<(&CaseResult, Derived)> = results
        .iter()
        .filter(|r| r.touchdown.is_some())
        .map(|r| (r, derived(r, nominal)))
        .collect();
    let td = |f: fn(&super::case::Touchdown) -> f64| {
        FigureStats::of(
            touched
                .iter()
                .filter_map(|(r, _)| r.touchdown.as_ref().map(f)),
        )
    };
    let mut figures = BTreeMap::new();
    let mut put = |name: &str, s: Option<FigureStats>| {
        if let Some(s) = s {
            figures.insert(name.to_string(), s);
        }
    };
    put("vertical_speed_mps", td(|t| t.vertical_speed_mps));
    put("horizontal_speed_mps", td(|t| t.horizontal_speed_mps));
    put("tilt_deg", td(|t| t.tilt_deg));
    put("touchdown_t_s", td(|t| t.t_s));
    put(
        "site_error_m",
        FigureStats::of(touched.iter().map(|(_, d)| d.site_error_m)),
    );
    put(
        "downrange_error_m",
        FigureStats::of(touched.iter().map(|(_, d)| d.downrange_error_m)),
    );
    put(
        "crossrange_error_m",
        FigureStats::of(touched.iter().map(|(_, d)| d.crossrange_error_m)),
    );
    // Navigation error at the end (touchdown for the cases that touched down).
    let nav = |f: fn(&super::case::NavError) -> f64| {
        FigureStats::of(
            touched
                .iter()
                .filter_map(|(r, _)| r.nav_error.as_ref().map(f)),
        )
    };
    put("nav_error_m", nav(|e| e.position_m));
    put("nav_horizontal_error_m", nav(|e| e.horizontal_m));
    put("nav_altitude_error_m", nav(|e| e.altitude_m.abs()));
    put(
        "nav_horizontal_error_50m_m",
        FigureStats::of(
            touched
                .iter()
                .filter_map(|(r, _)| r.nav_error_50m.map(|e| e.horizontal_m)),
        ),
    );
    put(
        "propellant_used_kg",
        FigureStats::of(
            results
                .iter()
                .filter(|r| !r.digest.is_empty())
                .map(|r| r.propellant_used_kg),
        ),
    );
    // Over the landed cases: one crash hundreds of km away must not set the ellipse.
    let footprint: Vec<(f64, f64)> = touched
        .iter()
        .filter(|(r, _)| r.outcome == "landed")
        .map(|(_, d)| (d.downrange_error_m, d.crossrange_error_m))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect();
    let mut worst = BTreeMap::new();
    let mut rank = |name: &str, key: &dyn Fn(&(&CaseResult, Derived)) -> f64| {
        let mut v: Vec<(f64, u64)> = touched
            .iter()
            .filter_map(|c| c.0.index.map(|i| (key(c), i)))
            .filter(|(x, _)| x.is_finite())
            .collect();
        v.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        worst.insert(name.to_string(), v.iter().take(5).map(|x| x.1).collect());
    };
    rank("vertical_speed_mps", &|c| {
        c.0.touchdown.map_or(f64::NAN, |t| t.vertical_speed_mps)
    });
    rank("horizontal_speed_mps", &|c| {
        c.0.touchdown.map_or(f64::NAN, |t| t.horizontal_speed_mps)
    });
    rank("tilt_deg", &|c| {
        c.0.touchdown.map_or(f64::NAN, |t| t.tilt_deg)
    });
    rank("site_error_m", &|c| c.1.site_error_m);
    let failures: Vec<Failure> = results
        .iter()
        .filter(|r| r.outcome != "landed")
        .filter_map(|r| {
            r.index.map(|index| Failure {
                index,
                outcome: r.outcome.clone(),
                outcome_reason: r.outcome_reason.clone(),
                error: r.error.clone(),
            })
        })
        .collect();
    Summary {
        name: spec.name.clone(),
        cases: spec.cases,
        merged: results.len() as u64,
        seed: spec.seed,
        propulsion: spec.base.propulsion.as_str().into(),
        landed,
        landed_fraction: if results.is_empty() {
            0.0
        } else {
            landed as f64 / results.len() as f64
        },
        outcomes,
        crash_reasons,
        unsafe_touchdowns,
        landed_by_faults,
        nominal: NominalSummary {
            outcome: nominal.outcome.clone(),
            digest: nominal.digest.clone(),
            vertical_speed_mps: nominal.touchdown.map(|t| t.vertical_speed_mps),
            propellant_used_kg: nominal.propellant_used_kg,
        },
        figures,
        footprint_3sigma: Ellipse::of(&footprint),
        worst,
        failure_count: failures.len() as u64,
        failures: failures.into_iter().take(200).collect(),
        missing,
        drivers: super::drivers::rank(spec, results, nominal),
    }
}

/// What a merge produced.
pub struct Merged {
    /// The summary written.
    pub summary: Summary,
    /// The results, by index.
    pub results: Vec<CaseResult>,
    /// The nominal run.
    pub nominal: CaseResult,
    /// Touchdown limits of the scenario: vertical and horizontal speed, m/s.
    pub nominal_limits: (f64, f64),
}

/// Reads every case result of the campaign in `store`, with the nominal run.
/// Missing cases are an error unless `partial`.
pub fn collect(
    spec: &CampaignSpec,
    store: &Store,
    nominal: CaseResult,
    partial: bool,
) -> Result<Merged, CampaignError> {
    let mut results = Vec::with_capacity(spec.cases as usize);
    let mut missing = Vec::new();
    for i in 0..spec.cases {
        match store.read_case(i)? {
            Some(r) => results.push(r),
            None => missing.push(i),
        }
    }
    if !missing.is_empty() && !partial {
        let shown: Vec<String> = missing.iter().take(10).map(u64::to_string).collect();
        return Err(CampaignError::Store(format!(
            "{} of {} cases have no result yet (first: {}{}); run the campaign (or its missing shards) again to finish them, or merge with --partial",
            missing.len(),
            spec.cases,
            shown.join(", "),
            if missing.len() > 10 { ", ..." } else { "" }
        )));
    }
    let summary = summarise(spec, &results, &nominal, missing);
    let limits = &spec.base.scenario.touchdown;
    Ok(Merged {
        summary,
        results,
        nominal,
        nominal_limits: (limits.vertical_speed_mps, limits.horizontal_speed_mps),
    })
}

/// Writes `cases.csv` and `summary.json` of `merged` into the store's directory.
pub fn write(store: &Store, merged: &Merged) -> Result<(), CampaignError> {
    write_atomic(
        &store.dir().join("cases.csv"),
        cases_csv(&merged.results, &merged.nominal).as_bytes(),
    )?;
    let json = serde_json::to_string_pretty(&merged.summary)
        .map_err(|e| CampaignError::Store(format!("summary.json: {e}")))?;
    write_atomic(&store.dir().join("summary.json"), (json + "\n").as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_order_statistics() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 1.0), 5.0);
        assert!((quantile(&v, 0.01) - 1.04).abs() < 1e-12);
        let s = FigureStats::of([3.0, f64::NAN, 1.0, 2.0]).unwrap();
        assert_eq!((s.count, s.mean, s.min, s.max), (3, 2.0, 1.0, 3.0));
        assert!((s.std - 1.0).abs() < 1e-12);
        assert!(FigureStats::of([f64::NAN]).is_none());
    }

    #[test]
    fn the_ellipse_of_an_axis_aligned_cloud_has_its_sigmas() {
        // Points at +-a on x and +-b on y: variances a^2/2 . n/(n-1) with 4 points.
        let (a, b) = (30.0, 10.0);
        let pts = [(a, 0.0), (-a, 0.0), (0.0, b), (0.0, -b)];
        let e = Ellipse::of(&pts).unwrap();
        let sx = (2.0 * a * a / 3.0).sqrt();
        let sy = (2.0 * b * b / 3.0).sqrt();
        assert!((e.semi_major_m - 3.0 * sx).abs() < 1e-9);
        assert!((e.semi_minor_m - 3.0 * sy).abs() < 1e-9);
        assert!(e.angle_deg.abs() < 1e-9);
        // Rotated by 90 degrees: the major axis follows.
        let rot: Vec<(f64, f64)> = pts.iter().map(|&(x, y)| (-y, x)).collect();
        assert!((Ellipse::of(&rot).unwrap().angle_deg.abs() - 90.0).abs() < 1e-9);
    }

    #[test]
    fn csv_text_fields_are_quoted() {
        assert_eq!(text("a,b"), "\"a,b\"");
        assert_eq!(text("say \"x\""), "\"say \"\"x\"\"\"");
        assert_eq!(text("plain"), "plain");
    }
}
