//! `oils validate`'s library: the comparison can fail (a perturbed model breaks the
//! bounds, a slightly biased one passes the paper but not the goal), hifi against itself
//! is exact, the JSON has the keys scripts rely on, bad profiles are refused clearly, the
//! transient window is long enough for the hifi model, and the uncertainty file round-trips.

use oils_emulator::config::{PropulsionConfig, ScenarioConfig};
use oils_emulator::propulsion::hifi::{HifiParams, HifiPropulsion};
use oils_emulator::propulsion::{BuildError, EngineCommand, Propulsion, PropulsionOutput};
use oils_lab::validation::cases::{self, CaseKind, WindowKind, TRANSIENT_WINDOW_S};
use oils_lab::validation::compare::run_case;
use oils_lab::validation::report::{Bounds, ValidationReport};
use oils_lab::validation::run_cases;
use oils_lab::validation::uncertainty::ModelUncertainty;

const DT_NS: u64 = 10_000_000;

fn hifi() -> HifiPropulsion {
    HifiPropulsion::new(&HifiParams::default(), &PropulsionConfig::default()).unwrap()
}

/// Hifi with a constant thrust offset on every engine that is producing thrust.
struct Biased {
    inner: HifiPropulsion,
    bias_n: f64,
}

impl Propulsion for Biased {
    fn name(&self) -> &'static str {
        "biased"
    }
    fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
        self.inner.step(cmd, dt_ns);
        self.output()
    }
    fn output(&self) -> PropulsionOutput {
        let mut o = self.inner.output();
        for t in &mut o.thrust_n {
            if *t > 1.0 {
                *t += self.bias_n;
            }
        }
        o
    }
}

fn short_cases() -> Vec<cases::Case> {
    vec![cases::sine(550.0, 3.0), cases::rise()]
}

fn validate_with(bias_n: f64) -> (ValidationReport, Vec<oils_lab::validation::compare::Trace>) {
    let truth = || -> Result<Box<dyn Propulsion>, BuildError> { Ok(Box::new(hifi())) };
    let model = move || -> Result<Box<dyn Propulsion>, BuildError> {
        Ok(Box::new(Biased {
            inner: hifi(),
            bias_n,
        }))
    };
    let bounds = Bounds::PAPER;
    let mass = ScenarioConfig::default().wet_mass_kg();
    let (reports, traces) =
        run_cases(&short_cases(), &truth, &model, DT_NS, mass, &bounds, |_| {}).unwrap();
    let report = ValidationReport::new(
        "test".into(),
        "hifi".into(),
        "none".into(),
        "defaults".into(),
        10.0,
        bounds,
        reports,
    );
    (report, traces)
}

#[test]
fn hifi_against_itself_has_zero_error_and_passes() {
    let (r, _) = validate_with(0.0);
    for c in &r.cases {
        assert_eq!(c.thrust_max_abs_error_n, 0.0, "{}", c.name);
        assert_eq!(c.mass_max_abs_error_kg, 0.0);
        assert_eq!(c.gas_pressure_max_abs_error_pa, 0.0);
        assert!(c.pass && c.pass_goal);
    }
    assert!(r.pass && r.pass_goal);
}

#[test]
fn a_perturbed_model_fails_and_a_slightly_biased_one_misses_only_the_goal() {
    let (bad, _) = validate_with(25.0);
    assert!(!bad.pass && !bad.pass_goal);
    for c in &bad.cases {
        assert!(!c.pass, "{}", c.name);
        assert!((c.thrust_max_abs_error_n - 25.0).abs() < 1e-9);
    }
    // 1.5 N: inside every paper bound (>= 2 N), outside the goal's 1 N for sine/steady.
    let (slight, _) = validate_with(1.5);
    assert!(slight.pass, "{}", slight.table());
    assert!(!slight.pass_goal);
    let rise = &slight.cases[1];
    let steady = rise
        .checks
        .iter()
        .find(|k| k.what.contains("steady"))
        .unwrap();
    assert!(steady.pass && !steady.pass_goal);
    let transient = rise
        .checks
        .iter()
        .find(|k| k.what.contains("transient"))
        .unwrap();
    assert!(transient.pass && transient.pass_goal);
}

