//! The fixed-step scheduler: one loop that publishes Telemetry(k), waits for Command(k),
//! holds it over `[t_k, t_k+1)` while the plant integrates, and repeats.
//!
//! The loop is generic over the [`Link`] (iceoryx2 across processes, in-process, replay)
//! and the [`StepClock`] (lockstep, realtime, replay), so every way of running a run is
//! this one loop:
//! * lockstep waits for every command; a flight software silent for the link timeout
//!   ends the run with an error;
//! * realtime paces step starts against absolute monotonic deadlines; a command not in
//!   by its deadline is a deadline miss, handled by the [`MissPolicy`].
//!
//! The step path (everything inside the loop) does no heap allocation, locking or
//! logging: the plant and propulsion are built before tick 0, the link's ports exist,
//! the recorder takes a copy through a bounded channel, the histograms are preallocated.

use crate::clock::StepClock;
use crate::digest::RunDigest;
use crate::faults::{FaultPlan, FaultReport, FaultyLink};
use crate::fsw_monitor::FswMonitor;
use crate::link::{ExchangeError, Link};
use crate::plant::{ActuatorCommand, Plant, PlantStatus, TouchdownState};
use crate::recorder::{
    Record, Recorder, StepTimes, REC_COMMAND_RECEIVED, REC_DEADLINE_MISS, REC_ENDED_AFTER_PUBLISH,
    REC_END_OF_RUN, REC_FAULT_CLEARED, REC_FAULT_FIRED, REC_REJECTED_VALUES,
};
use crate::sanitize::sanitize;
use crate::timing::{TimingMonitor, TimingThresholds};
use oils_shared::clock::{monotonic_ns, monotonic_ns_if};
use oils_shared::link::LinkError;
use oils_shared::{Command, PacketHeader, Telemetry, TLM_FLAG_COMPUTER_RESET, TLM_FLAG_END_OF_RUN};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};

/// How steps are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Wait for every command; as fast as possible; deterministic.
    Lockstep,
    /// Pace against the monotonic clock; late commands are deadline misses.
    Realtime,
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "lockstep" => Ok(Mode::Lockstep),
            "realtime" => Ok(Mode::Realtime),
            other => Err(format!(
                "unknown mode `{other}` (expected lockstep or realtime)"
            )),
        }
    }
}

/// What to do when a command misses its deadline (realtime). Written `hold`, `zero` or
/// `abort:N` on the command line and in configuration files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
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

impl std::str::FromStr for MissPolicy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("miss policy `{s}`: expected hold, zero or abort:N with N >= 1");
        match s {
            "hold" => Ok(MissPolicy::Hold),
            "zero" => Ok(MissPolicy::Zero),
            _ => {
                let after: u64 = s
                    .strip_prefix("abort:")
                    .and_then(|n| n.parse().ok())
                    .ok_or_else(bad)?;
                if after == 0 {
                    return Err(bad());
                }
                Ok(MissPolicy::Abort { after })
            }
        }
    }
}

impl TryFrom<String> for MissPolicy {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<MissPolicy> for String {
    fn from(p: MissPolicy) -> String {
        match p {
            MissPolicy::Hold => "hold".into(),
            MissPolicy::Zero => "zero".into(),
            MissPolicy::Abort { after } => format!("abort:{after}"),
        }
    }
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

/// Loop settings (everything but the physics and the pacing, which is the clock's).
#[derive(Debug, Clone, PartialEq)]
pub struct SchedulerConfig {
    /// Plant integration period (the base tick), nanoseconds.
    pub dt_ns: u64,
    /// Flight-software cycle, nanoseconds: one exchange per cycle, a whole multiple of
    /// `dt_ns` (checked before tick 0 by the run configuration's schedule).
    pub fsw_period_ns: u64,
    /// Longest simulated time before the run ends as `completed`, nanoseconds.
    pub max_duration_ns: i64,
    /// Run id stamped on every packet.
    pub run_id: u64,
    /// Realtime: what a miss does.
    pub miss_policy: MissPolicy,
    /// Realtime: no command for this long means the flight software is gone, ms.
    pub link_timeout_ms: u64,
    /// Rated thrust of one engine, newtons: the sanitiser's clamp.
    pub max_thrust_n: f64,
    /// Timing bounds; a broken one fails the run.
    pub thresholds: TimingThresholds,
    /// Whether each exchange is timed on the wall clock (its round trip; the report's
    /// `timing`). Off only for a lockstep run in process whose timing nobody reads (a
    /// campaign case, [`crate::session::Extras::untimed`]): the two clock reads a step
    /// are then not made, and the round trip is not recorded. Nothing simulated and
    /// nothing in the digest depends on it.
    pub time_exchanges: bool,
}

/// What a finished run reports (the report module turns it into JSON and a table).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunSummary {
    /// Digest over every packet, hex.
    pub digest: String,
    /// Flight-software cycles run (one telemetry/command exchange each; with the default
    /// periods one plant step each).
    pub steps: u64,
    /// Plant steps integrated (`steps` times the plant steps per cycle, but for a cycle
    /// cut short by touchdown or an abort).
    pub plant_steps: u64,
    /// Per rate group, in realtime, the cycles that overran: `fsw`, a command that
    /// missed its deadline; `plant`, a cycle whose integration ended after the next
    /// cycle's start. Zero in lockstep.
    pub overruns: Vec<RateGroupOverruns>,
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
    /// Every fault that fired: kind, target, when, and when it cleared.
    pub faults: Vec<FaultReport>,
    /// What the propulsion model reported at the end (surrogate envelope exits, shadow
    /// divergence); `None` for models with nothing to report.
    pub propulsion_diagnostics: Option<crate::propulsion::PropulsionDiagnostics>,
    /// With the devices on: samples per device that were lost (a full frame or queue);
    /// zero when every sample reached the flight software.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sensors_dropped: Option<crate::sensors::DroppedSamples>,
    /// What the flight software said of itself (protocol v3's `FswReport`), checked
    /// against the truth: navigation error at the end and consistency, boots, rate
    /// groups; `None` when it said nothing.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fsw_report: Option<crate::fsw_monitor::FswSelfReport>,
}

/// Overruns of one rate group.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RateGroupOverruns {
    /// The group.
    pub group: &'static str,
    /// Its period, nanoseconds.
    pub period_ns: u64,
    /// Periods that overran.
    pub count: u64,
}

