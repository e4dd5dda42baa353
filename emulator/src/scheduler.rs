//! The fixed-step scheduler: one loop that publishes Telemetry(k), waits for Command(k),
//! holds it over `[t_k, t_k+1)` while the plant integrates, and repeats.
//!
//! * `lockstep` waits for every command (deterministic, as fast as both processes go);
//!   a stub silent for `link_timeout_ms` ends the run with an error.
//! * `realtime` paces step starts against absolute monotonic deadlines (`t0 + k dt /
//!   speed`); a command not received `deadline_frac` of a period after its step started
//!   is a deadline miss, handled by the [`MissPolicy`].
//!
//! The step path (everything inside the loop) does no heap allocation, locking or
//! logging: the plant and propulsion are built before tick 0, the link's ports exist,
//! the recorder takes a copy through a bounded channel, the histograms are preallocated.

use crate::config::ScenarioConfig;
use crate::digest::RunDigest;
use crate::plant::{ActuatorCommand, Plant, PlantStatus, TouchdownState};
use crate::recorder::{
    Record, Recorder, REC_COMMAND_RECEIVED, REC_DEADLINE_MISS, REC_END_OF_RUN, REC_REJECTED_VALUES,
};
use crate::sanitize::sanitize;
use crate::timing::{TimingMonitor, TimingThresholds};
use oils_shared::clock::{monotonic_ns, sleep_until_ns};
use oils_shared::link::{EmulatorLink, LinkError};
use oils_shared::{Command, PacketHeader, TLM_FLAG_END_OF_RUN};
use serde::Serialize;
use std::sync::atomic::{AtomicBool, Ordering};

/// How steps are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Wait for every command; as fast as possible; deterministic.
    Lockstep,
    /// Pace against the monotonic clock; late commands are deadline misses.
    Realtime,
}

/// What to do when a command misses its deadline (realtime).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum MissPolicy {
    /// Hold the last command applied.
    Hold,
    /// Engines off, zero torque.
    Zero,
    /// Hold the last command, and abort the run at the N-th miss.
    Abort {
        /// Misses tolerated before aborting (the N-th aborts).
        after: u64,
    },
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Outcome {
    /// Touched down within the limits.
    Landed,
    /// Touched down outside the limits.
    Crashed,
    /// Stopped early: signal, silent stub, protocol error or too many misses.
    Aborted,
    /// Reached the duration limit in flight.
    Completed,
}

/// Loop settings (everything but the physics).
#[derive(Debug, Clone, PartialEq)]
pub struct SchedulerConfig {
    /// Pacing mode.
    pub mode: Mode,
    /// Realtime speed factor (2.0 = twice as fast as real time).
    pub speed: f64,
    /// Step, nanoseconds.
    pub dt_ns: u64,
    /// Longest simulated time before the run ends as `completed`, nanoseconds.
    pub max_duration_ns: i64,
    /// Run id stamped on every packet.
    pub run_id: u64,
    /// Realtime: fraction of a period after a step's start by which its command must
    /// have arrived.
    pub deadline_frac: f64,
    /// Realtime: what a miss does.
    pub miss_policy: MissPolicy,
    /// No command for this long means the stub is gone, milliseconds.
    pub link_timeout_ms: u64,
    /// How long to wait for a stub to connect, milliseconds.
    pub startup_timeout_ms: u64,
    /// Realtime: spin this long before each step start instead of sleeping.
    pub wake_spin_ns: u64,
    /// Timing bounds; a broken one fails the run.
    pub thresholds: TimingThresholds,
}

/// What a finished run reports (the report module turns it into JSON and a table).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Digest over every packet, hex.
    pub digest: String,
    /// Steps integrated.
    pub steps: u64,
    /// How it ended.
    pub outcome: Outcome,
    /// Why it was aborted, if it was.
    pub error: Option<String>,
    /// Touchdown state, if it touched down.
    pub touchdown: Option<TouchdownState>,
    /// Simulated time at the end, seconds.
    pub sim_time_s: f64,
    /// Propellant used by the end, kilograms.
    pub propellant_used_kg: f64,
    /// Commands with at least one replaced value.
    pub rejected_commands: u64,
    /// Command values replaced in all.
    pub rejected_values: u64,
    /// Timing.
    pub timing: crate::timing::TimingSummary,
    /// Threshold violations, as sentences.
    pub threshold_violations: Vec<String>,
    /// Records written to the log.
    pub log_records: u64,
    /// What the propulsion model reported at the end (surrogate envelope exits, shadow
    /// divergence); `None` for models with nothing to report.
    pub propulsion_diagnostics: Option<crate::propulsion::PropulsionDiagnostics>,
}

