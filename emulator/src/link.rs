//! The emulator's side of the exchange, whatever carries it: publish Telemetry(k),
//! receive Command(k) by a deadline. The scheduler is generic over [`Link`], so one
//! loop serves every transport:
//!
//! * [`EmulatorLink`]: iceoryx2 shared memory to a separate onboard process (the bench);
//! * [`InProcLink`]: the flight software called in the emulator's thread (campaigns,
//!   regression): no IPC, the same packets, so the same digest;
//! * [`ReplayLink`]: a recorded log's commands played back, checking that the emulator
//!   produces the recorded telemetry again (record == replay).
//!
//! Calls on the step path do not allocate.

use crate::recorder::{Log, REC_COMMAND_RECEIVED, REC_END_OF_RUN};
use oils_onboard_stub::fsw::FlightSoftware;
use oils_onboard_stub::runner::answer;
use oils_shared::link::{EmulatorLink, LinkError};
use oils_shared::{AsBytes, Command, Telemetry};
use std::sync::atomic::AtomicBool;

/// What can stop an exchange.
#[derive(Debug, thiserror::Error)]
pub enum ExchangeError {
    /// The iceoryx2 link failed or was interrupted.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The in-process flight software reported a failed step.
    #[error("flight software: {0}")]
    FlightSoftware(#[from] oils_onboard_stub::fsw::FswFailure),
    /// A replayed run produced telemetry other than the recorded one.
    #[error("replay diverged at step {step}: the emulator's telemetry differs from the log's")]
    ReplayDiverged {
        /// First step that differs.
        step: u64,
    },
}

/// The emulator's end of a telemetry/command exchange.
pub trait Link {
    /// Hands Telemetry(k) to the flight software.
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError>;
    /// The next command, waiting until the monotonic time `deadline_ns` at most.
    /// `Ok(None)`: nothing by the deadline. Honours `stop` while it waits
    /// (`LinkError::Interrupted`).
    fn receive_until(
        &mut self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError>;
    /// Whether a transport sits between publish and receive. When it does not (in
    /// process), the transport figure is reported absent, never invented.
    fn has_transport(&self) -> bool;
}

impl Link for EmulatorLink {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        Ok(EmulatorLink::publish(self, tlm)?)
    }

    fn receive_until(
        &mut self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        Ok(EmulatorLink::receive_until(self, deadline_ns, stop)?)
    }

    fn has_transport(&self) -> bool {
        true
    }
}

/// The flight software in the emulator's thread: `publish` runs its step at once (as
/// the onboard stub would, stamping the command the same way), `receive_until` hands
/// the command over.
pub struct InProcLink<F: FlightSoftware + ?Sized> {
    fsw: Box<F>,
    pending: Option<Command>,
}

impl<F: FlightSoftware + ?Sized> InProcLink<F> {
    /// Wraps a flight software (built before tick 0).
    pub fn new(fsw: Box<F>) -> Self {
        Self { fsw, pending: None }
    }

    /// The flight software, for inspection after a run.
    pub fn fsw(&self) -> &F {
        &self.fsw
    }
}

impl<F: FlightSoftware + ?Sized> Link for InProcLink<F> {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        // The end-of-run telemetry is not answered, as on the wire.
        self.pending = (tlm.header.flags & oils_shared::TLM_FLAG_END_OF_RUN == 0)
            .then(|| answer(self.fsw.as_mut(), tlm));
        // A failed step ends the run, as it ends the stub.
        match self.fsw.failure() {
            Some(f) => Err(f.into()),
            None => Ok(()),
        }
    }

    fn receive_until(
        &mut self,
        _deadline_ns: u64,
        _stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        Ok(self.pending.take())
    }

    fn has_transport(&self) -> bool {
        false
    }
}

/// Plays a recorded run's commands back, and checks each telemetry the emulator
/// publishes against the recorded one (the run id aside, which names services only).
pub struct ReplayLink {
    log: Log,
    next: usize,
    pending: Option<Command>,
}

impl ReplayLink {
    /// A replay of `log`'s records.
    pub fn new(log: Log) -> Self {
        Self {
            log,
            next: 0,
            pending: None,
        }
    }

    /// Records replayed so far (up to the last step published; a step whose telemetry
    /// a fault withheld is not published, but counts).
    pub fn replayed(&self) -> usize {
        self.next
    }
}

fn same_telemetry(a: &Telemetry, b: &Telemetry) -> bool {
    let (mut a, mut b) = (*a, *b);
    a.header.run_id = 0;
    b.header.run_id = 0;
    a.as_bytes() == b.as_bytes()
}

impl Link for ReplayLink {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        // One record per step from step 0: the step is the record's position.
        let step = tlm.header.step;
        let Some(rec) = usize::try_from(step)
            .ok()
            .and_then(|i| self.log.records.get(i))
        else {
            return Err(ExchangeError::ReplayDiverged { step });
        };
        if !same_telemetry(&rec.telemetry, tlm) {
            return Err(ExchangeError::ReplayDiverged { step });
        }
        self.next = step as usize + 1;
        self.pending = (rec.flags & REC_COMMAND_RECEIVED != 0 && rec.flags & REC_END_OF_RUN == 0)
            .then_some(rec.command);
        Ok(())
    }

    fn receive_until(
        &mut self,
        _deadline_ns: u64,
        _stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        Ok(self.pending.take())
    }

    fn has_transport(&self) -> bool {
        false
    }
}
