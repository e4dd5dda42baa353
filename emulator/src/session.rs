//! One bench run from the emulator's side: command-line arguments in, report out.
//! Builds everything before tick 0 (scenario, propulsion, plant, node, link, recorder),
//! waits for the onboard computer, runs the scheduler, and closes the log.

use crate::config::{ConfigError, ScenarioConfig};
use crate::plant::Plant;
use crate::propulsion::{build_for_bench, ModelFiles, PropulsionKind};
use crate::recorder::{Recorder, RecorderError};
use crate::report::RunReport;
use crate::scheduler::{self, MissPolicy, Mode, SchedulerConfig, SchedulerError};
use crate::timing::TimingThresholds;
use oils_shared::link::{create_node, EmulatorLink, LinkError, WaitStrategy};
use oils_shared::PROTOCOL_VERSION;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Pacing mode on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// Wait for every command (deterministic, as fast as possible).
    Lockstep,
    /// Pace against the wall clock times `--speed`.
    Realtime,
}

/// Flight software the spawned stub runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FswArg {
    /// The reference descent GNC.
    Gnc,
    /// Open-loop playback of `--profile`.
    Playback,
}

/// Navigation noise switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OnOff {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// Arguments of a bench run (`oils run`, `oils-emulator`).
#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// lockstep: wait for each command (deterministic); realtime: pace against the clock.
    #[arg(long, value_enum, default_value = "lockstep")]
    pub mode: ModeArg,
    /// Realtime speed factor (2 = twice real time).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Step in milliseconds (1-100).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=100))]
    pub dt_ms: u64,
    /// Longest simulated time, seconds; the run ends `completed` if still flying.
    #[arg(long, default_value_t = 2000.0)]
    pub duration: f64,
    /// Propulsion model: ideal (first-order lag), hifi (physics, the truth model),
    /// surrogate (the learned model) or shadow (hifi drives, the surrogate runs beside
    /// it; their divergence goes in the report).
    #[arg(long, default_value = "ideal")]
    pub propulsion: String,
    /// Hifi parameter TOML for `--propulsion hifi|shadow` (default: emulator/config/hifi.toml's values).
    #[arg(long)]
    pub hifi_params: Option<PathBuf>,
    /// Surrogate model file for `--propulsion surrogate|shadow` (default: the committed model).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Flight software of the spawned stub.
    #[arg(long, value_enum, default_value = "gnc")]
    pub fsw: FswArg,
    /// Thrust-command profile CSV for `--fsw playback`.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Seed of every random stream (navigation noise, ...).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Seeded navigation noise on the telemetry.
    #[arg(long, value_enum, default_value = "on")]
    pub nav_noise: OnOff,
    /// Scenario TOML overriding any default (template: emulator/config/scenario.toml).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Log file (default: oils-out/<run id>.oilslog).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Do not write a log.
    #[arg(long, conflicts_with = "log")]
    pub no_log: bool,
    /// How the emulator waits for commands: busy, event or hybrid (default: busy in
    /// lockstep, hybrid in realtime).
    #[arg(long)]
    pub wait: Option<String>,
    /// Realtime deadline-miss policy: hold, zero or abort:N.
    #[arg(long, default_value = "hold")]
    pub miss_policy: String,
    /// Realtime: a command must arrive within this fraction of a period.
    #[arg(long, default_value_t = 0.5)]
    pub deadline_frac: f64,
    /// Realtime: spin this many microseconds before each step start.
    #[arg(long, default_value_t = 200)]
    pub wake_spin_us: u64,
    /// The stub is declared dead after this long without a command, milliseconds.
    #[arg(long, default_value_t = 2000)]
    pub link_timeout_ms: u64,
    /// How long to wait for the stub to connect, milliseconds.
    #[arg(long, default_value_t = 10000)]
    pub startup_timeout_ms: u64,
    /// Run the emulator (and the stub it spawns) under SCHED_FIFO at this priority (1-99)
    /// with memory locked: the way to a tight realtime wake error on a busy machine.
    /// Needs root or CAP_SYS_NICE.
    #[arg(long, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: Option<i32>,
    /// Run id (hex); default: a fresh one. It names the run's iceoryx2 services.
    #[arg(long)]
    pub run_id: Option<String>,
    /// Fail the run if the p99 wake error exceeds this, microseconds.
    #[arg(long)]
    pub max_wake_p99_us: Option<f64>,
    /// Fail the run if the p99 round trip exceeds this, microseconds.
    #[arg(long)]
    pub max_round_trip_p99_us: Option<f64>,
    /// Fail the run if the p99 transport exceeds this, microseconds.
    #[arg(long)]
    pub max_transport_p99_us: Option<f64>,
    /// Fail the run if there are more deadline misses than this.
    #[arg(long)]
    pub max_deadline_misses: Option<u64>,
}

