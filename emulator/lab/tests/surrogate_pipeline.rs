//! The surrogate end to end: the committed default model loads and is what the committed
//! configuration trains (bit for bit); bad model files are refused with a clear error; the
//! runtime tracks its reference model on commands it was not trained on, starts where the
//! reference starts, and counts inputs outside its envelope.

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::HifiPropulsion;
use oils_emulator::propulsion::surrogate::model_file::{ModelFile, ModelFileError};
use oils_emulator::propulsion::surrogate::valve::ValveFilter;
use oils_emulator::propulsion::surrogate::{SurrogatePropulsion, DEFAULT_MODEL_JSON};
use oils_emulator::propulsion::{build, EngineCommand, Propulsion, PropulsionKind, PropulsionSpec};
use oils_lab::training::derive::{self, ValveSpec};
use oils_lab::training::excitation::ExcitationConfig;
use oils_lab::training::{hifi_params_of, train_configured, Quiet, TrainConfig};
use std::path::PathBuf;

/// `emulator/`, which holds the configuration, models and data the lab reads.
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn committed_config() -> TrainConfig {
    let text = std::fs::read_to_string(root().join("config/train.toml")).unwrap();
    TrainConfig::from_toml(&text).unwrap()
}

#[test]
fn retrain_reproduces_committed_model() {
    let cfg = committed_config();
    let outcome = train_configured(&cfg, &Quiet).unwrap();
    // Cross-validation over the whole [cv] grid for every variant, and its choice of
    // penalty inside the grid: at an end, the grid would have cut the search short.
    for res in &outcome.cv {
        let searched: std::collections::BTreeSet<usize> = res.points.iter().map(|p| p.n).collect();
        assert_eq!(
            searched,
            cfg.cv.histories().collect(),
            "{:?}: history lengths searched",
            res.variant
        );
        assert!(
            !res.mu_at_grid_end(),
            "{:?}: the chosen mu {} is at an end of the grid {}..{}",
            res.variant,
            res.chosen().mu,
            cfg.cv.mu_min,
            cfg.cv.mu_max
        );
    }
    let fresh = outcome.deployed_model().to_json();
    let committed = std::fs::read_to_string(root().join("models/surrogate-default.json")).unwrap();
    assert!(
        fresh == committed,
        "retraining emulator/config/train.toml does not reproduce \
         emulator/models/surrogate-default.json; regenerate with \
         `cargo run --release -- train --model emulator/models/surrogate-default.json`"
    );
    // And it is what the binary embeds.
    assert_eq!(committed, DEFAULT_MODEL_JSON);
}

#[test]
fn committed_default_model_loads_and_starts_at_rest() {
    let file = ModelFile::parse(DEFAULT_MODEL_JSON).unwrap();
    let cfg = committed_config();
    let reference = build(&PropulsionSpec::new(cfg.reference, &cfg.propulsion)).unwrap();
    let surrogate = build(&PropulsionSpec::new(
        PropulsionKind::Surrogate,
        &PropulsionConfig::default(),
    ))
    .unwrap();
    assert_eq!(surrogate.name(), "surrogate");
    let (r, s) = (reference.output(), surrogate.output());
    assert_eq!(r.thrust_n, s.thrust_n);
    assert_eq!(r.gas_pressure_pa, s.gas_pressure_pa);
    assert_eq!(r.ejected_kg(), s.ejected_kg());
    assert!(file.sparsity_pct > 0.0 && file.sparsity_pct < 100.0);
    assert_eq!(file.provenance.reference, cfg.reference.as_str());
}

fn refusal(text: &str, bench_step_ns: u64) -> ModelFileError {
    match ModelFile::parse(text) {
        Err(e) => e,
        Ok(f) => f.check_step(bench_step_ns).unwrap_err(),
    }
}

