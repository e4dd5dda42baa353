//! Issue #36: what a run's log holds after the run was interrupted, and that two runs
//! cannot write one log. Each test runs the real `oils` binary and interrupts it as a
//! user would (Ctrl-C, kill -9), once its log holds records (the log's size is polled;
//! nothing here measures time).

mod common;
use common::*;
use std::path::Path;
use std::process::{Child, Stdio};

/// Bytes of a few hundred records: the run is well under way.
const UNDER_WAY_BYTES: u64 = 300 * 920;

/// Starts `oils run` flying hifi for 600 s (far longer than the test waits) into `log`.
fn start_long_run(log: &Path, format: &str, link: &str) -> Child {
    oils()
        .args([
            "run",
            "--propulsion",
            "hifi",
            "--duration",
            "600",
            "--link",
            link,
            "--log-format",
            format,
            "--log",
        ])
        .arg(log)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawning oils run")
}

/// Waits until `log` has grown past `bytes` (the run is writing records), or the run
/// ended (then the test fails with its output).
fn wait_for_records(child: &mut Child, log: &Path, bytes: u64) {
    loop {
        if std::fs::metadata(log).is_ok_and(|m| m.len() > bytes) {
            return;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("oils run ended ({status}) before its log held records");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) on our own child's pid.
    let rc = unsafe { libc::kill(child.id() as i32, sig) };
    assert_eq!(rc, 0, "kill");
}

/// `oils run`, interrupted by `sig` once its log holds records, then `oils replay` of the
/// log: it must replay every record and say where the recorded run ended.
fn interrupted_run_replays(name: &str, link: &str, sig: i32, says: &str) {
    interrupted_run_replays_as(name, "oilslog", link, sig, says, UNDER_WAY_BYTES);
}

fn interrupted_run_replays_as(
    name: &str,
    format: &str,
    link: &str,
    sig: i32,
    says: &str,
    under_way_bytes: u64,
) {
    let dir = scratch(name);
    let log = dir.join(format!("run.{format}"));
    let mut child = start_long_run(&log, format, link);
    wait_for_records(&mut child, &log, under_way_bytes);
    signal(&child, sig);
    let run = child.wait_with_output().unwrap();
    assert!(!run.status.success(), "{}", text(&run));
    let replay = run_oils(&["replay", log.to_str().unwrap()]);
    assert!(replay.status.success(), "{name}: {}", text(&replay));
    let out = String::from_utf8_lossy(&replay.stdout);
    assert!(
        out.contains("every telemetry identical"),
        "{}",
        text(&replay)
    );
    assert!(out.contains(says), "{name}: {}", text(&replay));
    if sig == libc::SIGINT {
        // The run closed its log: the replay's digest is the run's.
        let digest = |o: &std::process::Output| {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .find(|l| l.starts_with("digest"))
                .map(str::to_string)
        };
        assert!(digest(&run).is_some(), "{}", text(&run));
        assert_eq!(digest(&run), digest(&replay), "{}", text(&replay));
    }
}

/// "replay diverged at step N" for every interrupted run: the replay flew on past the
/// step the recorded run ended at. Now it ends there, as the recorded run did.
#[test]
fn a_run_stopped_by_ctrl_c_replays() {
    interrupted_run_replays(
        "crash-sigint-inproc",
        "inproc",
        libc::SIGINT,
        "replayed up to there",
    );
    interrupted_run_replays(
        "crash-sigint-iceoryx2",
        "iceoryx2",
        libc::SIGINT,
        "replayed up to there",
    );
}

/// kill -9 leaves a log without its end record: every record in it replays, and the
/// replay says the log ends without its end.
#[test]
fn a_run_killed_with_sigkill_replays_up_to_its_last_record() {
    interrupted_run_replays(
        "crash-sigkill",
        "iceoryx2",
        libc::SIGKILL,
        "log ends without its end record: run interrupted after",
    );
}

/// An MCAP log killed mid-run was lost entirely ("record with opcode 06 length exceeds
/// limit"). Now every whole chunk is recovered, said so, and replays.
#[test]
fn an_mcap_log_killed_mid_run_keeps_its_whole_chunks() {
    // Two chunks (about 150 kB each compressed) are in the file.
    interrupted_run_replays_as(
        "crash-sigkill-mcap",
        "mcap",
        "inproc",
        libc::SIGKILL,
        "log ends without its end record: run interrupted after",
        400_000,
    );
}

/// Two runs given one `--log` both exited 0 and spliced it. Now the second fails at
/// once, naming the file, and the first's log is whole.
#[test]
fn a_second_run_on_the_same_log_fails_at_once() {
    for format in ["oilslog", "mcap"] {
        let dir = scratch(&format!("crash-two-runs-{format}"));
        let log = dir.join(format!("run.{format}"));
        let mut first = start_long_run(&log, format, "inproc");
        wait_for_records(&mut first, &log, 16 << 10);
        let second = run_oils(&[
            "run",
            "--link",
            "inproc",
            "--duration",
            "5",
            "--log-format",
            format,
            "--log",
            log.to_str().unwrap(),
        ]);
        signal(&first, libc::SIGINT);
        let first = first.wait_with_output().unwrap();
        assert!(!second.status.success(), "{format}: {}", text(&second));
        let e = String::from_utf8_lossy(&second.stderr);
        assert!(
            e.contains(log.to_str().unwrap()) && e.contains("being written by another run"),
            "{format}: {}",
            text(&second)
        );
        assert!(
            !String::from_utf8_lossy(&second.stdout).contains("outcome"),
            "{format}: the second run ran: {}",
            text(&second)
        );
        // The first run's log reads whole, of its run only.
        let export = run_oils(&[
            "export",
            log.to_str().unwrap(),
            "--csv",
            dir.join("x.csv").to_str().unwrap(),
        ]);
        assert!(
            export.status.success(),
            "{format}: {}\n{}",
            text(&export),
            text(&first)
        );
    }
}
