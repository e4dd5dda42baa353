//! The stub's IPC loop: receive Telemetry(k), run the flight software, stamp and publish
//! Command(k). The only module of the stub that touches the link.
//!
//! The step path does no heap allocation, locking or logging: the flight software's
//! `step` must not allocate (trait contract), and the link's calls do not.

use crate::fsw::FlightSoftware;
use oils_shared::clock::monotonic_ns;
use oils_shared::link::{LinkError, StubLink};
use oils_shared::{Command, PacketHeader, Telemetry, TLM_FLAG_END_OF_RUN};
use std::sync::atomic::AtomicBool;

/// How the stub's loop ended well.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StubSummary {
    /// Commands sent.
    pub commands: u64,
    /// Last step answered.
    pub last_step: u64,
}

/// Why the stub's loop ended badly.
#[derive(Debug, thiserror::Error)]
pub enum StubError {
    /// Link failure (includes a protocol mismatch and interruption by a signal).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// No telemetry for too long: the emulator is gone.
    #[error("emulator silent for {waited_ms} ms after step {last_step} (did it die?)")]
    EmulatorSilent {
        /// Last step answered.
        last_step: u64,
        /// How long we waited.
        waited_ms: u64,
    },
    /// The emulator's packet speaks another protocol.
    #[error(transparent)]
    Protocol(#[from] oils_shared::ProtocolMismatch),
    /// The flight software reported a failed step.
    #[error(transparent)]
    FlightSoftware(#[from] crate::fsw::FswFailure),
}

/// Runs the flight software on Telemetry(k) and returns Command(k) stamped as the wire
/// wants it: the header echoes the telemetry's run, step and time, and
/// `stub_compute_ns` holds the flight software's own step time (monotonic clock; the
/// digest ignores it). Every link uses this, so a command is the same whichever link
/// carries it.
pub fn answer<F: FlightSoftware + ?Sized>(fsw: &mut F, tlm: &Telemetry) -> Command {
    let started_ns = monotonic_ns();
    let mut cmd = fsw.step(tlm);
    let compute_ns = monotonic_ns().saturating_sub(started_ns);
    cmd.header = PacketHeader::new(tlm.header.run_id, tlm.header.step, tlm.header.t_ns);
    cmd.stub_compute_ns = compute_ns;
    cmd
}

/// Serves one run until the emulator sends its end-of-run telemetry.
pub fn serve(
    link: &StubLink,
    fsw: &mut dyn FlightSoftware,
    timeout_ms: u64,
    stop: &AtomicBool,
) -> Result<StubSummary, StubError> {
    let mut summary = StubSummary {
        commands: 0,
        last_step: 0,
    };
    loop {
        let waited_from = monotonic_ns();
        let tlm = match link.receive_until(waited_from + timeout_ms * 1_000_000, stop)? {
            Some(t) => t,
            None => {
                return Err(StubError::EmulatorSilent {
                    last_step: summary.last_step,
                    waited_ms: (monotonic_ns() - waited_from) / 1_000_000,
                })
            }
        };
        tlm.header.check_peer()?;
        if tlm.header.flags & TLM_FLAG_END_OF_RUN != 0 {
            return Ok(summary);
        }
        let cmd = answer(fsw, &tlm);
        if let Some(failure) = fsw.failure() {
            return Err(failure.into());
        }
        link.publish(&cmd)?;
        summary.commands += 1;
        summary.last_step = tlm.header.step;
    }
}
