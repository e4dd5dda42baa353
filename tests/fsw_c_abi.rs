//! End to end, real processes: C-ABI flight software in the stub (`oils stub --fsw
//! c:PATH`) flying against `oils run --no-stub`. The plain-C example lands the
//! terminal-descent scenario with a repeatable digest; the Rust reference GNC exported
//! through the same ABI (`oils-cabi-gnc`) lands the default descent with the native digest.

mod common;
use common::*;

#[path = "../shared/tests/common/c_build.rs"]
mod c_build;

use std::path::{Path, PathBuf};

/// `oils stub --fsw c:LIB` on `run_id`, as a client command.
fn c_stub(run_id: &str, lib: &Path) -> std::process::Command {
    let mut c = oils();
    c.args(["stub", "--run-id", run_id, "--fsw"])
        .arg(format!("c:{}", lib.display()));
    c
}

/// Flies `run_args` with the C library in the stub; returns the report.
fn fly_c(dir: &Path, name: &str, tag: u64, lib: &Path, run_args: &[&str]) -> serde_json::Value {
    let rep = dir.join(format!("{name}.json"));
    let id = run_id(tag);
    let mut args = vec!["--no-log", "--report", rep.to_str().unwrap()];
    args.extend_from_slice(run_args);
    let (emulator, stub) = fly_with_client(&args, &id, c_stub(&id, lib));
    assert!(stub.status.success(), "stub: {}", text(&stub));
    assert!(emulator.status.success(), "oils run: {}", text(&emulator));
    report(&rep)
}

#[test]
fn c_example_lands_the_terminal_descent_with_a_repeatable_digest() {
    let dir = scratch("c-example");
    let lib = c_build::shared_library(
        &c_build::terminal_descent_c(),
        "terminal_descent",
        &dir,
        &[],
    );
    let scenario = terminal_descent_scenario();
    let args = ["--scenario", scenario.to_str().unwrap(), "--seed", "5"];
    let a = fly_c(&dir, "a", 0xc1, &lib, &args);
    assert_soft_touchdown(&a, &scenario);
    let steps = a["steps"].as_u64().unwrap();
    assert!(steps > 5_000, "{steps}");
    // The stub timed the library's every step, like any flight software.
    assert_eq!(
        a["timing"]["stub_compute_ns"]["count"].as_u64(),
        Some(steps)
    );
    assert!(a["timing"]["stub_compute_ns"]["max"].as_u64().unwrap() > 0);
    assert_eq!(a["rejected_commands"], 0);
    let b = fly_c(&dir, "b", 0xc2, &lib, &args);
    assert_eq!(a["digest"], b["digest"], "same inputs, same digest");
    assert_eq!(a["steps"], b["steps"]);
}

/// `liboils_cabi_gnc.so`, built by cargo beside this test (a dev-dependency with a
/// `cdylib` crate type).
fn cabi_gnc_library() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    [deps.to_path_buf(), deps.parent().unwrap().to_path_buf()]
        .iter()
        .map(|d| d.join("liboils_cabi_gnc.so"))
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("liboils_cabi_gnc.so not built beside {}", exe.display()))
}

#[test]
fn rust_gnc_through_the_c_abi_gives_the_native_digest() {
    let dir = scratch("cabi-gnc");
    let native_rep = dir.join("native.json");
    let out = run_oils(&["run", "--no-log", "--report", native_rep.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out));
    let native = report(&native_rep);
    assert_eq!(native["outcome"], "landed");
    let through_c = fly_c(&dir, "cabi", 0xc3, &cabi_gnc_library(), &[]);
    assert_eq!(through_c["outcome"], "landed");
    assert_eq!(through_c["steps"], native["steps"]);
    assert_eq!(
        through_c["digest"], native["digest"],
        "the GNC through the C ABI must fly exactly the native descent"
    );
}

