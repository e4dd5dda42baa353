//! The stub's IPC loop: receive Telemetry(k), run the flight software, stamp and publish
//! Command(k). The only module of the stub that touches the link.
//!
//! The step path does no heap allocation, locking or logging: the flight software's
//! `step` must not allocate (trait contract), and the link's calls do not.
//!
//! A watchdog thread beside the loop ends the process when the flight software does not
//! return from a step (a C library in an endless loop): a termination signal only raises
//! a flag the loop reads between steps, so without it such a stub ignores SIGINT and
//! SIGTERM and outlives every timeout.

use crate::fsw::FlightSoftware;
use oils_shared::clock::monotonic_ns;
use oils_shared::fsw::announced_frames;
use oils_shared::link::{LinkError, StubLink};
use oils_shared::TLM_FLAG_END_OF_RUN;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// How the stub's loop ended well.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StubSummary {
    /// Commands sent.
    pub commands: u64,
    /// Last step answered.
    pub last_step: u64,
    /// Frames handed to the flight software (protocol v4), each checked against its
    /// announcement's length and hash.
    pub frames: u64,
    /// Frames announced that were not on their service (lost).
    pub frames_missed: u64,
}

/// Why the stub's loop ended badly.
#[derive(Debug, thiserror::Error)]
pub enum StubError {
    /// Link failure (includes a protocol mismatch and interruption by a signal).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The emulator's process exited without an end-of-run telemetry.
    #[error("the emulator (pid {pid}) exited without ending the run, after step {last_step}; noticed {waited_ms} ms into the wait for the next telemetry")]
    EmulatorGone {
        /// The emulator's process id.
        pid: i32,
        /// Last step answered.
        last_step: u64,
        /// How long we had waited.
        waited_ms: u64,
    },
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
    /// A frame's bytes are not the ones its telemetry announced (length or XXH3-64).
    #[error("frame {seq} of frame device {device} does not match its announcement (length or hash): the frame path corrupted it")]
    FrameMismatch {
        /// `FRAME_DEVICE_*`.
        device: u32,
        /// The frame's counter.
        seq: u64,
    },
}

pub use oils_shared::fsw::answer;

/// While it waits for telemetry, the stub checks this often (wall time) whether the
/// emulator's process still runs: a dead emulator is noticed within this bound, whatever
/// the speed factor stretches the period to.
pub const EMULATOR_CHECK_MS: u64 = 100;

/// Longest silence the stub waits out when it cannot watch the emulator's process (no
/// pidfd, or the emulator in another pid namespace): `timeout_ms` is capped to this, so
/// even then a dead emulator is given up within 10 s of wall time.
pub const BLIND_TIMEOUT_CAP_MS: u64 = 10_000;

/// Exit status of a stub whose flight software never returned from a step.
pub const STUCK_EXIT_CODE: i32 = 3;

/// After a termination signal, how long the flight software may stay in its step before
/// the watchdog ends the process, milliseconds.
pub const STUCK_AFTER_SIGNAL_MS: u64 = 1000;

/// How often the watchdog looks, milliseconds.
const WATCHDOG_PERIOD_MS: u64 = 50;

/// Which step the flight software is in and since when (two relaxed stores a step).
#[derive(Default)]
struct StepWatch {
    /// When the step began, monotonic nanoseconds; 0 between steps.
    since_ns: AtomicU64,
    /// The step.
    step: AtomicU64,
}

/// Ends the process (status [`STUCK_EXIT_CODE`], the flight software not finalised) when
/// a step has lasted `timeout_ms` (the emulator gave up on it long before), or
/// [`STUCK_AFTER_SIGNAL_MS`] after a termination signal; returns when `done` is raised.
fn watchdog(watch: &StepWatch, done: &AtomicBool, stop: &AtomicBool, timeout_ms: u64) {
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(std::time::Duration::from_millis(WATCHDOG_PERIOD_MS));
        let since_ns = watch.since_ns.load(Ordering::Relaxed);
        if since_ns == 0 {
            continue;
        }
        let in_step_ms = monotonic_ns().saturating_sub(since_ns) / 1_000_000;
        let signalled = stop.load(Ordering::Relaxed);
        if in_step_ms >= timeout_ms || (signalled && in_step_ms >= STUCK_AFTER_SIGNAL_MS) {
            eprintln!(
                "error: onboard stub: the flight software has not returned from its step {} for {in_step_ms} ms{}; exiting with status {STUCK_EXIT_CODE}, without finalising it",
                watch.step.load(Ordering::Relaxed),
                if signalled { " (a termination signal came)" } else { "" }
            );
            // SAFETY: ends the process at once; the stuck thread cannot be unwound, and
            // the next node's dead-node cleanup removes what iceoryx2 leaves.
            unsafe { libc::_exit(STUCK_EXIT_CODE) };
        }
    }
}

