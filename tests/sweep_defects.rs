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
        assert!(stderr(&out).contains("name the same file"), "{}", stderr(&out));
        assert_eq!(std::fs::read(&log).unwrap(), before, "{args:?} touched the log");
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
    assert!(stderr(&out).contains("name the same file"), "{}", stderr(&out));
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
