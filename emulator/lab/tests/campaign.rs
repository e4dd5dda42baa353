//! Campaign case construction: draws depend on (master seed, case, name) only, the
//! applied values are the configuration's, model error follows the uncertainty file.

use oils_emulator::propulsion::PropulsionKind;
use oils_lab::campaign::case::{case_setup, load_uncertainty, nominal_config};
use oils_lab::campaign::spec::CampaignSpec;
use std::path::Path;

fn spec(text: &str) -> CampaignSpec {
    CampaignSpec::parse(text, Path::new("test.toml")).unwrap()
}

const A: &str = "[[dispersion]]\nname = \"alt\"\ntargets = [\"scenario.initial.altitude_m\"]\ndist = { kind = \"normal\", mean = 0.0, std = 100.0 }\n";
const B: &str = "[[dispersion]]\nname = \"mass\"\ntargets = [\"scenario.lander.dry_mass_kg\"]\napply = \"scale\"\ndist = { kind = \"uniform\", min = 0.9, max = 1.1 }\n";
const C: &str = "[[dispersion]]\nname = \"rates\"\ntargets = [\"scenario.initial.body_rate_rad_s[0]\", \"scenario.initial.body_rate_rad_s[2]\"]\napply = \"set\"\ndist = { kind = \"choice\", values = [-0.01, 0.01] }\n";

#[test]
fn adding_or_reordering_dispersions_changes_no_other_draw() {
    let head = "cases = 50\nseed = 9\n";
    let ab = spec(&format!("{head}{A}{B}"));
    let cba = spec(&format!("{head}{C}{B}{A}"));
    for i in 0..50 {
        let x = case_setup(&ab, None, i).unwrap();
        let y = case_setup(&cba, None, i).unwrap();
        assert_eq!(x.applied["alt"], y.applied["alt"]);
        assert_eq!(x.applied["mass"], y.applied["mass"]);
        assert_eq!(
            x.config.seed, y.config.seed,
            "the run seed is a stream of its own"
        );
        // Applied values are what the configuration holds.
        assert_eq!(x.config.scenario.initial.altitude_m, x.applied["alt"]);
        assert_eq!(y.config.scenario.initial.body_rate_rad_s[1], 0.0);
        assert!([-0.01, 0.01].contains(&y.applied["rates[0]"]));
        assert_eq!(
            y.config.scenario.initial.body_rate_rad_s[2],
            y.applied["rates[1]"]
        );
    }
    // Another case, another master seed: other draws.
    let a0 = case_setup(&ab, None, 0).unwrap().applied["alt"];
    assert_ne!(a0, case_setup(&ab, None, 1).unwrap().applied["alt"]);
    let other = spec(&format!("cases = 50\nseed = 10\n{A}{B}"));
    assert_ne!(a0, case_setup(&other, None, 0).unwrap().applied["alt"]);
}

#[test]
fn draws_follow_their_distribution() {
    let s = spec(&format!("cases = 2000\nseed = 1\n{A}{B}"));
    let alts: Vec<f64> = (0..2000)
        .map(|i| case_setup(&s, None, i).unwrap().applied["alt"] - 30_000.0)
        .collect();
    let mean = alts.iter().sum::<f64>() / alts.len() as f64;
    let std = (alts.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 1999.0).sqrt();
    // Standard errors: 100/sqrt(2000) = 2.2 m on the mean, ~1.6 % on the std.
    assert!(mean.abs() < 10.0, "{mean}");
    assert!((std - 100.0).abs() < 6.0, "{std}");
    let masses: Vec<f64> = (0..2000)
        .map(|i| case_setup(&s, None, i).unwrap().applied["mass"] / 750.0)
        .collect();
    assert!(masses.iter().all(|m| (0.9..1.1).contains(m)));
}