/// The same GNC flying on its own navigation filter (`--fsw-params` with `navigation =
/// "sensors"`) gives the digest of the native `--gnc-nav sensors`; parameters it cannot
/// read fail its init with the reason.
#[test]
fn rust_gnc_on_sensor_navigation_through_the_c_abi_gives_the_native_digest() {
    let dir = scratch("cabi-gnc-sensors");
    let native_rep = dir.join("native.json");
    let out = run_oils(&[
        "run",
        "--no-log",
        "--telemetry",
        "sensors",
        "--gnc-nav",
        "sensors",
        "--report",
        native_rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let native = report(&native_rep);
    assert_eq!(native["outcome"], "landed");
    // The library with `params` as its --fsw-params file, against `oils run --no-stub
    // --telemetry sensors` and `extra`: the emulator's and the stub's outputs.
    let fly_cabi = |params: &str, tag: u64, extra: &[&str]| {
        let file = dir.join(format!("gnc-{tag:x}.toml"));
        std::fs::write(&file, params).unwrap();
        let id = run_id(tag);
        let mut stub = c_stub(&id, &cabi_gnc_library());
        stub.arg("--fsw-params").arg(&file);
        let mut args = vec!["--no-log", "--telemetry", "sensors"];
        args.extend_from_slice(extra);
        fly_with_client(&args, &id, stub)
    };
    let rep = dir.join("cabi.json");
    let (emulator, stub) = fly_cabi(
        "navigation = \"sensors\"\n",
        0xc4,
        &["--report", rep.to_str().unwrap()],
    );
    assert!(stub.status.success(), "stub: {}", text(&stub));
    assert!(emulator.status.success(), "oils run: {}", text(&emulator));
    assert_eq!(report(&rep)["digest"], native["digest"]);

    let (_, stub) = fly_cabi(
        "navigation = \"gps\"\n",
        0xc5,
        &["--startup-timeout-ms", "3000"],
    );
    assert!(!stub.status.success());
    assert!(
        String::from_utf8_lossy(&stub.stderr).contains("liboils_cabi_gnc: --fsw-params"),
        "{}",
        text(&stub)
    );
}

/// A C flight software that misbehaves at step `BAD_STEP` as `-D` says: SEGV (writes
/// through NULL), LOOP (never returns), STATUS=n (returns n); before, it holds hover
/// thrust.
const MISBEHAVING_C: &str = r#"
#include "oils.h"
#include <stdlib.h>
uint32_t oils_fsw_abi_version(void) { return OILS_FSW_ABI_VERSION; }
#ifdef WRONG_HASH
uint64_t oils_fsw_layout_hash(void) { return UINT64_C(0x1234); }
#else
uint64_t oils_fsw_layout_hash(void) { return OILS_FSW_LAYOUT_HASH; }
#endif
static int context;
void *oils_fsw_init(const oils_fsw_config *c) { (void)c; return &context; }
int32_t oils_fsw_step(void *ctx, const oils_telemetry *tlm, oils_command *cmd) {
  (void)ctx;
  if (tlm->header.step == BAD_STEP) {
#ifdef SEGV
    volatile int *volatile p = NULL;
    *p = 1;
#endif
#ifdef LOOP
    volatile unsigned spin = 0;
    for (;;) spin++;
#endif
#ifdef STATUS
    return STATUS;
#endif
  }
  for (int i = 0; i < OILS_ENGINE_COUNT; i++) {
    cmd->thrust_cmd_n[i] = 500.0;
    cmd->engine_on[i] = 1;
  }
  return OILS_FSW_STATUS_OK;
}
void oils_fsw_fini(void *ctx) { (void)ctx; }
"#;

/// The step at which the misbehaving library misbehaves.
const BAD_STEP: u64 = 300;

fn misbehaving(dir: &Path, name: &str, define: &str) -> PathBuf {
    let src = dir.join(format!("{name}.c"));
    std::fs::write(&src, MISBEHAVING_C).unwrap();
    let bad_step = format!("BAD_STEP={BAD_STEP}");
    c_build::shared_library(&src, name, dir, &[&bad_step, define])
}

/// `oils run` with `args` and `--fsw c:LIB`, its output and report (if written).
fn run_c(
    lib: &Path,
    rep: &Path,
    args: &[&str],
) -> (std::process::Output, Option<serde_json::Value>) {
    let _ = std::fs::remove_file(rep);
    let out = oils()
        .arg("run")
        .arg("--fsw")
        .arg(format!("c:{}", lib.display()))
        .arg("--report")
        .arg(rep)
        .args(args)
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    let r = rep.is_file().then(|| report(rep));
    (out, r)
}

/// The steps of a log's records, in file order (every record's CRC checked).
fn log_steps(log: &Path) -> Vec<u64> {
    let log = oils_emulator::recorder::read_log(log).unwrap();
    assert!(log.damaged_records.is_empty());
    log.records
        .iter()
        .map(|r| r.telemetry.header.step)
        .collect()
}

/// Issue #36: a library that dereferences NULL in the stub was reported as "stub silent
/// (did it die?)" after the link timeout, its signal lost. Now the spawned stub's death is
/// noticed, named with its signal and step, in the report too, with the library's hash.
#[test]
fn a_c_library_crashing_in_the_stub_is_reported_with_its_signal_and_step() {
    let dir = scratch("c-segv");
    let lib = misbehaving(&dir, "segv", "SEGV");
    let (rep, log) = (dir.join("r.json"), dir.join("run.oilslog"));
    let (out, r) = run_c(&lib, &rep, &["--log", log.to_str().unwrap()]);
    assert!(!out.status.success(), "{}", text(&out));
    let r = r.unwrap_or_else(|| panic!("no report: {}", text(&out)));
    assert_eq!(r["outcome"], "aborted");
    assert_eq!(r["steps"], BAD_STEP);
    let why = r["error"].as_str().unwrap();
    assert!(
        why.contains("killed by SIGSEGV (signal 11")
            && why.contains(&format!("at step {BAD_STEP}")),
        "{why}"
    );
    assert!(!why.contains("silent"), "{why}");
    assert!(
        r["onboard_process"]["ended"]
            .as_str()
            .unwrap()
            .contains("SIGSEGV"),
        "{r}"
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("killed by SIGSEGV"));
    // The report names the very file flown.
    let hash = oils_onboard_stub::c_library::file_blake3(&lib).unwrap();
    assert_eq!(r["fsw_library"]["blake3"], hash.as_str());
    assert_eq!(r["fsw_library"]["path"], lib.display().to_string().as_str());
    // Every step before the crash is in the log, and the end-of-run record.
    let steps = log_steps(&log);
    assert_eq!(steps, (0..=BAD_STEP).collect::<Vec<_>>());
}

/// Issue #36: a C step's nonzero status was not in the report (across processes the run
/// said "stub silent"; in process there was no report at all). Now both links report the
/// step and the status, and fly the same packets up to it.
#[test]
fn a_failed_c_step_puts_its_step_and_status_in_the_report_on_either_link() {
    let dir = scratch("c-status");
    let lib = misbehaving(&dir, "status", "STATUS=7");
    let want = serde_json::json!({"step": BAD_STEP, "status": 7});
    let rep = dir.join("ipc.json");
    let (out, ipc) = run_c(&lib, &rep, &["--no-log"]);
    assert!(!out.status.success(), "{}", text(&out));
    let ipc = ipc.unwrap_or_else(|| panic!("no report: {}", text(&out)));
    assert_eq!(ipc["fsw_failure"], want, "{ipc}");
    let why = ipc["error"].as_str().unwrap();
    assert!(
        why.contains(&format!("failed at step {BAD_STEP} (status 7)")),
        "{why}"
    );
    assert_eq!(ipc["onboard_process"]["ended"], "exited with status 1");

    let rep = dir.join("inproc.json");
    let (out, inproc) = run_c(
        &lib,
        &rep,
        &["--no-log", "--link", "inproc", "--allow-inproc-c"],
    );
    assert!(!out.status.success(), "{}", text(&out));
    let inproc = inproc.unwrap_or_else(|| panic!("no report: {}", text(&out)));
    assert_eq!(inproc["outcome"], "aborted");
    assert_eq!(inproc["fsw_failure"], want, "{inproc}");
    assert_eq!(
        inproc["error"].as_str().unwrap(),
        format!("flight software failed at step {BAD_STEP} (status 7)")
    );
    assert_eq!(inproc["steps"], ipc["steps"]);
    assert_eq!(
        inproc["digest"], ipc["digest"],
        "the same packets up to the failure"
    );
}

/// Issue #36: a stub that refused its library at load left the emulator waiting out its
/// whole start-up timeout, then failed without the report asked for. Now the stub's exit
/// is noticed while waiting, and named, with its last words, in a report of a run
/// aborted before step 0.
#[test]
fn a_library_refused_at_load_ends_the_run_before_step_0_with_a_report() {
    let dir = scratch("c-refused");
    let lib = misbehaving(&dir, "hash", "WRONG_HASH");
    let rep = dir.join("r.json");
    let (out, r) = run_c(&lib, &rep, &["--no-log", "--startup-timeout-ms", "600000"]);
    assert!(!out.status.success(), "{}", text(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("exited with status 1 before it joined the run")
            && err.contains("layout hash 0x0000000000001234"),
        "{err}"
    );
    let r = r.unwrap_or_else(|| panic!("no report: {}", text(&out)));
    assert_eq!(r["outcome"], "aborted");
    assert_eq!(r["steps"], 0);
    assert!(r["error"].as_str().unwrap().contains("layout hash"), "{r}");
    assert_eq!(r["onboard_process"]["ended"], "exited with status 1");
}

/// Waits for `child`, failing the test if it runs on for `secs` (then killed).
fn exit_within(child: &mut std::process::Child, secs: u64) -> std::process::ExitStatus {
    let until = std::time::Instant::now() + std::time::Duration::from_secs(secs);
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if std::time::Instant::now() > until {
            let _ = child.kill();
            panic!("still running after {secs} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Issue #36: a library that never returns ignored SIGINT and SIGTERM (the stub needed
/// SIGKILL) and the run only said "stub silent". Now the run says the stub was still
/// running and was killed, and a stuck stub started by hand ends on SIGTERM.
#[test]
fn a_c_library_that_never_returns_is_reported_and_its_stub_ends_on_sigterm() {
    let dir = scratch("c-loop");
    let lib = misbehaving(&dir, "loop", "LOOP");
    let rep = dir.join("r.json");
    let (out, r) = run_c(&lib, &rep, &["--no-log", "--link-timeout-ms", "500"]);
    assert!(!out.status.success(), "{}", text(&out));
    let r = r.unwrap_or_else(|| panic!("no report: {}", text(&out)));
    assert_eq!(r["steps"], BAD_STEP);
    let why = r["error"].as_str().unwrap();
    assert!(
        why.contains("silent") && why.contains("was still running"),
        "{why}"
    );
    assert!(r["onboard_process"]["ended"]
        .as_str()
        .unwrap()
        .contains("killed"));

    // By hand: the emulator gives up on it; SIGTERM then ends the stub, stuck as it is.
    let id = run_id(0xc6);
    let mut emulator = oils()
        .args([
            "run",
            "--no-stub",
            "--no-log",
            "--run-id",
            &id,
            "--link-timeout-ms",
            "500",
        ])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Patient with a silent emulator: only the signal can end it.
    let mut stub = c_stub(&id, &lib)
        .args(["--timeout-ms", "600000"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    assert!(!exit_within(&mut emulator, 60).success());
    // The emulator is gone and the stub still in its step.
    assert!(stub.try_wait().unwrap().is_none());
    // SAFETY: plain kill(2) on our own child.
    unsafe { libc::kill(stub.id() as i32, libc::SIGTERM) };
    let status = exit_within(&mut stub, 30);
    assert_eq!(
        status.code(),
        Some(oils_onboard_stub::runner::STUCK_EXIT_CODE)
    );
    let mut err = String::new();
    std::io::Read::read_to_string(stub.stderr.as_mut().unwrap(), &mut err).unwrap();
    assert!(
        err.contains(&format!("has not returned from its step {BAD_STEP}"))
            && err.contains("termination signal"),
        "{err}"
    );
}

/// A C library is refused in process unless asked for; asked for, one that never returns
/// ends `oils run` (status 3) with a report, the log holding every step before it.
#[test]
fn in_process_a_c_library_is_refused_unless_allowed_and_then_watched() {
    let dir = scratch("c-inproc");
    let lib = misbehaving(&dir, "loop", "LOOP");
    let (rep, log) = (dir.join("r.json"), dir.join("run.oilslog"));
    let (out, r) = run_c(&lib, &rep, &["--link", "inproc", "--no-log"]);
    assert!(!out.status.success());
    assert!(r.is_none());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--allow-inproc-c") && err.contains("isolates"),
        "{err}"
    );

    let mut run = oils()
        .arg("run")
        .arg(format!("--fsw=c:{}", lib.display()))
        .args([
            "--link",
            "inproc",
            "--allow-inproc-c",
            "--link-timeout-ms",
            "500",
        ])
        .arg("--report")
        .arg(&rep)
        .arg("--log")
        .arg(&log)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let status = exit_within(&mut run, 60);
    assert_eq!(
        status.code(),
        Some(oils_onboard_stub::runner::STUCK_EXIT_CODE)
    );
    let r = report(&rep);
    assert_eq!(r["outcome"], "aborted");
    assert_eq!(r["steps"], BAD_STEP);
    let why = r["error"].as_str().unwrap();
    assert!(
        why.contains(&format!("has not returned from step {BAD_STEP}")),
        "{why}"
    );
    assert_eq!(log_steps(&log), (0..BAD_STEP).collect::<Vec<_>>());
}

/// Issue #36: "repeat from the report" silently flew whatever the file had become. Now
/// the report holds the library's BLAKE3, and `--config-from` refuses a changed file
/// unless `--fsw` names it anew.
#[test]
fn config_from_refuses_a_c_library_that_changed_since_the_report() {
    let dir = scratch("c-changed");
    let lib = misbehaving(&dir, "lib", "STATUS=7");
    let rep = dir.join("first.json");
    let (_, first) = run_c(
        &lib,
        &rep,
        &["--no-log", "--link", "inproc", "--allow-inproc-c"],
    );
    let first = first.expect("a report");
    let again = dir.join("again.json");
    let repeat = |extra: &[&str]| {
        let _ = std::fs::remove_file(&again);
        let out = oils()
            .args(["run", "--no-log", "--allow-inproc-c", "--config-from"])
            .arg(&rep)
            .arg("--report")
            .arg(&again)
            .args(extra)
            .output()
            .unwrap();
        (out, again.is_file().then(|| report(&again)))
    };
    // Unchanged: it repeats, digest and all.
    let (_, r) = repeat(&[]);
    assert_eq!(r.expect("a report")["digest"], first["digest"]);
    // Rebuilt differently: refused, naming both hashes.
    let src = dir.join("lib.c");
    c_build::shared_library(&src, "lib", &dir, &["BAD_STEP=200", "STATUS=7"]);
    let (out, r) = repeat(&[]);
    assert!(!out.status.success() && r.is_none(), "{}", text(&out));
    let err = String::from_utf8_lossy(&out.stderr);
    let then = first["fsw_library"]["blake3"].as_str().unwrap();
    assert!(
        err.contains("has changed since that run") && err.contains(then),
        "{err}"
    );
    // Named anew: flown as it is now.
    let fsw = format!("c:{}", lib.display());
    let (_, r) = repeat(&["--fsw", &fsw]);
    let r = r.expect("a report");
    assert_eq!(r["fsw_failure"]["step"], 200);
    assert_ne!(r["fsw_library"]["blake3"], then);
}

/// `onboard-stub/examples/c/frames.c` (the C example plus `oils_fsw_frame`), built as a
/// user would, linked with the machine's libxxhash for the hash check.
fn frames_library(dir: &Path) -> PathBuf {
    let src = c_build::include_dir().join("../../onboard-stub/examples/c/frames.c");
    let out = dir.join("libframes.so");
    let output = c_build::c_compiler()
        .args([
            "-std=c11",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-pedantic",
            "-shared",
            "-fPIC",
        ])
        .arg("-I")
        .arg(c_build::include_dir())
        .arg("-I")
        .arg(src.parent().unwrap())
        .arg(&src)
        .arg("-o")
        .arg(&out)
        .args(["-lm", "-l:libxxhash.so.0"])
        .output()
        .expect("running the C compiler");
    assert!(
        output.status.success(),
        "building frames.c:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    out
}

#[test]
fn c_flight_software_reads_every_frame_in_place_and_checks_its_hash() {
    let dir = scratch("c-frames");
    let lib = frames_library(&dir);
    // The terminal descent with the test card on (a 2 MiB frame a second).
    let scenario = dir.join("terminal-descent-test-card.toml");
    let mut text_toml = std::fs::read_to_string(terminal_descent_scenario()).unwrap();
    text_toml.push_str("\n[sensors.test_card]\nenabled = true\n");
    std::fs::write(&scenario, text_toml).unwrap();
    let rep = dir.join("report.json");
    let outcome = dir.join("stub-outcome.json");
    let id = run_id(0xc7);
    let mut stub = c_stub(&id, &lib);
    stub.arg("--outcome").arg(&outcome);
    let (emulator, stub) = fly_with_client(
        &[
            "--no-log",
            "--report",
            rep.to_str().unwrap(),
            "--scenario",
            scenario.to_str().unwrap(),
        ],
        &id,
        stub,
    );
    assert!(stub.status.success(), "stub: {}", text(&stub));
    assert!(emulator.status.success(), "oils run: {}", text(&emulator));
    let r = report(&rep);
    assert_soft_touchdown(&r, &terminal_descent_scenario());
    // The stub checked each frame before the library saw it; the library checked it
    // again (length, XXH3-64, the card's counter) and counted it.
    let o: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&outcome).unwrap()).unwrap();
    let frames = o["frames"].as_u64().unwrap();
    assert_eq!(o["frames_missed"], 0);
    assert!(
        frames + 1 >= r["sim_time_s"].as_f64().unwrap() as u64 && frames > 10,
        "{frames} frames in {} s",
        r["sim_time_s"]
    );
    assert!(
        text(&stub).contains(&format!("frames: {frames} checked")),
        "{}",
        text(&stub)
    );
}

/// The same GNC with terrain navigation and hazard avoidance (`map` and
/// `hazard_avoidance` in its `--fsw-params`): through the C ABI it reads the camera's
/// and the lidar's frames in place (`oils_fsw_frame`, zero-copy over iceoryx2) and flies
/// the hazardous-site descent with the digest of the native GNC.
#[test]
fn rust_gnc_with_terrain_navigation_through_the_c_abi_gives_the_native_digest() {
    let dir = scratch("cabi-gnc-terrain");
    let map = dir.join("hazardous-site.oilsmap");
    let out = run_oils(&[
        "map",
        "--scenario",
        "hazardous-site",
        "--cells",
        "512",
        "--out",
        map.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let native_rep = dir.join("native.json");
    let out = run_oils(&[
        "run",
        "--scenario",
        "hazardous-site",
        "--no-log",
        "--gnc-map",
        map.to_str().unwrap(),
        "--gnc-hda",
        "on",
        "--report",
        native_rep.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let native = report(&native_rep);
    assert_eq!(native["outcome"], "landed");
    let params = dir.join("gnc.toml");
    std::fs::write(
        &params,
        format!(
            "navigation = \"sensors\"\nhazard_avoidance = true\nmap = \"{}\"\n",
            map.display()
        ),
    )
    .unwrap();
    let id = run_id(0xc8);
    let mut stub = c_stub(&id, &cabi_gnc_library());
    stub.arg("--fsw-params").arg(&params);
    let rep = dir.join("cabi.json");
    let (emulator, stub) = fly_with_client(
        &[
            "--no-log",
            "--scenario",
            "hazardous-site",
            "--telemetry",
            "sensors",
            "--report",
            rep.to_str().unwrap(),
        ],
        &id,
        stub,
    );
    assert!(stub.status.success(), "stub: {}", text(&stub));
    assert!(emulator.status.success(), "oils run: {}", text(&emulator));
    let through_c = report(&rep);
    assert_eq!(through_c["outcome"], "landed");
    assert_eq!(
        through_c["digest"], native["digest"],
        "the terrain-navigating GNC through the C ABI must fly the native descent"
    );
}
