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
use crate::sensors::FrameSink;
use core::mem::{offset_of, size_of};
use oils_shared::{AsBytes, Command, FrameAnnouncement, Telemetry};
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

/// A [`Link`] with the run's link faults in front of it, built once per run: it is a
/// `Link` itself (a withheld telemetry is not published and nothing is received for
/// it), and it adds what only a faulty link does: whether telemetry is withheld or the
/// computer resets, the commands it drops, delays, duplicates or corrupts on their way
/// to the sanitiser ([`FaultyLink::deliver`]). Frames pass through untouched.
pub struct FaultyLink<'a, L: Link + ?Sized> {
    inner: &'a mut L,
    faults: LinkFaults,
}

impl<'a, L: Link + ?Sized> FaultyLink<'a, L> {
    /// Wraps `inner` for one run with the run's link faults.
    pub fn new(inner: &'a mut L, faults: LinkFaults) -> Self {
        Self { inner, faults }
    }

    /// The link faults, for the plan to take back at the end of the run.
    pub fn into_faults(self) -> LinkFaults {
        self.faults
    }

    /// The faults active now (`active`, the plan's mask) and those that fired this
    /// step (their delay lines start empty).
    pub fn set_active(&mut self, active: u64, fired: u64) {
        self.faults.set_active(active, fired);
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

    /// Publishes the end-of-run telemetry whatever the faults: the flight software must
    /// learn that the run ended.
    pub fn publish_end_of_run(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        self.inner.publish(tlm)
    }

    /// Whether a stale duplicate of the previous command arrives now (it is discarded
    /// as late).
    pub fn take_stale_duplicate(&mut self) -> bool {
        self.faults.duplicate.take().is_some()
    }

    /// Turns the command that came off the wire (`None`: nothing arrived) into what
    /// reaches the sanitiser, in place (no copy of the packet on the way).
    pub fn deliver(&mut self, cmd: &mut Option<Command>) {
        self.faults.deliver(cmd)
    }
}

impl<L: Link + ?Sized> FrameSink for FaultyLink<'_, L> {
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError> {
        self.inner.frame_buffer(device, bytes)
    }

    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError> {
        self.inner.publish_frame(ann)
    }
}

impl<L: Link + ?Sized> Link for FaultyLink<'_, L> {
    /// Publishes Telemetry(k) unless a fault withholds it ([`FaultyLink::withheld`]
    /// says which).
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        if self.faults.withheld() {
            return Ok(());
        }
        self.inner.publish(tlm)
    }

    /// The next command on the wire; at once `None` while telemetry is withheld (the
    /// flight software had nothing to answer).
    fn receive_until(
        &mut self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        if self.faults.withheld() {
            return Ok(None);
        }
        self.inner.receive_until(deadline_ns, stop)
    }

    fn has_transport(&self) -> bool {
        self.inner.has_transport()
    }
}

/// The byte range of a command the plant acts on: from `thrust_cmd_n` to the end of
/// `attitude_mode` (thrusts, on/off switches, torques, the stub's compute time, thruster
/// on-times, attitude mode), taken from the packet layout. The header is the link's
/// framing (a damaged one is a stale or foreign packet, not a corrupt command) and the
/// flight software's self-report after it is read before delivery, not by the plant.
pub const COMMAND_PAYLOAD_BYTES: core::ops::Range<usize> =
    offset_of!(Command, thrust_cmd_n)..offset_of!(Command, attitude_mode) + size_of::<u32>();