/// Errors that stop a run before it starts.
#[derive(Debug, thiserror::Error)]
pub enum SchedulerError {
    /// The link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The log failed.
    #[error(transparent)]
    Recorder(#[from] crate::recorder::RecorderError),
    /// A loop setting is invalid.
    #[error("invalid run setting: {0}")]
    Config(String),
}

impl SchedulerConfig {
    /// Checks the settings before tick 0.
    pub fn validate(&self) -> Result<(), SchedulerError> {
        let bad = |s: String| Err(SchedulerError::Config(s));
        if !(1_000_000..=100_000_000).contains(&self.dt_ns) {
            return bad(format!("step {} ns is outside 1-100 ms", self.dt_ns));
        }
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 1e6) {
            return bad(format!("speed {} must be in (0, 1e6]", self.speed));
        }
        if !(self.deadline_frac > 0.0 && self.deadline_frac <= 1.0) {
            return bad(format!(
                "deadline fraction {} must be in (0, 1]",
                self.deadline_frac
            ));
        }
        if self.max_duration_ns <= 0 {
            return bad("duration must be positive".into());
        }
        if let MissPolicy::Abort { after: 0 } = self.miss_policy {
            return bad("abort-after must be at least 1".into());
        }
        Ok(())
    }
}

/// Why the loop stopped early.
enum Abort {
    Interrupted,
    StubSilent { step: u64, waited_ms: u64 },
    Protocol(String),
    TooManyMisses(u64),
}

impl Abort {
    fn message(&self) -> String {
        match self {
            Abort::Interrupted => "interrupted by a termination signal".into(),
            Abort::StubSilent { step, waited_ms } => format!(
                "onboard stub silent for {waited_ms} ms at step {step} (did it die?); the log holds every step before it"
            ),
            Abort::Protocol(m) => m.clone(),
            Abort::TooManyMisses(n) => format!("aborted after {n} deadline misses (miss policy)"),
        }
    }
}

/// Called after each integrated step with the step index; a seam for tests and tools
/// (the allocation proof samples its counter here). Must not allocate or block.
pub type StepObserver<'a> = &'a mut dyn FnMut(u64);

/// Runs one bench run over an established link. The plant is built, the stub connected.
pub fn run(
    cfg: &SchedulerConfig,
    scenario: &ScenarioConfig,
    plant: &mut Plant,
    link: &EmulatorLink,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
) -> Result<RunSummary, SchedulerError> {
    run_observed(cfg, scenario, plant, link, recorder, stop, None)
}

