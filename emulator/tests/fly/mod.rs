//! Shared by the test binaries that fly whole runs in process with the reference flight
//! software (`rates`, `faults`): one way to start a run, so the two cannot drift.

use oils_emulator::report::RunReport;
use oils_emulator::run_config::RunConfig;
use oils_emulator::session;
use std::sync::atomic::AtomicBool;

/// Flies `cfg` in process with a fresh run id.
pub fn try_fly(cfg: &RunConfig) -> Result<RunReport, session::SessionError> {
    let run_id = session::fresh_run_id();
    let fsw = oils_onboard_stub::build::build_fsw(
        &cfg.fsw,
        None,
        None,
        run_id,
        Some(oils_onboard_stub::gnc::SiteTarget {
            latitude_deg: cfg.scenario.site.latitude_deg,
            longitude_deg: cfg.scenario.site.longitude_deg,
        }),
        cfg.gnc.clone(),
    )
    .unwrap();
    session::run(
        cfg,
        run_id,
        &AtomicBool::new(false),
        session::Onboard::InProcess(fsw),
        session::Extras::default(),
    )
}

/// [`try_fly`], which must succeed.
#[allow(dead_code)] // not every binary that includes this module calls it
pub fn fly(cfg: &RunConfig) -> RunReport {
    try_fly(cfg).unwrap()
}
