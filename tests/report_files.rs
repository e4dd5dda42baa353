//! Report files: refused before tick 0 when they cannot be written, created private.

use std::os::unix::fs::PermissionsExt;
use std::process::Command;

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("oils-report-files-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_report_that_cannot_be_written_is_refused_before_the_run() {
    let dir = scratch("refused");
    // A directory cannot be made under a regular file, not even by root.
    let file = dir.join("plain-file");
    std::fs::write(&file, b"x").unwrap();
    let report = file.join("sub").join("r.json");
    let out = Command::new(env!("CARGO_BIN_EXE_oils"))
        .args([
            "run",
            "--link",
            "inproc",
            "--no-log",
            "--duration",
            "100000",
        ])
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stdout}{stderr}");
    assert!(
        stderr.contains("plain-file"),
        "the error names the path: {stderr}"
    );
    // Refused before tick 0: no outcome was printed.
    assert!(!stdout.contains("outcome"), "{stdout}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_report_is_created_readable_by_its_owner_only() {
    let dir = scratch("private");
    let report = dir.join("r.json");
    let out = Command::new(env!("CARGO_BIN_EXE_oils"))
        .args(["run", "--link", "inproc", "--no-log", "--duration", "2"])
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mode = std::fs::metadata(&report).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o600, "report mode {mode:o}");
    let _ = std::fs::remove_dir_all(&dir);
}
