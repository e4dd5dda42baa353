//! The link: the one module that touches iceoryx2, shared by both processes (and by any
//! Rust flight code that wants to sit on the other side).
//!
//! A [`Link<Tx, Rx>`] publishes `Tx` packets and receives `Rx` packets over the run's
//! publish-subscribe services, plus one event service per direction so a receiver can
//! sleep instead of spin. The emulator creates the four services (and stamps the protocol
//! version, schema hash and its wait strategy on them as attributes); the stub opens them.
//!
//! Hot-path calls ([`Link::publish`], [`Link::try_receive`], [`Link::receive_until`]) do
//! not allocate: iceoryx2 loans come from shared memory set up at creation.
//!
//! Frames (protocol v4): the emulator may also create one publish-subscribe service per
//! imaging device ([`FrameSpec`], `oils/<run>/frame/<device>`) carrying `[u8]` dynamic
//! slices with a [`FrameAnnouncement`] user header. The renderer writes straight into the
//! loan ([`EmulatorLink::frame_buffer`], then [`EmulatorLink::publish_frame`]); the stub
//! reads the sample in place ([`StubLink::with_frame`]). No frame byte is ever copied.

use crate::clock::monotonic_ns;
use crate::domain::{Domain, DomainError};
use crate::service::RunServices;
use crate::{
    frame_device_name, Command, FrameAnnouncement, Telemetry, PROTOCOL_VERSION, SCHEMA_HASH,
};
use core::fmt::Debug;
use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use core::time::Duration;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::sample_mut::SampleMut;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
use iceoryx2::service::port_factory::event::PortFactory as EventFactory;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use std::str::FromStr;

/// How a receiver waits for the next packet.
///
/// On a 2-core machine the choice is a trade: busy-polling answers in well under a
/// microsecond but burns a core; event wake-ups cost tens of microseconds but sleep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitStrategy {
    /// Spin on the subscriber. Fastest; one core per waiting process. After
    /// [`WaitStrategy::BUSY_YIELD_AFTER_NS`] of spinning it yields the CPU between polls, so
    /// on a loaded machine a descheduled peer gets to run instead of waiting a time slice.
    BusyPoll,
    /// Block on the peer's event notification.
    Event,
    /// Spin for `spin_ns`, then block on the event.
    Hybrid {
        /// How long to spin before sleeping, nanoseconds.
        spin_ns: u64,
    },
}

impl WaitStrategy {
    /// Default spin window of the hybrid strategy: long enough to catch a peer that
    /// answers within one plant or GNC step, short enough not to starve a 2-core machine.
    pub const DEFAULT_SPIN_NS: u64 = 50_000;
    /// Busy-poll spins this long before it starts yielding between polls: far longer than
    /// a lockstep peer needs on a quiet machine (a few microseconds), far shorter than a
    /// scheduler time slice.
    pub const BUSY_YIELD_AFTER_NS: u64 = 20_000;

    /// Whether a sender using this strategy must notify its peer after each packet.
    pub fn notifies(&self) -> bool {
        !matches!(self, WaitStrategy::BusyPoll)
    }

    /// Short name, as on the command line and in service attributes.
    pub fn as_str(&self) -> &'static str {
        match self {
            WaitStrategy::BusyPoll => "busy",
            WaitStrategy::Event => "event",
            WaitStrategy::Hybrid { .. } => "hybrid",
        }
    }
}

impl FromStr for WaitStrategy {
    type Err = LinkError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "busy" | "busy-poll" => Ok(WaitStrategy::BusyPoll),
            "event" => Ok(WaitStrategy::Event),
            "hybrid" => Ok(WaitStrategy::Hybrid {
                spin_ns: Self::DEFAULT_SPIN_NS,
            }),
            _ => Err(LinkError::BadWaitStrategy),
        }
    }
}

