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
//! Every link is also a [`FrameSink`] (protocol v4): the frame devices render into the
//! buffer it hands out (an iceoryx2 loan on [`BoundLink`]; [`FrameSlots`] allocated before
//! tick 0 in process and in a replay) and it publishes the frame.
//!
//! Calls on the step path do not allocate.

use crate::recorder::{Log, REC_COMMAND_RECEIVED, REC_END_OF_RUN};
use crate::sensors::FrameSink;
use oils_shared::fsw::{announced_frames, answer, FlightSoftware, FswFailure};
use oils_shared::link::{EmulatorLink, FrameSpec, LinkError, PeerPort};
use oils_shared::{AsBytes, Command, FrameAnnouncement, Telemetry, TLM_FLAG_END_OF_RUN};
use std::sync::atomic::AtomicBool;

/// What can stop an exchange.
#[derive(Debug, thiserror::Error)]
pub enum ExchangeError {
    /// The iceoryx2 link failed or was interrupted.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The in-process flight software reported a failed step.
    #[error(transparent)]
    FlightSoftware(#[from] FswFailure),
    /// The flight-software process bound to the run exited (watched through a pidfd).
    #[error("the flight-software process (pid {pid}) exited without answering step {step}; the run is bound to the process that joined it (--allow-reattach lets a restarted one take over)")]
    FlightSoftwareGone {
        /// Its process id.
        pid: i32,
        /// The step whose command it did not send.
        step: u64,
    },
    /// A command came from another flight-software process than the one bound to the run.
    #[error(
        "flight software changed: the command for step {step} came from another process ({from}) than the one that joined the run ({bound}); the flight software restarted, or a second one joined. The run is bound to the process that joined it (--allow-reattach lets a new one take over)"
    )]
    ForeignFlightSoftware {
        /// The step the command claimed to answer.
        step: u64,
        /// Who sent it.
        from: PeerPort,
        /// Who the run is bound to.
        bound: PeerPort,
    },
    /// What a replay's frames were handed to failed (an export's file write).
    #[error("the frames' export failed: {0}")]
    FrameTap(String),
    /// A replayed run produced telemetry other than the recorded one.
    #[error("replay diverged at step {step}: the emulator's telemetry differs from the log's")]
    ReplayDiverged {
        /// First step that differs.
        step: u64,
    },
}

/// The emulator's end of a telemetry/command exchange (and of the frame services: a
/// frame published through its [`FrameSink`] goes out before the telemetry announcing it).
pub trait Link: FrameSink {
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

/// A flight software that took a run over under `--allow-reattach`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Reattachment {
    /// The step whose command first came from the new process.
    pub step: u64,
    /// The process the run was bound to.
    pub from: PeerPort,
    /// The process it is bound to now.
    pub to: PeerPort,
}

/// Most re-attachments a run keeps a record of (more are counted, not kept), so that
/// recording one never allocates on the step path.
pub const MAX_REATTACHMENTS_KEPT: usize = 16;

/// The iceoryx2 link of a run, bound to the flight-software process that joined it: every
/// command must come from the publisher [`EmulatorLink::wait_for_peer`] saw join (iceoryx2
/// stamps the publisher on each sample). A command from any other publisher (a restarted
/// stub, a second process after the first vanished) is
/// [`ExchangeError::ForeignFlightSoftware`], unless re-attachment is allowed: then the run
/// is bound to the newcomer and the change recorded.
///
/// Without re-attachment the joined process is watched ([`EmulatorLink::watch_peer`]): its
/// exit ends the run at once ([`ExchangeError::FlightSoftwareGone`]), not after the link
/// timeout. With it, a dead process may yet be replaced, so it is waited for as before.
pub struct BoundLink {
    link: EmulatorLink,
    bound: PeerPort,
    allow_reattach: bool,
    reattachments: Vec<Reattachment>,
    reattach_count: u64,
    /// The step of the last telemetry published.
    step: u64,
}