#[test]
fn bad_model_files_are_refused_clearly() {
    let good = DEFAULT_MODEL_JSON;
    assert!(ModelFile::parse(good)
        .unwrap()
        .check_step(10_000_000)
        .is_ok());
    assert_eq!(
        ModelFile::parse(good)
            .unwrap()
            .check_step(20_000_000)
            .unwrap(),
        2
    );

    // One version: any other, older or newer, is refused by name, telling to retrain.
    for (found, text) in [
        (99, good.replacen("\"version\": 8", "\"version\": 99", 1)),
        (7, good.replacen("\"version\": 8", "\"version\": 7", 1)),
        (1, good.replacen("\"version\": 8", "\"version\": 1", 1)),
    ] {
        let e = refusal(&text, 10_000_000);
        assert!(
            matches!(e, ModelFileError::WrongVersion { found: f } if f == found),
            "{e}"
        );
        assert!(e.to_string().contains(&format!("version {found}")), "{e}");
        assert!(e.to_string().contains("retrain with `oils train`"), "{e}");
    }
    // A field this build does not know is refused, wherever it is, never ignored.
    let unknown_at: [&[&str]; 4] = [
        &[],
        &["model"],
        &["model", "submodels", "0", "features"],
        &["model", "submodels", "0", "rows", "0"],
    ];
    for path in unknown_at {
        let mut v: serde_json::Value = serde_json::from_str(good).unwrap();
        let mut at = &mut v;
        for key in path {
            at = match key.parse::<usize>() {
                Ok(i) => &mut at[i],
                Err(_) => &mut at[*key],
            };
        }
        at.as_object_mut()
            .unwrap()
            .insert("added_later".into(), serde_json::json!(1));
        let e = refusal(&v.to_string(), 10_000_000);
        assert!(
            e.to_string().contains("unknown field `added_later`"),
            "{path:?}: {e}"
        );
    }
    // A stroke map that does not rise, or that leaves the park position outside its
    // range, is refused by name.
    let mut bent: serde_json::Value = serde_json::from_str(good).unwrap();
    bent["model"]["submodels"][0]["features"]["valve"]["stroke"]["stroke"][1] =
        serde_json::json!(0.1);
    let e = refusal(&bent.to_string(), 10_000_000);
    assert!(
        e.to_string().contains("stroke map: strokes must rise"),
        "{e}"
    );
    let mut moved: serde_json::Value = serde_json::from_str(good).unwrap();
    moved["model"]["submodels"][0]["features"]["valve"]["stroke"]["first_n"] =
        serde_json::json!(400.0);
    let e = refusal(&moved.to_string(), 10_000_000);
    assert!(e.to_string().contains("outside the stroke map"), "{e}");
    // Taking the valve filter out of a model that reads it leaves features it cannot
    // have: refused, not misread.
    let mut stripped: serde_json::Value = serde_json::from_str(good).unwrap();
    for sub in stripped["model"]["submodels"].as_array_mut().unwrap() {
        sub["features"].as_object_mut().unwrap().remove("valve");
    }
    // The draw changes are summed over the valve filter: that is named first.
    let e = refusal(&stripped.to_string(), 10_000_000);
    assert!(
        e.to_string()
            .contains("valve_sum needs a per-engine layout with a valve filter"),
        "{e}"
    );
    for sub in stripped["model"]["submodels"].as_array_mut().unwrap() {
        sub["features"].as_object_mut().unwrap().remove("valve_sum");
    }
    let e = refusal(&stripped.to_string(), 10_000_000);
    assert!(e.to_string().contains("feature_names has"), "{e}");

    // Phase indicators in a MIMO submodel are refused (they are per-engine features).
    let mimo = good.find("\"layout\": \"mimo\"").expect("a mimo submodel");
    let at = mimo
        + good[mimo..]
            .find("\"start_steps\": 0")
            .expect("start_steps");
    let text = format!(
        "{}\"start_steps\": 3{}",
        &good[..at],
        &good[at + "\"start_steps\": 0".len()..]
    );
    let e = refusal(&text, 10_000_000);
    assert!(e.to_string().contains("per-engine features only"), "{e}");
    // So are draw changes there: a MIMO submodel has no valve filter to sum.
    let text = format!(
        "{}\"start_steps\": 0, \"valve_sum\": true{}",
        &good[..at],
        &good[at + "\"start_steps\": 0".len()..]
    );
    let e = refusal(&text, 10_000_000);
    assert!(
        e.to_string()
            .contains("valve_sum needs a per-engine layout"),
        "{e}"
    );

    let e = refusal(good, 15_000_000);
    assert!(matches!(e, ModelFileError::SampleTime { .. }), "{e}");
    assert!(e.to_string().contains("does not fit the bench step"));

    let truncated = &good[..good.len() / 2];
    let e = refusal(truncated, 10_000_000);
    assert!(matches!(e, ModelFileError::Truncated { .. }), "{e}");

    // A coefficient replaced by NaN (bare), by null (serde_json's NaN) and by an
    // overflowing number.
    let at = good.find("\"coef\": ").unwrap() + "\"coef\": ".len();
    let end = at + good[at..].find(['\n', ',']).unwrap();
    for bad in ["NaN", "null", "1e999"] {
        let text = format!("{}{bad}{}", &good[..at], &good[end..]);
        let e = refusal(&text, 10_000_000);
        assert!(matches!(e, ModelFileError::Invalid(_)), "{bad}: {e}");
        assert!(e.to_string().contains("non-finite"), "{bad}: {e}");
    }

    let other = good.replacen("oils-surrogate", "something-else", 1);
    assert!(matches!(
        refusal(&other, 10_000_000),
        ModelFileError::WrongFormat(_)
    ));

    let missing = std::env::temp_dir().join("oils-no-such-model.json");
    let e = SurrogatePropulsion::from_path(&missing, &PropulsionConfig::default(), 10_000_000)
        .unwrap_err();
    assert!(matches!(e, ModelFileError::Io { .. }));
}