/// Flips `bits` random bits of a command's payload ([`COMMAND_PAYLOAD_BYTES`]), as a
/// damaged packet would arrive.
fn corrupt(cmd: &mut Command, bits: u32, rng: &mut ChaCha8Rng) {
    let mut bytes = [0u8; size_of::<Command>()];
    bytes.copy_from_slice(cmd.as_bytes());
    let range = COMMAND_PAYLOAD_BYTES.start * 8..COMMAND_PAYLOAD_BYTES.end * 8;
    for _ in 0..bits {
        let bit = rng.gen_range(range.clone());
        bytes[bit / 8] ^= 1 << (bit % 8);
    }
    if let Some(c) = Command::from_bytes(&bytes) {
        *cmd = c;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sanitize::sanitize;
    use oils_shared::{ATTITUDE_MODE_THRUSTERS, ENGINE_COUNT, THRUSTER_COUNT};

    /// Every field of the payload, by its offset and size in the layout.
    fn payload_fields() -> Vec<(&'static str, usize, usize)> {
        vec![
            (
                "thrust_cmd_n",
                offset_of!(Command, thrust_cmd_n),
                size_of::<[f64; ENGINE_COUNT]>(),
            ),
            (
                "engine_on",
                offset_of!(Command, engine_on),
                size_of::<[u32; ENGINE_COUNT]>(),
            ),
            (
                "torque_cmd_body_nm",
                offset_of!(Command, torque_cmd_body_nm),
                size_of::<[f64; 3]>(),
            ),
            (
                "stub_compute_ns",
                offset_of!(Command, stub_compute_ns),
                size_of::<u64>(),
            ),
            (
                "thruster_on_time_ns",
                offset_of!(Command, thruster_on_time_ns),
                size_of::<[u64; THRUSTER_COUNT]>(),
            ),
            (
                "attitude_mode",
                offset_of!(Command, attitude_mode),
                size_of::<u32>(),
            ),
        ]
    }

    #[test]
    fn the_payload_range_is_exactly_the_fields_the_plant_acts_on() {
        let fields = payload_fields();
        let mut end = COMMAND_PAYLOAD_BYTES.start;
        for (name, offset, size) in &fields {
            assert_eq!(*offset, end, "{name} does not follow the field before it");
            end = offset + size;
        }
        assert_eq!(end, COMMAND_PAYLOAD_BYTES.end);
    }

    /// A clean command of the thrusters' mode, mid-throttle, thrusters firing briefly.
    fn clean() -> Command {
        Command {
            thrust_cmd_n: [400.0; ENGINE_COUNT],
            engine_on: [1; ENGINE_COUNT],
            torque_cmd_body_nm: [1.0, -2.0, 0.5],
            thruster_on_time_ns: [1_000_000; THRUSTER_COUNT],
            attitude_mode: ATTITUDE_MODE_THRUSTERS,
            ..Command::default()
        }
    }

    /// Flips the bit 0x80 of one byte of a clean command; returns the sanitiser's count of
    /// replaced values, its answer and the corrupt command.
    fn flip(byte: usize) -> (u32, crate::plant::ActuatorCommand, Command) {
        let mut bytes = [0u8; size_of::<Command>()];
        bytes.copy_from_slice(clean().as_bytes());
        bytes[byte] ^= 0x80;
        let cmd = Command::from_bytes(&bytes).unwrap();
        let (safe, rejected) = sanitize(&cmd, 800.0, 0, 10_000_000);
        (rejected, safe, cmd)
    }

    #[test]
    fn a_corrupt_bit_reaches_every_field_and_the_sanitiser_answers_for_each() {
        let (clean_safe, clean_rejected) = sanitize(&clean(), 800.0, 0, 10_000_000);
        assert_eq!(clean_rejected, 0);
        for (name, offset, _) in payload_fields() {
            // The top byte of the field's first element (little-endian).
            let elem = match name {
                "engine_on" | "attitude_mode" => 4,
                _ => 8,
            };
            let (rejected, safe, cmd) = flip(offset + elem - 1);
            assert_ne!(cmd, clean(), "{name}: the flip changed nothing");
            match name {
                // Sign bit: a negative thrust becomes 0 N, counted.
                "thrust_cmd_n" => {
                    assert_eq!(rejected, 1, "{name}");
                    assert_eq!(safe.engines.thrust_cmd_n[0], 0.0);
                }
                // 0x80000001 is neither off nor on: off, counted.
                "engine_on" => {
                    assert_eq!(rejected, 1, "{name}");
                    assert!(!safe.engines.on[0]);
                }
                // A finite torque of the other sign is a valid command: passed through.
                "torque_cmd_body_nm" => {
                    assert_eq!(rejected, 0, "{name}");
                    assert_eq!(safe.torque_cmd_body_nm[0], -1.0);
                }
                // Timing only: the actuators are untouched.
                "stub_compute_ns" => {
                    assert_eq!(rejected, 0, "{name}");
                    assert_eq!(safe, clean_safe);
                }
                // An on-time beyond the cycle is clamped to the cycle, counted.
                "thruster_on_time_ns" => {
                    assert_eq!(rejected, 1, "{name}");
                    assert_eq!(safe.thruster_on_time_ns[0], 10_000_000);
                }
                // An unknown attitude mode: ideal torque with zero torque, counted.
                "attitude_mode" => {
                    assert_eq!(rejected, 1, "{name}");
                    assert!(!safe.use_thrusters);
                    assert_eq!(safe.torque_cmd_body_nm, [0.0; 3]);
                }
                other => panic!("no expectation for {other}"),
            }
        }
    }

    #[test]
    fn random_corruption_lands_in_every_field() {
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(3);
        let fields = payload_fields();
        let mut hit = vec![0usize; fields.len()];
        for _ in 0..2000 {
            let mut c = clean();
            corrupt(&mut c, 1, &mut rng);
            let (a, b) = (clean(), c);
            let (a, b) = (a.as_bytes(), b.as_bytes());
            let byte = (0..a.len())
                .find(|&i| a[i] != b[i])
                .expect("one bit flipped");
            assert!(COMMAND_PAYLOAD_BYTES.contains(&byte));
            let k = fields
                .iter()
                .position(|(_, o, s)| (*o..o + s).contains(&byte))
                .unwrap();
            hit[k] += 1;
        }
        assert!(hit.iter().all(|&n| n > 0), "{hit:?}");
    }
}
