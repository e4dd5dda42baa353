//! A run is bound to the flight-software process that joined it, and a stub notices its
//! emulator's death (it watches the process) rather than waiting out its timeout. Real
//! processes, real iceoryx2.

mod common;
use common::*;
use std::process::{Child, ExitStatus, Stdio};
use std::time::{Duration, Instant};

fn wait_with_deadline(child: &mut Child, secs: u64) -> ExitStatus {
    let until = Instant::now() + Duration::from_secs(secs);
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > until {
            let _ = child.kill();
            let _ = child.wait();
            panic!("process still running after {secs} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn stderr_of(child: &mut Child) -> String {
    let mut err = String::new();
    if let Some(e) = child.stderr.as_mut() {
        std::io::Read::read_to_string(e, &mut err).unwrap();
    }
    err
}

/// `oils run --no-stub` in realtime on `id`, for `duration` simulated seconds.
fn realtime_emulator(id: &str, duration: &str, rep: &std::path::Path, extra: &[&str]) -> Child {
    oils()
        .args([
            "run",
            "--no-stub",
            "--run-id",
            id,
            "--mode",
            "realtime",
            "--duration",
            duration,
            "--link-timeout-ms",
            "4000",
            "--no-log",
            "--report",
            rep.to_str().unwrap(),
        ])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn stub(id: &str) -> Child {
    oils()
        .args(["stub", "--run-id", id])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap()
}

/// Issue #24: after the stub is killed, a second stub started with the same run id took
/// the run over silently (COMPLETED, exit 0). Now the run aborts and says why.
#[test]
fn a_restarted_flight_software_aborts_the_run_naming_the_cause() {
    let dir = scratch("rebind");
    let id = run_id(11);
    let rep = dir.join("report.json");
    let mut emulator = realtime_emulator(&id, "6", &rep, &[]);
    let mut watch = StderrWatch::take(&mut emulator);
    let mut first = stub(&id);
    watch.wait_for(JOINED, 60);
    std::thread::sleep(Duration::from_millis(500));
    first.kill().unwrap(); // SIGKILL: the flight software vanishes
    first.wait().unwrap();
    let mut second = stub(&id);
    let status = wait_with_deadline(&mut emulator, 20);
    let err = watch.rest();
    // The run ended when the first died; the second may still wait for services.
    let _ = second.kill();
    let _ = second.wait();
    assert!(!status.success(), "a taken-over run must fail: {err}");
    let r = report(&rep);
    assert_eq!(r["outcome"], "aborted", "{r}");
    let why = r["error"].as_str().unwrap();
    // The bound process is watched: its death ends the run, or, when the second answers
    // within the watch's 20 ms, the command from another process does. Either way the
    // run is not taken over and the reason names the way to allow it.
    assert!(
        (why.contains("exited without answering step") || why.contains("flight software changed"))
            && why.contains("--allow-reattach"),
        "{why}"
    );
    // The old process is named by pid.
    assert!(why.contains(&format!("pid {}", first.id())), "{why}");
    assert!(r.get("reattachments").is_none());
}

/// With `--allow-reattach` the same take-over is allowed, and reported.
#[test]
fn allow_reattach_lets_a_restarted_flight_software_fly_on_and_reports_it() {
    let dir = scratch("reattach");
    let id = run_id(12);
    let rep = dir.join("report.json");
    let mut emulator = realtime_emulator(&id, "5", &rep, &["--allow-reattach"]);
    let mut watch = StderrWatch::take(&mut emulator);
    let mut first = stub(&id);
    watch.wait_for(JOINED, 60);
    std::thread::sleep(Duration::from_millis(500));
    first.kill().unwrap();
    first.wait().unwrap();
    let mut second = stub(&id);
    let status = wait_with_deadline(&mut emulator, 20);
    let err = watch.rest();
    assert!(wait_with_deadline(&mut second, 10).success());
    assert!(status.success(), "{err}");
    let r = report(&rep);
    assert_eq!(r["outcome"], "completed", "{r}");
    assert_eq!(r["reattachments"], 1, "{r}");
    assert_eq!(r["config"]["allow_reattach"], true);
    let warnings = r["warnings"].to_string();
    assert!(
        warnings.contains("re-attached")
            && warnings.contains(&format!("pid {}", second.id()))
            && warnings.contains(&format!("pid {}", first.id())),
        "{warnings}"
    );
}

/// Issue #24: the stub waited `5000 + 3 dt/speed` ms for a dead emulator, hours at a slow
/// speed. Now it watches the emulator's process and gives up within a bounded wall time.
#[test]
fn a_stub_gives_up_on_a_dead_emulator_promptly_even_at_a_crawl() {
    let dir = scratch("crawl");
    let id = run_id(13);
    let rep = dir.join("report.json");
    // dt 100 ms at speed 0.002: a 50 s period; `oils run` would give its stub
    // 5000 + 3 * 50 000 ms of patience for a silent (live) emulator.
    let mut emulator = oils()
        .args([
            "run",
            "--no-stub",
            "--run-id",
            &id,
            "--mode",
            "realtime",
            "--dt-ms",
            "100",
            "--speed",
            "0.002",
            "--no-log",
            "--report",
            rep.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut watch = StderrWatch::take(&mut emulator);
    let mut stub = oils()
        .args(["stub", "--run-id", &id, "--timeout-ms", "155000"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    watch.wait_for(JOINED, 60);
    std::thread::sleep(Duration::from_millis(1000)); // answered step 0, waiting
    emulator.kill().unwrap(); // SIGKILL: no end-of-run telemetry
    emulator.wait().unwrap();
    // A hang guard only (its 155 s timeout is longer): the proof that the stub noticed
    // the death rather than waiting out its timeout is the message, which names the
    // emulator's exit; a timeout says "emulator silent".
    let status = wait_with_deadline(&mut stub, 60);
    let err = stderr_of(&mut stub);
    assert!(!status.success(), "{err}");
    assert!(!err.contains("silent"), "{err}");
    assert!(
        err.contains(&format!("the emulator (pid {})", emulator.id()))
            && err.contains("exited without ending the run"),
        "{err}"
    );
}
