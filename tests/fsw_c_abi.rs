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
