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
//! A cycle is a pipeline of owned stages, each in its own module with one job:
//! * faults fire at the cycle's start and act through each stage's hook;
//! * [`devices`]: the devices turn the truth into Telemetry(k)
//!   ([`crate::devices::Devices`]: sensors, ideal navigation, state-vector uplink), the
//!   telemetry faults on top;
//! * [`exchange`]: the link carries it out and Command(k) back, checked, timed,
//!   digested, through the link faults and the sanitiser;
//! * [`recording`]: the cycle's log record;
//! * [`truth`]: the plant integrates the held command up to the next cycle, the devices
//!   sampling each step.
//!
//! The step path (everything inside the loop) does no heap allocation, locking or
//! logging: the plant and propulsion are built before tick 0, the link's ports exist,
//! the recorder takes a copy through a bounded channel, the histograms are preallocated.

mod devices;
mod exchange;
mod recording;
mod truth;

use crate::clock::StepClock;
use crate::devices::Devices;
use crate::faults::{FaultPlan, FaultReport, FaultyLink};
use crate::link::{ExchangeError, Link};
use crate::plant::{Plant, PlantStatus, TouchdownState};
use crate::recorder::{Recorder, StepTimes, REC_FAULT_CLEARED, REC_FAULT_FIRED};
use crate::timing::TimingThresholds;
use devices::DeviceStage;
use exchange::{ExchangeStage, Stop};
use oils_shared::clock::{monotonic_ns, monotonic_ns_if};
use oils_shared::TLM_FLAG_END_OF_RUN;
use recording::Recording;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use truth::TruthStage;

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
/// the plant and its devices built.
#[allow(clippy::too_many_arguments)]
pub fn run<L: Link + ?Sized, C: StepClock + ?Sized>(
    cfg: &SchedulerConfig,
    plant: &mut Plant,
    devices: &mut Devices,
    link: &mut L,
    clock: &mut C,
    faults: &mut FaultPlan,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
) -> Result<RunSummary, SchedulerError> {
    run_observed(
        cfg, plant, devices, link, clock, faults, recorder, stop, None,
    )
}

/// [`run`], calling `observer` after every integrated step.
///
/// A cycle is the stages in turn: the faults due fire (each acting through its stage's
/// hook), the devices compose Telemetry(k) from the truth, the exchange sends it and
/// turns what comes back into the command the plant holds, the recording logs the
/// cycle, and the truth integrates the held command up to the next cycle. A stage that
/// ends the run says why ([`Abort`]); the next cycle then sends the end of the run.
#[allow(clippy::too_many_arguments)]
pub fn run_observed<L: Link + ?Sized, C: StepClock + ?Sized>(
    cfg: &SchedulerConfig,
    plant: &mut Plant,
    devices: &mut Devices,
    link: &mut L,
    clock: &mut C,
    faults: &mut FaultPlan,
    recorder: Option<&Recorder>,
    stop: &AtomicBool,
    mut observer: Option<StepObserver<'_>>,
) -> Result<RunSummary, SchedulerError> {
    let mut truth = TruthStage::new(cfg.dt_ns, cfg.fsw_period_ns, faults);
    let mut onboard = DeviceStage::new();
    let mut recording = Recording::new(recorder);
    let mut abort: Option<Abort> = None;
    let mut steps = 0u64;
    let mut plant_overruns = 0u64;
    clock.start();
    let mut exchange =
        ExchangeStage::new(link.has_transport(), monotonic_ns_if(cfg.time_exchanges));
    // The link with the run's link faults in front, for the whole run (the faults go
    // back to the plan at the end).
    let mut link = FaultyLink::new(&mut *link, faults.take_link_faults());
    let mut k: u64 = 0;

    loop {
        let mut step_times = StepTimes::default();
        if let Some(late_ns) = clock.wait_for_step(k, stop) {
            exchange.timing.record_wake_error(late_ns);
            step_times.wake_error_ns = Some(late_ns.min(i64::MAX as u64) as i64);
        }
        let t_ns = plant.time_ns();
        if abort.is_none() && stop.load(Ordering::Relaxed) {
            abort = Some(Abort::Interrupted);
        }

        // Faults: those due fire, each through its stage's hook.
        let (fired, cleared) = faults.advance(k, t_ns, plant.altitude_m());
        let mut fault_flags = 0u32;
        if fired | cleared != 0 {
            DeviceStage::apply_faults(faults, devices, fired, cleared);
            truth.apply_faults(plant, fired, cleared);
            if fired != 0 {
                fault_flags |= REC_FAULT_FIRED;
            }
            if cleared != 0 {
                fault_flags |= REC_FAULT_CLEARED;
            }
        }
        let faults_active = faults.active_mask();
        link.set_active(faults_active, fired);
        let telemetry_faults = faults.telemetry_faults();

        // Devices: Telemetry(k) from the truth.
        let resetting = link.resetting();
        let tlm = onboard.compose(
            cfg.run_id,
            k,
            resetting,
            plant,
            devices,
            telemetry_faults,
            fired,
        );

        let finished = abort.is_some() || truth.touched_down() || t_ns >= cfg.max_duration_ns;
        if finished {
            let mut tlm = *tlm;
            tlm.header.flags |= TLM_FLAG_END_OF_RUN;
            exchange.end_of_run(&mut link, &tlm);
            let after_publish = exchange.published == Some(k);
            recording.record_end(
                fault_flags,
                after_publish,
                &tlm,
                plant,
                faults_active,
                step_times,
            );
            break;
        }

        // Exchange: out, back, checked, faulted, sanitised.
        let exchanged = match exchange.exchange(
            cfg,
            k,
            t_ns,
            tlm,
            plant,
            &mut link,
            clock,
            stop,
            &mut step_times,
        ) {
            Ok(x) => x,
            Err(Stop::Abort(a)) => {
                abort = Some(a);
                continue;
            }
            Err(Stop::Failed(e)) => return Err(e),
        };

        // Recording: the cycle's record.
        if let Err(a) = recording.record(
            k,
            fault_flags | exchanged.flags,
            tlm,
            exchanged.received,
            &exchange.applied,
            plant,
            faults_active,
            step_times,
        ) {
            abort = Some(a);
            continue;
        }

        // Truth: Command(k) held over the cycle.
        if let Some(a) = truth.advance(
            k,
            plant,
            devices,
            &mut link,
            &exchange.applied,
            &mut observer,
        ) {
            abort = Some(a);
        }
        if clock.cycle_overran(k) {
            plant_overruns += 1;
        }
        steps += 1;
        k += 1;
    }

    faults.put_back_link_faults(link.into_faults());
    let wall_s = monotonic_ns().saturating_sub(clock.started_ns()) as f64 * 1e-9;
    let sim_time_s = plant.time_ns() as f64 * 1e-9;
    let timing = exchange.timing.summary(wall_s, sim_time_s);
    let (outcome, touchdown) = match (&abort, truth.status) {
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
        digest: exchange.digest.hex(),
        steps,
        plant_steps: truth.plant_steps,
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
        rejected_commands: exchange.rejected_commands,
        rejected_values: exchange.rejected_values,
        threshold_violations: cfg.thresholds.violations(&timing),
        timing,
        log_records: 0,
        faults: faults.report(),
        propulsion_diagnostics: plant.propulsion_diagnostics(),
        sensors_dropped: devices.sensors().map(|s| s.dropped()),
        fsw_report: Some(exchange.fsw_monitor.finish())
            .filter(|r| r.boot_count > 0 || r.navigation_reported),
    })
}