/// What can go wrong on the link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// iceoryx2 refused an operation.
    #[error("iceoryx2: {what}: {detail}")]
    Iceoryx {
        /// The operation.
        what: &'static str,
        /// iceoryx2's error, printed.
        detail: String,
    },
    /// The peer speaks another protocol.
    #[error(transparent)]
    Protocol(#[from] crate::ProtocolMismatch),
    /// The services of this run id already exist (another bench uses it).
    #[error("run id {run_id:016x} is already in use on this machine; pick another --run-id")]
    RunIdInUse {
        /// The run id.
        run_id: u64,
    },
    /// The peer did not show up in time.
    #[error("no peer on run {run_id:016x} after {waited_ms} ms ({what})")]
    PeerTimeout {
        /// The run id.
        run_id: u64,
        /// How long we waited.
        waited_ms: u64,
        /// What was missing.
        what: &'static str,
    },
    /// A termination signal arrived while waiting.
    #[error("interrupted by a termination signal")]
    Interrupted,
    /// Unknown wait strategy name.
    #[error("unknown wait strategy (expected busy, event or hybrid)")]
    BadWaitStrategy,
    /// The oils iceoryx2 domain is unusable.
    #[error(transparent)]
    Domain(#[from] DomainError),
    /// The onboard process started for the run exited before it joined.
    #[error("the onboard process (pid {pid}) exited {waited_ms} ms after it was started, before it joined run {run_id:016x}")]
    PeerExited {
        /// The run id.
        run_id: u64,
        /// Its process id.
        pid: i32,
        /// How long the emulator had waited for it.
        waited_ms: u64,
    },
    /// A frame for a device that has no frame service on this link.
    #[error("no frame service for frame device {device} on this link")]
    NoFrameService {
        /// The `FRAME_DEVICE_*` id.
        device: u32,
    },
    /// A frame larger than its service's slices (set at creation).
    #[error(
        "a frame of {bytes} bytes for frame device {device} exceeds its service's {max_bytes}"
    )]
    FrameTooLarge {
        /// The `FRAME_DEVICE_*` id.
        device: u32,
        /// The frame's length.
        bytes: usize,
        /// The service's largest frame.
        max_bytes: usize,
    },
    /// A frame device id that is not a `FRAME_DEVICE_*`.
    #[error("unknown frame device {device}")]
    UnknownFrameDevice {
        /// The id.
        device: u32,
    },
    /// The emulator's `oils.frames` attribute does not parse.
    #[error(
        "the run's oils.frames attribute `{value}` does not parse (expected device:max_bytes,...)"
    )]
    BadFrameAttribute {
        /// The attribute's text.
        value: String,
    },
    /// The peer process this side watches ([`Link::watch_peer`]) has exited, and nothing
    /// it sent is left to receive.
    #[error("the peer process (pid {pid}) exited")]
    PeerGone {
        /// Its process id.
        pid: i32,
    },
}

/// While a side that watches its peer's process ([`Link::watch_peer`]) waits for a
/// packet, it checks this often (wall time) whether that process still runs: a peer that
/// died is noticed within this bound, not after a timeout.
pub const PEER_CHECK_NS: u64 = 20_000_000;

fn ice<E: Debug>(what: &'static str) -> impl FnOnce(E) -> LinkError {
    move |e| LinkError::Iceoryx {
        what,
        detail: format!("{e:?}"),
    }
}

/// Attribute keys the emulator stamps on the run's telemetry-event service.
pub mod attribute_keys {
    /// Protocol version, decimal.
    pub const PROTOCOL_VERSION: &str = "oils.protocol_version";
    /// Schema hash, `0x`-prefixed hex.
    pub const SCHEMA_HASH: &str = "oils.schema_hash";
    /// The emulator's wait strategy (`busy`, `event`, `hybrid`).
    pub const WAIT: &str = "oils.wait";
    /// The run's frame services (protocol v4): `device:max_bytes` pairs separated by
    /// commas, device the `FRAME_DEVICE_*` id (`3:2097152`); empty or absent: none.
    pub const FRAMES: &str = "oils.frames";
}

/// One frame service of a run: the device and its largest frame (the slice length its
/// publisher is created with).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameSpec {
    /// `FRAME_DEVICE_*`.
    pub device: u32,
    /// Largest frame, bytes.
    pub max_bytes: usize,
}

/// Most frames a frame subscriber keeps unread: frames are announced by the next
/// telemetry and read before its step, so one is waiting at a time; two leave room for
/// a slow reader without making the publisher hold more shared memory.
pub const FRAME_SUBSCRIBER_BUFFER: usize = 2;

type FrameService = PubSubFactory<ipc::Service, [u8], FrameAnnouncement>;

/// The emulator's port of one frame service, with the loan the renderer writes into.
struct FrameTx {
    spec: FrameSpec,
    _service: FrameService,
    publisher: Publisher<ipc::Service, [u8], FrameAnnouncement>,
    loan: Option<SampleMut<ipc::Service, [u8], FrameAnnouncement>>,
}

/// The onboard side's port of one frame service.
struct FrameRx {
    device: u32,
    _service: FrameService,
    subscriber: Subscriber<ipc::Service, [u8], FrameAnnouncement>,
}

/// `device:max_bytes,...` of [`attribute_keys::FRAMES`].
fn frames_attribute(frames: &[FrameSpec]) -> String {
    let parts: Vec<String> = frames
        .iter()
        .map(|f| format!("{}:{}", f.device, f.max_bytes))
        .collect();
    parts.join(",")
}

/// Parses [`attribute_keys::FRAMES`].
pub fn parse_frames_attribute(value: &str) -> Result<Vec<FrameSpec>, LinkError> {
    let bad = || LinkError::BadFrameAttribute {
        value: value.to_string(),
    };
    value
        .split(',')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let (d, n) = p.split_once(':').ok_or_else(bad)?;
            Ok(FrameSpec {
                device: d.parse().map_err(|_| bad())?,
                max_bytes: n.parse().map_err(|_| bad())?,
            })
        })
        .collect()
}

fn frame_service_name(run_id: u64, device: u32) -> Result<ServiceName, LinkError> {
    let name = frame_device_name(device).ok_or(LinkError::UnknownFrameDevice { device })?;
    service_name(RunServices::new(run_id).frame(name).as_str())
}