/// Drives reference and surrogate with the same commands; returns the RMS thrust error
/// of the surrogate and of the naive prediction "thrust = command" (over all engines),
/// the largest ejected-mass error, and the surrogate's out-of-envelope count.
fn compare(commands: &[EngineCommand]) -> (f64, f64, f64, u64) {
    let cfg = committed_config();
    let mut reference = build(&PropulsionSpec::new(cfg.reference, &cfg.propulsion)).unwrap();
    let mut surrogate =
        SurrogatePropulsion::default_model(&PropulsionConfig::default(), None).unwrap();
    let (mut se, mut se_naive, mut n) = (0.0, 0.0, 0.0);
    let mut mass_err = 0.0f64;
    for c in commands {
        let r = reference.step(c, 10_000_000);
        let s = surrogate.step(c, 10_000_000);
        for e in 0..4 {
            let cmd = if c.on[e] { c.thrust_cmd_n[e] } else { 0.0 };
            se += (s.thrust_n[e] - r.thrust_n[e]).powi(2);
            se_naive += (cmd - r.thrust_n[e]).powi(2);
            n += 1.0;
        }
        mass_err = mass_err.max((s.ejected_kg() - r.ejected_kg()).abs());
    }
    (
        (se / n).sqrt(),
        (se_naive / n).sqrt(),
        mass_err,
        surrogate.out_of_envelope_steps(),
    )
}

#[test]
fn surrogate_tracks_reference_on_unseen_excitation() {
    // A different seed and time scale than training: new stairs, ramps, switching; one
    // cycle without the long burn (the burn only adds propellant use).
    let ex = ExcitationConfig {
        seed: 12345,
        time_scale: 0.7,
        amplitude_n: 150.0,
        cycles: 2,
        burn_s: 0.0,
        ..committed_config().excitation
    }
    .generate(10_000_000);
    let commands: Vec<EngineCommand> = ex
        .inputs
        .iter()
        .map(oils_lab::training::dataset::command_of)
        .collect();
    let (rmse, naive, mass_err, outside) = compare(&commands);
    // The learned dynamics must explain the reference better than the command does, and
    // keep propellant use within half the paper's 1.5 kg bound. (The transient bounds of
    // the issue are not met yet: docs/surrogate.md reports the held-out errors.)
    assert!(
        rmse < naive,
        "surrogate RMSE {rmse} N vs command-as-thrust {naive} N"
    );
    assert!(mass_err < 0.75, "mass error {mass_err} kg");
    assert_eq!(outside, 0);
}

#[test]
fn commands_outside_the_envelope_are_counted() {
    let inside = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    let mut below = inside;
    below.thrust_cmd_n[1] = 50.0; // on, but far below the 320 N trained on
    let mut s = SurrogatePropulsion::default_model(&PropulsionConfig::default(), None).unwrap();
    for _ in 0..100 {
        s.step(&inside, 10_000_000);
    }
    assert_eq!(
        s.out_of_envelope_steps(),
        0,
        "outside during normal commands"
    );
    for _ in 0..10 {
        s.step(&below, 10_000_000);
    }
    assert_eq!(
        s.out_of_envelope_steps(),
        10,
        "outside after the low commands"
    );
}

