//! End-to-end: the `oils` binary spawns a real onboard-stub process and the two fly the
//! default descent over real iceoryx2 shared memory.

mod common;
use common::*;

#[test]
fn default_descent_lands_within_limits_and_reports() {
    let dir = scratch("default");
    let rep = dir.join("report.json");
    let log = dir.join("run.oilslog");
    let out = run_oils(&[
        "run",
        "--report",
        rep.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = report(&rep);
    assert_eq!(r["outcome"], "landed", "{}", text(&out));
    assert_eq!(r["mode"], "lockstep");
    let td = &r["touchdown"];
    assert!(td["vertical_speed_mps"].as_f64().unwrap() <= 2.0, "{td}");
    assert!(td["horizontal_speed_mps"].as_f64().unwrap() <= 0.5, "{td}");
    assert!(td["tilt_deg"].as_f64().unwrap() <= 10.0, "{td}");
    let used = td["propellant_used_kg"].as_f64().unwrap();
    assert!(used > 500.0 && used < 1000.0, "propellant used {used}");
    assert!(td["t_s"].as_f64().unwrap() > 300.0);
    let steps = r["steps"].as_u64().unwrap();
    assert!(steps > 30_000, "{steps}");
    let digest = r["digest"].as_str().unwrap();
    assert_eq!(digest.len(), 32, "XXH3-128 as hex: {digest}");
    assert!(digest.chars().all(|c| c.is_ascii_hexdigit()));
    for key in [
        "wake_error_ns",
        "round_trip_ns",
        "stub_compute_ns",
        "transport_ns",
    ] {
        for p in ["p50", "p99", "p999", "max"] {
            assert!(r["timing"][key][p].is_u64(), "timing.{key}.{p} missing");
        }
    }
    assert_eq!(
        r["timing"]["round_trip_ns"]["count"].as_u64().unwrap(),
        steps
    );
    assert_eq!(r["timing"]["deadline_misses"], 0);
    // Wall time and the realtime factor are reported (their values are the machine's).
    assert!(r["timing"]["wall_s"].is_f64());
    assert!(r["timing"]["realtime_factor"].is_f64());
    assert_eq!(r["rejected_commands"], 0);

    // The log holds every step plus the final telemetry, and exports to CSV.
    let csv = dir.join("run.csv");
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let text_csv = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text_csv.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("telemetry.header.step,telemetry.header.t_ns,"),
        "{header}"
    );
    assert_eq!(lines.count() as u64, steps + 1);
}

#[test]
fn same_configuration_same_digest_other_seed_other_digest() {
    let dir = scratch("determinism");
    let digest_of = |name: &str, extra: &[&str]| -> String {
        let rep = dir.join(format!("{name}.json"));
        let mut args = vec![
            "run",
            "--no-log",
            "--duration",
            "120",
            "--report",
            rep.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let out = run_oils(&args);
        assert!(out.status.success(), "{}", text(&out));
        report(&rep)["digest"].as_str().unwrap().to_string()
    };
    let a = digest_of("a", &["--seed", "7"]);
    let b = digest_of("b", &["--seed", "7"]);
    assert_eq!(
        a, b,
        "two identical lockstep runs must give the same digest"
    );
    let c = digest_of("c", &["--seed", "8"]);
    assert_ne!(a, c, "another seed must give another digest");
    let d = digest_of("d", &["--seed", "7", "--dt-ms", "20"]);
    assert_ne!(a, d, "another step must give another digest");
}

#[test]
fn two_runs_at_once_do_not_collide() {
    let dir = scratch("parallel");
    let spawn = |name: &str| {
        let rep = dir.join(format!("{name}.json"));
        let child = oils()
            .args([
                "run",
                "--no-log",
                "--duration",
                "200",
                "--seed",
                "3",
                "--report",
                rep.to_str().unwrap(),
            ])
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("spawn");
        (child, rep)
    };
    let (mut c1, r1) = spawn("one");
    let (mut c2, r2) = spawn("two");
    assert!(c1.wait().unwrap().success());
    assert!(c2.wait().unwrap().success());
    let (r1, r2) = (report(&r1), report(&r2));
    assert_ne!(r1["run_id"], r2["run_id"]);
    assert_eq!(
        r1["digest"], r2["digest"],
        "same inputs, same digest, even side by side"
    );
}

#[test]
fn playback_flies_a_profile_open_loop() {
    let dir = scratch("playback");
    let profile = dir.join("profile.csv");
    std::fs::write(&profile, "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,800,800,800,800,1,1,1,1\n2,400,400,400,400,1,1,1,1\n").unwrap();
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--fsw",
        "playback",
        "--profile",
        profile.to_str().unwrap(),
        "--duration",
        "5",
        "--no-log",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = report(&rep);
    assert_eq!(r["outcome"], "completed");
    assert_eq!(r["steps"], 500);
}

#[test]
fn realtime_mode_paces_and_reports_wake_error() {
    let dir = scratch("realtime");
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--mode",
        "realtime",
        "--speed",
        "4",
        "--duration",
        "2",
        "--no-log",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = report(&rep);
    assert_eq!(r["mode"], "realtime");
    assert_eq!(r["steps"], 200);
    // Every paced step start counts, including the end-of-run telemetry's.
    assert_eq!(r["timing"]["wake_error_ns"]["count"], 201);
    // The schedule itself (absolute starts every period / speed) is checked on a
    // simulated time source in `clock.rs`; wall time is the machine's, not asserted.
}

#[test]
fn a_broken_threshold_fails_the_run_and_names_it() {
    let dir = scratch("threshold");
    let rep = dir.join("report.json");
    // 1 ns of round trip is impossible: the run must fail and say which bound broke.
    let out = run_oils(&[
        "run",
        "--duration",
        "1",
        "--no-log",
        "--max-round-trip-p99-us",
        "0.001",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(!out.status.success(), "{}", text(&out));
    let all = text(&out);
    assert!(all.contains("round_trip p99"), "{all}");
    assert!(!report(&rep)["threshold_violations"]
        .as_array()
        .unwrap()
        .is_empty());
}

#[test]
fn bad_command_line_input_is_a_clear_error() {
    let cases: &[(&[&str], &str)] = &[
        (&["run", "--dt-ms", "0"], "dt-ms"),
        (&["run", "--dt-ms", "101"], "dt-ms"),
        (
            &["run", "--scenario", "/nonexistent/scenario.toml"],
            "scenario",
        ),
        (&["run", "--fsw", "playback"], "--profile"),
        (&["run", "--propulsion", "warp"], "warp"),
        (&["run", "--link", "carrier-pigeon"], "--link"),
        (&["run", "--config", "/nonexistent/run.toml"], "run.toml"),
        (&["run", "--max-wake-p99-us", "nan"], "max-wake-p99-us"),
        (
            &["run", "--link-timeout-ms", "18446744073709551615"],
            "link-timeout-ms",
        ),
        (&["run", "--miss-policy", "abort:0"], "miss-policy"),
        (&["run", "--speed=-1"], "speed"),
        (&["run", "--wait", "sometimes"], "--wait"),
        (
            &["export", "/nonexistent.oilslog", "--csv", "/tmp/x.csv"],
            "nonexistent",
        ),
    ];
    for (args, needle) in cases {
        let out = run_oils(args);
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(needle),
            "{args:?}: stderr lacks `{needle}`:\n{err}"
        );
        assert!(!err.contains("panicked"), "{args:?} panicked:\n{err}");
    }
}

#[test]
fn malformed_profile_names_the_line() {
    let dir = scratch("badprofile");
    let profile = dir.join("bad.csv");
    std::fs::write(
        &profile,
        "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,800,800,800,800,1,1,1,1\n1,abc,0,0,0,1,1,1,1\n",
    )
    .unwrap();
    let out = run_oils(&[
        "run",
        "--fsw",
        "playback",
        "--profile",
        profile.to_str().unwrap(),
        "--no-log",
        "--startup-timeout-ms",
        "3000",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 3"), "{err}");
}

#[test]
fn rt_priority_runs_or_says_why_not() {
    let dir = scratch("rtprio");
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--mode",
        "realtime",
        "--speed",
        "10",
        "--duration",
        "1",
        "--no-log",
        "--rt-priority",
        "5",
        "--report",
        rep.to_str().unwrap(),
    ]);
    if out.status.success() {
        // Permitted (root or CAP_SYS_NICE): the run paced all its steps.
        assert_eq!(report(&rep)["steps"], 100);
    } else {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("--rt-priority 5") && err.contains("CAP_SYS_NICE"),
            "{err}"
        );
    }
}

/// What a realtime run's stepping threads obtained is in the report, for the emulator
/// and the stub, whether or not the machine granted it: pinned, or a warning saying why
/// not; memory locked, or a warning saying why not. Never silence. No timing asserted.
#[test]
fn realtime_report_says_what_was_obtained() {
    let dir = scratch("rt-hygiene");
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--mode",
        "realtime",
        "--speed",
        "10",
        "--duration",
        "1",
        "--no-log",
        "--cpus",
        "0,0",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("realtime    emulator"),
        "{}",
        text(&out)
    );
    let r = report(&rep);
    let warnings: Vec<String> = r["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap().to_string())
        .collect();
    for (who, prefix) in [("emulator", "emulator: "), ("onboard", "onboard stub: ")] {
        let s = &r["realtime"][who];
        assert_eq!(s["sched_policy"], "SCHED_OTHER", "{who}: {s}");
        assert_eq!(s["sched_priority"], 0, "{who}: {s}");
        assert_eq!(s["cpu_requested"], 0, "{who}: {s}");
        assert_eq!(s["memory_lock_requested"], true, "{who}: {s}");
        assert!(
            s["stack_prefaulted_bytes"].as_u64().unwrap() > 0,
            "{who}: {s}"
        );
        let said = |what: &str| {
            warnings
                .iter()
                .any(|w| w.starts_with(prefix) && w.contains(what))
        };
        if s["pinned"] == true {
            assert_eq!(s["cpus_allowed"], serde_json::json!([0]), "{who}: {s}");
        } else {
            assert!(said("not pinned to CPU 0"), "{who}: {s} {warnings:?}");
        }
        if s["memory_locked"] != true {
            assert!(said("memory not locked"), "{who}: {s} {warnings:?}");
        }
        assert_eq!(s["wake_latency_requested"], true, "{who}: {s}");
        if s["wake_latency_held"] != true {
            assert!(said("wake-up latency not held"), "{who}: {s} {warnings:?}");
        }
    }
}

#[test]
fn bad_cpu_lists_are_refused_before_tick_0() {
    for (cpus, says) in [
        ("0,x", "`x` is not a CPU number"),
        ("0,1,0", "3 CPUs given"),
        ("", "an empty list"),
        ("999", "CPU 999 is not online"),
        ("0,99999", "CPU 99999 is not online"),
    ] {
        let out = run_oils(&["run", "--link", "inproc", "--no-log", "--cpus", cpus]);
        assert!(!out.status.success(), "--cpus {cpus:?} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains(says) && !err.contains("panicked"),
            "--cpus {cpus:?}: {err}"
        );
    }
}

/// A lockstep run in process asks for nothing and says so.
#[test]
fn lockstep_report_says_nothing_was_asked() {
    let dir = scratch("rt-none");
    let rep = dir.join("report.json");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--duration",
        "1",
        "--no-log",
        "--report",
        rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let r = report(&rep);
    let s = &r["realtime"]["emulator"];
    assert_eq!(s["memory_lock_requested"], false, "{s}");
    assert_eq!(s["memory_locked"], false, "{s}");
    assert_eq!(s["wake_latency_requested"], false, "{s}");
    assert_eq!(s["wake_latency_held"], false, "{s}");
    assert_eq!(s["cpu_requested"], serde_json::Value::Null, "{s}");
    assert_eq!(s["pinned"], false, "{s}");
    assert_eq!(r["realtime"]["onboard"], serde_json::Value::Null);
}
