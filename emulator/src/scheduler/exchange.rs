//! The exchange stage: Telemetry(k) out over the link, Command(k) back by its deadline,
//! checked, timed, digested, passed through the link's faults and the sanitiser into
//! the command the plant holds. A missing command is a deadline miss, handled by the
//! [`MissPolicy`].

use super::{Abort, MissPolicy, SchedulerConfig, SchedulerError};
use crate::clock::StepClock;
use crate::digest::RunDigest;
use crate::faults::FaultyLink;
use crate::fsw_monitor::FswMonitor;
use crate::link::{ExchangeError, Link};
use crate::plant::{ActuatorCommand, Plant};
use crate::recorder::{StepTimes, REC_COMMAND_RECEIVED, REC_DEADLINE_MISS, REC_REJECTED_VALUES};
use crate::sanitize::sanitize;
use crate::timing::TimingMonitor;
use oils_shared::clock::monotonic_ns_if;
use oils_shared::link::LinkError;
use oils_shared::{Command, Telemetry};
use std::sync::atomic::AtomicBool;

/// Why an exchange ended the cycle early.
pub(super) enum Stop {
    /// The run ends (its end-of-run telemetry still goes out).
    Abort(Abort),
    /// The link broke: the run cannot go on.
    Failed(SchedulerError),
}

impl From<Abort> for Stop {
    fn from(a: Abort) -> Self {
        Stop::Abort(a)
    }
}

/// What an exchange leaves for the recording.
pub(super) struct Exchanged {
    /// `REC_*` flags of the exchange (command received, deadline miss, rejected values).
    pub(super) flags: u32,
    /// The command as it came off the wire (before link faults), when one did.
    pub(super) received: Option<Command>,
}

/// The exchange's state across cycles: its timing, the digest, the flight software's
/// silence and self-report, and the command the plant holds.
pub(super) struct ExchangeStage {
    pub(super) timing: TimingMonitor,
    pub(super) digest: RunDigest,
    /// The fsw monitor: the flight software's self-report checked against the truth.
    pub(super) fsw_monitor: FswMonitor,
    /// The command the plant holds (the last one applied).
    pub(super) applied: ActuatorCommand,
    /// Commands with at least one replaced value, and the values replaced.
    pub(super) rejected_commands: u64,
    pub(super) rejected_values: u64,
    /// The last step whose telemetry went out mid-step (a replay must know whether the
    /// end came before or after it: the end record says).
    pub(super) published: Option<u64>,
    with_transport: bool,
    /// Wall-clock time of the last command (or of the first telemetry the flight
    /// software could answer after a silence it was excused), ns.
    last_command_ns: u64,
}

impl ExchangeStage {
    pub(super) fn new(with_transport: bool, now_ns: u64) -> Self {
        Self {
            timing: TimingMonitor::new(),
            digest: RunDigest::new(),
            fsw_monitor: FswMonitor::new(),
            applied: ActuatorCommand::default(),
            rejected_commands: 0,
            rejected_values: 0,
            published: None,
            with_transport,
            last_command_ns: now_ns,
        }
    }

    /// The last telemetry, [`oils_shared::TLM_FLAG_END_OF_RUN`] set, to a flight
    /// software that may be gone already (best effort).
    pub(super) fn end_of_run<L: Link + ?Sized>(
        &mut self,
        link: &mut FaultyLink<'_, L>,
        tlm: &Telemetry,
    ) {
        let _ = link.publish_end_of_run(tlm);
        self.digest.add_telemetry(tlm);
    }