#[test]
fn the_model_error_is_drawn_from_the_validated_statistics_for_the_surrogate_only() {
    let s = spec("cases = 400\nseed = 2\n[model_error]\n");
    let u = load_uncertainty(&s)
        .unwrap()
        .expect("the committed statistics");
    let steady = u.thrust_n.steady;
    let mut biases = Vec::new();
    for i in 0..400 {
        let c = case_setup(&s, Some(&u), i).unwrap();
        let me = &c.config.scenario.model_error;
        assert!(me.enabled);
        assert_eq!(me.transient_std_n, u.thrust_n.transient.std);
        assert_eq!(me.transient_max_abs_n, u.thrust_n.transient.max_abs);
        for e in 0..4 {
            assert_eq!(c.applied[&format!("model_error_bias_n[{e}]")], me.bias_n[e]);
            assert!(me.bias_n[e].abs() <= steady.max_abs);
            biases.push(me.bias_n[e]);
        }
    }
    let n = biases.len() as f64;
    let mean = biases.iter().sum::<f64>() / n;
    let std = (biases.iter().map(|b| (b - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    assert!(
        (mean - steady.mean).abs() < 4.0 * steady.std / n.sqrt(),
        "{mean}"
    );
    assert!(
        (std / steady.std - 1.0).abs() < 0.1,
        "{std} vs {}",
        steady.std
    );

    let mut hifi = s.clone();
    hifi.base.propulsion = PropulsionKind::Hifi;
    assert!(load_uncertainty(&hifi).unwrap().is_none());
    let c = case_setup(&hifi, None, 0).unwrap();
    assert!(!c.config.scenario.model_error.enabled);
}

#[test]
fn hifi_dispersions_reach_the_hifi_parameters_and_only_for_hifi() {
    let text = "cases = 3\nseed = 4\n[base]\npropulsion = \"hifi\"\n[[dispersion]]\nname = \"set_point\"\ntargets = [\"hifi.regulator.lockup_pressure_pa\"]\nmodels = [\"hifi\"]\ndist = { kind = \"uniform\", min = 1000.0, max = 2000.0 }\n";
    let s = spec(text);
    let c = case_setup(&s, None, 0).unwrap();
    let p = c
        .config
        .hifi
        .as_ref()
        .expect("hifi parameters materialised")
        .regulator
        .lockup_pressure_pa;
    assert!((17.3e5 + 1000.0..17.3e5 + 2000.0).contains(&p), "{p}");
    let mut surrogate = s.clone();
    surrogate.base.propulsion = PropulsionKind::Surrogate;
    let c = case_setup(&surrogate, None, 0).unwrap();
    assert!(c.config.hifi.is_none());
    assert!(c.applied.is_empty());
}

#[test]
fn draws_that_break_the_configuration_make_an_invalid_case() {
    let text = "cases = 3\nseed = 4\n[[dispersion]]\nname = \"mass\"\ntargets = [\"scenario.lander.dry_mass_kg\"]\napply = \"set\"\ndist = { kind = \"uniform\", min = -10.0, max = -5.0 }\n";
    let c = case_setup(&spec(text), None, 0).unwrap();
    let why = c.invalid.expect("a negative dry mass is invalid");
    assert!(why.contains("dry_mass_kg"), "{why}");
}

#[test]
fn faults_strike_with_their_probability_inside_their_window() {
    let text = "cases = 1000\nseed = 5\n[[fault]]\nname = \"out\"\nfault = \"engine-off:1\"\nprobability = 0.3\nwindow_s = [100.0, 200.0]\n";
    let s = spec(text);
    let mut struck = 0;
    for i in 0..1000 {
        let c = case_setup(&s, None, i).unwrap();
        if let Some(t) = c.applied.get("out") {
            struck += 1;
            assert!((100.0..=200.0).contains(t));
            assert_eq!(c.config.faults.len(), 1);
            assert_eq!(c.faults[0], format!("engine-off:1@t={t}"));
        } else {
            assert!(c.config.faults.is_empty());
        }
    }
    // Binomial(1000, 0.3): sd 14.5.
    assert!((struck as i64 - 300).abs() < 60, "{struck}");
    let n = nominal_config(&s);
    assert!(n.faults.is_empty());
}
