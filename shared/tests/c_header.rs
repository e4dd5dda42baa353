//! `shared/include/oils.h` is what the generator writes today, and a C compiler agrees
//! with the Rust layout: the header's `_Static_assert`s compile, and a C program that
//! hashes `OILS_SCHEMA` itself gets `OILS_SCHEMA_HASH` and the Rust sizes.

use oils_shared::c_abi::{c_header, FSW_LAYOUT_HASH};
use oils_shared::{Command, Telemetry, SCHEMA_HASH};
use std::process::Command as Process;

mod common;
use common::c_build::{c_compiler, include_dir};

#[test]
fn c_header_is_current() {
    let committed = std::fs::read_to_string(include_dir().join("oils.h")).expect("oils.h");
    assert!(
        committed == c_header(),
        "shared/include/oils.h is stale: regenerate it with\n    \
         cargo run -p oils-shared --example c_header > shared/include/oils.h"
    );
}

const PROBE_C: &str = r#"
#include "oils.h"
#include <stdio.h>
#include <string.h>

int main(void) {
    const char *s = OILS_SCHEMA;
    uint64_t h = UINT64_C(0xcbf29ce484222325);
    for (size_t i = 0; i < strlen(s); i++) {
        h ^= (uint64_t)(unsigned char)s[i];
        h *= UINT64_C(0x100000001b3);
    }
    printf("%d %zu %zu 0x%016llx 0x%016llx 0x%016llx\n", h == OILS_SCHEMA_HASH,
           sizeof(oils_telemetry), sizeof(oils_command), (unsigned long long)h,
           (unsigned long long)OILS_SCHEMA_HASH, (unsigned long long)OILS_FSW_LAYOUT_HASH);
    return 0;
}
"#;

#[test]
fn c_compiler_agrees_with_the_rust_layout() {
    let dir = std::env::temp_dir().join(format!("oils-c-header-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = dir.join("probe.c");
    let exe = dir.join("probe");
    std::fs::write(&src, PROBE_C).unwrap();
    let out = c_compiler()
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-pedantic", "-I"])
        .arg(include_dir())
        .arg(&src)
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("running the C compiler");
    assert!(
        out.status.success(),
        "oils.h does not compile (a _Static_assert failed?):\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Process::new(&exe).output().expect("running the probe");
    let text = String::from_utf8_lossy(&run.stdout).trim().to_string();
    let expected = format!(
        "1 {} {} {SCHEMA_HASH:#018x} {SCHEMA_HASH:#018x} {FSW_LAYOUT_HASH:#018x}",
        size_of::<Telemetry>(),
        size_of::<Command>()
    );
    assert_eq!(text, expected);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_wrong_offset_fails_to_compile() {
    // The static assertions bite: a header whose Command has one more field before
    // `engine_on` must not compile.
    let dir = std::env::temp_dir().join(format!("oils-c-header-bad-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = c_header().replace(
        "  uint32_t engine_on[4];",
        "  uint32_t extra;\n  uint32_t engine_on[4];",
    );
    assert_ne!(bad, c_header());
    std::fs::write(dir.join("oils.h"), bad).unwrap();
    std::fs::write(
        dir.join("probe.c"),
        "#include \"oils.h\"\nint main(void) { return 0; }\n",
    )
    .unwrap();
    let out = c_compiler()
        .args(["-std=c11", "-I"])
        .arg(&dir)
        .arg(dir.join("probe.c"))
        .arg("-o")
        .arg(dir.join("probe"))
        .output()
        .expect("running the C compiler");
    assert!(!out.status.success(), "a moved field compiled");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("oils_command.engine_on offset"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
}