/// Why a session could not run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// Bad argument.
    #[error("{0}")]
    Argument(String),
    /// Scenario file unreadable or invalid.
    #[error("scenario {path}: {why}")]
    ScenarioFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
    /// Invalid configuration value.
    #[error(transparent)]
    Config(#[from] ConfigError),
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
    #[error("--rt-priority {priority} (needs root or CAP_SYS_NICE)")]
    RealtimePriority {
        /// The priority asked for.
        priority: i32,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Propulsion model could not be built.
    #[error("propulsion")]
    Propulsion(#[from] crate::propulsion::BuildError),
}

/// A fresh run id: process id and monotonic time mixed (naming only; never enters the
/// plant, and the digest ignores it).
pub fn fresh_run_id() -> u64 {
    let mut x = oils_shared::clock::monotonic_ns() ^ ((std::process::id() as u64) << 40);
    // splitmix64 finaliser: spreads the bits so ids look unrelated.
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

impl RunArgs {
    /// The run id asked for, or a fresh one.
    pub fn run_id(&self) -> Result<u64, SessionError> {
        match &self.run_id {
            Some(s) => u64::from_str_radix(s.trim_start_matches("0x"), 16)
                .map_err(|_| SessionError::Argument(format!("--run-id {s}: not a hex number"))),
            None => Ok(fresh_run_id()),
        }
    }

    /// The wait strategy: as asked, else busy-poll in lockstep (fastest; two processes
    /// on two cores, and the recorder thread mostly sleeps) and hybrid in realtime
    /// (spin briefly, then sleep on the event: leaves the core free between steps).
    pub fn wait_strategy(&self) -> Result<WaitStrategy, SessionError> {
        match &self.wait {
            Some(w) => w.parse().map_err(|_| {
                SessionError::Argument(format!("--wait {w}: expected busy, event or hybrid"))
            }),
            None => Ok(match self.mode {
                ModeArg::Lockstep => WaitStrategy::BusyPoll,
                ModeArg::Realtime => WaitStrategy::Hybrid {
                    spin_ns: WaitStrategy::DEFAULT_SPIN_NS,
                },
            }),
        }
    }

    fn miss_policy(&self) -> Result<MissPolicy, SessionError> {
        let bad = || {
            SessionError::Argument(format!(
                "--miss-policy {}: expected hold, zero or abort:N",
                self.miss_policy
            ))
        };
        match self.miss_policy.as_str() {
            "hold" => Ok(MissPolicy::Hold),
            "zero" => Ok(MissPolicy::Zero),
            s => {
                let n = s.strip_prefix("abort:").ok_or_else(bad)?;
                let after: u64 = n.parse().map_err(|_| bad())?;
                if after == 0 {
                    return Err(bad());
                }
                Ok(MissPolicy::Abort { after })
            }
        }
    }

    /// The propulsion model asked for.
    pub fn propulsion_kind(&self) -> Result<PropulsionKind, SessionError> {
        self.propulsion.parse().map_err(SessionError::Argument)
    }

    /// The scenario: defaults, overridden by `--scenario`, then by flags; validated.
    pub fn scenario(&self) -> Result<ScenarioConfig, SessionError> {
        let mut s = match &self.scenario {
            Some(path) => load_scenario(path)?,
            None => ScenarioConfig::default(),
        };
        s.nav_noise.enabled = self.nav_noise == OnOff::On;
        s.validate()?;
        Ok(s)
    }

    /// Scheduler settings.
    pub fn scheduler_config(&self, run_id: u64) -> Result<SchedulerConfig, SessionError> {
        if !(self.duration.is_finite() && self.duration > 0.0 && self.duration <= 1e6) {
            return Err(SessionError::Argument(format!(
                "--duration {}: expected (0, 1e6] seconds",
                self.duration
            )));
        }
        let us = |v: Option<f64>| v.map(|x| (x.max(0.0) * 1000.0) as u64);
        let cfg = SchedulerConfig {
            mode: match self.mode {
                ModeArg::Lockstep => Mode::Lockstep,
                ModeArg::Realtime => Mode::Realtime,
            },
            speed: self.speed,
            dt_ns: self.dt_ms * 1_000_000,
            max_duration_ns: (self.duration * 1e9) as i64,
            run_id,
            deadline_frac: self.deadline_frac,
            miss_policy: self.miss_policy()?,
            link_timeout_ms: self.link_timeout_ms,
            startup_timeout_ms: self.startup_timeout_ms,
            wake_spin_ns: self.wake_spin_us * 1000,
            thresholds: TimingThresholds {
                wake_error_p99_ns: us(self.max_wake_p99_us),
                round_trip_p99_ns: us(self.max_round_trip_p99_us),
                transport_p99_ns: us(self.max_transport_p99_us),
                deadline_misses: self.max_deadline_misses,
            },
        };
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks everything that can be checked before any resource is taken.
    pub fn validate(&self) -> Result<(), SessionError> {
        self.scenario()?;
        self.scheduler_config(0)?;
        self.wait_strategy()?;
        self.propulsion_kind()?;
        if self.fsw == FswArg::Playback && self.profile.is_none() {
            return Err(SessionError::Argument(
                "--fsw playback needs --profile CSV".into(),
            ));
        }
        if let Some(path) = &self.profile {
            // Fail here, before any process or service exists, not in the spawned stub.
            oils_shared::profile::ThrustProfile::load(path)
                .map_err(|e| SessionError::Argument(format!("{}: {e}", path.display())))?;
        }
        Ok(())
    }
}

/// Reads a scenario TOML file.
pub fn load_scenario(path: &Path) -> Result<ScenarioConfig, SessionError> {
    let text = std::fs::read_to_string(path).map_err(|e| SessionError::ScenarioFile {
        path: path.to_path_buf(),
        why: e.to_string(),
    })?;
    toml::from_str(&text).map_err(|e| SessionError::ScenarioFile {
        path: path.to_path_buf(),
        why: e.to_string(),
    })
}

/// Runs one session. `spawn_stub(run_id, wait)` is called once the services exist (the
/// `oils` binary starts the stub process there; `oils-emulator` prints how to start one).
pub fn run_session(
    args: &RunArgs,
    stop: &AtomicBool,
    spawn_stub: &mut dyn FnMut(u64, WaitStrategy) -> Result<(), SessionError>,
) -> Result<RunReport, SessionError> {
    args.validate()?;
    let run_id = args.run_id()?;
    let scenario = args.scenario()?;
    let sched = args.scheduler_config(run_id)?;
    let wait = args.wait_strategy()?;
    let kind = args.propulsion_kind()?;
    let files = ModelFiles {
        surrogate_model: args.model.clone(),
        hifi_params: args.hifi_params.clone(),
    };
    let propulsion = build_for_bench(kind, &scenario.propulsion, &files, sched.dt_ns)?;
    let mut plant = Plant::new(&scenario, propulsion, args.seed)?;

    if let Some(priority) = args.rt_priority {
        oils_shared::clock::set_realtime_priority(priority)
            .map_err(|source| SessionError::RealtimePriority { priority, source })?;
    }
    let node = create_node("oils-emulator")?;
    let link = EmulatorLink::create(&node, run_id, wait)?;
    let log_path = if args.no_log {
        None
    } else {
        Some(
            args.log
                .clone()
                .unwrap_or_else(|| PathBuf::from(format!("oils-out/{run_id:016x}.oilslog"))),
        )
    };
    let recorder = match &log_path {
        Some(p) => {
            if let Some(dir) = p.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|source| RecorderError::Io {
                    path: dir.to_path_buf(),
                    source,
                })?;
            }
            let header = serde_json::json!({
                "protocol_version": PROTOCOL_VERSION,
                "run_id": format!("{run_id:016x}"),
                "mode": format!("{:?}", sched.mode).to_lowercase(),
                "dt_ns": sched.dt_ns,
                "seed": args.seed,
                "propulsion": kind.as_str(),
                "scenario": scenario,
            });
            Some(Recorder::create(p, &header.to_string())?)
        }
        None => None,
    };
    spawn_stub(run_id, wait)?;
    link.wait_for_peer(sched.startup_timeout_ms, stop)?;
    let mut summary = scheduler::run(
        &sched,
        &scenario,
        &mut plant,
        &link,
        recorder.as_ref(),
        stop,
    )?;
    if let Some(r) = recorder {
        summary.log_records = r.finish()?;
    }
    Ok(RunReport {
        run_id: format!("{run_id:016x}"),
        mode: sched.mode,
        speed: sched.speed,
        dt_ms: args.dt_ms as f64,
        seed: args.seed,
        propulsion: kind.as_str().into(),
        fsw: format!("{:?}", args.fsw).to_lowercase(),
        wait: wait.as_str().into(),
        protocol_version: PROTOCOL_VERSION,
        log: log_path.map(|p| p.display().to_string()),
        summary,
    })
}
