//! Issue #24 item 7: property tests of the loaders (the longer fuzz runs are in `fuzz/`).
//! Whatever the input, the profile reader, the configuration loaders, the model file
//! loader and the log reader return a value or an error, never panic; what they accept
//! obeys their rules. And every float the bench writes reads back bit for bit.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::propulsion::hifi::HifiParams;
use oils_emulator::propulsion::surrogate::model_file::ModelFile;
use oils_emulator::propulsion::surrogate::DEFAULT_MODEL_JSON;
use oils_emulator::recorder::{parse_log, Record, Recorder};
use oils_emulator::run_config::RunConfig;
use oils_emulator::session;
use oils_lab::campaign::case::{CaseResult, Touchdown, Trace};
use oils_lab::campaign::Store;
use oils_lab::mcap_log::{export_mcap, parse_mcap};
use oils_shared::profile::{ThrustProfile, MAX_PROFILE_END_S, RATED_THRUST_N};
use proptest::prelude::*;
use std::path::Path;

/// Numbers as files hold them: ordinary, huge, tiny, negative, not finite, not numbers.
fn number_text() -> impl Strategy<Value = String> {
    prop_oneof![
        (-1e4f64..1e4).prop_map(|v| v.to_string()),
        any::<f64>().prop_map(|v| format!("{v:e}")),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("-inf".to_string()),
        Just("1e300".to_string()),
        Just("-0".to_string()),
        Just("".to_string()),
        "[0-9eE.+-]{1,12}",
    ]
}

fn profile_line() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => (
            number_text(),
            prop::collection::vec(number_text(), 4),
            prop::collection::vec(prop_oneof![Just("0"), Just("1"), Just("2"), Just("x")], 4),
        )
            .prop_map(|(t, c, o)| format!("{t},{},{}", c.join(","), o.join(","))),
        1 => Just(String::new()),
        1 => ".{0,40}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    #[test]
    fn profile_reader_never_panics_and_keeps_its_rules(
        lines in prop::collection::vec(profile_line(), 0..30),
        header in prop::bool::weighted(0.9),
    ) {
        let mut text = String::new();
        if header {
            text.push_str("t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n");
        }
        for l in &lines {
            text.push_str(l);
            text.push('\n');
        }
        match ThrustProfile::parse(&text) {
            Ok(p) => {
                let rows = p.rows();
                prop_assert!(!rows.is_empty());
                for w in rows.windows(2) {
                    prop_assert!(w[0].t_ns < w[1].t_ns);
                }
                for r in rows {
                    prop_assert!(r.t_ns >= 0 && r.t_ns as f64 <= MAX_PROFILE_END_S * 1e9);
                    prop_assert!(r.thrust_cmd_n.iter().all(|c| (0.0..=RATED_THRUST_N).contains(c)));
                }
                prop_assert_eq!(ThrustProfile::parse(&p.to_csv()).unwrap(), p);
            }
            Err(e) => {
                prop_assert!(e.line <= text.lines().count());
                prop_assert!(e.to_string().len() < 300, "{}", e);
            }
        }
    }

    #[test]
    fn profile_reader_takes_any_text(text in ".{0,300}") {
        let _ = ThrustProfile::parse(&text);
    }

    #[test]
    fn scenario_and_run_config_loaders_never_panic(
        fields in prop::collection::vec(
            (prop::sample::select(vec![
                "[nav_noise]\nposition_m", "[nav_noise]\naltitude_m", "[touchdown]\nvertical_speed_mps",
                "[touchdown]\nstability_factor", "[initial]\naltitude_m", "[initial]\nhorizontal_speed_m_s",
                "[moon]\nmu_m3_s2", "[propulsion]\nmax_thrust_n", "[propulsion]\ngas_pressure_pa",
                "[lander]\ndry_mass_kg", "[lander]\ninertia_wet_kg_m2",
            ]), number_text()),
            0..4,
        ),
        run_fields in prop::collection::vec(
            (prop::sample::select(vec!["speed", "duration_s", "deadline_frac", "dt_ms", "link_timeout_ms"]), number_text()),
            0..3,
        ),
    ) {
        let scenario: String = fields.iter().map(|(k, v)| format!("{k} = {v}\n")).collect();
        if let Ok(c) = toml::from_str::<ScenarioConfig>(&scenario) {
            if c.validate().is_ok() {
                prop_assert!(c.nav_noise.position_m.is_finite() && c.touchdown.stability_factor.is_finite());
                prop_assert!(c.initial.altitude_m.is_finite() && c.moon.mu_m3_s2.is_finite());
            }
        }
        let mut run: String = run_fields.iter().map(|(k, v)| format!("{k} = {v}\n")).collect();
        run.push_str(&scenario.replace("\n[", "\n[scenario.").replacen('[', "[scenario.", usize::from(scenario.starts_with('['))));
        if let Ok(c) = toml::from_str::<RunConfig>(&run) {
            if c.validate().is_ok() {
                prop_assert!(c.speed.is_finite() && c.duration_s.is_finite());
            }
        }
    }

    #[test]
    fn hifi_parameter_loader_never_panics(
        fields in prop::collection::vec(
            (prop::sample::select(vec![
                "[bottle]\ninitial_pressure_pa", "[bottle]\nvolume_m3", "[bottle]\ninitial_temperature_k",
                "[regulator]\nlockup_pressure_pa", "[tanks]\nnominal_pressure_pa", "[engine]\nthroat_area_m2",
                "[integration]\nsubstep_s", "[helium]\ngamma", "[feed]\nlaminar_flow_frac",
            ]), number_text()),
            0..4,
        ),
    ) {
        let text: String = fields.iter().map(|(k, v)| format!("{k} = {v}\n")).collect();
        if let Ok(p) = toml::from_str::<HifiParams>(&text) {
            if p.validate().is_ok() {
                prop_assert!(p.bottle.initial_pressure_pa <= 1e8);
            }
        }
    }

    #[test]
    fn model_file_loader_never_panics(
        edits in prop::collection::vec((0usize..200_000, number_text()), 1..4),
    ) {
        // Replace the number that starts at or after each offset with another.
        let mut text = DEFAULT_MODEL_JSON.to_string();
        for (at, v) in edits {
            let at = at % text.len();
            let Some(start) = text[at..].find(|c: char| c.is_ascii_digit()).map(|i| i + at) else { continue };
            let end = text[start..]
                .find(|c: char| !(c.is_ascii_digit() || "eE.+-".contains(c)))
                .map_or(text.len(), |i| i + start);
            text.replace_range(start..end, &v);
        }
        if let Ok(f) = ModelFile::parse(&text) {
            prop_assert!(f.model.check().is_ok());
        }
    }

    #[test]
    fn model_file_loader_takes_any_bytes(prefix in 0usize..140_000, tail in ".{0,20}") {
        let cut = prefix.min(DEFAULT_MODEL_JSON.len());
        let cut = (0..=cut).rev().find(|&i| DEFAULT_MODEL_JSON.is_char_boundary(i)).unwrap_or(0);
        let text = format!("{}{tail}", &DEFAULT_MODEL_JSON[..cut]);
        let _ = ModelFile::parse(&text);
    }

    #[test]
    fn log_reader_never_panics(
        flips in prop::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        cut in any::<usize>(),
        garbage in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let bytes = damaged(good_log(), &flips, cut, &garbage);
        if let Ok(log) = parse_log(Path::new("fuzz.oilslog"), &bytes) {
            prop_assert!(log.records.len() + log.damaged_records.len() <= 5);
        }
        let _ = parse_log(Path::new("fuzz.oilslog"), &garbage);
    }

    /// The MCAP reader on a damaged export: an error or a log, never a panic or an abort
    /// (mcap 0.26's own readers did both; `mcap_log` tests keep the two inputs found).
    #[test]
    fn mcap_reader_never_panics(
        flips in prop::collection::vec((any::<usize>(), any::<u8>()), 0..8),
        cut in any::<usize>(),
        garbage in prop::collection::vec(any::<u8>(), 0..64),
    ) {
        let bytes = damaged(good_mcap(), &flips, cut, &garbage);
        if let Ok(log) = parse_mcap(Path::new("fuzz.mcap"), &bytes) {
            prop_assert!(log.records.len() <= 5);
        }
        let _ = parse_mcap(Path::new("fuzz.mcap"), &garbage);
    }
}