/// Errors that stop a run before it starts.
#[derive(Debug, thiserror::Error)]
pub enum SchedulerError {
    /// The link failed.
    #[error(transparent)]
    Link(#[from] ExchangeError),
    /// The log failed.
    #[error(transparent)]
    Recorder(#[from] crate::recorder::RecorderError),
}

/// Why the loop stopped early.
enum Abort {
    Interrupted,
    StubSilent { step: u64, waited_ms: u64 },
    Protocol(String),
    TooManyMisses(u64),
    NotFinite { step: u64, what: &'static str },
    PropulsionFailed { step: u64, why: &'static str },
    LogFailed { step: u64 },
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
            Abort::NotFinite { step, what } => format!(
                "the plant's {what} is not finite after step {step}; the physics broke down (check the scenario and model parameters)"
            ),
            Abort::PropulsionFailed { step, why } => {
                format!("the propulsion model failed at step {step}: {why}")
            }
            Abort::LogFailed { step } => format!(
                "the log writer failed at step {step}; the run was stopped there"
            ),
        }
    }
}

/// Called after each integrated step with the step index and the plant; a seam for
/// tests and tools (the allocation proof samples its counter here, a campaign case
/// samples its trajectory). Must not allocate or block in the steps it is measured on.
pub type StepObserver<'a> = &'a mut dyn FnMut(u64, &Plant);

/// Runs one bench run over an established link with the flight software connected,
/// the plant built.
pub fn run<L: Link + ?Sized, C: StepClock + ?Sized>(
    cfg: &SchedulerConfig,
    plant: &mut Plant,
    link: &mut L,
    clock: &mut C,
    faults: &mut FaultPlan,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
) -> Result<RunSummary, SchedulerError> {
    run_observed(cfg, plant, link, clock, faults, recorder, stop, None)
}

/// [`run`], calling `observer` after every integrated step.
#[allow(clippy::too_many_arguments)]
pub fn run_observed<L: Link + ?Sized, C: StepClock + ?Sized>(
    cfg: &SchedulerConfig,
    plant: &mut Plant,
    link: &mut L,
    clock: &mut C,
    faults: &mut FaultPlan,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
    mut observer: Option<StepObserver<'_>>,
) -> Result<RunSummary, SchedulerError> {
    let mut timing = TimingMonitor::new();
    let mut digest = RunDigest::new();
    let with_transport = link.has_transport();
    let mut plant_faults = [None; crate::faults::MAX_FAULTS];
    for (i, slot) in plant_faults.iter_mut().enumerate().take(faults.len()) {
        *slot = faults.plant_fault(i);
    }
    let mut applied = ActuatorCommand::default();
    let mut status = PlantStatus::Flying;
    let mut rejected_commands = 0u64;
    let mut rejected_values = 0u64;
    let mut abort: Option<Abort> = None;
    let mut steps = 0u64;
    let mut plant_steps = 0u64;
    let mut plant_overruns = 0u64;
    let plant_steps_per_cycle = (cfg.fsw_period_ns / cfg.dt_ns.max(1)).max(1);
    // A failed log (a full disk, ...) ends the run like any abort: the flight software
    // is told, the summary is made, and the session names the writer's error.
    let mut recorder = recorder;
    clock.start();
    // Untimed (`time_exchanges` off), every exchange's clock reading is 0, this too.
    let now_ns = || monotonic_ns_if(cfg.time_exchanges);
    let mut last_command_ns = now_ns();
    let mut k: u64 = 0;
    // The last step whose telemetry went out mid-step (a replay must know whether the
    // end came before or after it: the end record says).
    let mut published: Option<u64> = None;
    // A computer reset was under way at the last step.
    let mut was_resetting = false;
    let mut fsw_monitor = FswMonitor::new();
    // Telemetry(k), filled in place each step (`Plant::telemetry_into`).
    let mut tlm = Telemetry::default();

    loop {
        let mut step_times = StepTimes::default();
        if let Some(late_ns) = clock.wait_for_step(k, stop) {
            timing.record_wake_error(late_ns);
            step_times.wake_error_ns = Some(late_ns.min(i64::MAX as u64) as i64);
        }
        let t_ns = plant.time_ns();
        if abort.is_none() && stop.load(Ordering::Relaxed) {
            abort = Some(Abort::Interrupted);
        }
        let (fired, cleared) = faults.advance(k, t_ns, plant.altitude_m());
        let mut fault_flags = 0u32;
        if fired | cleared != 0 {
            if let Some(sensors) = plant.sensors_mut() {
                faults.apply_device_faults(fired, cleared, sensors);
            }
            for (i, f) in plant_faults.iter().enumerate().take(faults.len()) {
                let bit = 1u64 << i;
                if let (true, Some(f)) = ((fired | cleared) & bit != 0, f) {
                    plant.set_fault(f, fired & bit != 0);
                }
            }
            if fired != 0 {
                fault_flags |= REC_FAULT_FIRED;
            }
            if cleared != 0 {
                fault_flags |= REC_FAULT_CLEARED;
            }
        }
        let faults_active = faults.active_mask();
        let (sensor_faults, link_faults) = faults.stages();
        let mut link = FaultyLink::new(&mut *link, link_faults);
        let resetting = link.resetting();
        let mut header = PacketHeader::new(cfg.run_id, k, t_ns);
        if resetting {
            header.flags |= TLM_FLAG_COMPUTER_RESET;
        } else if was_resetting {
            // The computer is back: the ground uplinks a fresh state vector.
            plant.uplink_state_vector();
        }
        was_resetting = resetting;
        plant.telemetry_into(header, &mut tlm);
        sensor_faults.apply(&mut tlm, fired);
        let finished = abort.is_some()
            || matches!(status, PlantStatus::Touchdown(_))
            || t_ns >= cfg.max_duration_ns;
        if finished {
            tlm.header.flags |= TLM_FLAG_END_OF_RUN;
            // Best effort: the flight software may be gone already.
            let _ = link.publish_end_of_run(&tlm);
            digest.add_telemetry(&tlm);
            if let Some(r) = recorder {
                // Best effort too: a failed writer already ended the run.
                let after_publish = if published == Some(k) {
                    REC_ENDED_AFTER_PUBLISH
                } else {
                    0
                };
                let _ = r.record(&Record {
                    flags: REC_END_OF_RUN | after_publish | fault_flags,
                    telemetry: tlm,
                    command: Command::default(),
                    applied: ActuatorCommand::default(),
                    truth: plant.truth(),
                    faults_active,
                    timing: step_times,
                });
            }
            break;
        }

        // A link fault may keep Telemetry(k) from the flight software: then nothing is
        // published, nothing can answer, and the step is a miss.
        let withheld = link.withheld();
        let published_ns = now_ns();
        if link.publish(&tlm)? {
            digest.add_telemetry(&tlm);
            published = Some(k);
        } else {
            // The flight software is excused while it sees nothing: its silence is
            // counted from the first telemetry it could have answered again.
            last_command_ns = published_ns;
        }

        let deadline_ns = clock.command_deadline_ns(k, published_ns);
        let received = loop {
            if withheld {
                break None;
            }
            match link.receive_until(deadline_ns, stop) {
                Ok(Some(c)) if c.header.step < k => timing.record_late_command(),
                Ok(other) => break other,
                Err(ExchangeError::Link(LinkError::Interrupted)) => {
                    abort = Some(Abort::Interrupted);
                    break None;
                }
                // Once, at the end of the run: the message may allocate. The flight
                // software failed, died or changed: the run ends, and is reported.
                Err(
                    e @ (ExchangeError::ForeignFlightSoftware { .. }
                    | ExchangeError::FlightSoftware(_)
                    | ExchangeError::FlightSoftwareGone { .. }),
                ) => {
                    abort = Some(Abort::Protocol(e.to_string()));
                    break None;
                }
                Err(e) => return Err(e.into()),
            }
        };
        let received_ns = now_ns();
        if abort.is_some() {
            continue;
        }
        // A duplicated command from the previous step arrives stale, and is discarded.
        if link.take_stale_duplicate() {
            timing.record_late_command();
        }

        let mut flags = fault_flags;
        // What came off the wire; the link faults then make it what is delivered.
        let mut wire_cmd = received;
        match &wire_cmd {
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
                // Untimed (`time_exchanges` off), nothing was measured: nothing recorded.
                if cfg.time_exchanges {
                    let round_trip_ns = received_ns - published_ns;
                    step_times.round_trip_ns = Some(round_trip_ns);
                    if with_transport {
                        timing.record_exchange(round_trip_ns, cmd.stub_compute_ns);
                        step_times.transport_ns =
                            Some(round_trip_ns.saturating_sub(cmd.stub_compute_ns));
                    } else {
                        timing.record_in_process(round_trip_ns, cmd.stub_compute_ns);
                    }
                }
                digest.add_command(cmd);
                fsw_monitor.record(cmd, &plant.truth(), t_ns);
                flags |= REC_COMMAND_RECEIVED;
            }
            None if !withheld && !clock.misses_allowed() => {
                abort = Some(Abort::StubSilent {
                    step: k,
                    waited_ms: (received_ns - published_ns) / 1_000_000,
                });
                continue;
            }
            None => {}
        }
        // The command as received, for the log (copied only when there is one).
        let logged_cmd = recorder.map(|_| wire_cmd.unwrap_or_default());
        // Link faults act between the wire and the sanitiser. While the computer
        // resets, what comes back is ignored: the main engines hold their command, the
        // attitude torque stops (held thruster pulses never fire twice).
        if resetting {
            link.deliver(&mut None);
            applied.torque_cmd_body_nm = [0.0; 3];
        } else {
            link.deliver(&mut wire_cmd);
            match &wire_cmd {
                Some(cmd) => {
                    let (safe, rejected) = sanitize(cmd, cfg.max_thrust_n, t_ns, cfg.fsw_period_ns);
                    if rejected > 0 {
                        rejected_commands += 1;
                        rejected_values += rejected as u64;
                        flags |= REC_REJECTED_VALUES;
                    }
                    applied = safe;
                }
                None => {
                    timing.record_deadline_miss();
                    flags |= REC_DEADLINE_MISS;
                    // Only a realtime run can miss a deadline on a live link: in lockstep
                    // a miss comes from a fault alone (simulated), and a dead peer is
                    // what `receive_until` waiting out the link timeout finds.
                    let silent_ms = received_ns.saturating_sub(last_command_ns) / 1_000_000;
                    if clock.misses_allowed() && silent_ms >= cfg.link_timeout_ms {
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
        }
        if let Some(r) = recorder {
            let logged = r.record(&Record {
                flags,
                telemetry: tlm,
                command: logged_cmd.unwrap_or_default(),
                applied,
                truth: plant.truth(),
                faults_active,
                timing: step_times,
            });
            if logged.is_err() {
                recorder = None;
                abort = Some(Abort::LogFailed { step: k });
                continue;
            }
        }
        // Command(k) is held over the flight-software cycle: the plant steps on the
        // base tick until the next exchange (once, with the default periods).
        for _ in 0..plant_steps_per_cycle {
            status = plant.step(&applied, cfg.dt_ns);
            if let Some(what) = plant.first_non_finite() {
                abort = Some(Abort::NotFinite { step: k, what });
            } else if let Some(why) = plant.propulsion_failure() {
                abort = Some(Abort::PropulsionFailed { step: k, why });
            }
            if let Some(observe) = observer.as_mut() {
                observe(plant_steps, plant);
            }
            plant_steps += 1;
            if abort.is_some() || matches!(status, PlantStatus::Touchdown(_)) {
                break;
            }
        }
        if clock.cycle_overran(k) {
            plant_overruns += 1;
        }
        steps += 1;
        k += 1;
    }

    let wall_s = monotonic_ns().saturating_sub(clock.started_ns()) as f64 * 1e-9;
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
        plant_steps,
        overruns: vec![
            RateGroupOverruns {
                group: "plant",
                period_ns: cfg.dt_ns,
                count: plant_overruns,
            },
            RateGroupOverruns {
                group: "fsw",
                period_ns: cfg.fsw_period_ns,
                count: if clock.misses_allowed() && !clock.is_replay() {
                    timing.deadline_misses
                } else {
                    0
                },
            },
        ],
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
        faults: faults.report(),
        propulsion_diagnostics: plant.propulsion_diagnostics(),
        sensors_dropped: plant.sensors().map(|s| s.dropped()),
        fsw_report: Some(fsw_monitor.finish())
            .filter(|r| r.boot_count > 0 || r.navigation_reported),
    })
}