#[test]
fn json_report_has_the_required_keys() {
    let (r, _) = validate_with(3.0);
    let v: serde_json::Value = serde_json::from_str(&r.to_json()).unwrap();
    assert_eq!(v["pass"], serde_json::Value::Bool(false));
    assert!(v["pass_goal"].is_boolean());
    let cases = v["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 2);
    for c in cases {
        for key in [
            "name",
            "thrust_max_abs_error_n",
            "thrust_rms_error_n",
            "mass_max_abs_error_kg",
            "gas_pressure_max_abs_error_pa",
            "pass",
            "pass_goal",
        ] {
            assert!(!c[key].is_null(), "missing {key}");
        }
    }
    assert_eq!(cases[1]["windows"][0]["kind"], "transient");
    assert_eq!(cases[1]["windows"][1]["kind"], "steady");
    assert!((v["bounds"]["descent_n"].as_f64().unwrap() - 15.0).abs() < 1e-12);
}

#[test]
fn bad_profiles_are_refused_with_a_clear_error() {
    let dir = std::env::temp_dir().join(format!("oils-validate-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let garbled = dir.join("garbled.csv");
    std::fs::write(
        &garbled,
        "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,600,600,600,600,1,1,1,1\n1,abc,600,600,600,1,1,1,1\n",
    )
    .unwrap();
    // The path, then the reader's error as the source (printed once, by the chain).
    let chain = |e: &dyn std::error::Error| {
        let mut s = e.to_string();
        let mut source = e.source();
        while let Some(c) = source {
            s = format!("{s}: {c}");
            source = c.source();
        }
        s
    };
    let e = chain(&cases::from_path(&garbled, CaseKind::Profile, 800.0).unwrap_err());
    assert!(e.contains("garbled.csv") && e.contains("line 3"), "{e}");
    assert_eq!(e.matches("line 3").count(), 1, "{e}");
    let missing = dir.join("missing.csv");
    let e = cases::from_path(&missing, CaseKind::Profile, 800.0)
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.csv"), "{e}");
    let too_high = dir.join("high.csv");
    std::fs::write(
        &too_high,
        "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,600,600,600,1600,1,1,1,1\n",
    )
    .unwrap();
    let e = chain(&cases::from_path(&too_high, CaseKind::Profile, 800.0).unwrap_err());
    assert!(e.contains("cmd4") && e.contains("1600"), "{e}");
    let ok = dir.join("ok.csv");
    std::fs::write(
        &ok,
        "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,600,600,600,600,1,1,1,1\n1,0,0,0,0,0,0,0,0\n",
    )
    .unwrap();
    let c = cases::from_path(&ok, CaseKind::Profile, 800.0).unwrap();
    assert_eq!(c.name, "profile-ok");
    assert_eq!(c.duration_ns, 3_000_000_000);
    assert_eq!(c.windows[0].kind, WindowKind::Descent);
}

/// The transient window must cover the hifi model's own settling: after it, every
/// engine stays within half the steady bound (1 N) of where the hold ends.
#[test]
fn hifi_settles_within_the_transient_window() {
    let mass = ScenarioConfig::default().wet_mass_kg();
    let mut slowest_s = 0.0f64;
    for case in [cases::rise(), cases::fall()] {
        let mut a = hifi();
        let mut b = hifi();
        let trace = run_case(&case, &mut a, &mut b, DT_NS, mass).unwrap();
        for w in case.windows.chunks(2) {
            let (tr, st) = (w[0], w[1]);
            assert_eq!(
                (tr.kind, st.kind),
                (WindowKind::Transient, WindowKind::Steady)
            );
            let hold: Vec<_> = trace
                .samples
                .iter()
                .filter(|s| s.t_ns > tr.start_ns && s.t_ns <= st.end_ns)
                .collect();
            let last = hold.last().unwrap().truth;
            // Last sample of the hold that is more than 1 N away from the hold's end.
            let settle_ns = hold
                .iter()
                .filter(|s| (0..4).any(|e| (s.truth[e] - last[e]).abs() > 1.0))
                .map(|s| s.t_ns - tr.start_ns)
                .max()
                .unwrap_or(0);
            slowest_s = slowest_s.max(settle_ns as f64 * 1e-9);
        }
    }
    eprintln!("slowest hifi settling to 1 N after a stair: {slowest_s:.2} s");
    assert!(slowest_s > 0.05, "the stairs must move the engines");
    assert!(
        slowest_s <= TRANSIENT_WINDOW_S,
        "hifi needs {slowest_s} s to settle, longer than the transient window"
    );
}

#[test]
fn uncertainty_round_trips_and_knows_its_model() {
    let (_, traces) = validate_with(1.0);
    let bytes = b"model bytes";
    let u = ModelUncertainty::from_traces(&traces, "m.json", bytes, "hifi", 10.0);
    assert!(
        (u.thrust_n.steady.mean - 1.0).abs() < 1e-9,
        "{:?}",
        u.thrust_n.steady
    );
    assert!(u.thrust_n.steady.std < 1e-9);
    assert!(u.thrust_n.transient.count > 0);
    assert_eq!(u.cases.len(), 2);
    let path = std::env::temp_dir().join(format!("oils-unc-{}.json", std::process::id()));
    u.save(&path).unwrap();
    let back = ModelUncertainty::load(&path).unwrap();
    // serde_json parses decimals to within an ulp, not always bit for bit.
    assert_eq!(back.cases.len(), u.cases.len());
    assert_eq!(back.thrust_n.transient.count, u.thrust_n.transient.count);
    assert!((back.thrust_n.transient.mean - u.thrust_n.transient.mean).abs() < 1e-12);
    assert!((back.thrust_n.transient.std - u.thrust_n.transient.std).abs() < 1e-12);
    assert!(back.matches_model(bytes) && !back.matches_model(b"other"));
    std::fs::write(&path, "{\"format\": \"x\"}").unwrap();
    assert!(ModelUncertainty::load(&path).is_err());
    assert_eq!(
        ModelUncertainty::path_beside(std::path::Path::new("a/b/model.json")),
        std::path::Path::new("a/b/model.uncertainty.json")
    );
}
