//! The defects a 131-case fault sweep found (issue #57), one reproducing test each:
//! outputs that overwrite their input or each other, bad numbers flown instead of
//! refused, campaigns that fail without saying so.

mod common;
use common::*;
use std::process::Output;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A short in-process run of the terminal descent logged to `log`.
fn short_logged_run(log: &std::path::Path) {
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--duration",
        "1",
        "--scenario",
        "terminal-descent",
        "--log",
        log.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
}

/// `oils export LOG --csv LOG` replaced the log by its CSV and exited 0.
#[test]
fn export_refuses_an_output_that_is_its_log() {
    let dir = scratch("sweep-export-alias");
    let log = dir.join("run.oilslog");
    short_logged_run(&log);
    let before = std::fs::read(&log).unwrap();
    let l = log.to_str().unwrap();
    // The same file spelt another way too.
    let other = format!("{}/./run.oilslog", dir.display());
    for args in [
        vec!["export", l, "--csv", l],
        vec!["export", l, "--profile", other.as_str()],
        vec!["export", l, "--csv", "x.csv", "--layout", "x.csv"],
    ] {
        let out = oils().args(&args).current_dir(&dir).output().unwrap();
        assert!(!out.status.success(), "{args:?} should fail");
        assert!(
            stderr(&out).contains("name the same file"),
            "{}",
            stderr(&out)
        );
        assert_eq!(
            std::fs::read(&log).unwrap(),
            before,
            "{args:?} touched the log"
        );
    }
}

/// `oils run --log X --report X` replaced the log by the report and exited 0.
#[test]
fn run_refuses_a_report_that_is_its_log() {
    let dir = scratch("sweep-run-alias");
    let x = dir.join("x");
    let out = run_oils(&[
        "run",
        "--link",
        "inproc",
        "--duration",
        "1",
        "--scenario",
        "terminal-descent",
        "--log",
        x.to_str().unwrap(),
        "--report",
        x.to_str().unwrap(),
    ]);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        stderr(&out).contains("name the same file"),
        "{}",
        stderr(&out)
    );
}

/// `--every 0` silently meant 1.
#[test]
fn export_refuses_every_zero() {
    let dir = scratch("sweep-every");
    let log = dir.join("run.oilslog");
    short_logged_run(&log);
    let prof = dir.join("p.csv");
    let out = run_oils(&[
        "export",
        log.to_str().unwrap(),
        "--profile",
        prof.to_str().unwrap(),
        "--every",
        "0",
    ]);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(stderr(&out).contains("--every"), "{}", stderr(&out));
    assert!(!prof.exists());
}

/// A campaign whose base flies an FMU exited 0 with every case `error` ("propulsion"):
/// now the spec is refused before a case runs, naming the reason.
#[test]
fn a_campaign_on_an_fmu_is_refused_with_the_reason() {
    let dir = scratch("sweep-mc-fmu");
    let spec = dir.join("fmu.toml");
    std::fs::write(
        &spec,
        "cases = 2\nseed = 1\n[base]\npropulsion = \"fmu\"\npropulsion_fmu = \"hifi.fmu\"\n",
    )
    .unwrap();
    let out = run_oils(&[
        "mc",
        "run",
        "--no-plots",
        "--spec",
        spec.to_str().unwrap(),
        "--out",
        dir.join("c").to_str().unwrap(),
    ]);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("base.propulsion = \"fmu\""),
        "{}",
        text(&out)
    );
}

/// `sensor-bias:laser-altimeter,value=1e300` drove the reference GNC's filter to NaN
/// and a 79 m/s crash; two `value=1.7e308` biases summed to inf in telemetry. A fault
/// value beyond any quantity the bench measures is refused, naming it.
#[test]
fn unphysical_fault_values_are_refused() {
    for faults in [
        vec!["sensor-bias:laser-altimeter,value=1e300@t=0.5"],
        vec![
            "sensor-bias:altitude_m,value=1.7e308@t=0.5",
            "sensor-bias:altitude_m,value=1.7e308@t=0.6",
        ],
    ] {
        let mut args = vec![
            "run",
            "--link",
            "inproc",
            "--no-log",
            "--duration",
            "1",
            "--scenario",
            "terminal-descent",
            "--telemetry",
            "sensors",
        ];
        for f in &faults {
            args.extend(["--fault", f]);
        }
        let out = run_oils(&args);
        assert!(!out.status.success(), "{faults:?}: {}", text(&out));
        assert!(
            stderr(&out).contains("out of its range"),
            "{}",
            stderr(&out)
        );
    }
}