/// Serves one run until the emulator sends its end-of-run telemetry.
///
/// Waiting for Telemetry(k), the stub gives up when the emulator's process exits (checked
/// every [`EMULATOR_CHECK_MS`]) or after `timeout_ms` of silence from a live emulator (an
/// emulator that cannot be watched: at most [`BLIND_TIMEOUT_CAP_MS`]). A step that does not
/// return ends the process (see [`STUCK_EXIT_CODE`]).
pub fn serve(
    link: &StubLink,
    fsw: &mut dyn FlightSoftware,
    timeout_ms: u64,
    stop: &AtomicBool,
) -> Result<StubSummary, StubError> {
    let watch = StepWatch::default();
    let done = AtomicBool::new(false);
    std::thread::scope(|s| {
        // Started before tick 0 (spawning allocates); joined when the loop is over.
        s.spawn(|| watchdog(&watch, &done, stop, timeout_ms));
        let served = serve_watched(link, fsw, timeout_ms, stop, &watch);
        done.store(true, Ordering::Relaxed);
        served
    })
}

fn serve_watched(
    link: &StubLink,
    fsw: &mut dyn FlightSoftware,
    timeout_ms: u64,
    stop: &AtomicBool,
    watch: &StepWatch,
) -> Result<StubSummary, StubError> {
    let mut summary = StubSummary {
        commands: 0,
        last_step: 0,
        frames: 0,
        frames_missed: 0,
    };
    loop {
        let waited_from = monotonic_ns();
        let blind_ms = timeout_ms.min(BLIND_TIMEOUT_CAP_MS);
        let tlm = loop {
            let watched = link.emulator_process();
            let limit_ms = if watched.is_some() {
                timeout_ms
            } else {
                blind_ms
            };
            let deadline_ns = waited_from.saturating_add(limit_ms.saturating_mul(1_000_000));
            let slice_end_ns = monotonic_ns()
                .saturating_add(EMULATOR_CHECK_MS * 1_000_000)
                .min(deadline_ns);
            if let Some(t) = link.receive_until(slice_end_ns, stop)? {
                break t;
            }
            let waited_ms = (monotonic_ns() - waited_from) / 1_000_000;
            if let Some(p) = watched.filter(|p| !p.alive()) {
                // A last look: it may have sent its final telemetry just before exiting.
                if let Some(t) = link.try_receive()? {
                    break t;
                }
                return Err(StubError::EmulatorGone {
                    pid: p.pid(),
                    last_step: summary.last_step,
                    waited_ms,
                });
            }
            if monotonic_ns() >= deadline_ns {
                return Err(StubError::EmulatorSilent {
                    last_step: summary.last_step,
                    waited_ms,
                });
            }
        };
        tlm.header.check_peer()?;
        if tlm.header.flags & TLM_FLAG_END_OF_RUN != 0 {
            return Ok(summary);
        }
        watch.step.store(tlm.header.step, Ordering::Relaxed);
        watch
            .since_ns
            .store(monotonic_ns().max(1), Ordering::Relaxed);
        // The frames this telemetry announces, read in place from their services and
        // checked against their announcements (an XXH3 pass, ~0.1 ms for 2 MiB) before
        // the flight software sees them.
        for ann in announced_frames(&tlm) {
            let read = link.with_frame(ann, |header, pixels| {
                let intact = header == ann && ann.matches(pixels);
                if intact {
                    fsw.frame(ann, pixels);
                }
                intact
            })?;
            match read {
                Some(true) => summary.frames += 1,
                Some(false) => {
                    watch.since_ns.store(0, Ordering::Relaxed);
                    return Err(StubError::FrameMismatch {
                        device: ann.device,
                        seq: ann.seq,
                    });
                }
                None => summary.frames_missed += 1,
            }
        }
        let cmd = answer(fsw, &tlm);
        watch.since_ns.store(0, Ordering::Relaxed);
        if let Some(failure) = fsw.failure() {
            return Err(failure.into());
        }
        link.publish(&cmd)?;
        summary.commands += 1;
        summary.last_step = tlm.header.step;
    }
}