/// Creates an iceoryx2 node for one side of the link, in the oils domain this
/// environment selects ([`crate::domain::Domain::from_env`]: a directory private to the
/// user, a prefix of its own).
///
/// Signal handling is left to the caller (both binaries install their own SIGINT and
/// SIGTERM flag before tick 0, so a signal is seen even before any iceoryx2 wait). Dead
/// nodes of earlier crashed runs are cleaned up on creation.
pub fn create_node(name: &str) -> Result<Node<ipc::Service>, LinkError> {
    create_node_in(name, &Domain::from_env()?)
}

/// Creates an iceoryx2 node in `domain`.
pub fn create_node_in(name: &str, domain: &Domain) -> Result<Node<ipc::Service>, LinkError> {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Error);
    let node_name = NodeName::new(name).map_err(ice("node name"))?;
    // An explicit config: no config-file lookup, so no warning at every start.
    let config = domain.iceoryx2_config()?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(ice("create node"))
}

fn service_name(s: &str) -> Result<ServiceName, LinkError> {
    ServiceName::new(s).map_err(ice("service name"))
}

/// One side of the link: publishes `Tx`, receives `Rx`.
pub struct Link<Tx, Rx>
where
    Tx: Debug + ZeroCopySend + Copy + 'static,
    Rx: Debug + ZeroCopySend + Copy + 'static,
{
    run_id: u64,
    wait: WaitStrategy,
    publisher: Publisher<ipc::Service, Tx, ()>,
    subscriber: Subscriber<ipc::Service, Rx, ()>,
    notifier: Notifier<ipc::Service>,
    listener: Listener<ipc::Service>,
    tx_service: PubSubFactory<ipc::Service, Tx, ()>,
    rx_service: PubSubFactory<ipc::Service, Rx, ()>,
    _tx_event: EventFactory<ipc::Service>,
    _rx_event: EventFactory<ipc::Service>,
    sleeps: AtomicU64,
    wake_notifications: AtomicU64,
    /// The peer process, watched through a pidfd (the stub watches the emulator).
    peer_process: std::sync::OnceLock<PeerProcess>,
    /// The peer process whose exit ends a receive ([`Link::watch_peer`]).
    watched_peer: std::sync::OnceLock<PeerProcess>,
    /// When the watched peer is checked next, monotonic nanoseconds.
    next_peer_check_ns: AtomicU64,
    /// The emulator's frame publishers (empty on the onboard side).
    frames_tx: Vec<FrameTx>,
    /// The onboard side's frame subscribers (empty on the emulator's side).
    frames_rx: Vec<FrameRx>,
}

/// A peer's iceoryx2 publisher: who sent a packet. iceoryx2 stamps it on every sample
/// from the publisher's port, so a flight software cannot forge or forget it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PeerPort {
    /// iceoryx2's unique publisher id.
    pub publisher: u128,
    /// The process that created it, if iceoryx2 still lists the port.
    pub pid: Option<i32>,
}

impl core::fmt::Display for PeerPort {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.pid {
            Some(pid) => write!(f, "pid {pid}, publisher {:x}", self.publisher),
            None => write!(f, "publisher {:x}, process gone", self.publisher),
        }
    }
}

/// A peer process watched through a Linux pidfd: readable once it has exited.
#[derive(Debug)]
pub struct PeerProcess {
    pid: i32,
    fd: std::os::fd::OwnedFd,
}

impl PeerProcess {
    /// Watches process `pid`; `None` where the kernel cannot (no pidfd_open, another
    /// pid namespace, no such process).
    pub fn watch(pid: i32) -> Option<Self> {
        if pid <= 0 {
            return None;
        }
        // SAFETY: pidfd_open takes a pid and flags and returns a new descriptor or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid, 0) };
        if fd < 0 {
            return None;
        }
        // SAFETY: a fresh descriptor that nothing else owns.
        let fd =
            unsafe { <std::os::fd::OwnedFd as std::os::fd::FromRawFd>::from_raw_fd(fd as i32) };
        Some(Self { pid, fd })
    }

    /// The process id.
    pub fn pid(&self) -> i32 {
        self.pid
    }

    /// Whether the process still runs (one non-blocking poll; no allocation).
    pub fn alive(&self) -> bool {
        let mut p = libc::pollfd {
            fd: std::os::fd::AsRawFd::as_raw_fd(&self.fd),
            events: libc::POLLIN,
            revents: 0,
        };
        // SAFETY: one valid pollfd, zero timeout.
        let n = unsafe { libc::poll(&mut p, 1, 0) };
        !(n > 0 && p.revents & (libc::POLLIN | libc::POLLHUP | libc::POLLERR) != 0)
    }
}

/// How often a receiver slept on the peer's event, and how many notifications it saw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WakeCounts {
    /// Waits on the peer's event (each at most 1 ms).
    pub sleeps: u64,
    /// Notifications from the peer seen while sleeping.
    pub notifications: u64,
}