impl BoundLink {
    /// Binds `link` to `joined` (from [`EmulatorLink::wait_for_peer`]).
    pub fn new(link: EmulatorLink, joined: PeerPort, allow_reattach: bool) -> Self {
        if let (false, Some(pid)) = (allow_reattach, joined.pid) {
            link.watch_peer(pid);
        }
        Self {
            link,
            bound: joined,
            allow_reattach,
            reattachments: Vec::with_capacity(MAX_REATTACHMENTS_KEPT),
            reattach_count: 0,
            step: 0,
        }
    }

    /// The underlying link.
    pub fn link(&self) -> &EmulatorLink {
        &self.link
    }

    /// The process the run is bound to now.
    pub fn bound(&self) -> PeerPort {
        self.bound
    }

    /// Re-attachments so far (only with `allow_reattach`), and the first
    /// [`MAX_REATTACHMENTS_KEPT`] of them.
    pub fn reattachments(&self) -> (u64, &[Reattachment]) {
        (self.reattach_count, &self.reattachments)
    }
}

impl FrameSink for BoundLink {
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError> {
        Ok(self.link.frame_buffer(device, bytes)?)
    }

    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError> {
        Ok(self.link.publish_frame(ann)?)
    }
}

/// Frame buffers of a link without shared memory (in process, a replay): one per frame
/// device, allocated before tick 0 at its largest frame, each holding the last frame
/// published until the next one is rendered.
#[derive(Debug, Default)]
pub struct FrameSlots {
    slots: Vec<FrameSlot>,
}

#[derive(Debug)]
struct FrameSlot {
    spec: FrameSpec,
    buf: Vec<u8>,
    /// The frame in `buf`, once published.
    published: Option<FrameAnnouncement>,
}

impl FrameSlots {
    /// A buffer for each of `specs` (allocated now).
    pub fn new(specs: &[FrameSpec]) -> Self {
        Self {
            slots: specs
                .iter()
                .map(|spec| FrameSlot {
                    spec: *spec,
                    buf: vec![0; spec.max_bytes],
                    published: None,
                })
                .collect(),
        }
    }

    fn slot(&mut self, device: u32) -> Result<&mut FrameSlot, ExchangeError> {
        self.slots
            .iter_mut()
            .find(|s| s.spec.device == device)
            .ok_or(ExchangeError::Link(LinkError::NoFrameService { device }))
    }

    /// The published frame `ann` announces, if it is the one held.
    pub fn pixels(&self, ann: &FrameAnnouncement) -> Option<&[u8]> {
        let slot = self.slots.iter().find(|s| s.spec.device == ann.device)?;
        (slot.published.as_ref() == Some(ann)).then(|| &slot.buf[..ann.bytes as usize])
    }
}

impl FrameSink for FrameSlots {
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError> {
        let slot = self.slot(device)?;
        if bytes > slot.spec.max_bytes {
            return Err(LinkError::FrameTooLarge {
                device,
                bytes,
                max_bytes: slot.spec.max_bytes,
            }
            .into());
        }
        slot.published = None;
        Ok(&mut slot.buf[..bytes])
    }

    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError> {
        let slot = self.slot(ann.device)?;
        if ann.bytes as usize > slot.spec.max_bytes {
            return Err(LinkError::FrameTooLarge {
                device: ann.device,
                bytes: ann.bytes as usize,
                max_bytes: slot.spec.max_bytes,
            }
            .into());
        }
        slot.published = Some(*ann);
        Ok(())
    }
}

