//! The run core's contracts:
//! * `regress_*`: the default descent's digest for each propulsion model equals the
//!   frozen one in `tests/data/frozen-digests.toml` (any change of physics, GNC,
//!   protocol or model shows here);
//! * `contract_*`: the same `RunConfig` gives the same digest in process and across two
//!   processes over real iceoryx2; a report repeats its run; a log replays to the same
//!   digest (record == replay); the log carries the true state.

mod common;
use common::*;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::{LinkKind, RunConfig};
use oils_emulator::session;
use std::sync::atomic::AtomicBool;

/// The default run configuration for `model`, in process, without a log.
fn inproc_config(model: PropulsionKind) -> RunConfig {
    let mut cfg = RunConfig {
        link: LinkKind::Inproc,
        propulsion: model,
        ..Default::default()
    };
    cfg.log.enabled = false;
    cfg
}

fn digest_in_process(cfg: &RunConfig) -> String {
    let stop = AtomicBool::new(false);
    let report =
        oils_lab::onboard::fly_in_process(cfg, session::fresh_run_id(), &stop, Default::default())
            .expect("in-process run");
    report.summary.digest
}

fn regress_and_contract(model: PropulsionKind) {
    let cfg = inproc_config(model);
    let inproc = digest_in_process(&cfg);
    assert_eq!(
        inproc,
        frozen_digest(model.as_str()),
        "{}: the default descent's digest moved",
        model.as_str()
    );
    let r = report_across_processes(&format!("contract-{}", model.as_str()), &cfg.to_toml());
    assert_eq!(r["digest"].as_str().unwrap(), inproc);
    assert_eq!(r["link"], "iceoryx2");
    assert_eq!(r["propulsion"], model.as_str());
    assert_eq!(r["config"]["propulsion"], model.as_str());
}

#[test]
fn regress_and_contract_ideal() {
    regress_and_contract(PropulsionKind::Ideal);
}

#[test]
fn regress_and_contract_surrogate() {
    regress_and_contract(PropulsionKind::Surrogate);
}

#[test]
fn regress_and_contract_hifi() {
    regress_and_contract(PropulsionKind::Hifi);
}

#[test]
fn contract_in_process_timing_has_no_transport() {
    let dir = scratch("inproc-timing");
    let rep = dir.join("r.json");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "ideal",
        "--duration",
        "50",
        "--no-log",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = report(&rep);
    let steps = r["steps"].as_u64().unwrap();
    assert_eq!(r["timing"]["round_trip_ns"]["count"], steps);
    assert_eq!(r["timing"]["stub_compute_ns"]["count"], steps);
    assert_eq!(r["timing"]["transport_ns"]["count"], 0);
    assert_eq!(r["wait"], "none");
    assert_eq!(r["link"], "inproc");
}