impl WakeCounts {
    /// The receiver slept on the peer's event but the peer never notified: it flew on
    /// the 1 ms re-polls alone (a foreign client that ignores `oils.wait`).
    pub fn peer_never_notified(&self) -> bool {
        self.sleeps > 0 && self.notifications == 0
    }
}

/// The emulator's side.
pub type EmulatorLink = Link<Telemetry, Command>;
/// The onboard computer's side.
pub type StubLink = Link<Command, Telemetry>;

impl EmulatorLink {
    /// Creates the run's services. Fails with [`LinkError::RunIdInUse`] if they exist.
    pub fn create(
        node: &Node<ipc::Service>,
        run_id: u64,
        wait: WaitStrategy,
    ) -> Result<Self, LinkError> {
        Self::create_with_frames(node, run_id, wait, &[])
    }

    /// Creates the run's services and one frame service per entry of `frames` (protocol
    /// v4), announced on the telemetry event's `oils.frames` attribute so the stub opens
    /// them with the rest.
    pub fn create_with_frames(
        node: &Node<ipc::Service>,
        run_id: u64,
        wait: WaitStrategy,
        frames: &[FrameSpec],
    ) -> Result<Self, LinkError> {
        let names = RunServices::new(run_id);
        let version = PROTOCOL_VERSION.to_string();
        let hash = format!("{SCHEMA_HASH:#x}");
        let frames_attr = frames_attribute(frames);
        let mut attrs = AttributeSpecifier::new();
        for (k, v) in [
            (attribute_keys::PROTOCOL_VERSION, version.as_str()),
            (attribute_keys::SCHEMA_HASH, hash.as_str()),
            (attribute_keys::WAIT, wait.as_str()),
            (attribute_keys::FRAMES, frames_attr.as_str()),
        ] {
            // iceoryx2 refuses an empty value: a run without frames has no `oils.frames`.
            if v.is_empty() {
                continue;
            }
            attrs = attrs
                .define(&key(k)?, &value(v)?)
                .map_err(ice("service attributes"))?;
        }
        let in_use = |e: &dyn Debug| format!("{e:?}").contains("AlreadyExists");
        let tlm_service = node
            .service_builder(&service_name(names.telemetry().as_str())?)
            .publish_subscribe::<Telemetry>()
            .max_publishers(1)
            .max_subscribers(4)
            .subscriber_max_buffer_size(4)
            .history_size(0)
            .create()
            .map_err(|e| {
                if in_use(&e) {
                    LinkError::RunIdInUse { run_id }
                } else {
                    ice("create telemetry service")(e)
                }
            })?;
        let cmd_service = node
            .service_builder(&service_name(names.command().as_str())?)
            .publish_subscribe::<Command>()
            .max_publishers(1)
            .max_subscribers(2)
            .subscriber_max_buffer_size(4)
            .history_size(0)
            .create()
            .map_err(ice("create command service"))?;
        let cmd_event = node
            .service_builder(&service_name(names.command_event().as_str())?)
            .event()
            .create()
            .map_err(ice("create command event"))?;
        let mut frames_tx = Vec::with_capacity(frames.len());
        for spec in frames {
            let service = node
                .service_builder(&frame_service_name(run_id, spec.device)?)
                .publish_subscribe::<[u8]>()
                .user_header::<FrameAnnouncement>()
                .max_publishers(1)
                .max_subscribers(4)
                .subscriber_max_buffer_size(FRAME_SUBSCRIBER_BUFFER)
                .history_size(0)
                .create()
                .map_err(ice("create frame service"))?;
            let publisher = service
                .publisher_builder()
                .initial_max_slice_len(spec.max_bytes)
                .max_loaned_samples(1)
                .create()
                .map_err(ice("create frame publisher"))?;
            frames_tx.push(FrameTx {
                spec: *spec,
                _service: service,
                publisher,
                loan: None,
            });
        }
        // Created last: the telemetry event carries the announcement, and a client that
        // finds it may open every other service at once (the stub does; a client that
        // found it before the command event existed failed with `DoesNotExist`).
        let tlm_event = node
            .service_builder(&service_name(names.telemetry_event().as_str())?)
            .event()
            .create_with_attributes(&attrs)
            .map_err(ice("create telemetry event"))?;
        let mut link =
            Self::from_services(run_id, wait, tlm_service, cmd_service, tlm_event, cmd_event)?;
        link.frames_tx = frames_tx;
        Ok(link)
    }

