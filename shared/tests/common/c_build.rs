//! C for the tests of three crates (shared, onboard-stub, the root's end-to-end tests,
//! which include this file by path): the machine's C compiler, and C flight software
//! built into a shared library the way a user would build theirs
//! (`cc -shared -fPIC -I shared/include`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

/// `shared/include`, where `oils.h` lives.
pub fn include_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .map(|d| d.join("shared/include"))
        .find(|d| d.join("oils.h").is_file())
        .expect("shared/include/oils.h above this crate")
}

/// The C example flight software, `onboard-stub/examples/c/terminal_descent.c`.
pub fn terminal_descent_c() -> PathBuf {
    include_dir().join("../../onboard-stub/examples/c/terminal_descent.c")
}

/// The machine's C compiler at `-O2`: `$CC` if set, else `cc` (what a user building
/// their flight software would call; no target triple assumed).
pub fn c_compiler() -> std::process::Command {
    let cc = std::env::var_os("CC").unwrap_or_else(|| "cc".into());
    let mut cmd = std::process::Command::new(cc);
    cmd.arg("-O2");
    cmd
}

/// Compiles `src` (and `-D` `defines`) into `out_dir/lib<name>.so`; panics with the
/// compiler's messages on failure. Warnings are errors: the examples must build clean.
pub fn shared_library(src: &Path, name: &str, out_dir: &Path, defines: &[&str]) -> PathBuf {
    let mut cmd = c_compiler();
    let out = out_dir.join(format!("lib{name}.so"));
    cmd.args([
        "-std=c11",
        "-Wall",
        "-Wextra",
        "-Werror",
        "-pedantic",
        "-shared",
        "-fPIC",
    ]);
    for d in defines {
        cmd.arg(format!("-D{d}"));
    }
    cmd.arg("-I")
        .arg(include_dir())
        .arg(src)
        .arg("-o")
        .arg(&out)
        .arg("-lm");
    let output = cmd.output().expect("running the C compiler");
    assert!(
        output.status.success(),
        "building {}:\n{}",
        src.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    out
}
