//! Protocol v2's devices through a whole run:
//! * `regress_*`: a descent with the devices on (`--telemetry both`) has the frozen digest
//!   of `tests/data/frozen-digests.toml` and the same digest across two processes over
//!   real iceoryx2 as in process;
//! * the flight software sees device samples, not the ideal navigation, with
//!   `--telemetry sensors`, and the CSV export carries them beside the truth;
//! * a configuration whose devices do not fit the schedule, or a reference GNC asked to
//!   fly without its navigation source, is refused before tick 0 with the reason.

mod common;
use common::*;
use oils_emulator::propulsion::PropulsionKind;
use oils_emulator::run_config::{LinkKind, RunConfig, TelemetrySource};
use oils_emulator::session;
use std::path::Path;
use std::sync::atomic::AtomicBool;

/// The default descent with the devices on beside the ideal navigation, ideal propulsion.
fn sensors_config() -> RunConfig {
    let mut cfg = RunConfig {
        link: LinkKind::Inproc,
        propulsion: PropulsionKind::Ideal,
        telemetry: TelemetrySource::Both,
        dt_ms: 5,
        ..Default::default()
    };
    cfg.log.enabled = false;
    cfg
}

#[test]
fn regress_and_contract_with_sensors_on() {
    let cfg = sensors_config();
    let stop = AtomicBool::new(false);
    let run =
        oils_lab::onboard::fly_in_process(&cfg, session::fresh_run_id(), &stop, Default::default())
            .expect("in-process run");
    assert_eq!(format!("{:?}", run.summary.outcome), "Landed");
    let inproc = run.summary.digest;
    assert_eq!(
        inproc,
        frozen_digest("ideal_sensors"),
        "the descent with the devices on moved"
    );

    let r = report_across_processes("sensors-contract", &cfg.to_toml());
    assert_eq!(r["digest"].as_str().unwrap(), inproc);
    assert_eq!(r["config"]["telemetry"], "both");
}

/// Flies the descent profile open loop (`--fsw playback`, ideal propulsion) with
/// `--telemetry sensors` for `duration` seconds plus `extra` flags, exports the log as
/// CSV and returns its header and rows.
fn fly_sensors_to_csv(
    name: &str,
    duration: &str,
    extra: &[&str],
) -> (Vec<String>, Vec<Vec<String>>) {
    let dir = scratch(name);
    let log = dir.join("run.oilslog");
    let csv = dir.join("run.csv");
    let profile = Path::new(env!("CARGO_MANIFEST_DIR")).join("emulator/data/descent-profile.csv");
    let mut args = vec![
        "run",
        "--link",
        "inproc",
        "--fsw",
        "playback",
        "--profile",
        profile.to_str().unwrap(),
        "--propulsion",
        "ideal",
        "--telemetry",
        "sensors",
        "--duration",
        duration,
        "--log",
        log.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let out = run_oils(&args);
    assert!(out.status.success(), "{}", text(&out));
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let body = std::fs::read_to_string(&csv).unwrap();
    let mut lines = body.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

/// Column index of `name` in a CSV header.
fn col(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

#[test]
fn sensor_telemetry_carries_device_samples_and_no_ideal_navigation() {
    let (header, rows) = fly_sensors_to_csv("sensors-only", "3", &[]);
    for prefix in [
        "imu_",
        "star_tracker_",
        "laser_altimeter_",
        "rf_altimeter_",
        "velocimeter_",
        "thruster_",
    ] {
        assert!(
            header.iter().any(|c| c.starts_with(prefix)),
            "no {prefix} column"
        );
    }
    // 3 s at 10 ms cycles, plus the end record.
    assert!(rows.len() >= 300, "{} rows", rows.len());
    let flags = col(&header, "telemetry.header.flags");
    let imu_count = col(&header, "imu_count");
    let imu_valid = col(&header, "imu_valid[0]");
    let imu_t = [col(&header, "imu_t_ns[0]"), col(&header, "imu_t_ns[1]")];
    let dvz = col(&header, "imu_delta_v_z_body_m_s[0]");
    let alt_count = col(&header, "laser_altimeter_count");
    let pos = col(&header, "telemetry.nav.pos_mci_m[0]");
    let mut laser_samples = 0;
    // From the third cycle on (the first delivers what 1 ms of latency let through).
    for row in &rows[2..rows.len() - 1] {
        let f: u32 = row[flags].parse().unwrap();
        assert_eq!(
            f & oils_shared::TLM_FLAG_SENSORS,
            oils_shared::TLM_FLAG_SENSORS
        );
        assert_eq!(f & oils_shared::TLM_FLAG_IDEAL_NAV, 0);
        assert_eq!(
            row[pos].parse::<f64>().unwrap(),
            0.0,
            "ideal navigation off"
        );
        // 200 Hz in 10 ms cycles: two IMU samples a cycle, 5 ms apart, both good.
        assert_eq!(row[imu_count], "2");
        assert_eq!(row[imu_valid], "1");
        let t0: i64 = row[imu_t[0]].parse().unwrap();
        let t1: i64 = row[imu_t[1]].parse().unwrap();
        assert_eq!(t1 - t0, 5_000_000);
        // Coasting at first, then braking: the body +Z increment is never negative
        // beyond the noise, and finite.
        assert!(row[dvz].parse::<f64>().unwrap().is_finite());
        laser_samples += row[alt_count].parse::<u32>().unwrap();
    }
    // 10 Hz laser altimeter over about 3 s (its range limit may keep it unlocked at
    // 30 km: the samples come, valid or not).
    assert!(
        laser_samples >= 28,
        "{laser_samples} laser altimeter samples"
    );
}

#[test]
fn devices_that_do_not_fit_the_schedule_are_refused_naming_them() {
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--telemetry",
        "both",
        "--dt-ms",
        "10",
        "--no-log",
    ]);
    assert!(!out.status.success());
    let e = text(&out);
    assert!(e.contains("imu") && e.contains("plant step"), "{e}");

    // Asked for explicitly, the reference GNC on the ideal navigation source with no
    // such source in the telemetry is refused.
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--telemetry",
        "sensors",
        "--gnc-nav",
        "bench",
        "--no-log",
    ]);
    assert!(!out.status.success());
    let e = text(&out);
    assert!(e.contains("reference GNC") && e.contains("both"), "{e}");
}