    /// The frame services this link publishes on.
    pub fn frame_specs(&self) -> impl Iterator<Item = FrameSpec> + '_ {
        self.frames_tx.iter().map(|f| f.spec)
    }

    /// A writable buffer of `bytes` in the shared memory of `device`'s next frame: an
    /// iceoryx2 loan, held until [`EmulatorLink::publish_frame`] (a second call before it
    /// hands out the same loan if the length matches). The renderer must write every
    /// byte. No allocation.
    pub fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], LinkError> {
        let tx = self
            .frames_tx
            .iter_mut()
            .find(|f| f.spec.device == device)
            .ok_or(LinkError::NoFrameService { device })?;
        if bytes > tx.spec.max_bytes {
            return Err(LinkError::FrameTooLarge {
                device,
                bytes,
                max_bytes: tx.spec.max_bytes,
            });
        }
        if tx.loan.as_ref().is_some_and(|l| l.payload().len() != bytes) {
            tx.loan = None;
        }
        if tx.loan.is_none() {
            let uninit = tx
                .publisher
                .loan_slice_uninit(bytes)
                .map_err(ice("loan frame"))?;
            // SAFETY: the chunk lies in a shared-memory segment that the kernel zero-filled
            // when iceoryx2 mapped it and that has only ever held bytes written since, so
            // every byte is initialised (a `u8` has no invalid bit patterns); iceoryx2's
            // `MaybeUninit` is its type-level caution for payloads in general. Skipping
            // `loan_slice`'s fill saves writing 2 MiB of zeros a camera frame, and the
            // renderer overwrites every byte anyway (the `FrameSource` contract).
            tx.loan = Some(unsafe { uninit.assume_init() });
        }
        Ok(tx
            .loan
            .as_mut()
            .map(|l| l.payload_mut())
            .unwrap_or_default())
    }

    /// Sends the frame [`EmulatorLink::frame_buffer`] handed out for `ann.device`, with
    /// `ann` as its user header. Does not notify: the telemetry that announces it follows
    /// and wakes the peer. No allocation.
    pub fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), LinkError> {
        let device = ann.device;
        let tx = self
            .frames_tx
            .iter_mut()
            .find(|f| f.spec.device == device)
            .ok_or(LinkError::NoFrameService { device })?;
        let Some(mut sample) = tx.loan.take() else {
            return Err(LinkError::Iceoryx {
                what: "publish frame",
                detail: "no frame buffer was loaned for this frame".into(),
            });
        };
        *sample.user_header_mut() = *ann;
        sample.send().map_err(ice("send frame"))?;
        Ok(())
    }

    /// Waits until the stub has subscribed to telemetry and publishes commands; returns
    /// the command publisher that joined (the run is bound to it: the command service
    /// admits one publisher at a time, and every command sample names its publisher).
    pub fn wait_for_peer(&self, timeout_ms: u64, stop: &AtomicBool) -> Result<PeerPort, LinkError> {
        self.wait_for_peer_watching(timeout_ms, stop, None)
    }

    /// [`EmulatorLink::wait_for_peer`], giving up with [`LinkError::PeerExited`] as soon as
    /// `launched` (the onboard process started for this run) exits before it joined: a
    /// stub that refused its flight software does not leave the emulator waiting out the
    /// start-up timeout.
    pub fn wait_for_peer_watching(
        &self,
        timeout_ms: u64,
        stop: &AtomicBool,
        launched: Option<&PeerProcess>,
    ) -> Result<PeerPort, LinkError> {
        let start = monotonic_ns();
        loop {
            let subscribed = self.tx_service.dynamic_config().number_of_subscribers() >= 1;
            let joined = self.command_publisher();
            if let (true, Some(port)) = (subscribed, joined) {
                self.publisher
                    .update_connections()
                    .map_err(ice("update connections"))?;
                return Ok(port);
            }
            if stop.load(Ordering::Relaxed) {
                return Err(LinkError::Interrupted);
            }
            let waited_ms = (monotonic_ns() - start) / 1_000_000;
            if let Some(p) = launched.filter(|p| !p.alive()) {
                return Err(LinkError::PeerExited {
                    run_id: self.run_id,
                    pid: p.pid(),
                    waited_ms,
                });
            }
            if waited_ms >= timeout_ms {
                return Err(LinkError::PeerTimeout {
                    run_id: self.run_id,
                    waited_ms,
                    what: "no onboard stub connected",
                });
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl EmulatorLink {
    /// The command service's publisher (the first one listed), if any.
    pub fn command_publisher(&self) -> Option<PeerPort> {
        let mut found = None;
        self.rx_service.dynamic_config().list_publishers(|p| {
            found = Some(PeerPort {
                publisher: p.publisher_id.value(),
                pid: p.node_id.pid::<ipc::Service>().ok().map(|pid| pid.value()),
            });
            CallbackProgression::Stop
        });
        found
    }

    /// The process behind command publisher `publisher`, if iceoryx2 still lists it.
    pub fn command_publisher_pid(&self, publisher: u128) -> Option<i32> {
        let mut pid = None;
        self.rx_service.dynamic_config().list_publishers(|p| {
            if p.publisher_id.value() == publisher {
                pid = p.node_id.pid::<ipc::Service>().ok().map(|pid| pid.value());
                return CallbackProgression::Stop;
            }
            CallbackProgression::Continue
        });
        pid
    }
}

/// What the emulator announced on its services.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PeerAnnouncement {
    /// The emulator's protocol version.
    pub protocol_version: u32,
    /// The emulator's schema hash.
    pub schema_hash: u64,
    /// The emulator's wait strategy, if it announced one.
    pub wait: Option<WaitStrategy>,
    /// The run's frame services (protocol v4; empty when none or unreadable).
    pub frames: Vec<FrameSpec>,
}

impl StubLink {
    /// Opens the run's services, retrying until the emulator has created them. Checks the
    /// protocol version and schema hash the emulator announced before touching the typed
    /// services, so a mismatch is a clear error naming both versions.
    /// `wait: None` adopts the emulator's announced strategy.
    pub fn open(
        node: &Node<ipc::Service>,
        run_id: u64,
        wait: Option<WaitStrategy>,
        timeout_ms: u64,
        stop: &AtomicBool,
    ) -> Result<Self, LinkError> {
        let names = RunServices::new(run_id);
        let start = monotonic_ns();
        let tlm_event = loop {
            match node
                .service_builder(&service_name(names.telemetry_event().as_str())?)
                .event()
                .open()
            {
                Ok(s) => break s,
                Err(e) => {
                    let msg = format!("{e:?}");
                    if !msg.contains("DoesNotExist")
                        && !msg.contains("InsufficientPermissions")
                        && !msg.contains("ServiceInCorruptedState")
                        && !msg.contains("HangsInCreation")
                    {
                        return Err(ice("open telemetry event")(e));
                    }
                }
            }
            if stop.load(Ordering::Relaxed) {
                return Err(LinkError::Interrupted);
            }
            let waited_ms = (monotonic_ns() - start) / 1_000_000;
            if waited_ms >= timeout_ms {
                return Err(LinkError::PeerTimeout {
                    run_id,
                    waited_ms,
                    what: "no emulator created the run's services",
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        let announced = read_announcement(tlm_event.attributes());
        if announced.protocol_version != PROTOCOL_VERSION || announced.schema_hash != SCHEMA_HASH {
            return Err(LinkError::Protocol(crate::ProtocolMismatch {
                ours_version: PROTOCOL_VERSION,
                ours_schema_hash: SCHEMA_HASH,
                peer_version: announced.protocol_version,
                peer_schema_hash: announced.schema_hash,
            }));
        }
        let wait = wait.or(announced.wait).unwrap_or(WaitStrategy::Hybrid {
            spin_ns: WaitStrategy::DEFAULT_SPIN_NS,
        });
        let cmd_service = node
            .service_builder(&service_name(names.command().as_str())?)
            .publish_subscribe::<Command>()
            .open()
            .map_err(ice("open command service"))?;
        let tlm_service = node
            .service_builder(&service_name(names.telemetry().as_str())?)
            .publish_subscribe::<Telemetry>()
            .open()
            .map_err(ice("open telemetry service"))?;
        let cmd_event = node
            .service_builder(&service_name(names.command_event().as_str())?)
            .event()
            .open()
            .map_err(ice("open command event"))?;
        let mut frames_rx = Vec::new();
        for spec in &announced.frames {
            let service = node
                .service_builder(&frame_service_name(run_id, spec.device)?)
                .publish_subscribe::<[u8]>()
                .user_header::<FrameAnnouncement>()
                .open()
                .map_err(ice("open frame service"))?;
            let subscriber = service
                .subscriber_builder()
                .create()
                .map_err(ice("create frame subscriber"))?;
            frames_rx.push(FrameRx {
                device: spec.device,
                _service: service,
                subscriber,
            });
        }
        let mut link =
            Self::from_services(run_id, wait, cmd_service, tlm_service, cmd_event, tlm_event)?;
        link.frames_rx = frames_rx;
        link.emulator_process();
        Ok(link)
    }

    /// The frame devices whose services this link reads.
    pub fn frame_devices(&self) -> impl Iterator<Item = u32> + '_ {
        self.frames_rx.iter().map(|f| f.device)
    }

    /// Calls `read` with the frame `ann` announces, in place in shared memory (no copy):
    /// its user header (the announcement as published) and its pixel bytes, held only
    /// during the call. Older frames waiting on the device's service are dropped on the
    /// way. `Ok(None)`: the frame is not there (lost, or the device has no service).
    /// No allocation.
    pub fn with_frame<R>(
        &self,
        ann: &FrameAnnouncement,
        read: impl FnOnce(&FrameAnnouncement, &[u8]) -> R,
    ) -> Result<Option<R>, LinkError> {
        let Some(rx) = self.frames_rx.iter().find(|f| f.device == ann.device) else {
            return Ok(None);
        };
        while let Some(sample) = rx.subscriber.receive().map_err(ice("receive frame"))? {
            let header = sample.user_header();
            if header.seq < ann.seq {
                continue;
            }
            if header.seq > ann.seq {
                // A later frame than announced: this one was lost.
                return Ok(None);
            }
            return Ok(Some(read(header, sample.payload())));
        }
        Ok(None)
    }

    /// The emulator's process (the telemetry publisher's), watched through a pidfd from
    /// the first call that finds it listed; `None` while it is not, or where it cannot be
    /// watched (see [`PeerProcess::watch`]). No allocation.
    pub fn emulator_process(&self) -> Option<&PeerProcess> {
        if let Some(p) = self.peer_process.get() {
            return Some(p);
        }
        let mut pid = None;
        self.rx_service.dynamic_config().list_publishers(|p| {
            pid = p.node_id.pid::<ipc::Service>().ok().map(|pid| pid.value());
            CallbackProgression::Stop
        });
        let watched = PeerProcess::watch(pid?)?;
        Some(self.peer_process.get_or_init(|| watched))
    }
}

fn key(s: &str) -> Result<AttributeKey, LinkError> {
    AttributeKey::new(s.as_bytes()).map_err(ice("attribute key"))
}

fn value(s: &str) -> Result<AttributeValue, LinkError> {
    AttributeValue::new(s.as_bytes()).map_err(ice("attribute value"))
}

fn read_announcement(attrs: &AttributeSet) -> PeerAnnouncement {
    let get = |k: &str| -> Option<String> {
        let k = key(k).ok()?;
        attrs
            .key_value(&k, 0)
            .map(|v| String::from_utf8_lossy(v.as_bytes()).into_owned())
    };
    PeerAnnouncement {
        protocol_version: get(attribute_keys::PROTOCOL_VERSION)
            .and_then(|v| v.parse().ok())
            .unwrap_or(0),
        schema_hash: get(attribute_keys::SCHEMA_HASH)
            .and_then(|v| u64::from_str_radix(v.trim_start_matches("0x"), 16).ok())
            .unwrap_or(0),
        wait: get(attribute_keys::WAIT).and_then(|v| v.parse().ok()),
        frames: get(attribute_keys::FRAMES)
            .and_then(|v| parse_frames_attribute(&v).ok())
            .unwrap_or_default(),
    }
}

impl<Tx, Rx> Link<Tx, Rx>
where
    Tx: Debug + ZeroCopySend + Copy + 'static,
    Rx: Debug + ZeroCopySend + Copy + 'static,
{
    fn from_services(
        run_id: u64,
        wait: WaitStrategy,
        tx_service: PubSubFactory<ipc::Service, Tx, ()>,
        rx_service: PubSubFactory<ipc::Service, Rx, ()>,
        tx_event: EventFactory<ipc::Service>,
        rx_event: EventFactory<ipc::Service>,
    ) -> Result<Self, LinkError> {
        let publisher = tx_service
            .publisher_builder()
            .create()
            .map_err(ice("create publisher"))?;
        let subscriber = rx_service
            .subscriber_builder()
            .create()
            .map_err(ice("create subscriber"))?;
        let notifier = tx_event
            .notifier_builder()
            .create()
            .map_err(ice("create notifier"))?;
        let listener = rx_event
            .listener_builder()
            .create()
            .map_err(ice("create listener"))?;
        Ok(Self {
            run_id,
            wait,
            publisher,
            subscriber,
            notifier,
            listener,
            tx_service,
            rx_service,
            _tx_event: tx_event,
            _rx_event: rx_event,
            sleeps: AtomicU64::new(0),
            wake_notifications: AtomicU64::new(0),
            peer_process: std::sync::OnceLock::new(),
            watched_peer: std::sync::OnceLock::new(),
            next_peer_check_ns: AtomicU64::new(0),
            frames_tx: Vec::new(),
            frames_rx: Vec::new(),
        })
    }

    /// Watches process `pid` (the peer bound to the run) from now on: once it has exited
    /// and nothing it sent is left, [`Link::receive_until`] fails with
    /// [`LinkError::PeerGone`] (checked every [`PEER_CHECK_NS`]) instead of waiting out its
    /// deadline. `false` where the process cannot be watched ([`PeerProcess::watch`]) or
    /// one is watched already.
    pub fn watch_peer(&self, pid: i32) -> bool {
        PeerProcess::watch(pid).is_some_and(|p| self.watched_peer.set(p).is_ok())
    }

    /// The watched peer's pid if it was due for a check and has exited (no allocation).
    fn watched_peer_exited(&self, now_ns: u64) -> Option<i32> {
        let peer = self.watched_peer.get()?;
        if now_ns < self.next_peer_check_ns.load(Ordering::Relaxed) {
            return None;
        }
        self.next_peer_check_ns
            .store(now_ns.saturating_add(PEER_CHECK_NS), Ordering::Relaxed);
        (!peer.alive()).then(|| peer.pid())
    }

    /// The run id.
    pub fn run_id(&self) -> u64 {
        self.run_id
    }

    /// The wait strategy in use.
    pub fn wait_strategy(&self) -> WaitStrategy {
        self.wait
    }

    /// How often [`Link::receive_until`] slept on the peer's event and how many of the
    /// peer's notifications it saw: with an `event` or `hybrid` wait, a run whose
    /// [`WakeCounts::peer_never_notified`] is true had a peer that does not notify.
    pub fn wake_counts(&self) -> WakeCounts {
        WakeCounts {
            sleeps: self.sleeps.load(Ordering::Relaxed),
            notifications: self.wake_notifications.load(Ordering::Relaxed),
        }
    }

    /// Whether the peer's receiving port is still attached (a cleanly exited peer
    /// detaches; a killed one stays until dead-node cleanup).
    pub fn peer_attached(&self) -> bool {
        self.tx_service.dynamic_config().number_of_subscribers() >= 1
    }

    /// Publishes one packet (copied into a loaned shared-memory slot), then notifies the
    /// peer unless we busy-poll.
    pub fn publish(&self, packet: &Tx) -> Result<(), LinkError> {
        let sample = self.publisher.loan_uninit().map_err(ice("loan"))?;
        let sample = sample.write_payload(*packet);
        sample.send().map_err(ice("send"))?;
        if self.wait.notifies() {
            self.notifier.notify().map_err(ice("notify"))?;
        }
        Ok(())
    }

    /// Takes the next packet, if one is waiting.
    pub fn try_receive(&self) -> Result<Option<Rx>, LinkError> {
        Ok(self.try_receive_from()?.map(|(p, _)| p))
    }

    /// Takes the next packet, if one is waiting, with the id of the iceoryx2 publisher
    /// that sent it (stamped by iceoryx2 on the sample).
    pub fn try_receive_from(&self) -> Result<Option<(Rx, u128)>, LinkError> {
        match self.subscriber.receive().map_err(ice("receive"))? {
            Some(sample) => Ok(Some((
                *sample.payload(),
                sample.header().publisher_id().value(),
            ))),
            None => Ok(None),
        }
    }

    /// Waits for the next packet until the monotonic time `deadline_ns`, with this
    /// link's wait strategy. `Ok(None)` when the deadline passes; `Err(Interrupted)` when
    /// `stop` is raised (checked between polls and at least every millisecond).
    pub fn receive_until(
        &self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<Rx>, LinkError> {
        Ok(self.receive_until_from(deadline_ns, stop)?.map(|(p, _)| p))
    }

    /// [`Link::receive_until`], with the id of the publisher that sent the packet.
    pub fn receive_until_from(
        &self,
        deadline_ns: u64,
        stop: &AtomicBool,
    ) -> Result<Option<(Rx, u128)>, LinkError> {
        let started_ns = monotonic_ns();
        let yield_after_ns = started_ns.saturating_add(WaitStrategy::BUSY_YIELD_AFTER_NS);
        let spin_until_ns = match self.wait {
            WaitStrategy::BusyPoll => deadline_ns,
            WaitStrategy::Event => 0,
            WaitStrategy::Hybrid { spin_ns } => {
                monotonic_ns().saturating_add(spin_ns).min(deadline_ns)
            }
        };
        loop {
            if let Some(p) = self.try_receive_from()? {
                return Ok(Some(p));
            }
            let now = monotonic_ns();
            if let Some(pid) = self.watched_peer_exited(now) {
                // A last look: it may have sent its packet just before it exited.
                if let Some(p) = self.try_receive_from()? {
                    return Ok(Some(p));
                }
                return Err(LinkError::PeerGone { pid });
            }
            if now >= deadline_ns {
                return Ok(None);
            }
            if stop.load(Ordering::Relaxed) {
                return Err(LinkError::Interrupted);
            }
            if now < spin_until_ns {
                if self.wait == WaitStrategy::BusyPoll && now > yield_after_ns {
                    std::thread::yield_now();
                } else {
                    core::hint::spin_loop();
                }
                continue;
            }
            // Sleep on the peer's event, in slices of at most 1 ms so a peer that does not
            // notify (a busy-polling emulator, or foreign code) is still seen promptly.
            let slice_ns = (deadline_ns - now).min(1_000_000);
            self.sleeps.fetch_add(1, Ordering::Relaxed);
            self.listener
                .timed_wait(
                    |_| {
                        self.wake_notifications.fetch_add(1, Ordering::Relaxed);
                    },
                    Duration::from_nanos(slice_ns),
                )
                .map_err(ice("event wait"))?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wait_strategy_names_round_trip() {
        for w in ["busy", "event", "hybrid"] {
            assert_eq!(w.parse::<WaitStrategy>().unwrap().as_str(), w);
        }
        assert!("spin".parse::<WaitStrategy>().is_err());
        assert!(!WaitStrategy::BusyPoll.notifies());
        assert!(WaitStrategy::Event.notifies());
    }

    #[test]
    fn frames_attribute_round_trips_and_refuses_junk() {
        let specs = [
            FrameSpec {
                device: crate::FRAME_DEVICE_TEST_CARD,
                max_bytes: 2 << 20,
            },
            FrameSpec {
                device: crate::FRAME_DEVICE_LIDAR,
                max_bytes: 65536,
            },
        ];
        let text = frames_attribute(&specs);
        assert_eq!(text, "3:2097152,2:65536");
        assert_eq!(parse_frames_attribute(&text).unwrap(), specs);
        assert!(parse_frames_attribute("").unwrap().is_empty());
        assert!(parse_frames_attribute("3").is_err());
        assert!(parse_frames_attribute("x:1").is_err());
    }
}
