//! `--fsw c:PATH`: C flight software built with the `cc` crate, loaded and checked by the
//! stub's loader, stepped through the `FlightSoftware` trait.

mod common;
use common::c_build::{shared_library, terminal_descent_c};
use oils_onboard_stub::build::build_fsw;
use oils_onboard_stub::fsw::{FswFailure, FswSpec};
use oils_shared::c_abi::{FSW_ABI_VERSION, FSW_LAYOUT_HASH};
use oils_shared::{PacketHeader, Telemetry};
use std::path::{Path, PathBuf};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("oils-c-lib-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A minimal library whose version, hash, step status and exports the test chooses.
const PROBE_C: &str = r#"
#include "oils.h"
#include <string.h>
#ifndef VERSION
#define VERSION OILS_FSW_ABI_VERSION
#endif
#ifndef HASH
#define HASH OILS_FSW_LAYOUT_HASH
#endif
#ifndef FAIL_STATUS
#define FAIL_STATUS OILS_FSW_STATUS_OK
#endif
uint32_t oils_fsw_abi_version(void) { return VERSION; }
uint64_t oils_fsw_layout_hash(void) { return HASH; }
static int context;
void *oils_fsw_init(const oils_fsw_config *c) {
  int ok = c->abi_version == OILS_FSW_ABI_VERSION && c->protocol_version == OILS_PROTOCOL_VERSION
        && c->schema_hash == OILS_SCHEMA_HASH && c->run_id == UINT64_C(0x22)
        && c->params != NULL && strlen(c->params) == c->params_len;
  return ok ? &context : NULL;
}
int32_t oils_fsw_step(void *ctx, const oils_telemetry *tlm, oils_command *cmd) {
  (void)ctx;
  cmd->thrust_cmd_n[0] = (double)tlm->header.step;
  cmd->engine_on[0] = 1;
  return tlm->header.step >= 3 ? FAIL_STATUS : OILS_FSW_STATUS_OK;
}
#ifndef OMIT_FINI
void oils_fsw_fini(void *ctx) { (void)ctx; }
#endif
"#;

fn probe(dir: &Path, name: &str, defines: &[&str]) -> FswSpec {
    let src = dir.join(format!("{name}.c"));
    std::fs::write(&src, PROBE_C).unwrap();
    FswSpec::CLibrary(shared_library(&src, name, dir, defines))
}

/// The loader's error, as printed (the flight software itself has no `Debug`).
fn load_error(spec: &FswSpec, params: Option<&Path>, run_id: u64) -> String {
    match build_fsw(spec, None, params, run_id, None, Default::default()) {
        Ok(_) => panic!("{spec} loaded"),
        Err(e) => e.to_string(),
    }
}

fn tlm(step: u64) -> Telemetry {
    Telemetry {
        header: PacketHeader::new(0x22, step, step as i64 * 10_000_000),
        ..Default::default()
    }
}

#[test]
fn a_library_steps_and_its_failure_stops_it() {
    let dir = scratch("fails");
    let spec = probe(&dir, "fails", &["FAIL_STATUS=7"]);
    let Ok(mut fsw) = build_fsw(&spec, None, None, 0x22, None, Default::default()) else {
        panic!("does not load")
    };
    assert_eq!(fsw.name(), "c");
    for k in 0..3 {
        let cmd = fsw.step(&tlm(k));
        assert_eq!(cmd.thrust_cmd_n[0], k as f64);
        assert_eq!(cmd.engine_on[0], 1);
        assert_eq!(fsw.failure(), None);
    }
    let cmd = fsw.step(&tlm(3));
    assert_eq!(
        cmd.engine_on, [0; 4],
        "a failed step's command is not the library's"
    );
    assert_eq!(fsw.failure(), Some(FswFailure { step: 3, status: 7 }));
    assert!(fsw
        .failure()
        .unwrap()
        .to_string()
        .contains("step 3 (status 7)"));
}

#[test]
fn init_gets_the_run_id_and_the_parameters() {
    let dir = scratch("init");
    let spec = probe(&dir, "init", &[]);
    let params = dir.join("params.txt");
    std::fs::write(&params, "gain = 2\n").unwrap();
    assert!(build_fsw(&spec, None, Some(&params), 0x22, None, Default::default()).is_ok());
    // The probe refuses any other run id: init's NULL is a clear error.
    let err = load_error(&spec, None, 0x23);
    assert!(err.contains("oils_fsw_init refused the run"), "{err}");
}

#[test]
fn another_abi_version_or_layout_is_refused_naming_both() {
    let dir = scratch("abi");
    let spec = probe(&dir, "v99", &["VERSION=99"]);
    let err = load_error(&spec, None, 0x22);
    for part in [
        "C ABI v99".to_string(),
        format!("speaks v{FSW_ABI_VERSION}"),
        format!("{FSW_LAYOUT_HASH:#018x}"),
        "libv99.so".to_string(),
    ] {
        assert!(err.contains(&part), "`{part}` missing from: {err}");
    }
    let spec = probe(&dir, "hash", &["HASH=UINT64_C(0x1234)"]);
    let err = load_error(&spec, None, 0x22);
    assert!(err.contains("layout hash 0x0000000000001234"), "{err}");
    assert!(err.contains(&format!("{FSW_LAYOUT_HASH:#018x}")), "{err}");
}

#[test]
fn a_missing_function_or_file_is_named() {
    let dir = scratch("missing");
    let spec = probe(&dir, "nofini", &["OMIT_FINI"]);
    let err = load_error(&spec, None, 0x22);
    assert!(err.contains("does not export `oils_fsw_fini`"), "{err}");
    let none = FswSpec::CLibrary(dir.join("libnot-there.so"));
    let err = load_error(&none, None, 0x22);
    assert!(
        err.contains("cannot load") && err.contains("libnot-there.so"),
        "{err}"
    );
}

#[test]
fn the_c_example_holds_its_weight_on_the_profile() {
    // Upright over the +Z axis, descending exactly at the profile speed (20 m/s at 2 km):
    // the example commands gravity's thrust, shared by the four engines, and no torque.
    let dir = scratch("example");
    let lib = shared_library(&terminal_descent_c(), "terminal_descent", &dir, &[]);
    let Ok(mut fsw) = build_fsw(
        &FswSpec::CLibrary(lib),
        None,
        None,
        1,
        None,
        Default::default(),
    ) else {
        panic!("does not load")
    };
    let r_m = 1_737_400.0 + 1.2 + 2000.0;
    let mut t = tlm(0);
    t.nav.pos_mci_m = [0.0, 0.0, r_m];
    t.nav.vel_mci_m_s = [0.0, 0.0, -20.0];
    t.nav.q_mci_from_body = [1.0, 0.0, 0.0, 0.0];
    t.altitude_m = 2000.0;
    t.mass_estimate_kg = 1000.0;
    let cmd = fsw.step(&t);
    let weight_per_engine_n = 1000.0 * 4.9028e12 / (r_m * r_m) / 4.0;
    for i in 0..4 {
        assert_eq!(cmd.engine_on[i], 1);
        assert!(
            (cmd.thrust_cmd_n[i] - weight_per_engine_n).abs() < 1e-9,
            "{} vs {weight_per_engine_n}",
            cmd.thrust_cmd_n[i]
        );
    }
    assert_eq!(cmd.torque_cmd_body_nm, [0.0; 3]);
    // Falling faster than the profile: more thrust than the weight.
    t.nav.vel_mci_m_s = [0.0, 0.0, -25.0];
    assert!(fsw.step(&t).thrust_cmd_n[0] > weight_per_engine_n + 1.0);
    assert_eq!(fsw.failure(), None);
}

#[test]
fn a_library_is_hashed_and_refused_when_it_is_not_the_file_expected() {
    use oils_onboard_stub::build::build_fsw_expecting;
    use oils_onboard_stub::c_library::{file_blake3, CLibraryFsw};
    let dir = scratch("hash");
    let spec = probe(&dir, "hashed", &[]);
    let FswSpec::CLibrary(path) = &spec else {
        unreachable!()
    };
    let hash = file_blake3(path).unwrap();
    assert_eq!(hash.len(), 64);
    let fsw = CLibraryFsw::load_expecting(path, 0x22, "", Some(&hash)).unwrap();
    assert_eq!(fsw.blake3(), hash);
    let other = "0".repeat(64);
    let err = match build_fsw_expecting(
        &spec,
        None,
        None,
        0x22,
        Some(&other),
        None,
        Default::default(),
    ) {
        Ok(_) => panic!("a file with another hash loaded"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains("the file changed") && err.contains(&hash) && err.contains(&other),
        "{err}"
    );
}