#[test]
fn a_bench_step_of_two_samples_is_two_model_steps() {
    // The runtime's fast path (bench step = the model's sample time) and its general path
    // (several samples per bench step) must agree: same end state, the mean of the two
    // trapezoids, flows over the longer step.
    let cfg = PropulsionConfig::default();
    let mut fine = SurrogatePropulsion::default_model(&cfg, None).unwrap();
    let mut coarse = SurrogatePropulsion::default_model(&cfg, Some(20_000_000)).unwrap();
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true, true, false, true],
    };
    // Before any step: no flows, and the mean thrust is the thrust.
    for s in [&fine, &coarse] {
        let at_rest = s.output();
        assert_eq!(at_rest.mean_thrust_n, at_rest.thrust_n);
        assert_eq!((at_rest.fuel_flow_kg_s, at_rest.ox_flow_kg_s), (0.0, 0.0));
    }
    for k in 0..300u32 {
        cmd.thrust_cmd_n[(k % 4) as usize] = 350.0 + f64::from(k % 7) * 60.0;
        cmd.on[2] = k > 40;
        let before = fine.output();
        let a = fine.step(&cmd, 10_000_000);
        let b = fine.step(&cmd, 10_000_000);
        let c = coarse.step(&cmd, 20_000_000);
        // `output()` is recomputed from the latest step, not stored: it must be what the
        // step returned, on either path.
        assert_eq!(fine.output(), b, "step {k}");
        assert_eq!(coarse.output(), c, "step {k}");
        assert_eq!(c.thrust_n, b.thrust_n, "step {k}");
        assert_eq!(c.ejected_fuel_kg, b.ejected_fuel_kg);
        assert_eq!(c.gas_pressure_pa, b.gas_pressure_pa);
        for e in 0..4 {
            let trapezoids =
                0.5 * (before.thrust_n[e] + a.thrust_n[e]) + 0.5 * (a.thrust_n[e] + b.thrust_n[e]);
            assert_eq!(
                a.mean_thrust_n[e],
                0.5 * (before.thrust_n[e] + a.thrust_n[e])
            );
            assert_eq!(c.mean_thrust_n[e], trapezoids / 2.0);
        }
        let flow = (b.ejected_fuel_kg - before.ejected_fuel_kg) / 0.02;
        assert!((c.fuel_flow_kg_s - flow).abs() <= 1e-9 * flow.abs().max(1e-3));
        let fine_flow = (a.ejected_ox_kg - before.ejected_ox_kg) / 0.01;
        assert!((a.ox_flow_kg_s - fine_flow).abs() <= 1e-9 * fine_flow.abs().max(1e-3));
    }
}

#[test]
fn bad_penalties_in_a_training_configuration_are_refused_clearly() {
    let text = std::fs::read_to_string(root().join("config/train.toml")).unwrap();
    assert!(
        text.contains("\nsystem_mu = 1e-3\n"),
        "the committed setting moved"
    );
    for (bad, key) in [
        ("system_mu = -1e-3", "variants.system_mu = -0.001"),
        ("system_mu = 0.0", "variants.system_mu = 0"),
        ("system_mu = nan", "variants.system_mu = NaN"),
    ] {
        let edited = text.replace("\nsystem_mu = 1e-3\n", &format!("\n{bad}\n"));
        let err = TrainConfig::from_toml(&edited).unwrap_err().to_string();
        assert!(
            err.contains(key) && err.contains("positive"),
            "{bad}: unclear error {err:?}"
        );
    }
    // Without it, the penalty multiple applies again (and is checked).
    let without = text.replace("\nsystem_mu = 1e-3\n", "\n");
    let cfg = TrainConfig::from_toml(&without).unwrap();
    assert_eq!(cfg.variants.system_mu, None);
    let zero_scale = without.replace("system_mu_scale = 10.0", "system_mu_scale = 0.0");
    let err = TrainConfig::from_toml(&zero_scale).unwrap_err().to_string();
    assert!(err.contains("variants.system_mu_scale"), "{err}");
}

#[test]
fn draw_changes_without_a_valve_filter_are_refused_clearly() {
    let text = std::fs::read_to_string(root().join("config/train.toml")).unwrap();
    assert!(
        TrainConfig::from_toml(&text)
            .unwrap()
            .variants
            .engine_valve_sum
    );
    // Without the valve filter there is nothing to sum.
    let start = text
        .find("[variants.engine_valve]")
        .expect("a valve filter section");
    let without_valve = &text[..start];
    assert!(!without_valve.contains("[variants.engine_valve"));
    let err = TrainConfig::from_toml(without_valve)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("engine_valve_sum") && err.contains("engine_valve]"),
        "unclear error {err:?}"
    );
}

