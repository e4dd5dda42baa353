//! The flight software a run configuration names, built as a value and handed to the
//! run core: what `oils run --link inproc`, campaign cases and the lab's tools fly.

use oils_emulator::report::RunReport;
use oils_emulator::run_config::RunConfig;
use oils_emulator::session::{self, Extras, Onboard, SessionError};
use oils_onboard_stub::build::{build_fsw, FswBuildError};
use oils_shared::fsw::FlightSoftware;
use oils_shared::profile::ProfileRules;
use std::sync::atomic::AtomicBool;

/// An in-process run could not fly.
#[derive(Debug, thiserror::Error)]
pub enum FlyError {
    /// The flight software could not be built.
    #[error("flight software: {0}")]
    Fsw(#[from] FswBuildError),
    /// The run failed.
    #[error(transparent)]
    Session(#[from] SessionError),
}

/// The flight software `cfg` names (`cfg.fsw`, with its profile and parameter file),
/// built before tick 0 for the run `run_id`.
pub fn flight_software(
    cfg: &RunConfig,
    run_id: u64,
) -> Result<Box<dyn FlightSoftware>, FswBuildError> {
    let rules = ProfileRules::rated(cfg.scenario.propulsion.max_thrust_n);
    build_fsw(
        &cfg.fsw,
        cfg.profile.as_deref().map(|p| (p, &rules)),
        cfg.fsw_params.as_deref(),
        run_id,
        Some(site_target(&cfg.scenario)),
        cfg.gnc.clone(),
    )
}

/// The scenario's landing site as the reference GNC is told it.
pub fn site_target(
    scenario: &oils_emulator::config::ScenarioConfig,
) -> oils_onboard_stub::gnc::SiteTarget {
    oils_onboard_stub::gnc::SiteTarget {
        latitude_deg: scenario.site.latitude_deg,
        longitude_deg: scenario.site.longitude_deg,
    }
}

/// Flies `cfg` in this process (its link must be `inproc`) with the flight software it
/// names; `extras` as for [`session::run`].
pub fn fly_in_process(
    cfg: &RunConfig,
    run_id: u64,
    stop: &AtomicBool,
    extras: Extras<'_>,
) -> Result<RunReport, FlyError> {
    let fsw = flight_software(cfg, run_id)?;
    Ok(session::run(
        cfg,
        run_id,
        stop,
        Onboard::InProcess(fsw),
        extras,
    )?)
}