/// [`good_log`] exported to MCAP, as bytes.
fn good_mcap() -> Vec<u8> {
    use std::sync::OnceLock;
    static MCAP: OnceLock<Vec<u8>> = OnceLock::new();
    MCAP.get_or_init(|| {
        let path = std::env::temp_dir().join(format!("oils-prop-{}.mcap", std::process::id()));
        let log = parse_log(Path::new("good.oilslog"), &good_log()).unwrap();
        export_mcap(&log, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        bytes
    })
    .clone()
}

/// `bytes` with some flipped, cut short, and garbage appended.
fn damaged(mut bytes: Vec<u8>, flips: &[(usize, u8)], cut: usize, garbage: &[u8]) -> Vec<u8> {
    for &(at, b) in flips {
        let i = at % bytes.len();
        bytes[i] ^= b;
    }
    bytes.truncate(cut % (bytes.len() + 1));
    bytes.extend_from_slice(garbage);
    bytes
}

/// A valid OILSLOG3 log of five records, as bytes.
fn good_log() -> Vec<u8> {
    use std::sync::OnceLock;
    static LOG: OnceLock<Vec<u8>> = OnceLock::new();
    LOG.get_or_init(|| {
        let path = std::env::temp_dir().join(format!("oils-prop-{}.oilslog", std::process::id()));
        let header =
            oils_emulator::session::log_header(&oils_emulator::run_config::RunConfig::default(), 0);
        let rec = Recorder::create(&path, &header).unwrap();
        for k in 0..5u64 {
            let mut r = Record::default();
            r.telemetry.header.step = k;
            r.command.thrust_cmd_n[0] = 400.0;
            rec.record(&r).unwrap();
        }
        rec.finish().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        bytes
    })
    .clone()
}

/// Any finite f64, every bit pattern equally likely (subnormals, huge, -0.0 included).
fn any_finite() -> impl Strategy<Value = f64> {
    any::<u64>()
        .prop_map(f64::from_bits)
        .prop_filter("finite", |x| x.is_finite())
}

/// Any finite f32, by bit pattern.
fn any_finite_f32() -> impl Strategy<Value = f32> {
    any::<u32>()
        .prop_map(f32::from_bits)
        .prop_filter("finite", |x| x.is_finite())
}

/// A run configuration with `x` spread over its float fields (not validated: a writer
/// and its reader must keep whatever they are given).
fn config_with(x: &[f64]) -> RunConfig {
    let mut c = RunConfig {
        speed: x[0],
        duration_s: x[1],
        deadline_frac: x[2],
        ..RunConfig::default()
    };
    let s = &mut c.scenario;
    s.lander.engine_thrust_scale = [x[3], x[4], x[5], x[6]];
    s.lander.engine_misalignment_deg[1][0] = x[7];
    s.initial.altitude_m = x[8];
    s.moon.mu_m3_s2 = x[9];
    s.model_error.bias_n[2] = x[10];
    c.thresholds.max_wake_p99_us = Some(x[11]);
    let mut hifi = HifiParams::default();
    hifi.bottle.initial_pressure_pa = x[0];
    c.hifi = Some(hifi);
    c
}

/// Bit-exact comparison: serde_json writes a float's shortest round-trip digits, which
/// differ for any two bit patterns (0.0 and -0.0 included).
macro_rules! same {
    ($a:expr, $b:expr) => {
        serde_json::to_string($a).unwrap() == serde_json::to_string($b).unwrap()
    };
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Issue #36: `engine_thrust_scale = 0.9985811925219601` came back one ulp off from
    /// a report and a log header (serde_json's default float parser), so `oils replay`
    /// diverged at step 1 and `--config-from` gave another digest; a merge rewrote the
    /// nominal run's figures. Every writer and reader of the bench's floats: the run
    /// configuration as TOML (`--print-config`, `--config`, campaign.toml), as a report's
    /// `config` (`--config-from`), in a log header (`oils replay`), and a campaign's
    /// case and nominal records.
    #[test]
    fn every_float_the_bench_writes_reads_back_bit_for_bit(
        x in prop::collection::vec(any_finite(), 12),
        t in prop::collection::vec(any_finite_f32(), 3),
    ) {
        let dir = std::env::temp_dir().join(format!("oils-prop-floats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cfg = config_with(&x);

        let toml_path = dir.join("run.toml");
        std::fs::write(&toml_path, cfg.to_toml()).unwrap();
        let back = RunConfig::load_toml(&toml_path).unwrap();
        prop_assert!(same!(&back, &cfg), "TOML: {:?}", x);

        // What RunReport::to_json writes around the configuration.
        let report = serde_json::to_string_pretty(&serde_json::json!({
            "run_id": "0000000000000001", "config": cfg, "sim_time_s": x[1],
        })).unwrap();
        let report_path = dir.join("report.json");
        std::fs::write(&report_path, report).unwrap();
        let back = RunConfig::load_from_report(&report_path).unwrap();
        prop_assert!(same!(&back, &cfg), "report: {:?}", x);

        let (back, run_id) = session::read_log_header(&session::log_header(&cfg, 7)).unwrap();
        prop_assert_eq!(run_id, 7);
        prop_assert!(same!(&back, &cfg), "log header: {:?}", x);

        let store = Store::new(&dir.join("campaign"));
        std::fs::create_dir_all(dir.join("campaign/cases")).unwrap();
        for index in [Some(3), None] {
            let record = CaseResult {
                index,
                seed: 1,
                outcome: "landed".into(),
                outcome_reason: None,
                error: None,
                digest: "ab".into(),
                steps: 2,
                sim_time_s: x[0],
                touchdown: Some(Touchdown {
                slope_deg: 0.0,
                roughness_m: 0.0,
                    t_s: x[1],
                    vertical_speed_mps: x[2],
                    horizontal_speed_mps: x[3],
                    tilt_deg: x[4],
                }),
                propellant_used_kg: x[5],
                downrange_m: Some(x[6]),
                crossrange_m: Some(x[7]),
                nav_error: None,
                nav_error_50m: None,
                nav_horizontal_by_altitude: Vec::new(),
                fault_events: 0,
                faults: vec![],
                out_of_envelope: None,
                applied: [("altitude".to_string(), x[8]), ("engine_scale[2]".to_string(), x[9])].into(),
                trace: Trace {
                    t_s: vec![t[0]],
                    altitude_m: vec![t[1]],
                    horizontal_speed_m_s: vec![t[2]],
                    vertical_speed_m_s: vec![t[0]],
                },
                wall_s: x[10],
            };
            store.write_case(&record).unwrap();
            let path = index.map_or(store.nominal_path(), |i| store.case_path(i));
            let back = store.read_result(&path).unwrap().unwrap();
            prop_assert!(same!(&back, &record), "case record: {:?} {:?}", x, t);
        }
    }
}