#[test]
fn a_fixed_penalty_ignores_the_variant_penalty() {
    use oils_lab::training::fit::{sub_specs, Penalty, Variant};
    let cfg = committed_config();
    let specs = sub_specs(Variant::SharedEngine, 2, &cfg.variants);
    assert_eq!(specs[0].penalty, Penalty::Scaled(1.0));
    assert_eq!(specs[1].penalty, Penalty::Fixed(1e-3));
    for mu in [1e-6, 1e-5, 1.0] {
        assert_eq!(specs[0].penalty.at(mu), mu);
        assert_eq!(specs[1].penalty.at(mu), 1e-3);
    }
    let mut scaled = cfg.variants.clone();
    scaled.system_mu = None;
    let specs = sub_specs(Variant::SharedEngine, 2, &scaled);
    assert_eq!(specs[1].penalty.at(1e-5), 1e-5 * scaled.system_mu_scale);
}

/// The valve filter of the committed configuration with its stroke table derived from
/// hifi, and the committed model's ignition clock (fitting one takes a while).
fn committed_valve(cfg: &TrainConfig) -> ValveFilter {
    let spec = cfg.variants.engine_valve_spec.expect("a valve filter");
    let params = hifi_params_of(cfg).unwrap();
    let grid = spec.stroke.expect("a stroke table");
    let stroke = derive::stroke_table(&grid, &params, &cfg.propulsion).unwrap();
    let clock = ModelFile::parse(DEFAULT_MODEL_JSON)
        .unwrap()
        .model
        .submodels
        .iter()
        .find_map(|s| s.features.valve.and_then(|v| v.ignition));
    let plain = ValveSpec {
        stroke: None,
        ignition: None,
        ..spec
    };
    ValveFilter {
        stroke: Some(stroke),
        ignition: clock,
        ..plain.plain().unwrap()
    }
}

/// The stroke table `oils train` derives is hifi's calibration: it spans the throttle
/// range, its slope is the segments' to 0.5 %, and it is far from linear (which is why
/// it is there).
#[test]
fn the_stroke_map_is_hifis_calibration() {
    let cfg = committed_config();
    let map = committed_valve(&cfg).stroke.unwrap();
    let hifi = HifiPropulsion::new(&hifi_params_of(&cfg).unwrap(), &cfg.propulsion).unwrap();
    for (k, s) in map.strokes().iter().enumerate() {
        let [fuel, ox] = hifi
            .throttle_table()
            .positions(map.first_n() + map.step_n() * k as f64);
        assert_eq!(*s, 0.5 * (fuel + ox));
    }
    assert_eq!(
        (map.first_n(), map.last_n()),
        (
            cfg.propulsion.throttle_min_frac * cfg.propulsion.max_thrust_n,
            cfg.propulsion.max_thrust_n
        )
    );
    let worst = map
        .segment_slopes()
        .map(|(t, k)| (map.slope_at(t) / k - 1.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.005, "slope off by {:.2} %", 100.0 * worst);
    assert!(map.slope_at(map.first_n()) > 2.0 * map.slope_at(map.last_n()));
}

/// What `oils train` derives from hifi follows hifi's parameters: with the regulator set
/// 1 bar higher (lock-up and the tanks' regulated pressure, which hifi's calibration
/// assumes), every knot of the stroke table opens less (more pressure across the valve
/// for the same thrust), and the ignition clock fitted to that hifi differs from the
/// default one and places its ignitions at least as well as the stale clock does. (2 bar
/// lower, hifi's valves cannot reach full thrust: its calibration refuses.)
#[test]
fn derived_constants_follow_a_changed_regulator_set_point() {
    let cfg = committed_config();
    let spec = cfg.variants.engine_valve_spec.expect("a valve filter");
    let base = hifi_params_of(&cfg).unwrap();
    let mut high = base.clone();
    high.regulator.lockup_pressure_pa += 1e5;
    high.tanks.nominal_pressure_pa += 1e5;
    let dt_s = cfg.sample_time_ns as f64 * 1e-9;
    let (f0, fit0) = spec.derive(&base, &cfg.propulsion, dt_s).unwrap();
    let (f1, fit1) = spec.derive(&high, &cfg.propulsion, dt_s).unwrap();
    let (s0, s1) = (f0.stroke.unwrap(), f1.stroke.unwrap());
    for (k, (a, b)) in s0.strokes().iter().zip(s1.strokes()).enumerate() {
        assert!(b < a, "knot {k}: stroke {b} at 18 bar, {a} at 17 bar");
    }
    let (fit0, fit1) = (fit0.unwrap(), fit1.unwrap());
    eprintln!("17 bar: {fit0}\n18 bar: {fit1}");
    let c = |f: &derive::ClockFit| {
        (
            f.clock.fill_n_s,
            f.clock.sag_per_n,
            f.clock.priming_sag_per_n,
        )
    };
    assert_ne!(c(&fit0), c(&fit1));
    let without_clock = ValveFilter {
        ignition: None,
        ..f1
    };
    let (_, stale_rms_s, _) =
        derive::clock_spread(&without_clock, fit0.clock, &high, &cfg.propulsion, dt_s).unwrap();
    eprintln!(
        "the 17 bar clock on the 18 bar hifi: spread RMS {:.2} ms",
        stale_rms_s * 1e3
    );
    assert!(fit1.rms_s <= stale_rms_s);
    // Both fits place hifi's ignitions within a few milliseconds (one 10 ms step).
    assert!(fit0.rms_s < 2e-3 && fit1.rms_s < 2e-3);
}

/// The model inputs of a validation case, step by 10 ms step, with each step's start.
fn case_inputs(
    case: &oils_lab::validation::cases::Case,
) -> impl Iterator<
    Item = (
        i64,
        oils_emulator::propulsion::surrogate::features::InputVec,
    ),
> + '_ {
    use oils_emulator::propulsion::surrogate::input_of;
    use oils_lab::validation::compare::command_at;
    (0..case.duration_ns)
        .step_by(10_000_000)
        .map(|t_ns| (t_ns, input_of(&command_at(case, t_ns))))
}