    /// One exchange: publishes `tlm` (unless a link fault withholds it), waits for the
    /// command by the clock's deadline, and turns what arrives into
    /// [`ExchangeStage::applied`].
    #[allow(clippy::too_many_arguments)]
    pub(super) fn exchange<L: Link + ?Sized, C: StepClock + ?Sized>(
        &mut self,
        cfg: &SchedulerConfig,
        k: u64,
        t_ns: i64,
        tlm: &Telemetry,
        plant: &Plant,
        link: &mut FaultyLink<'_, L>,
        clock: &mut C,
        stop: &AtomicBool,
        step_times: &mut StepTimes,
    ) -> Result<Exchanged, Stop> {
        // Untimed (`time_exchanges` off), every exchange's clock reading is 0.
        let now_ns = || monotonic_ns_if(cfg.time_exchanges);
        let resetting = link.resetting();
        // A link fault may keep Telemetry(k) from the flight software: then nothing is
        // published, nothing can answer, and the step is a miss.
        let withheld = link.withheld();
        let published_ns = now_ns();
        link.publish(tlm).map_err(|e| Stop::Failed(e.into()))?;
        if !withheld {
            self.digest.add_telemetry(tlm);
            self.published = Some(k);
        } else {
            // The flight software is excused while it sees nothing: its silence is
            // counted from the first telemetry it could have answered again.
            self.last_command_ns = published_ns;
        }

        let deadline_ns = clock.command_deadline_ns(k, published_ns);
        let mut received = None;
        if !withheld {
            loop {
                match link.receive_until(deadline_ns, stop) {
                    Ok(Some(c)) if c.header.step < k => self.timing.record_late_command(),
                    Ok(other) => {
                        received = other;
                        break;
                    }
                    Err(ExchangeError::Link(LinkError::Interrupted)) => {
                        return Err(Abort::Interrupted.into())
                    }
                    // Once, at the end of the run: the message may allocate. The flight
                    // software failed, died or changed: the run ends, and is reported.
                    Err(
                        e @ (ExchangeError::ForeignFlightSoftware { .. }
                        | ExchangeError::FlightSoftware(_)
                        | ExchangeError::FlightSoftwareGone { .. }),
                    ) => return Err(Abort::Protocol(e.to_string()).into()),
                    Err(e) => return Err(Stop::Failed(e.into())),
                }
            }
        }
        let received_ns = now_ns();
        // A duplicated command from the previous step arrives stale, and is discarded.
        if link.take_stale_duplicate() {
            self.timing.record_late_command();
        }

        let mut flags = 0u32;
        match &received {
            Some(cmd) => {
                self.accept(
                    cfg,
                    k,
                    cmd,
                    plant,
                    t_ns,
                    published_ns,
                    received_ns,
                    step_times,
                )?;
                flags |= REC_COMMAND_RECEIVED;
            }
            None if !withheld && !clock.misses_allowed() => {
                return Err(Abort::StubSilent {
                    step: k,
                    waited_ms: (received_ns - published_ns) / 1_000_000,
                }
                .into());
            }
            None => {}
        }
        // Link faults act between the wire and the sanitiser. While the computer
        // resets, what comes back is ignored: the main engines hold their command, the
        // attitude torque stops (held thruster pulses never fire twice).
        let mut delivered = received;
        if resetting {
            link.deliver(&mut None);
            self.applied.torque_cmd_body_nm = [0.0; 3];
        } else {
            link.deliver(&mut delivered);
            match &delivered {
                Some(cmd) => {
                    let (safe, rejected) = sanitize(cmd, cfg.max_thrust_n, t_ns, cfg.fsw_period_ns);
                    if rejected > 0 {
                        self.rejected_commands += 1;
                        self.rejected_values += rejected as u64;
                        flags |= REC_REJECTED_VALUES;
                    }
                    self.applied = safe;
                }
                None => {
                    flags |= REC_DEADLINE_MISS;
                    self.missed(cfg, k, clock, received_ns)?;
                }
            }
        }
        Ok(Exchanged { flags, received })
    }

    /// A command arrived: checks whom it answers, times the round trip, digests it and
    /// hands the flight software's self-report to the monitor.
    #[allow(clippy::too_many_arguments)]
    fn accept(
        &mut self,
        cfg: &SchedulerConfig,
        k: u64,
        cmd: &Command,
        plant: &Plant,
        t_ns: i64,
        published_ns: u64,
        received_ns: u64,
        step_times: &mut StepTimes,
    ) -> Result<(), Abort> {
        if let Err(m) = cmd.header.check_peer() {
            return Err(Abort::Protocol(m.to_string()));
        }
        if cmd.header.step != k || cmd.header.run_id != cfg.run_id {
            return Err(Abort::Protocol(format!(
                "command for run {:016x} step {} arrived while run {:016x} was at step {k}",
                cmd.header.run_id, cmd.header.step, cfg.run_id
            )));
        }
        self.last_command_ns = received_ns;
        // Untimed (`time_exchanges` off), nothing was measured: nothing recorded.
        if cfg.time_exchanges {
            let round_trip_ns = received_ns - published_ns;
            step_times.round_trip_ns = Some(round_trip_ns);
            if self.with_transport {
                self.timing
                    .record_exchange(round_trip_ns, cmd.stub_compute_ns);
                step_times.transport_ns = Some(round_trip_ns.saturating_sub(cmd.stub_compute_ns));
            } else {
                self.timing
                    .record_in_process(round_trip_ns, cmd.stub_compute_ns);
            }
        }
        self.digest.add_command(cmd);
        self.fsw_monitor.record(cmd, &plant.truth(), t_ns);
        Ok(())
    }

    /// No command to apply this cycle: a deadline miss, and what the miss policy does.
    fn missed<C: StepClock + ?Sized>(
        &mut self,
        cfg: &SchedulerConfig,
        k: u64,
        clock: &C,
        received_ns: u64,
    ) -> Result<(), Abort> {
        self.timing.record_deadline_miss();
        // Only a realtime run can miss a deadline on a live link: in lockstep a miss
        // comes from a fault alone (simulated), and a dead peer is what `receive_until`
        // waiting out the link timeout finds.
        let silent_ms = received_ns.saturating_sub(self.last_command_ns) / 1_000_000;
        if clock.misses_allowed() && silent_ms >= cfg.link_timeout_ms {
            return Err(Abort::StubSilent {
                step: k,
                waited_ms: silent_ms,
            });
        }
        match cfg.miss_policy {
            MissPolicy::Hold => {}
            MissPolicy::Zero => self.applied = ActuatorCommand::default(),
            MissPolicy::Abort { after } => {
                if self.timing.deadline_misses() >= after {
                    return Err(Abort::TooManyMisses(self.timing.deadline_misses()));
                }
            }
        }
        Ok(())
    }
}
