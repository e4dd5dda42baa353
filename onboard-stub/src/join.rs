//! Joining a run as the onboard process: open the run's services, build the flight
//! software and serve it to the end. The options are a plain value; the `oils stub`
//! command line turns its flags into one.

use crate::build::{build_fsw_expecting, FswBuildError};
use crate::fsw::{FswFailure, FswSpec};
use crate::runner::{serve, StubError, StubSummary};
use oils_shared::link::{create_node, LinkError, StubLink, WaitStrategy};
use oils_shared::profile::{ProfileRules, RATED_THRUST_N};
use oils_shared::realtime::{Hygiene, RealtimeStatus};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// How the onboard process joins a run (the flags of `oils stub`).
#[derive(Debug, Clone)]
pub struct StubOptions {
    /// Run id to join (hex), as printed by the emulator.
    pub run_id: String,
    /// Flight software to run.
    pub fsw: FswSpec,
    /// Thrust-command profile CSV for `playback`.
    pub profile: Option<PathBuf>,
    /// Engine rating the profile's commands are checked against, newtons.
    pub max_thrust_n: f64,
    /// For a C library: the text file handed to its `oils_fsw_init`.
    pub fsw_params: Option<PathBuf>,
    /// For a C library: refuse the file unless its BLAKE3 is this (`oils run` passes the
    /// hash it puts in the report).
    pub fsw_blake3: Option<String>,
    /// The scenario's landing site the reference GNC flies to (`None`: the default
    /// scenario's).
    pub site: Option<crate::gnc::SiteTarget>,
    /// What the reference GNC navigates from and turns the vehicle with.
    pub gnc: crate::fsw::GncOptions,
    /// busy, event or hybrid; `None`: what the emulator announces.
    pub wait: Option<String>,
    /// Give up after this long without telemetry, milliseconds.
    pub timeout_ms: u64,
    /// SCHED_FIFO priority (1-99); refused: the stub fails.
    pub rt_priority: Option<i32>,
    /// Lock memory and prefault the stack before serving (realtime runs); refused: a
    /// warning.
    pub lock_memory: bool,
    /// Pin the stepping thread to this CPU (checked online first); refused: a warning.
    pub cpu: Option<usize>,
    /// How long to wait for the emulator's services to appear, milliseconds.
    pub startup_timeout_ms: u64,
}

impl StubOptions {
    /// Options for `run_id` with the defaults of `oils stub`.
    pub fn new(run_id: impl Into<String>) -> Self {
        Self {
            run_id: run_id.into(),
            fsw: FswSpec::Gnc,
            profile: None,
            max_thrust_n: RATED_THRUST_N,
            fsw_params: None,
            fsw_blake3: None,
            site: None,
            gnc: Default::default(),
            wait: None,
            timeout_ms: 5000,
            rt_priority: None,
            lock_memory: false,
            cpu: None,
            startup_timeout_ms: 10_000,
        }
    }
}

/// Why the onboard process could not serve the run.
#[derive(Debug, thiserror::Error)]
pub enum JoinError {
    /// Bad option.
    #[error("{0}")]
    Argument(String),
    /// The flight software could not be built.
    #[error(transparent)]
    Fsw(#[from] FswBuildError),
    /// Link failure.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The loop failed.
    #[error(transparent)]
    Serve(#[from] StubError),
}

impl JoinError {
    /// The step the flight software reported failed, if that is what ended the stub.
    pub fn fsw_failure(&self) -> Option<FswFailure> {
        match self {
            JoinError::Serve(StubError::FlightSoftware(f)) => Some(*f),
            _ => None,
        }
    }
}

/// How the onboard process served a run, and what its stepping thread obtained.
#[derive(Debug)]
pub struct StubRun {
    /// The run served, or why not.
    pub served: Result<StubSummary, JoinError>,
    /// Scheduling, memory lock and pinning as read back before the first step (`None`:
    /// the stub failed before it got that far).
    pub realtime: Option<RealtimeStatus>,
}

/// Joins the run and serves it to the end.
pub fn run_stub(args: &StubOptions, stop: &AtomicBool) -> StubRun {
    let mut realtime = None;
    let served = join_and_serve(args, stop, &mut realtime);
    StubRun { served, realtime }
}

fn join_and_serve(
    args: &StubOptions,
    stop: &AtomicBool,
    realtime: &mut Option<RealtimeStatus>,
) -> Result<StubSummary, JoinError> {
    let run_id = u64::from_str_radix(args.run_id.trim_start_matches("0x"), 16)
        .map_err(|_| JoinError::Argument(format!("--run-id {}: not a hex number", args.run_id)))?;
    let wait: Option<WaitStrategy> = match &args.wait {
        Some(w) => Some(w.parse().map_err(|_| {
            JoinError::Argument(format!("--wait {w}: expected busy, event or hybrid"))
        })?),
        None => None,
    };
    if let Some(priority) = args.rt_priority {
        oils_shared::realtime::set_realtime_priority(priority).map_err(|e| {
            JoinError::Argument(format!(
                "--rt-priority {priority}: {e} (needs root or CAP_SYS_NICE)"
            ))
        })?;
    }
    if !(args.max_thrust_n.is_finite() && args.max_thrust_n > 0.0) {
        return Err(JoinError::Argument(format!(
            "--max-thrust-n {}: a finite number > 0 expected",
            args.max_thrust_n
        )));
    }
    if let Some(cpu) = args.cpu {
        oils_shared::realtime::check_cpus(&[cpu])
            .map_err(|e| JoinError::Argument(format!("--cpu {cpu}: {e}")))?;
    }
    let rules = ProfileRules::rated(args.max_thrust_n);
    let mut fsw = build_fsw_expecting(
        &args.fsw,
        args.profile.as_deref().map(|p| (p, &rules)),
        args.fsw_params.as_deref(),
        run_id,
        args.fsw_blake3.as_deref(),
        args.site,
        args.gnc.clone(),
    )?;
    // Before the link opens, so the emulator's first telemetry finds the stub ready:
    // memory locked (MCL_FUTURE: the link's shared memory comes locked), the stack
    // prefaulted, this (the stepping) thread pinned. The stub's watchdog thread, spawned
    // by `serve`, inherits the pin; it wakes every 50 ms for microseconds.
    let mut hygiene = Hygiene::new();
    if args.lock_memory {
        hygiene.lock_memory();
        hygiene.hold_wake_latency();
    }
    if let Some(cpu) = args.cpu {
        hygiene.pin_to(cpu);
    }
    let status = hygiene.status();
    for w in &status.warnings {
        eprintln!("oils stub: warning: {w}");
    }
    *realtime = Some(status);
    let node = create_node("oils-onboard-stub")?;
    let link = StubLink::open(&node, run_id, wait, args.startup_timeout_ms, stop)?;
    Ok(serve(&link, fsw.as_mut(), args.timeout_ms, stop)?)
}