/// With the stroke map, the valve filter follows hifi's own TFCV element run in stroke
/// through hifi's calibration table (lag, rate and backlash from hifi's parameters,
/// without quantisation), on the validation cases' commands: within 0.15 N RMS once the
/// starts are over and within 3 N at worst (measured 0.096 N and 2.4 N; the worst is in
/// a large step, where the filter takes one slope per step). The filter without the map
/// is checked the same way and strays several times further (0.73 N, 22 N): the map is
/// what brings it there.
#[test]
fn the_valve_filter_follows_hifis_valve_in_stroke() {
    use oils_emulator::propulsion::hifi::engine::{Tfcv, TfcvDynamics};
    use oils_emulator::propulsion::surrogate::valve::ValveTrack;
    use oils_lab::validation::cases::builtin;

    let cfg = committed_config();
    let filter = committed_valve(&cfg);
    let params = hifi_params_of(&cfg).unwrap();
    let hifi = HifiPropulsion::new(&params, &cfg.propulsion).unwrap();
    let e = &params.engine;
    let stroke_dynamics = TfcvDynamics {
        tau_s: e.tfcv_time_constant_s,
        rate_per_s: 1.0 / e.tfcv_full_stroke_s,
        half_backlash: 0.5 * e.tfcv_backlash_frac,
        quantum: 0.0,
    };
    let dt_s = 0.01;
    let decay = (-dt_s / e.tfcv_time_constant_s).exp();
    let stroke_of = |t: f64| {
        let [fuel, ox] = hifi.throttle_table().positions(t);
        0.5 * (fuel + ox)
    };
    // The inverse of the table's mean, by bisection over the throttle range.
    let thrust_of = |s: f64| {
        let (mut lo, mut hi) = (320.0, 800.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if stroke_of(mid) < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    // (worst, RMS after 3 s) over all cases, with and without the map.
    let stray = |filter: oils_emulator::propulsion::surrogate::valve::ValveFilter| {
        let (mut worst, mut sum2, mut n) = (0.0f64, 0.0, 0.0);
        for case in builtin() {
            let mut track = ValveTrack::new(filter, dt_s);
            let rest = stroke_of(filter.park_n);
            let mut valves = [Tfcv {
                target: rest,
                actuator: rest,
                valve: rest,
            }; 4];
            for (t_ns, u) in case_inputs(&case) {
                let s = track.advance(&u);
                for (e, v) in valves.iter_mut().enumerate() {
                    v.target = stroke_of(u[e].max(filter.park_n));
                    v.advance(dt_s, &stroke_dynamics, decay);
                    let off_n = (thrust_of(v.valve) - s.valve_n[e]).abs();
                    worst = worst.max(off_n);
                    if t_ns >= 3_000_000_000 {
                        sum2 += off_n * off_n;
                        n += 1.0;
                    }
                }
            }
        }
        (worst, (sum2 / n).sqrt())
    };
    let (worst_n, rms_n) = stray(filter);
    let (plain_worst_n, plain_rms_n) =
        stray(oils_emulator::propulsion::surrogate::valve::ValveFilter {
            stroke: None,
            ..filter
        });
    eprintln!(
        "valve filter against hifi's valve: worst {worst_n:.2} N, RMS {rms_n:.3} N; \
         without the map {plain_worst_n:.2} N, {plain_rms_n:.3} N"
    );
    assert!(worst_n < 3.0 && rms_n < 0.15, "{worst_n} N, {rms_n} N");
    assert!(plain_rms_n > 3.0 * rms_n && plain_worst_n > 3.0 * worst_n);

    // Beside the map, the ignition clock integrates the filter in newtons: the same
    // bits, and the same clock, as the filter without the map.
    let plain = oils_emulator::propulsion::surrogate::valve::ValveFilter {
        stroke: None,
        ..filter
    };
    for case in builtin() {
        let (mut with_map, mut without) =
            (ValveTrack::new(filter, dt_s), ValveTrack::new(plain, dt_s));
        for (t_ns, u) in case_inputs(&case) {
            let (a, b) = (*with_map.advance(&u), *without.advance(&u));
            assert_eq!(a.clock.valve, b.valve_n, "{} at {t_ns} ns", case.name);
            assert_eq!(a.clock.actuator, b.actuator_n);
            assert_eq!(a.since_ignition_s, b.since_ignition_s);
            assert_eq!(a.fill, b.fill);
        }
    }
}

/// A bad stroke map in a training configuration is refused with the reason and where it
/// is; without one the filter works in newtons.
#[test]
fn bad_stroke_maps_in_a_training_configuration_are_refused_clearly() {
    let text = std::fs::read_to_string(root().join("config/train.toml")).unwrap();
    assert!(
        text.contains("\nstep_n = 40.0\n"),
        "the committed grid moved"
    );
    let edited = text.replacen("\nstep_n = 40.0\n", "\nstep_n = 0.0\n", 1);
    let err = TrainConfig::from_toml(&edited).unwrap_err().to_string();
    assert!(err.contains("positive") && err.contains("stroke"), "{err}");
    // A grid that does not divide the throttle range is refused when derived.
    let edited = text.replacen("\nstep_n = 40.0\n", "\nstep_n = 70.0\n", 1);
    let cfg = TrainConfig::from_toml(&edited).unwrap();
    let params = hifi_params_of(&cfg).unwrap();
    let err = cfg.resolve(Some(&params)).unwrap_err().to_string();
    assert!(err.contains("does not divide the throttle range"), "{err}");
    // Without the table the filter works in newtons (and still has its clock to derive).
    let start = text.find("[variants.engine_valve.stroke]").unwrap();
    let end = text.find("[variants.engine_valve.ignition]").unwrap();
    let without = format!("{}{}", &text[..start], &text[end..]);
    let cfg = TrainConfig::from_toml(&without).unwrap();
    let spec = cfg.variants.engine_valve_spec.unwrap();
    assert!(spec.stroke.is_none() && spec.ignition.is_some());
    // Such a spec needs hifi: without it, it is refused by name rather than half used.
    let err = spec.plain().unwrap_err();
    assert!(err.contains("derived from the hifi reference"), "{err}");
}

/// A closed form: trained on the `ideal` propulsion, each engine's first-order lag
/// `T[t] = a T[t-1] + (1 - a) T_r[t]` with `a = exp(-dt / tau)` (the exact discretisation
/// of its commanded step), the paper variant recovers the pole `a`. The stored
/// coefficients act on scaled features, so a raw weight is the coefficient over that
/// feature's standard deviation. With n = 1 the representation is unique and engine e's
/// row weighs its own `T_o{e}[t-1]` by `a`; with the n that CV picks (n = 1..3) the lag
/// has many exact representations (any multiple of the previous step's equation can be
/// added), so the check is that `a` is a root of the row's own-thrust polynomial
/// `z^n - c_1 z^(n-1) - ... - c_n` (the other roots cancel against the command's).
/// Tolerance 1e-6 on a = 0.819 (dt 10 ms, tau 50 ms): the data is exact, so what
/// remains is the Lasso's shrinkage at the chosen penalty (measured below 1e-8). The
/// solver's settings are the defaults: the active-set solver ends at the optimality
/// conditions whatever the gap tolerance (coordinate descent stopped some 3e-3 short at
/// the committed 1e-4, and this test used to solve to 1e-10 with 200 000 sweeps). The
/// lag's many exact representations make the terms exactly collinear, which the solver
/// meets by swapping terms (`lasso.rs`, `swap_in`).
#[test]
fn trained_on_a_first_order_lag_the_paper_variant_recovers_its_pole() {
    use oils_lab::training::{fit::Variant, Deploy};
    let train = |history_max: usize| {
        let mut cfg = TrainConfig {
            reference: PropulsionKind::Ideal,
            train_variants: vec![Variant::Paper],
            deploy: Deploy::Paper,
            ..TrainConfig::default()
        };
        cfg.cv.history_max = history_max;
        cfg.cv.mu_min = 1e-8;
        cfg.cv.mu_max = 1e-2;
        cfg.cv.mu_count = 7;
        let file = train_configured(&cfg, &Quiet)
            .unwrap()
            .deployed_model()
            .clone();
        let dt_s = cfg.sample_time_ns as f64 * 1e-9;
        (file, (-dt_s / cfg.propulsion.thrust_lag_s).exp())
    };
    for history_max in [1, 3] {
        let (file, want) = train(history_max);
        let sub = &file.model.submodels[0];
        let n = file.selection.history;
        eprintln!(
            "CV over n = 1..{history_max} chose n = {n}, mu = {:e}; exp(-dt/tau) = {want:.6}",
            file.selection.mu
        );
        for e in 1..=4 {
            let row = sub
                .rows
                .iter()
                .find(|r| r.output == format!("T_o{e}"))
                .expect("a thrust row per engine");
            // The linear weight of a feature in this row, per unit of the raw feature.
            let weight = |name: &str| {
                let j = sub.feature_names.iter().position(|x| x == name).unwrap();
                row.terms
                    .iter()
                    .find(|t| t.name == name)
                    .map_or(0.0, |t| t.coef / sub.feature_std[j])
            };
            let c: Vec<f64> = (1..=n).map(|k| weight(&format!("T_o{e}[t-{k}]"))).collect();
            // Roots of z^n - c_1 z^(n-1) - ... - c_n: the companion matrix's eigenvalues.
            let companion = nalgebra::DMatrix::from_fn(n, n, |i, j| {
                if i == 0 {
                    c[j]
                } else {
                    f64::from(u8::from(j + 1 == i))
                }
            });
            let roots = companion.complex_eigenvalues();
            let nearest = roots
                .iter()
                .map(|z| ((z.re - want).powi(2) + z.im.powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min);
            eprintln!("engine {e}: own-thrust weights {c:?}, roots {roots:?}");
            assert!(
                nearest < 1e-3,
                "engine {e}: no root within 1e-3 of {want}: {roots:?}"
            );
            if n == 1 {
                assert!((c[0] - want).abs() < 1e-6, "engine {e}: {} vs {want}", c[0]);
                for other in sub.feature_names.iter().filter(|x| x.starts_with("T_o")) {
                    if *other != format!("T_o{e}[t-1]") {
                        assert!(weight(other).abs() < 1e-6, "engine {e}: {other}");
                    }
                }
            }
        }
    }
}

/// Issue #24: a coefficient of 1e300 loaded, and the plant turned NaN after one step.
/// Every number in a model file is bounded, and named when it is not.
#[test]
fn huge_model_numbers_are_refused_by_name() {
    let good = DEFAULT_MODEL_JSON;
    type Edit = fn(&mut serde_json::Value);
    let edits: [(&str, Edit); 5] = [
        ("coefficient", |v| {
            v["model"]["submodels"][0]["rows"][0]["terms"][0]["coef"] = serde_json::json!(1e300)
        }),
        ("intercept", |v| {
            v["model"]["submodels"][1]["rows"][0]["intercept"] = serde_json::json!(-1e300)
        }),
        ("scaling or envelope", |v| {
            v["model"]["submodels"][0]["feature_std"][0] = serde_json::json!(1e-300)
        }),
        ("scaling or envelope", |v| {
            v["model"]["submodels"][0]["envelope_hi"][0] = serde_json::json!(1e200)
        }),
        ("initial state", |v| {
            v["model"]["initial_state"][0] = serde_json::json!(1e200)
        }),
    ];
    for (what, edit) in edits {
        let mut v: serde_json::Value = serde_json::from_str(good).unwrap();
        edit(&mut v);
        let e = refusal(&v.to_string(), 10_000_000);
        assert!(
            matches!(e, ModelFileError::Invalid(_)) && e.to_string().contains(what),
            "{what}: {e}"
        );
    }
}
