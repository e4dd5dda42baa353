//! Link faults as a wrapper around a [`Link`]: [`FaultyLink`] withholds telemetry
//! (`telemetry-drop`, `stub-pause`) and, between the wire and the sanitiser, drops,
//! delays, duplicates or corrupts commands. Which steps are affected is decided by the
//! fault schedule on simulated time only; nothing here reads the wall clock, so a
//! lockstep run with link faults is the same run on a quiet and on a loaded machine.
//!
//! The wrapper keeps the wire packet apart from what it delivers: the digest and the
//! timing figures cover the packets that crossed the link, and the sanitiser sees what
//! the fault let through.

use super::action::LinkAction;
use crate::link::{ExchangeError, Link};
use oils_shared::{AsBytes, Command, Telemetry};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;
use std::sync::atomic::AtomicBool;

#[derive(Debug, Clone)]
struct Entry {
    /// Position of the fault in the run's list (its bit in the masks).
    index: usize,
    action: LinkAction,
    rng: ChaCha8Rng,
    /// Delay line of a command-delay fault (sized before tick 0).
    delayed: VecDeque<Command>,
}

/// The run's link faults, in declaration order, with their state.
#[derive(Debug, Clone, Default)]
pub struct LinkFaults {
    entries: Vec<Entry>,
    active: u64,
    /// Mask of the faults that withhold telemetry.
    withholding: u64,
    /// Mask of the computer-reset faults.
    resetting: u64,
    /// A duplicated command waiting to arrive (stale) at the next step.
    duplicate: Option<Command>,
}

impl LinkFaults {
    pub(super) fn add(&mut self, index: usize, action: LinkAction, rng: ChaCha8Rng) {
        let capacity = match action {
            LinkAction::CommandDelay { steps } => steps + 1,
            _ => 0,
        };
        if matches!(action, LinkAction::TelemetryDrop | LinkAction::StubPause) {
            self.withholding |= 1 << index;
        }
        if action == LinkAction::ComputerReset {
            self.resetting |= 1 << index;
        }
        self.entries.push(Entry {
            index,
            action,
            rng,
            delayed: VecDeque::with_capacity(capacity),
        });
    }

    pub(super) fn set_active(&mut self, active: u64, fired: u64) {
        self.active = active;
        if fired != 0 {
            for e in &mut self.entries {
                if fired & (1 << e.index) != 0 {
                    e.delayed.clear();
                }
            }
        }
    }

    /// Whether Telemetry(k) is withheld from the flight software now.
    pub fn withheld(&self) -> bool {
        self.active & self.withholding != 0
    }

    /// Whether the onboard computer is resetting now.
    pub fn resetting(&self) -> bool {
        self.active & self.resetting != 0
    }

    fn deliver(&mut self, cmd: &mut Option<Command>) {
        if self.active == 0 {
            return;
        }
        for e in &mut self.entries {
            if self.active & (1 << e.index) == 0 {
                continue;
            }
            match e.action {
                LinkAction::CommandDrop => *cmd = None,
                LinkAction::CommandDelay { steps } => {
                    if let Some(c) = cmd.take() {
                        e.delayed.push_back(c);
                    }
                    *cmd = if e.delayed.len() > steps {
                        e.delayed.pop_front()
                    } else {
                        None
                    };
                }
                LinkAction::CommandDuplicate => {
                    if let Some(c) = cmd {
                        self.duplicate = Some(*c);
                    }
                }
                LinkAction::CommandCorrupt { bits } => {
                    if let Some(c) = cmd.as_mut() {
                        corrupt(c, bits, &mut e.rng);
                    }
                }
                LinkAction::TelemetryDrop | LinkAction::StubPause | LinkAction::ComputerReset => {}
            }
        }
    }
}

/// A [`Link`] with the run's link faults in front of it.
pub struct FaultyLink<'a, L: Link + ?Sized> {
    inner: &'a mut L,
    faults: &'a mut LinkFaults,
}

impl<'a, L: Link + ?Sized> FaultyLink<'a, L> {
    /// Wraps `inner` for one run.
    pub fn new(inner: &'a mut L, faults: &'a mut LinkFaults) -> Self {
        Self { inner, faults }
    }

    /// Whether Telemetry(k) is withheld now: nothing is published, nothing can answer,
    /// and the step is a deadline miss (never a dead flight software).
    pub fn withheld(&self) -> bool {
        self.faults.withheld()
    }

    /// Whether the onboard computer is resetting now (a `computer-reset` fault).
    pub fn resetting(&self) -> bool {
        self.faults.resetting()
    }

    /// Publishes Telemetry(k) unless a fault withholds it; `Ok(true)`: it went out.
    pub fn publish(&mut self, tlm: &Telemetry) -> Result<bool, ExchangeError> {
        if self.faults.withheld() {
            return Ok(false);
        }
        self.inner.publish(tlm)?;
        Ok(true)
    }

    /// Publishes the end-of-run telemetry whatever the faults: the flight software must
    /// learn that the run ended.
    pub fn publish_end_of_run(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        self.inner.publish(tlm)
    }

    /// The next command on the wire, as [`Link::receive_until`]; at once `None` while
    /// telemetry is withheld (the flight software had nothing to answer).
    pub fn receive_until(
        &mut self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        if self.faults.withheld() {
            return Ok(None);
        }
        self.inner.receive_until(deadline_ns, stop)
    }

    /// Whether a stale duplicate of the previous command arrives now (it is discarded
    /// as late).
    pub fn take_stale_duplicate(&mut self) -> bool {
        self.faults.duplicate.take().is_some()
    }

    /// Turns the command that came off the wire (`None`: nothing arrived) into what
    /// reaches the sanitiser, in place (a command is 336 bytes: moved in and out, it was
    /// copied twice a step).
    pub fn deliver(&mut self, cmd: &mut Option<Command>) {
        self.faults.deliver(cmd)
    }

    /// The wrapped link's [`Link::has_transport`].
    pub fn has_transport(&self) -> bool {
        self.inner.has_transport()
    }
}

/// Flips `bits` random bits of a command's payload (thrusts, switches, torques: bytes
/// 40..112), as a damaged packet would arrive.
fn corrupt(cmd: &mut Command, bits: u32, rng: &mut ChaCha8Rng) {
    let mut bytes = [0u8; core::mem::size_of::<Command>()];
    bytes.copy_from_slice(cmd.as_bytes());
    for _ in 0..bits {
        let bit = rng.gen_range(40 * 8..112 * 8);
        bytes[bit / 8] ^= 1 << (bit % 8);
    }
    if let Some(c) = Command::from_bytes(&bytes) {
        *cmd = c;
    }
}