/// `--telemetry sensors` alone: the reference GNC flies the descent on its own filter,
/// says so on the header line, and lands.
#[test]
fn sensor_telemetry_alone_flies_the_reference_gnc_on_its_filter() {
    let dir = scratch("sensors-alone");
    let rep = dir.join("r.json");
    let out = run_oils(&[
        "run",
        "--telemetry",
        "sensors",
        "--link",
        "inproc",
        "--no-log",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let head = stdout.lines().next().unwrap_or_default();
    assert!(
        head.contains("telemetry sensors")
            && head.contains("fsw gnc (navigating on its own filter)"),
        "{head}"
    );
    let r = report(&rep);
    assert_eq!(r["config"]["gnc"]["navigation"], "sensors", "{r}");
    assert_eq!(r["outcome"], "landed", "{}", text(&out));
}

#[test]
fn a_device_fault_reaches_the_flight_software_through_a_run() {
    let (header, rows) = fly_sensors_to_csv(
        "sensors-fault",
        "2",
        &["--fault", "sensor-inhibit:rf-altimeter@t=1"],
    );
    let (t, n) = (
        col(&header, "telemetry.t_s"),
        col(&header, "rf_altimeter_count"),
    );
    let (st, valid, flags) = (
        col(&header, "rf_altimeter_t_ns[0]"),
        col(&header, "rf_altimeter_valid[0]"),
        col(&header, "rf_altimeter_flags[0]"),
    );
    let (mut before, mut after) = (0, 0);
    for row in &rows {
        if row[n] == "0" {
            continue;
        }
        let sampled_s = row[st].parse::<f64>().unwrap() * 1e-9;
        let f: u32 = row[flags].parse().unwrap();
        let inhibited = f & oils_shared::SAMPLE_FLAG_INHIBITED != 0;
        if sampled_s > 1.0 + 1e-9 {
            assert!(
                inhibited && row[valid] == "0",
                "t = {}: {}",
                row[t],
                row[flags]
            );
            after += 1;
        } else if sampled_s < 1.0 - 1e-9 {
            assert!(!inhibited, "t = {}", row[t]);
            before += 1;
        }
    }
    assert!(
        before >= 15 && after >= 15,
        "{before} before, {after} after"
    );

    // Without the devices on, such a fault is refused, naming why.
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--no-log",
        "--fault",
        "sensor-inhibit:rf-altimeter@t=1",
    ]);
    assert!(!out.status.success());
    let e = text(&out);
    assert!(
        e.contains("rf-altimeter") && e.contains("--telemetry"),
        "{e}"
    );
}