impl Link for BoundLink {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        self.step = tlm.header.step;
        Ok(self.link.publish(tlm)?)
    }

    fn receive_until(
        &mut self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        let received = match self.link.receive_until_from(deadline_ns, stop) {
            Err(LinkError::PeerGone { pid }) => {
                return Err(ExchangeError::FlightSoftwareGone {
                    pid,
                    step: self.step,
                })
            }
            other => other?,
        };
        let Some((cmd, publisher)) = received else {
            return Ok(None);
        };
        if publisher != self.bound.publisher {
            let from = PeerPort {
                publisher,
                pid: self.link.command_publisher_pid(publisher),
            };
            if !self.allow_reattach {
                return Err(ExchangeError::ForeignFlightSoftware {
                    step: cmd.header.step,
                    from,
                    bound: self.bound,
                });
            }
            if self.reattachments.len() < MAX_REATTACHMENTS_KEPT {
                self.reattachments.push(Reattachment {
                    step: cmd.header.step,
                    from: self.bound,
                    to: from,
                });
            }
            self.reattach_count += 1;
            self.bound = from;
        }
        Ok(Some(cmd))
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
    /// Whether the flight software's compute time is measured ([`Self::untimed`]).
    timed: bool,
    /// The frames handed to the flight software (the same bytes the renderer wrote).
    frames: FrameSlots,
}

impl<F: FlightSoftware + ?Sized> InProcLink<F> {
    /// Wraps a flight software (built before tick 0).
    pub fn new(fsw: Box<F>) -> Self {
        Self {
            fsw,
            pending: None,
            timed: true,
            frames: FrameSlots::default(),
        }
    }

    /// With a frame buffer for each of `specs` (the run's frame devices,
    /// [`crate::sensors::FrameRack::specs`]), allocated now: each frame the telemetry
    /// announces is handed to [`FlightSoftware::frame`] before its step.
    pub fn with_frames(mut self, specs: &[FrameSpec]) -> Self {
        self.frames = FrameSlots::new(specs);
        self
    }

    /// The same, with nothing timed on the wall clock: the commands' `stub_compute_ns`
    /// are 0 ([`oils_shared::fsw::answer_untimed`]) and the flight software is asked
    /// not to time its own work ([`FlightSoftware::set_compute_timing`]). The commands
    /// are otherwise the same, and so is the digest, which never covers those times.
    pub fn untimed(mut fsw: Box<F>) -> Self {
        fsw.set_compute_timing(false);
        Self {
            fsw,
            pending: None,
            timed: false,
            frames: FrameSlots::default(),
        }
    }

    /// The flight software, for inspection after a run.
    pub fn fsw(&self) -> &F {
        &self.fsw
    }
}

impl<F: FlightSoftware + ?Sized> FrameSink for InProcLink<F> {
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError> {
        self.frames.frame_buffer(device, bytes)
    }

    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError> {
        self.frames.publish_frame(ann)
    }
}

impl<F: FlightSoftware + ?Sized> Link for InProcLink<F> {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        // The announced frames first, in place, as the stub hands them over.
        if self.fsw.failure().is_none() {
            for ann in announced_frames(tlm) {
                if let Some(pixels) = self.frames.pixels(ann) {
                    self.fsw.frame(ann, pixels);
                }
            }
        }
        // The end-of-run telemetry is not answered, as on the wire; nor is anything once
        // a step has failed.
        self.pending = (tlm.header.flags & oils_shared::TLM_FLAG_END_OF_RUN == 0
            && self.fsw.failure().is_none())
        .then(|| {
            if self.timed {
                answer(self.fsw.as_mut(), tlm)
            } else {
                oils_shared::fsw::answer_untimed(self.fsw.as_mut(), tlm)
            }
        });
        Ok(())
    }

    fn receive_until(
        &mut self,
        _deadline_ns: u64,
        _stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        // A failed step is the answer to its telemetry: it ends the run (reported), as
        // it ends the stub, and its command is not applied.
        if let Some(f) = self.fsw.failure() {
            return Err(f.into());
        }
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
    /// The replay's frames: rendered again, checked through the telemetry's hashes.
    frames: FrameSlots,
    /// Who sees each frame published again (`oils export --frames`), if anyone.
    frame_tap: Option<FrameTap>,
    next: usize,
    pending: Option<Command>,
    /// The recorded run was aborted at this step after its telemetry had gone out: the
    /// replay ends its step there too (the end record says so).
    abort_at: Option<u64>,
    abort_now: bool,
    diverged: Option<u64>,
}

