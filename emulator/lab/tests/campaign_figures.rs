//! A campaign's figures and page from synthetic results (no descent flown): the
//! footprint ellipse is the landed cases', the drivers name the cause of the failures,
//! every figure is written and the page embeds each of them.

use oils_lab::campaign::case::{CaseResult, Touchdown, Trace};
use oils_lab::campaign::plots;
use oils_lab::campaign::spec::CampaignSpec;
use oils_lab::campaign::summary::{summarise, Merged};
use rand::{Rng, SeedableRng};
use std::path::Path;

fn spec(extra: &str) -> CampaignSpec {
    CampaignSpec::parse(
        &format!("name = \"synthetic\"\ncases = 200\nseed = 1\n{extra}"),
        Path::new("t.toml"),
    )
    .unwrap()
}

/// A case that came down at (downrange, crossrange) metres from the nominal's.
fn case(index: Option<u64>, landed: bool, at_m: (f64, f64), applied: &[(&str, f64)]) -> CaseResult {
    CaseResult {
        index,
        seed: 0,
        outcome: if landed { "landed" } else { "crashed" }.into(),
        outcome_reason: None,
        error: None,
        digest: "0123".into(),
        steps: 100,
        sim_time_s: 900.0,
        touchdown: Some(Touchdown {
            t_s: 900.0,
            vertical_speed_mps: if landed {
                0.93 + 1e-4 * at_m.0 / 100.0
            } else {
                60.0
            },
            horizontal_speed_mps: if landed {
                0.1 + (at_m.1 / 1e4).abs()
            } else {
                300.0
            },
            tilt_deg: 0.2,
            slope_deg: 1.0,
            roughness_m: 0.05,
        }),
        propellant_used_kg: 890.0 + at_m.0 / 1000.0,
        downrange_m: Some(at_m.0),
        crossrange_m: Some(at_m.1),
        nav_error: None,
        nav_error_50m: None,
        nav_horizontal_by_altitude: Vec::new(),
        fault_events: 0,
        faults: vec![],
        out_of_envelope: None,
        applied: applied.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        trace: Trace {
            t_s: vec![0.0, 450.0, 900.0],
            altitude_m: vec![30_000.0, 5000.0, 0.0],
            horizontal_speed_m_s: vec![1600.0, 200.0, 0.1],
            vertical_speed_m_s: vec![0.0, -50.0, -0.9],
        },
        wall_s: 0.0,
    }
}

/// 200 cases: landed ones spread 1 km by 300 m, 10 crashes 400 km away, all caused by
/// `cause` above 0.95; `noise` moves the landing point only.
fn campaign(spec: &CampaignSpec) -> Merged {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let nominal = case(None, true, (0.0, 0.0), &[]);
    let results: Vec<CaseResult> = (0..200)
        .map(|i| {
            let cause: f64 = rng.gen_range(0.0..1.0);
            let noise: f64 = rng.gen_range(-1.0..1.0);
            let dither: f64 = rng.gen_range(-1.0..1.0);
            let landed = cause <= 0.95;
            let at = if landed {
                (500.0 * noise, 150.0 * dither)
            } else {
                (400_000.0, -20_000.0)
            };
            case(
                Some(i),
                landed,
                at,
                &[("cause", cause), ("noise", noise), ("dither", dither)],
            )
        })
        .collect();
    let summary = summarise(spec, &results, &nominal, vec![]);
    Merged {
        summary,
        results,
        nominal,
        nominal_limits: (2.0, 0.5),
    }
}

#[test]
fn the_footprint_ellipse_is_the_landed_cases_not_set_by_crashes() {
    let s = spec("");
    let m = campaign(&s);
    assert!(m.summary.outcomes["crashed"] > 0);
    let e = m.summary.footprint_3sigma.as_ref().unwrap();
    // Landed: uniform over +-500 m downrange (sigma 289 m): 3 sigma is about 870 m.
    // With the crashes 400 km away it would be tens of kilometres.
    assert!(e.semi_major_m < 1200.0, "{e:?}");
    assert!(e.centre_m[0].abs() < 100.0, "{e:?}");
}

#[test]
fn the_drivers_in_the_summary_name_the_cause_of_the_failures_first() {
    let s = spec("");
    let m = campaign(&s);
    let d = &m.summary.drivers;
    assert_eq!(d[0].name, "cause", "{d:#?}");
    assert!(d[0].failure_rho.unwrap() > 0.3, "{:?}", d[0]);
    let json = serde_json::to_value(&m.summary).unwrap();
    assert_eq!(json["drivers"][0]["name"], "cause");
    assert!(json["drivers"][0]["figures"]["site_error_m"].is_number());
}

#[test]
fn every_figure_is_written_and_the_page_embeds_each() {
    let s = spec("[requirements]\nfootprint_m = [1500.0, 600.0]\n");
    let m = campaign(&s);
    let dir = std::env::temp_dir().join(format!("oils-campaign-figures-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let written = plots::write_all(&s, &m, &dir.join("plots")).unwrap();
    assert_eq!(written.len(), plots::FIGURES.len());
    for p in &written {
        let bytes = std::fs::read(p).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{}", p.display());
    }
    let page = oils_lab::report_page::write_campaign(&s, &m, &dir, &written).unwrap();
    assert_eq!(page, dir.join("report.html"));
    let html = std::fs::read_to_string(&page).unwrap();
    assert_eq!(html.matches("<img ").count(), written.len());
    assert_eq!(
        html.matches("src=\"data:image/png;base64,").count(),
        written.len()
    );
    assert!(!html.contains("http://") && !html.contains("https://"));
    // The drivers table, the worst cases with their commands, the spec.
    assert!(html.contains("<td class=\"l\">cause</td>"));
    assert!(html.contains("oils mc case"));
    assert!(html.contains("footprint_m"));
    assert!(html.contains("Requirement zone 1500 m by 600 m"));
    std::fs::remove_dir_all(&dir).unwrap();
}
