//! One bench run from a [`RunConfig`] to a [`RunReport`]: builds everything before
//! tick 0 (plant, propulsion, log, link), runs the scheduler over the configured link
//! and clock, and closes the log. Also replays a recorded log through the same loop.
//!
//! The flight software comes in as a value ([`Onboard`]): one built by the caller and
//! called in this thread, or a peer process the caller starts once the run's services
//! exist. No command-line types here, and nothing of the lab: binaries build the
//! `RunConfig` and the flight software, and hand in a [`SinkOpener`] for log formats
//! the core does not write itself.

use crate::clock::{LockstepClock, RealtimeClock, ReplayClock, StepClock};
use crate::devices::Devices;
use crate::faults::{FaultPlan, PlantFault};
use crate::link::{BoundLink, InProcLink, Link, ReplayLink};
use crate::plant::Plant;
use crate::propulsion;
use crate::recorder::{
    Log, LogFormat, Recorder, RecorderError, SinkOpener, REC_ENDED_AFTER_PUBLISH, REC_END_OF_RUN,
};
use crate::report::{RealtimeReport, RunReport};
use crate::run_config::{LinkKind, RunConfig, RunConfigError};
use crate::scheduler::{self, Mode, SchedulerConfig, SchedulerError};
use oils_shared::domain::Domain;
use oils_shared::fsw::FlightSoftware;
use oils_shared::link::{create_node_in, EmulatorLink, LinkError, PeerProcess, WaitStrategy};
use oils_shared::profile::ProfileRules;
use oils_shared::realtime::{Hygiene, RealtimeStatus};
use oils_shared::PROTOCOL_VERSION;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Why a run could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// The run configuration is invalid.
    #[error(transparent)]
    Config(#[from] RunConfigError),
    /// The scenario is invalid.
    #[error(transparent)]
    Scenario(#[from] crate::config::ConfigError),
    /// Link failure.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// Log failure.
    #[error(transparent)]
    Recorder(#[from] RecorderError),
    /// Scheduler failure.
    #[error(transparent)]
    Scheduler(#[from] SchedulerError),
    /// Real-time priority refused by the OS.
    #[error("rt_priority {priority} (needs root or CAP_SYS_NICE)")]
    RealtimePriority {
        /// The priority asked for.
        priority: i32,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A CPU to pin a stepping thread to cannot be used.
    #[error("invalid run configuration: cpus [flag --cpus]")]
    Cpus(#[from] oils_shared::realtime::CpusError),
    /// Propulsion model could not be built.
    #[error("propulsion")]
    Propulsion(#[from] crate::propulsion::BuildError),
    /// The flight software handed in does not fit the configured link.
    #[error("{0}")]
    Onboard(String),
    /// Starting the onboard process failed.
    #[error("starting the onboard process: {0}")]
    Launch(String),
    /// A log to replay is unusable.
    #[error("replay of {path}: {why}")]
    Replay {
        /// The log.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
}

/// What an onboard process needs to join an iceoryx2 run.
#[derive(Debug, Clone, PartialEq)]
pub struct StubLaunch {
    /// The run id naming the services.
    pub run_id: u64,
    /// The emulator's wait strategy (announced on the services too).
    pub wait: WaitStrategy,
}

/// Who flies the run, handed to the core as a value.
pub enum Onboard<'a> {
    /// Flight software called in the emulator's thread (`link = "inproc"`): the
    /// reference GNC, a profile playback, a C library, or the user's own Rust type.
    InProcess(Box<dyn FlightSoftware + 'a>),
    /// A separate onboard process over iceoryx2 (`link = "iceoryx2"`). Called once the
    /// run's services exist: it starts the process (the `oils` binary spawns
    /// `oils stub`) and returns its process id, or prints how to start one and returns
    /// `None`. A process it started is watched while the run waits for it to join: if it
    /// exits first, the run fails at once ([`LinkError::PeerExited`]).
    Peer(&'a mut dyn FnMut(&StubLaunch) -> Result<Option<u32>, SessionError>),
}

impl Onboard<'_> {
    fn link(&self) -> LinkKind {
        match self {
            Onboard::InProcess(_) => LinkKind::Inproc,
            Onboard::Peer(_) => LinkKind::Iceoryx2,
        }
    }
}

/// What a run may take beyond its configuration and flight software.
#[derive(Default)]
pub struct Extras<'a> {
    /// Called after every integrated step (a campaign case samples its trajectory there).
    pub observer: Option<scheduler::StepObserver<'a>>,
    /// Writers for log formats other than OILSLOG3 (the lab's MCAP sink).
    pub sinks: Option<&'a dyn SinkOpener>,
    /// Builds the propulsion models the core does not ([`propulsion::PropulsionKind::Fmu`]:
    /// the lab imports the user's FMU), from the run configuration, before tick 0.
    pub propulsion: Option<PropulsionBuilder<'a>>,
    /// Called once when the flight software on the link has joined (its command
    /// publisher, and the process that created it): `oils run --no-stub` says so, for the
    /// user who started it by hand.
    pub on_peer_joined: Option<&'a mut dyn FnMut(&oils_shared::link::PeerPort)>,
    /// Time nothing on the wall clock: no round trip, no compute time, no rate-group
    /// times (the report's `timing` then has no exchange recorded). For campaign cases,
    /// which report none of it: the clock reads were about 8 % of a case (nine a cycle;
    /// `perf`, 2-core VM). Lockstep in process only (an error otherwise). The digest
    /// and everything simulated are the same either way.
    pub untimed: bool,
}

/// A builder of propulsion models the core does not build (see [`Extras::propulsion`]).
pub type PropulsionBuilder<'a> =
    &'a dyn Fn(&RunConfig) -> Result<Box<dyn propulsion::Propulsion>, propulsion::BuildError>;

/// A fresh run id: process id and monotonic time mixed (naming only; never enters the
/// plant, and the digest ignores it).
pub fn fresh_run_id() -> u64 {
    let mut x = oils_shared::clock::monotonic_ns() ^ ((std::process::id() as u64) << 40);
    // splitmix64 finaliser: spreads the bits so ids look unrelated.
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// The plant a configuration describes, with its propulsion model (built before tick 0).
pub fn build_plant(cfg: &RunConfig) -> Result<Plant, SessionError> {
    let propulsion = propulsion::build(&cfg.propulsion_spec())?;
    Ok(Plant::new(&cfg.scenario, propulsion)?)
}

/// The devices a configuration puts on board: the ideal navigation source if its
/// telemetry carries it, the sensors if it carries them, the frame devices that are
/// enabled (looking at `plant`'s ground under the scenario's sun, held at its direction
/// at the run's start: it moves about 0.5 deg an hour as seen from the Moon), seeded
/// from the run's seed.
pub fn build_devices(cfg: &RunConfig, plant: &Plant) -> Result<Devices, SessionError> {
    let mut devices = Devices::new(&cfg.scenario, cfg.seed);
    devices.set_ideal_nav(cfg.telemetry.ideal_nav());
    if cfg.telemetry.sensors() {
        devices.attach_sensors(crate::sensors::SensorSuite::new(
            &cfg.scenario.sensors,
            cfg.seed,
        )?);
    }
    let sc = &cfg.scenario;
    let site = crate::world::terrain::SiteFrame::from_deg(
        sc.site.latitude_deg,
        sc.site.longitude_deg,
        sc.moon.radius_m,
    );
    let sun =
        crate::world::sun::Sun::new(&sc.sun, &site).map_err(|e| crate::config::ConfigError {
            field: "sun",
            value: e.to_string(),
            why: "a sun the frame devices can be lit by",
        })?;
    if let Some(rack) = crate::sensors::FrameRack::from_config(
        &cfg.scenario.sensors,
        cfg.seed,
        plant.ground(),
        sun.sun_dir_mcmf(0),
        sc.moon.radius_m,
    )? {
        devices.attach_frames(rack);
    }
    Ok(devices)
}

/// The run's faults, armed, after checking that the plant's propulsion model can
/// represent each (a fault it cannot is refused, naming the model).
pub fn fault_plan(cfg: &RunConfig, plant: &Plant) -> Result<FaultPlan, SessionError> {
    for spec in &cfg.faults {
        if let Some(f) = PlantFault::of(spec) {
            if !plant.supports(&f) {
                return Err(RunConfigError::Invalid {
                    field: "faults",
                    value: spec.to_string(),
                    why: format!(
                        "the {} propulsion model cannot represent {} (only hifi models it physically)",
                        cfg.propulsion.as_str(),
                        spec.kind.name()
                    ),
                }
                .into());
            }
        }
    }
    FaultPlan::compile(&cfg.faults, cfg.seed).map_err(|e| {
        RunConfigError::Invalid {
            field: "faults",
            value: e.spec.clone(),
            why: e.why,
        }
        .into()
    })
}

fn scheduler_config(cfg: &RunConfig, run_id: u64) -> SchedulerConfig {
    SchedulerConfig {
        dt_ns: cfg.dt_ns(),
        fsw_period_ns: cfg.fsw_period_ns(),
        max_duration_ns: (cfg.duration_s * 1e9) as i64,
        run_id,
        miss_policy: cfg.miss_policy,
        link_timeout_ms: cfg.link_timeout_ms,
        max_thrust_n: cfg.scenario.propulsion.max_thrust_n,
        thresholds: cfg.thresholds.to_thresholds(),
        time_exchanges: true,
    }
}

fn step_clock(cfg: &RunConfig) -> Box<dyn StepClock> {
    match cfg.mode {
        Mode::Lockstep => Box::new(LockstepClock::new(cfg.link_timeout_ms)),
        // Paced per flight-software cycle: the unit of exchange.
        Mode::Realtime => Box::new(RealtimeClock::new(
            cfg.fsw_period_ns(),
            cfg.speed,
            cfg.deadline_frac,
            cfg.wake_spin_us * 1000,
        )),
    }
}

/// The log header: the whole run configuration, so a log can be replayed or re-run, and
/// the layout of its records ([`crate::log_layout`]), so other languages read them
/// without a copy of any offset.
pub fn log_header(cfg: &RunConfig, run_id: u64) -> String {
    let site = crate::log_fields::Site::of_scenario(&cfg.scenario);
    serde_json::json!({
        "protocol_version": PROTOCOL_VERSION,
        "run_id": format!("{run_id:016x}"),
        "config": cfg,
        "layout": crate::log_layout::layout_or_error(&site),
    })
    .to_string()
}

/// The run configuration and run id of a [`log_header`], every number exactly as
/// written: serde_json's own parser may read a float one ulp off, and a replay would
/// then diverge at step 1 (issue #36).
pub fn read_log_header(header_json: &str) -> Result<(RunConfig, u64), String> {
    let header = crate::exact_json::value_from_str(header_json)
        .map_err(|e| format!("header is not JSON: {e}"))?;
    let config: RunConfig = serde_json::from_value(header["config"].clone())
        .map_err(|e| format!("header has no usable run configuration: {e}"))?;
    let run_id = header["run_id"]
        .as_str()
        .and_then(|s| u64::from_str_radix(s, 16).ok())
        .ok_or_else(|| "header has no run id".to_string())?;
    Ok((config, run_id))
}

fn open_recorder(
    cfg: &RunConfig,
    run_id: u64,
    sinks: Option<&dyn SinkOpener>,
) -> Result<Option<Recorder>, SessionError> {
    if !cfg.log.enabled {
        return Ok(None);
    }
    let path = cfg.log.path.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "oils-out/{run_id:016x}.{}",
            cfg.log.format.extension()
        ))
    });
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|source| RecorderError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    let header = log_header(cfg, run_id);
    Ok(Some(match cfg.log.format {
        LogFormat::Oilslog => Recorder::create(&path, &header)?,
        other => {
            match sinks.filter(|s| s.writes(other)) {
                Some(opener) => Recorder::with_sink(&path, opener.open(other, &path, &header)?)?,
                None => return Err(RunConfigError::Invalid {
                    field: "log.format",
                    value: other.extension().into(),
                    why:
                        "this program has no writer for that format (the `oils` binary writes MCAP)"
                            .into(),
                }
                .into()),
            }
        }
    }))
}

/// Runs one bench run with run id `run_id` ([`fresh_run_id`] for a new one), flown by
/// `onboard`, which must match the configured link.
pub fn run(
    cfg: &RunConfig,
    run_id: u64,
    stop: &AtomicBool,
    onboard: Onboard<'_>,
    mut extras: Extras<'_>,
) -> Result<RunReport, SessionError> {
    cfg.validate()?;
    if !cfg.cpus.is_empty() {
        oils_shared::realtime::check_cpus(&cfg.cpus)?;
    }
    if onboard.link() != cfg.link {
        return Err(SessionError::Onboard(format!(
            "the run's link is {} but the flight software was handed in for {}",
            cfg.link.as_str(),
            onboard.link().as_str()
        )));
    }
    let mut plant = match (cfg.propulsion, extras.propulsion) {
        (propulsion::PropulsionKind::Fmu, Some(build)) => Plant::new(&cfg.scenario, build(cfg)?)?,
        _ => build_plant(cfg)?,
    };
    let mut devices = build_devices(cfg, &plant)?;
    let mut faults = fault_plan(cfg, &plant)?;
    let mut sched = scheduler_config(cfg, run_id);
    if extras.untimed {
        if cfg.mode != Mode::Lockstep || onboard.link() != LinkKind::Inproc {
            return Err(SessionError::Onboard(
                "an untimed run must be lockstep and in process: a realtime run or a link is what timing is for".into(),
            ));
        }
        sched.time_exchanges = false;
    }
    let mut clock = step_clock(cfg);

    if let Some(priority) = cfg.rt_priority {
        oils_shared::realtime::set_realtime_priority(priority)
            .map_err(|source| SessionError::RealtimePriority { priority, source })?;
    }
    // Memory locked now (MCL_FUTURE: the link's shared memory and the log writer, set up
    // below, come locked too) and this thread's stack prefaulted; the thread is pinned
    // only once the stub is spawned (a child would inherit the pin). Undone on return.
    let mut hygiene = Hygiene::new();
    if cfg.realtime_memory() {
        hygiene.lock_memory();
        hygiene.hold_wake_latency();
    }
    let pin_and_tell = |hygiene: &mut Hygiene| {
        if let Some(cpu) = cfg.emulator_cpu() {
            hygiene.pin_to(cpu);
        }
        hygiene.status()
    };
    let mut warnings = Vec::new();
    let mut reattachments = None;
    let observer = extras.observer.take();
    let mut fsw_failure = None;
    let realtime: RealtimeStatus;
    let (summary, log_path, wait) = match onboard {
        Onboard::InProcess(fsw) => {
            let mut link = if extras.untimed {
                InProcLink::untimed(fsw)
            } else {
                InProcLink::new(fsw)
            }
            .with_frames(&devices.frame_specs());
            let recorder = open_recorder(cfg, run_id, extras.sinks)?;
            realtime = pin_and_tell(&mut hygiene);
            let summary = run_and_close(
                &sched,
                &mut plant,
                &mut devices,
                &mut link,
                clock.as_mut(),
                &mut faults,
                recorder,
                stop,
                observer,
            )?;
            fsw_failure = link.fsw().failure();
            (summary.0, summary.1, None)
        }
        Onboard::Peer(launch) => {
            if let Some(profile) = &cfg.profile {
                // Fail here, before any process or service exists, not in the spawned stub.
                let rules = ProfileRules::rated(cfg.scenario.propulsion.max_thrust_n);
                oils_shared::profile::ThrustProfile::load_with(profile, &rules).map_err(|e| {
                    RunConfigError::File {
                        path: profile.clone(),
                        why: e.to_string(),
                    }
                })?;
            }
            let wait = cfg.wait_strategy();
            let domain = Domain::from_env().map_err(LinkError::from)?;
            warnings.extend(domain.notes().iter().cloned());
            let node = create_node_in("oils-emulator", &domain)?;
            let link =
                EmulatorLink::create_with_frames(&node, run_id, wait, &devices.frame_specs())?;
            let recorder = open_recorder(cfg, run_id, extras.sinks)?;
            let launched = launch(&StubLaunch { run_id, wait })?
                .and_then(|pid| PeerProcess::watch(i32::try_from(pid).ok()?));
            let joined =
                link.wait_for_peer_watching(cfg.startup_timeout_ms, stop, launched.as_ref())?;
            if let Some(tell) = extras.on_peer_joined.take() {
                tell(&joined);
            }
            let mut link = BoundLink::new(link, joined, cfg.allow_reattach);
            realtime = pin_and_tell(&mut hygiene);
            let summary = run_and_close(
                &sched,
                &mut plant,
                &mut devices,
                &mut link,
                clock.as_mut(),
                &mut faults,
                recorder,
                stop,
                observer,
            )?;
            if wait.notifies() && link.link().wake_counts().peer_never_notified() {
                warnings.push(format!(
                    "the flight software never notified oils/{run_id:016x}/command-ready; each step waited for the 1 ms re-poll (docs/protocol.md, wait strategies)"
                ));
            }
            if cfg.allow_reattach {
                let (count, kept) = link.reattachments();
                reattachments = Some(count);
                for r in kept {
                    warnings.push(format!(
                        "flight software re-attached at step {}: {} took over from {} (--allow-reattach)",
                        r.step, r.to, r.from
                    ));
                }
                if count > kept.len() as u64 {
                    warnings.push(format!(
                        "{} more re-attachments not listed",
                        count - kept.len() as u64
                    ));
                }
            }
            (summary.0, summary.1, Some(wait))
        }
    };
    drop(hygiene);
    warnings.extend(realtime.warnings.iter().map(|w| format!("emulator: {w}")));
    let mut report = RunReport::new(cfg, run_id, wait, log_path, summary);
    report.realtime = Some(RealtimeReport {
        emulator: realtime,
        onboard: None,
    });
    report.warnings = warnings;
    report.reattachments = reattachments;
    report.fsw_failure = fsw_failure;
    Ok(report)
}

/// Runs the scheduler and closes the log (on every path: dropping the recorder syncs).
#[allow(clippy::too_many_arguments)]
fn run_and_close<L: Link + ?Sized>(
    sched: &SchedulerConfig,
    plant: &mut Plant,
    devices: &mut Devices,
    link: &mut L,
    clock: &mut dyn StepClock,
    faults: &mut FaultPlan,
    recorder: Option<Recorder>,
    stop: &AtomicBool,
    observer: Option<scheduler::StepObserver<'_>>,
) -> Result<(scheduler::RunSummary, Option<PathBuf>), SessionError> {
    let mut summary = scheduler::run_observed(
        sched,
        plant,
        devices,
        link,
        clock,
        faults,
        recorder.as_ref(),
        stop,
        observer,
    )?;
    let path = recorder.as_ref().map(|r| r.path().to_path_buf());
    if let Some(r) = recorder {
        match r.finish() {
            Ok(n) => summary.log_records = n,
            // The writer failed (a full disk: "No space left on device"), during the run
            // (which then stopped) or while closing: the run is aborted, with the
            // writer's own error, and still reported.
            Err(e) => {
                summary.outcome = scheduler::Outcome::Aborted;
                summary.touchdown = None;
                let why = error_chain(&e);
                summary.error = Some(match (&e, summary.error.take()) {
                    // The writer knows which record failed and how many reached the
                    // file; the loop only saw it later, at `steps`.
                    (RecorderError::Write { step, written, .. }, _) => {
                        summary.log_records = *written;
                        format!(
                            "{why}; the log writer failed at step {step}, the run stopped at step {}",
                            summary.steps
                        )
                    }
                    (_, Some(first)) => format!("{first}: {why}"),
                    (_, None) => why,
                });
            }
        }
    }
    Ok((summary, path))
}

/// An error and its causes on one line (`a: b: c`).
fn error_chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        s.push_str(": ");
        s.push_str(&cause.to_string());
        source = cause.source();
    }
    s
}

/// What a replay found.
#[derive(Debug, Clone)]
pub struct Replay {
    /// The run configuration read from the log's header.
    pub config: RunConfig,
    /// The replayed run (its digest is the recorded run's when the replay holds).
    pub report: RunReport,
    /// Records replayed.
    pub records: usize,
    /// How the recorded run ended early, when it did (a signal, an abort, a log cut
    /// short): the replay stopped there too, and says so.
    pub note: Option<String>,
}

/// Replays a recorded log through the same plant and loop: each recorded command is
/// fed back in, and each telemetry the emulator publishes must equal the recorded one
/// (else the replay stops with the first step that differs). The digest comes out the
/// recorded run's: record == replay. `log` is the file at `log_path`, read by whichever
/// reader its format needs ([`crate::recorder::read_log`] for OILSLOG6).
///
/// The replay ends where the log does: at the step its end record names, as the
/// recorded run ended it (before or after that step's telemetry went out, the end record
/// says which), or, for a log without its end (kill -9, a full disk), after its last
/// record. `stop` interrupts the replay itself.
pub fn replay(log_path: &Path, log: Log, stop: &AtomicBool) -> Result<Replay, SessionError> {
    replay_tapping_frames(log_path, log, stop, None)
}

/// [`replay`], handing every frame rendered again to `tap` (`oils export --frames`): the
/// log keeps the frames' hashes, not their pixels, and a frame is a pure function of the
/// run, so the replay renders each again and checks it against the recorded hash.
pub fn replay_tapping_frames(
    log_path: &Path,
    log: Log,
    stop: &AtomicBool,
    tap: Option<crate::link::FrameTap>,
) -> Result<Replay, SessionError> {
    let bad = |why: String| SessionError::Replay {
        path: log_path.to_path_buf(),
        why,
    };
    if !log.damaged_records.is_empty() {
        return Err(bad(format!(
            "{} damaged records (first at position {})",
            log.damaged_records.len(),
            log.damaged_records[0]
        )));
    }
    let (config, run_id) = read_log_header(&log.header_json).map_err(bad)?;
    config.validate()?;
    let Some(last) = log.records.last().copied() else {
        return Err(bad("the log holds no records".into()));
    };
    let mut plant = build_plant(&config)?;
    let mut devices = build_devices(&config, &plant)?;
    let mut faults = fault_plan(&config, &plant)?;
    let mut sched = scheduler_config(&config, run_id);
    let recorded = log.records.len();
    let last_step = last.telemetry.header.step;
    let ended = last.flags & REC_END_OF_RUN != 0;
    let after_publish = ended && last.flags & REC_ENDED_AFTER_PUBLISH != 0;
    // Where the recorded run's last step was: the replay's duration ends it there (the
    // scheduler's end of a run is the same whatever ended it), unless that step ended
    // after its telemetry went out: then the link ends it the same way.
    let end_t_ns = if ended {
        last.telemetry.header.t_ns
    } else {
        last.telemetry
            .header
            .t_ns
            .saturating_add(i64::try_from(sched.dt_ns).unwrap_or(i64::MAX))
    };
    let configured_end_ns = sched.max_duration_ns;
    if !after_publish {
        sched.max_duration_ns = sched.max_duration_ns.min(end_t_ns);
    }
    let mut link = ReplayLink::new(log)
        .with_frames(&devices.frame_specs())
        .aborting_at(after_publish.then_some(last_step));
    if let Some(tap) = tap {
        link = link.tapping_frames(tap);
    }
    let mut clock = ReplayClock::default();
    let mut summary = scheduler::run(
        &sched,
        &mut plant,
        &mut devices,
        &mut link,
        &mut clock,
        &mut faults,
        None,
        stop,
    )?;
    if stop.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(bad("the replay was interrupted".into()));
    }
    if let Some(step) = link.diverged() {
        return Err(bad(format!(
            "replay diverged at step {step}: the emulator's telemetry differs from the log's"
        )));
    }
    let records = link.replayed();
    if records != recorded {
        return Err(bad(format!(
            "replayed {records} of {recorded} records: the run ended differently"
        )));
    }
    let stopped_early =
        summary.outcome == scheduler::Outcome::Completed && end_t_ns < configured_end_ns;
    let note = if !ended {
        Some(format!(
            "log ends without its end record: run interrupted after {recorded} records; replayed every one"
        ))
    } else if after_publish {
        Some(format!(
            "the recorded run was aborted at step {last_step}, after its telemetry went out; replayed up to there"
        ))
    } else if stopped_early {
        Some(format!(
            "the recorded run was stopped before step {last_step} (a signal); replayed up to there"
        ))
    } else {
        None
    };
    // An abort the replay reproduced by itself (the physics broke down at the same
    // step) holds too: every record was replayed, identical.
    let note = note.or_else(|| {
        summary
            .error
            .as_ref()
            .map(|e| format!("the replayed run aborted where the recorded one did: {e}"))
    });
    if let Some(note) = &note {
        summary.outcome = scheduler::Outcome::Aborted;
        summary.touchdown = None;
        summary.error = Some(note.clone());
    }
    let mut replay_cfg = config.clone();
    replay_cfg.log.enabled = false;
    let report = RunReport::new(&replay_cfg, run_id, None, None, summary);
    Ok(Replay {
        config,
        report,
        records,
        note,
    })
}
