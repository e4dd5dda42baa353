//! `oils stub`: the onboard-computer process. `oils run` spawns it; started by hand it
//! joins a run whose id the emulator printed. The flags become a plain
//! [`StubOptions`]; the stub library does the rest.

use anyhow::{Context, Result};
use oils_onboard_stub::fsw::FswSpec;
use oils_onboard_stub::join::{run_stub, StubOptions};
use oils_shared::profile::RATED_THRUST_N;
use std::path::{Path, PathBuf};

/// Arguments of the onboard stub.
#[derive(Debug, Clone, clap::Args)]
pub struct StubArgs {
    /// Run id to join (hex), as printed by the emulator.
    #[arg(long)]
    pub run_id: String,
    /// Flight software to run: gnc, playback (with --profile) or c:PATH.
    #[arg(long, default_value = "gnc")]
    pub fsw: FswSpec,
    /// Thrust-command profile CSV for `--fsw playback`.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Engine rating the profile's commands are checked against, newtons (the run's
    /// `scenario.propulsion.max_thrust_n`; `oils run` passes it).
    #[arg(long, default_value_t = RATED_THRUST_N)]
    pub max_thrust_n: f64,
    /// For `--fsw c:PATH`: a text file handed to the library's `oils_fsw_init` as its
    /// parameters (any format the library reads; default: empty).
    #[arg(long)]
    pub fsw_params: Option<PathBuf>,
    /// For `--fsw c:PATH`: refuse the library unless its BLAKE3 (64 hex digits) is this
    /// (`oils run` passes the hash it records in the report).
    #[arg(long, value_name = "HEX")]
    pub fsw_blake3: Option<String>,
    /// The scenario's landing site the reference GNC flies to, `LAT,LON` in degrees
    /// (`oils run` passes its scenario's `[site]`; default: the default scenario's).
    #[arg(long, value_name = "LAT,LON", value_parser = parse_site, allow_hyphen_values = true)]
    pub site: Option<oils_onboard_stub::gnc::SiteTarget>,
    /// What the reference GNC navigates from: `bench` (the ideal navigation source) or
    /// `sensors` (its Kalman filter on the device samples).
    #[arg(long, default_value = "bench")]
    pub gnc_nav: oils_shared::fsw::GncNavigation,
    /// Terrain navigation data the reference GNC navigates by (`oils map`; with
    /// `--gnc-nav sensors`).
    #[arg(long, value_name = "MAP")]
    pub gnc_map: Option<std::path::PathBuf>,
    /// Hazard detection and avoidance at the hover (with `--gnc-nav sensors`).
    #[arg(long)]
    pub gnc_hda: bool,
    /// What the reference GNC turns the vehicle with: `torque` (ideal) or `thrusters`.
    #[arg(long, default_value = "torque")]
    pub gnc_attitude: oils_shared::fsw::GncAttitude,
    /// Write how the stub ended to FILE as JSON (`error`, `fsw_failure` with the step and
    /// the status a failed step returned, `commands`, `last_step`, `realtime`: scheduling,
    /// memory lock and pinning obtained); `oils run` reads it into its report.
    #[arg(long, value_name = "FILE")]
    pub outcome: Option<PathBuf>,
    /// busy, event or hybrid; default: what the emulator announces.
    #[arg(long)]
    pub wait: Option<String>,
    /// Give up after this long without telemetry, milliseconds.
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Run under SCHED_FIFO at this priority (1-99) (root or CAP_SYS_NICE; refused, the
    /// stub fails). A stub spawned by `oils run --rt-priority` inherits it anyway.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: Option<i32>,
    /// How long to wait for the emulator's services to appear, milliseconds.
    #[arg(long, default_value_t = 10000)]
    pub startup_timeout_ms: u64,
    /// Lock memory (`mlockall`), prefault the stack and hold the CPUs' wake-up latency
    /// at 0 (`/dev/cpu_dma_latency`) before the first step (`oils run` passes it for
    /// realtime runs). Refused: a warning, and the outcome says so.
    #[arg(long)]
    pub lock_memory: bool,
    /// Pin the stepping thread to this CPU (`oils run --cpus E,S` passes S). Refused: a
    /// warning, and the outcome says so.
    #[arg(long, value_name = "CPU")]
    pub cpu: Option<usize>,
}

impl From<&StubArgs> for StubOptions {
    fn from(a: &StubArgs) -> Self {
        StubOptions {
            run_id: a.run_id.clone(),
            fsw: a.fsw.clone(),
            profile: a.profile.clone(),
            max_thrust_n: a.max_thrust_n,
            fsw_params: a.fsw_params.clone(),
            fsw_blake3: a.fsw_blake3.clone(),
            site: a.site,
            gnc: oils_shared::fsw::GncOptions {
                navigation: a.gnc_nav,
                attitude: a.gnc_attitude,
                map: a.gnc_map.clone(),
                hazard_avoidance: a.gnc_hda,
            },
            wait: a.wait.clone(),
            timeout_ms: a.timeout_ms,
            rt_priority: a.rt_priority,
            lock_memory: a.lock_memory,
            cpu: a.cpu,
            startup_timeout_ms: a.startup_timeout_ms,
        }
    }
}

/// `LAT,LON` in degrees.
fn parse_site(s: &str) -> Result<oils_onboard_stub::gnc::SiteTarget, String> {
    let bad = || format!("{s}: expected LAT,LON in degrees");
    let (lat, lon) = s.split_once(',').ok_or_else(bad)?;
    let lat: f64 = lat.trim().parse().map_err(|_| bad())?;
    let lon: f64 = lon.trim().parse().map_err(|_| bad())?;
    if !(lat.abs() < 90.0 && lon.is_finite()) {
        return Err(bad());
    }
    Ok(oils_onboard_stub::gnc::SiteTarget {
        latitude_deg: lat,
        longitude_deg: lon,
    })
}

/// Runs `oils stub`: joins the run and serves it; with `--outcome`, writes how it ended.
pub fn run(a: &StubArgs) -> Result<()> {
    let stop = oils_shared::signals::termination_flag().context("installing signal handlers")?;
    let run = run_stub(&a.into(), &stop);
    let served = run.served;
    if let Some(path) = &a.outcome {
        let mut outcome = match &served {
            Ok(s) => serde_json::json!({
                "error": null, "fsw_failure": null,
                "commands": s.commands, "last_step": s.last_step,
                "frames": s.frames, "frames_missed": s.frames_missed,
            }),
            Err(e) => serde_json::json!({
                "error": format!("{e}"), "fsw_failure": e.fsw_failure(),
            }),
        };
        // What the stepping thread obtained, for the run report's `realtime.onboard`.
        outcome["realtime"] = serde_json::to_value(&run.realtime).unwrap_or_default();
        write_outcome(path, &outcome.to_string())
            .with_context(|| format!("--outcome {}", path.display()))?;
    }
    served.with_context(|| format!("onboard stub on run {}", a.run_id))?;
    Ok(())
}

/// Writes the outcome file owner-only, not following a symlink.
fn write_outcome(path: &Path, text: &str) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?;
    f.write_all(text.as_bytes())
}