impl ReplayLink {
    /// A replay of `log`'s records.
    pub fn new(log: Log) -> Self {
        Self {
            log,
            frames: FrameSlots::default(),
            frame_tap: None,
            next: 0,
            pending: None,
            abort_at: None,
            abort_now: false,
            diverged: None,
        }
    }

    /// `tap` sees every frame rendered again, in order ([`FrameTap`]).
    pub fn tapping_frames(mut self, tap: FrameTap) -> Self {
        self.frame_tap = Some(tap);
        self
    }

    /// With a frame buffer for each of `specs` (the run's frame devices): the replay
    /// renders every frame again, and its telemetry's hashes must be the log's.
    pub fn with_frames(mut self, specs: &[FrameSpec]) -> Self {
        self.frames = FrameSlots::new(specs);
        self
    }

    /// Ends the replay's step `step` as the recorded run ended it: aborted once its
    /// telemetry is out (an end record with `REC_ENDED_AFTER_PUBLISH`).
    pub fn aborting_at(mut self, step: Option<u64>) -> Self {
        self.abort_at = step;
        self
    }

    /// Records replayed so far (up to the last step published; a step whose telemetry
    /// a fault withheld is not published, but counts).
    pub fn replayed(&self) -> usize {
        self.next
    }

    /// The first step whose telemetry differed from the log's, the end's included (the
    /// scheduler does not stop on the end's: it is the last publish anyway).
    pub fn diverged(&self) -> Option<u64> {
        self.diverged
    }
}

fn same_telemetry(a: &Telemetry, b: &Telemetry) -> bool {
    let (mut a, mut b) = (*a, *b);
    a.header.run_id = 0;
    b.header.run_id = 0;
    a.as_bytes() == b.as_bytes()
}

impl FrameSink for ReplayLink {
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError> {
        self.frames.frame_buffer(device, bytes)
    }

    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError> {
        self.frames.publish_frame(ann)?;
        if let Some(tap) = self.frame_tap.as_mut() {
            let pixels = self.frames.pixels(ann).unwrap_or(&[]);
            tap(ann, pixels).map_err(|e| ExchangeError::FrameTap(e.to_string()))?;
        }
        Ok(())
    }
}

/// What sees every frame a replay renders again, with its announcement and its bytes
/// (an export: it may allocate and write files; a replay is not timed).
pub type FrameTap = Box<dyn FnMut(&FrameAnnouncement, &[u8]) -> std::io::Result<()>>;

impl Link for ReplayLink {
    fn publish(&mut self, tlm: &Telemetry) -> Result<(), ExchangeError> {
        // One record per step from step 0: the step is the record's position.
        let step = tlm.header.step;
        let end = tlm.header.flags & TLM_FLAG_END_OF_RUN != 0;
        let rec = usize::try_from(step)
            .ok()
            .and_then(|i| self.log.records.get(i));
        let same = match rec {
            // The recorded run aborted this step after its telemetry went out; the log
            // holds only the end telemetry published after it (a second draw of the
            // navigation noise), which the end's publish is compared with.
            Some(_) if !end && self.abort_at == Some(step) => true,
            Some(rec) => same_telemetry(&rec.telemetry, tlm),
            // The end of a log cut short (no end record): the replay's own last step.
            None => end && step as usize == self.log.records.len() && !self.log.complete,
        };
        if !same {
            self.diverged.get_or_insert(step);
            return Err(ExchangeError::ReplayDiverged { step });
        }
        let Some(rec) = rec else {
            return Ok(());
        };
        self.next = step as usize + 1;
        self.abort_now = !end && self.abort_at == Some(step);
        self.pending = (rec.flags & REC_COMMAND_RECEIVED != 0 && rec.flags & REC_END_OF_RUN == 0)
            .then_some(rec.command);
        Ok(())
    }

    fn receive_until(
        &mut self,
        _deadline_ns: u64,
        _stop: &AtomicBool,
    ) -> Result<Option<Command>, ExchangeError> {
        if std::mem::take(&mut self.abort_now) {
            return Err(LinkError::Interrupted.into());
        }
        Ok(self.pending.take())
    }

    fn has_transport(&self) -> bool {
        false
    }
}
