//! The stub's command line (`oils-onboard-stub`, and `oils stub` when the bench spawns
//! it): which run to join and which flight software to fly.

use crate::c_library::{CLibraryError, CLibraryFsw};
use crate::fsw::{FlightSoftware, FswSpec};
use crate::gnc::{GncConfig, GncConfigError, ReferenceGnc};
use crate::playback::ProfilePlayback;
use crate::runner::{serve, StubError, StubSummary};
use oils_shared::link::{create_node, LinkError, StubLink, WaitStrategy};
use oils_shared::profile::{ProfileError, ProfileRules, ThrustProfile, RATED_THRUST_N};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

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
    /// busy, event or hybrid; default: what the emulator announces.
    #[arg(long)]
    pub wait: Option<String>,
    /// Give up after this long without telemetry, milliseconds.
    #[arg(long, default_value_t = 5000)]
    pub timeout_ms: u64,
    /// Run under SCHED_FIFO at this priority (1-99) with memory locked (root or
    /// CAP_SYS_NICE). A stub spawned by `oils run --rt-priority` inherits it anyway.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: Option<i32>,
    /// How long to wait for the emulator's services to appear, milliseconds.
    #[arg(long, default_value_t = 10000)]
    pub startup_timeout_ms: u64,
}

/// Why the stub could not run.
#[derive(Debug, thiserror::Error)]
pub enum StubCliError {
    /// Bad argument.
    #[error("{0}")]
    Argument(String),
    /// Profile unreadable.
    #[error(transparent)]
    Profile(#[from] ProfileError),
    /// GNC configuration invalid.
    #[error(transparent)]
    Gnc(#[from] GncConfigError),
    /// C flight software could not be loaded.
    #[error(transparent)]
    CLibrary(#[from] CLibraryError),
    /// Link failure.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The loop failed.
    #[error(transparent)]
    Serve(#[from] StubError),
}

/// Largest `--fsw-params` file, bytes.
pub const MAX_FSW_PARAMS_BYTES: u64 = 1 << 20;

/// Builds the flight software asked for (allocation happens here, before tick 0).
/// `profile` is for playback (the file and the rules it is read with, see
/// `oils_shared::profile`); `fsw_params` (a text file of at most
/// [`MAX_FSW_PARAMS_BYTES`]) and `run_id` are handed to a C library's `oils_fsw_init`.
pub fn build_fsw(
    spec: &FswSpec,
    profile: Option<(&Path, &ProfileRules)>,
    fsw_params: Option<&Path>,
    run_id: u64,
) -> Result<Box<dyn FlightSoftware>, StubCliError> {
    match spec {
        FswSpec::Gnc => Ok(Box::new(ReferenceGnc::new(GncConfig::default())?)),
        FswSpec::CLibrary(path) => {
            let params = match fsw_params {
                Some(p) => read_params(p)?,
                None => String::new(),
            };
            Ok(Box::new(CLibraryFsw::load(path, run_id, &params)?))
        }
        FswSpec::External => Err(StubCliError::Argument(
            "--fsw external is flown by a client started by hand, not by this stub".into(),
        )),
        FswSpec::Playback => {
            let (path, rules) = profile.ok_or_else(|| {
                StubCliError::Argument("--fsw playback needs --profile CSV".into())
            })?;
            Ok(Box::new(ProfilePlayback::new(ThrustProfile::load_with(
                path, rules,
            )?)))
        }
    }
}

/// A flight software parameter file: text of at most [`MAX_FSW_PARAMS_BYTES`].
fn read_params(p: &Path) -> Result<String, StubCliError> {
    use std::io::Read;
    let bad = |why: String| StubCliError::Argument(format!("--fsw-params {}: {why}", p.display()));
    let file = std::fs::File::open(p).map_err(|e| bad(e.to_string()))?;
    let mut bytes = Vec::new();
    file.take(MAX_FSW_PARAMS_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| bad(e.to_string()))?;
    if bytes.len() as u64 > MAX_FSW_PARAMS_BYTES {
        return Err(bad(format!(
            "larger than {MAX_FSW_PARAMS_BYTES} bytes, the largest parameter file"
        )));
    }
    String::from_utf8(bytes).map_err(|_| bad("not UTF-8 text".into()))
}

/// Joins the run and serves it to the end.
pub fn run_stub(args: &StubArgs, stop: &AtomicBool) -> Result<StubSummary, StubCliError> {
    let run_id = u64::from_str_radix(args.run_id.trim_start_matches("0x"), 16).map_err(|_| {
        StubCliError::Argument(format!("--run-id {}: not a hex number", args.run_id))
    })?;
    let wait: Option<WaitStrategy> = match &args.wait {
        Some(w) => Some(w.parse().map_err(|_| {
            StubCliError::Argument(format!("--wait {w}: expected busy, event or hybrid"))
        })?),
        None => None,
    };
    if let Some(priority) = args.rt_priority {
        oils_shared::clock::set_realtime_priority(priority).map_err(|e| {
            StubCliError::Argument(format!(
                "--rt-priority {priority}: {e} (needs root or CAP_SYS_NICE)"
            ))
        })?;
    }
    if !(args.max_thrust_n.is_finite() && args.max_thrust_n > 0.0) {
        return Err(StubCliError::Argument(format!(
            "--max-thrust-n {}: a finite number > 0 expected",
            args.max_thrust_n
        )));
    }
    let rules = ProfileRules::rated(args.max_thrust_n);
    let mut fsw = build_fsw(
        &args.fsw,
        args.profile.as_deref().map(|p| (p, &rules)),
        args.fsw_params.as_deref(),
        run_id,
    )?;
    let node = create_node("oils-onboard-stub")?;
    let link = StubLink::open(&node, run_id, wait, args.startup_timeout_ms, stop)?;
    Ok(serve(&link, fsw.as_mut(), args.timeout_ms, stop)?)
}
