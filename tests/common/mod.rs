//! Helpers for the end-to-end tests: they run the real `oils` binary, which talks to a
//! real onboard-stub process over real iceoryx2 shared memory.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `oils` binary cargo built for these tests.
pub fn oils() -> Command {
    Command::new(env!("CARGO_BIN_EXE_oils"))
}

/// A fresh scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("oils-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

/// Runs `oils` with `args`, returns its output.
pub fn run_oils(args: &[&str]) -> Output {
    oils().args(args).output().expect("spawning oils")
}

/// Parses a JSON report.
pub fn report(path: &Path) -> serde_json::Value {
    let text =
        std::fs::read_to_string(path).unwrap_or_else(|e| panic!("report {}: {e}", path.display()));
    serde_json::from_str(&text).expect("report is JSON")
}

/// Text of both output streams, for assertion messages.
pub fn text(o: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A unique run id for tests that start the two processes by hand.
pub fn run_id(tag: u64) -> String {
    format!("{:016x}", (std::process::id() as u64) << 20 | tag)
}