#[test]
fn contract_a_report_repeats_its_run() {
    let dir = scratch("config-from");
    let first = dir.join("first.json");
    let again = dir.join("again.json");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "ideal",
        "--seed",
        "42",
        "--duration",
        "120",
        "--no-log",
        "--report",
        first.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    // Repeated across processes, from nothing but the report.
    let out = run_oils(&[
        "run",
        "--config-from",
        first.to_str().unwrap(),
        "--link",
        "iceoryx2",
        "--report",
        again.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let (a, b) = (report(&first), report(&again));
    assert_eq!(a["digest"], b["digest"]);
    assert_eq!(b["seed"], 42);
    assert_eq!(b["outcome"], "completed");
    // And a flag given with the file wins over it.
    let other = dir.join("other.json");
    let out = run_oils(&[
        "run",
        "--config-from",
        first.to_str().unwrap(),
        "--seed",
        "43",
        "--report",
        other.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert_ne!(report(&other)["digest"], a["digest"]);
}

#[test]
fn contract_record_equals_replay() {
    let dir = scratch("replay");
    let log = dir.join("run.oilslog");
    let rep = dir.join("run.json");
    let out = run_oils(&[
        "run",
        "--link",
        "iceoryx2",
        "--duration",
        "150",
        "--log",
        log.to_str().unwrap(),
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let replayed = dir.join("replay.json");
    let out = run_oils(&[
        "replay",
        log.to_str().unwrap(),
        "--report",
        replayed.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(report(&rep)["digest"], report(&replayed)["digest"]);

    // An edited header (the run's configuration) is refused by its CRC; one whose CRC
    // was recomputed no longer matches its records and does not replay.
    let bytes = std::fs::read(&log).unwrap();
    assert_eq!(&bytes[..8], b"OILSLOG8");
    let header_len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
    let mut header: serde_json::Value =
        serde_json::from_slice(&bytes[16..16 + header_len]).unwrap();
    header["config"]["seed"] = 1.into();
    let header = header.to_string();
    let forge = |crc: u32| {
        let mut forged = bytes[..8].to_vec();
        forged.extend_from_slice(&(header.len() as u32).to_le_bytes());
        forged.extend_from_slice(&crc.to_le_bytes());
        forged.extend_from_slice(header.as_bytes());
        forged.extend_from_slice(&bytes[16 + header_len..]);
        forged
    };
    let forged_log = dir.join("forged.oilslog");
    let stale_crc = u32::from_le_bytes(bytes[12..16].try_into().unwrap());
    std::fs::write(&forged_log, forge(stale_crc)).unwrap();
    let out = run_oils(&["replay", forged_log.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("header's CRC does not match"),
        "{}",
        text(&out)
    );
    let mut h = 0xffff_ffffu32;
    for b in header.as_bytes() {
        h ^= u32::from(*b);
        for _ in 0..8 {
            h = if h & 1 != 0 {
                (h >> 1) ^ 0xedb8_8320
            } else {
                h >> 1
            };
        }
    }
    std::fs::write(&forged_log, forge(!h)).unwrap();
    let out = run_oils(&["replay", forged_log.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("diverged at step 0"),
        "{}",
        text(&out)
    );
}

#[test]
fn contract_the_log_holds_the_truth_and_checks_itself() {
    let dir = scratch("truth");
    let log = dir.join("run.oilslog");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--propulsion",
        "hifi",
        "--duration",
        "30",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let csv = dir.join("run.csv");
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let body = std::fs::read_to_string(&csv).unwrap();
    let mut lines = body.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    };
    for name in [
        "truth.pos_mci_m[0]",
        "truth.vel_mci_m_s[2]",
        "truth.q_mci_from_body[0]",
        "truth.rate_body_rad_s[0]",
        "truth.mass_kg",
        "truth.altitude_m",
        "truth.contact",
        "propulsion.gas_pressure_pa",
        "propulsion.manifold_pressure_pa[0]",
        "propulsion.fuel_valve_position[0]",
        "propulsion.thrust_n[3]",
        "propulsion.ejected_ox_kg",
        "command.applied.thrust_cmd_n[0]",
    ] {
        col(name);
    }
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        rows.len(),
        3001,
        "30 s of 10 ms steps and the final telemetry"
    );
    // Navigation noise (on by default) is in the telemetry, not in the truth: the
    // noisy altitude differs from the true one, by the noise's size (0.5 m sigma).
    let (alt, true_alt) = (col("telemetry.altitude_m"), col("truth.altitude_m"));
    let diffs: Vec<f64> = rows.iter().map(|r| r[alt] - r[true_alt]).collect();
    assert!(diffs.iter().any(|d| *d != 0.0));
    assert!(diffs.iter().all(|d| d.abs() < 5.0), "{diffs:?}");
    // hifi's internals are there: the manifold holds pressure once the engines run,
    // and the valve strokes lie in [0, 1].
    let last = rows.last().unwrap();
    assert!(last[col("propulsion.manifold_pressure_pa[0]")] > 1e5);
    let v = last[col("propulsion.fuel_valve_position[0]")];
    assert!((0.0..=1.0).contains(&v), "{v}");
    // The true mass falls by the ejected propellant.
    assert!(rows[0][col("truth.mass_kg")] > last[col("truth.mass_kg")]);

    // Records damaged on disk are named by their steps, not exported as data: a byte
    // of the second frame's compressed records flipped damages its records, from step
    // 1024 on.
    let mut bytes = std::fs::read(&log).unwrap();
    let header_len = u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize;
    let body = 16 + header_len;
    let second = oils_emulator::recorder::frames(&bytes[body..]).0[1];
    assert_eq!(
        second.records as usize,
        oils_emulator::recorder::FRAME_RECORDS
    );
    let at = body
        + second.offset
        + oils_emulator::recorder::FRAME_HEADER_SIZE
        + second.packed_len as usize / 2;
    bytes[at] ^= 0x40;
    let damaged = dir.join("damaged.oilslog");
    std::fs::write(&damaged, bytes).unwrap();
    let out = run_oils(&[
        "export",
        damaged.to_str().unwrap(),
        "--csv",
        dir.join("d.csv").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("1024 damaged records") && err.contains("at steps 1024, 1025"),
        "{err}"
    );
}

/// Multi-rate (#32): plant at 5 ms, the surrogate sampled every 10 ms and held, the
/// flight software every 20 ms: the same configuration gives the same digest in process
/// and across processes, over the exchanges of a 20 ms cycle.
#[test]
fn contract_multi_rate_in_process_equals_across_processes() {
    let mut cfg = inproc_config(PropulsionKind::Surrogate);
    cfg.dt_ms = 5;
    cfg.fsw_period_ms = Some(20);
    cfg.duration_s = 60.0;
    let inproc = digest_in_process(&cfg);
    let r = report_across_processes("contract-multi-rate", &cfg.to_toml());
    assert_eq!(r["digest"].as_str().unwrap(), inproc);
    assert_eq!(r["outcome"], "completed");
    assert_eq!(r["steps"], 3000);
    assert_eq!(r["plant_steps"], 12_000);
    // Another period, another run: the schedule is in what the digest covers.
    cfg.fsw_period_ms = Some(10);
    assert_ne!(digest_in_process(&cfg), inproc);
}