/// [`run`], calling `observer` after every integrated step.
pub fn run_observed(
    cfg: &SchedulerConfig,
    scenario: &ScenarioConfig,
    plant: &mut Plant,
    link: &EmulatorLink,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
    mut observer: Option<StepObserver<'_>>,
) -> Result<RunSummary, SchedulerError> {
    cfg.validate()?;
    let max_thrust_n = scenario.propulsion.max_thrust_n;
    let mut timing = TimingMonitor::new();
    let mut digest = RunDigest::new();
    let period_ns = ((cfg.dt_ns as f64) / cfg.speed).round().max(1.0) as u64;
    let realtime = cfg.mode == Mode::Realtime;
    let mut applied = ActuatorCommand::default();
    let mut status = PlantStatus::Flying;
    let mut rejected_commands = 0u64;
    let mut rejected_values = 0u64;
    let mut abort: Option<Abort> = None;
    let mut steps = 0u64;
    let mut last_command_ns = monotonic_ns();
    let t0 = monotonic_ns() + if realtime { period_ns } else { 0 };
    let mut k: u64 = 0;

    loop {
        let scheduled_ns = t0 + k * period_ns;
        if realtime {
            sleep_until_ns(scheduled_ns, cfg.wake_spin_ns);
            timing.record_wake_error(monotonic_ns().saturating_sub(scheduled_ns));
        }
        let t_ns = plant.time_ns();
        if abort.is_none() && stop.load(Ordering::Relaxed) {
            abort = Some(Abort::Interrupted);
        }
        let mut tlm = plant.telemetry(PacketHeader::new(cfg.run_id, k, t_ns));
        let finished = abort.is_some()
            || matches!(status, PlantStatus::Touchdown(_))
            || t_ns >= cfg.max_duration_ns;
        if finished {
            tlm.header.flags |= TLM_FLAG_END_OF_RUN;
            // Best effort: the stub may be gone already.
            let _ = link.publish(&tlm);
            digest.add_telemetry(&tlm);
            if let Some(r) = recorder {
                r.record(&Record {
                    flags: REC_END_OF_RUN,
                    telemetry: tlm,
                    command: Command::default(),
                })?;
            }
            break;
        }

        let published_ns = monotonic_ns();
        link.publish(&tlm)?;
        digest.add_telemetry(&tlm);

        let deadline_ns = if realtime {
            scheduled_ns + (cfg.deadline_frac * period_ns as f64) as u64
        } else {
            published_ns + cfg.link_timeout_ms * 1_000_000
        };
        let received = loop {
            match link.receive_until(deadline_ns, stop) {
                Ok(Some(c)) if c.header.step < k => timing.record_late_command(),
                Ok(other) => break other,
                Err(LinkError::Interrupted) => {
                    abort = Some(Abort::Interrupted);
                    break None;
                }
                Err(e) => return Err(e.into()),
            }
        };
        let received_ns = monotonic_ns();
        if abort.is_some() {
            continue;
        }

        let mut flags = 0u32;
        let mut logged_cmd = Command::default();
        match received {
            Some(cmd) => {
                if let Err(m) = cmd.header.check_peer() {
                    abort = Some(Abort::Protocol(m.to_string()));
                    continue;
                }
                if cmd.header.step != k || cmd.header.run_id != cfg.run_id {
                    abort = Some(Abort::Protocol(format!(
                        "command for run {:016x} step {} arrived while run {:016x} was at step {k}",
                        cmd.header.run_id, cmd.header.step, cfg.run_id
                    )));
                    continue;
                }
                last_command_ns = received_ns;
                timing.record_exchange(received_ns - published_ns, cmd.stub_compute_ns);
                digest.add_command(&cmd);
                let (safe, rejected) = sanitize(&cmd, max_thrust_n);
                if rejected > 0 {
                    rejected_commands += 1;
                    rejected_values += rejected as u64;
                    flags |= REC_REJECTED_VALUES;
                }
                applied = safe;
                flags |= REC_COMMAND_RECEIVED;
                logged_cmd = cmd;
            }
            None if !realtime => {
                abort = Some(Abort::StubSilent {
                    step: k,
                    waited_ms: (received_ns - published_ns) / 1_000_000,
                });
                continue;
            }
            None => {
                timing.record_deadline_miss();
                flags |= REC_DEADLINE_MISS;
                let silent_ms = (received_ns - last_command_ns) / 1_000_000;
                if silent_ms >= cfg.link_timeout_ms {
                    abort = Some(Abort::StubSilent {
                        step: k,
                        waited_ms: silent_ms,
                    });
                    continue;
                }
                match cfg.miss_policy {
                    MissPolicy::Hold => {}
                    MissPolicy::Zero => applied = ActuatorCommand::default(),
                    MissPolicy::Abort { after } => {
                        if timing.deadline_misses() >= after {
                            abort = Some(Abort::TooManyMisses(timing.deadline_misses()));
                            continue;
                        }
                    }
                }
            }
        }
        if let Some(r) = recorder {
            r.record(&Record {
                flags,
                telemetry: tlm,
                command: logged_cmd,
            })?;
        }
        status = plant.step(&applied, cfg.dt_ns);
        if let Some(observe) = observer.as_mut() {
            observe(k);
        }
        steps += 1;
        k += 1;
    }

    let wall_s = (monotonic_ns().saturating_sub(t0.min(monotonic_ns()))) as f64 * 1e-9;
    let sim_time_s = plant.time_ns() as f64 * 1e-9;
    let timing = timing.summary(wall_s, sim_time_s);
    let (outcome, touchdown) = match (&abort, status) {
        (Some(_), _) => (Outcome::Aborted, None),
        (None, PlantStatus::Touchdown(td)) => (
            if td.landed {
                Outcome::Landed
            } else {
                Outcome::Crashed
            },
            Some(td),
        ),
        (None, PlantStatus::Flying) => (Outcome::Completed, None),
    };
    Ok(RunSummary {
        digest: digest.hex(),
        steps,
        outcome,
        error: abort.as_ref().map(Abort::message),
        touchdown,
        sim_time_s,
        propellant_used_kg: plant.propellant_used_kg(),
        rejected_commands,
        rejected_values,
        threshold_violations: cfg.thresholds.violations(&timing),
        timing,
        log_records: 0,
        propulsion_diagnostics: plant.propulsion_diagnostics(),
    })
}
