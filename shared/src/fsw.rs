//! The flight-software interface (one telemetry packet in, one command out) and the
//! plain value that names which flight software flies a run.
//!
//! It lives beside the packets, not in the stub, because both sides reach it: the
//! onboard stub serves a [`FlightSoftware`] over iceoryx2, and the emulator's run core
//! calls one in its own thread (the in-process link). Neither needs the other's code.

use crate::clock::monotonic_ns;
use crate::{
    Command, FrameAnnouncement, PacketHeader, Telemetry, FRAMES_MAX, TLM_FLAG_COMPUTER_RESET,
    TLM_FLAG_END_OF_RUN,
};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// Flight software the stub can run in the loop.
///
/// Contract: `step` is called once per bench step with Telemetry(k) and returns
/// Command(k). It fills `thrust_cmd_n`, `engine_on` (0/1) and `torque_cmd_body_nm`; the
/// IPC loop stamps the header and `stub_compute_ns`. `step` must not allocate, lock, log
/// or read the wall clock: simulated time is `tlm.header.t_ns`.
pub trait FlightSoftware {
    /// Short name for reports (`gnc`, `playback`, ...).
    fn name(&self) -> &'static str;
    /// Answers one telemetry packet.
    fn step(&mut self, tlm: &Telemetry) -> Command;
    /// Whether a step failed (flight software that can report a failure, like a C
    /// library's nonzero status). The loop checks it after every step and stops the run
    /// instead of sending that step's command.
    fn failure(&self) -> Option<FswFailure> {
        None
    }
    /// The onboard computer resets (telemetry flagged `TLM_FLAG_COMPUTER_RESET`): the
    /// flight software loses its state and starts again on the next unflagged telemetry.
    /// Called instead of `step` while the flag is up. Must not allocate. Default: nothing
    /// (flight software that keeps no state across steps).
    fn computer_reset(&mut self) {}
    /// Whether to time its own work on the wall clock (rate groups' compute times, cycle
    /// slips), for the report only. A campaign case turns it off (see
    /// [`answer_untimed`]): nothing it reports uses those figures, and the digest never
    /// covers them. Default: nothing (flight software that times nothing).
    fn set_compute_timing(&mut self, _on: bool) {}
    /// A frame the coming telemetry announces (protocol v4, `tlm.sensors.frames`), called
    /// before that telemetry's `step`, once per frame that arrived: `pixels` are the
    /// frame's bytes in place (in the iceoryx2 sample's shared memory, or the in-process
    /// link's buffer), valid during the call only; copy what you keep. Not called while the
    /// computer resets. Must not allocate. A frame that was lost is announced but never
    /// handed over (see [`announced_frames`]). Default: frames are ignored.
    fn frame(&mut self, _ann: &FrameAnnouncement, _pixels: &[u8]) {}
}

/// The frames `tlm` announces that a flight software is to be handed
/// ([`FlightSoftware::frame`]): none in an end-of-run telemetry or while the computer
/// resets (nothing runs on board).
pub fn announced_frames(tlm: &Telemetry) -> &[FrameAnnouncement] {
    if tlm.header.flags & (TLM_FLAG_END_OF_RUN | TLM_FLAG_COMPUTER_RESET) != 0 {
        return &[];
    }
    let n = (tlm.sensors.frame_count as usize).min(FRAMES_MAX);
    &tlm.sensors.frames[..n]
}

/// Runs the flight software on Telemetry(k) and returns Command(k) stamped as the wire
/// wants it: the header echoes the telemetry's run, step and time, and
/// `stub_compute_ns` holds the flight software's own step time (monotonic clock; the
/// digest ignores it). Every link uses this, so a command is the same whichever link
/// carries it.
pub fn answer<F: FlightSoftware + ?Sized>(fsw: &mut F, tlm: &Telemetry) -> Command {
    let started_ns = monotonic_ns();
    let mut cmd = answer_untimed(fsw, tlm);
    cmd.stub_compute_ns = monotonic_ns().saturating_sub(started_ns);
    cmd
}

/// [`answer`] without reading the clock: `stub_compute_ns` is 0. For campaign cases in
/// process, which report no compute time (two of the nine clock reads of a cycle, which
/// together were about 8 % of a case: `perf`, 2-core VM). The command is otherwise the
/// same.
pub fn answer_untimed<F: FlightSoftware + ?Sized>(fsw: &mut F, tlm: &Telemetry) -> Command {
    let mut cmd = if tlm.header.flags & TLM_FLAG_COMPUTER_RESET != 0 {
        // The computer is down: nothing runs, the emulator ignores what comes back.
        fsw.computer_reset();
        Command::default()
    } else {
        fsw.step(tlm)
    };
    cmd.header = PacketHeader::new(tlm.header.run_id, tlm.header.step, tlm.header.t_ns);
    cmd
}

/// How the reference GNC navigates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GncNavigation {
    /// From the bench's ideal navigation source (`nav`, with its noise): a complementary
    /// filter over it. Needs telemetry `nav` or `both`.
    #[default]
    Bench,
    /// From the device samples: the error-state Kalman filter, started from the ground's
    /// state vector. Needs telemetry `sensors` or `both`.
    Sensors,
}

/// How the reference GNC turns the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GncAttitude {
    /// The ideal body-torque actuator (the comparison case).
    #[default]
    Torque,
    /// The eight attitude thrusters, pulse-width modulated.
    Thrusters,
}

macro_rules! text_enum {
    ($t:ty, $what:literal, $($v:path => $s:literal),+) => {
        impl $t {
            /// The name on the command line and in a run configuration.
            pub fn as_str(&self) -> &'static str {
                match self { $($v => $s),+ }
            }
        }
        impl FromStr for $t {
            type Err = String;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                match s {
                    $($s => Ok($v),)+
                    other => Err(format!(
                        concat!("unknown ", $what, " `{}` (expected ", $($s, " "),+, ")"),
                        other
                    )),
                }
            }
        }
        impl fmt::Display for $t {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}
text_enum!(GncNavigation, "GNC navigation", GncNavigation::Bench => "bench", GncNavigation::Sensors => "sensors");
text_enum!(GncAttitude, "GNC attitude actuator", GncAttitude::Torque => "torque", GncAttitude::Thrusters => "thrusters");

/// The reference GNC's choices a run makes (the rest is the GNC's own configuration).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GncOptions {
    /// What it navigates from.
    pub navigation: GncNavigation,
    /// What turns the vehicle.
    pub attitude: GncAttitude,
    /// The terrain navigation data (onboard map and camera model, `oils map`) the
    /// reference GNC loads before the descent to navigate by the camera's frames (with
    /// `navigation = sensors`); none: no terrain-relative navigation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub map: Option<PathBuf>,
    /// Hazard detection and avoidance at the hover from the flash lidar's frames (with
    /// `navigation = sensors` and the lidar on board).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub hazard_avoidance: bool,
}

impl GncOptions {
    /// All at their defaults (`bench`, `torque`, no map): omitted from configurations.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

/// A step the flight software reported as failed (in a run report: `fsw_failure`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FswFailure {
    /// The step whose telemetry it was answering.
    pub step: u64,
    /// The status it returned (nonzero).
    pub status: i32,
}

impl fmt::Display for FswFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "flight software failed at step {} (status {})",
            self.step, self.status
        )
    }
}

impl std::error::Error for FswFailure {}

/// Which flight software flies a run, as written on the command line and in a run
/// configuration: `gnc`, `playback` (needs a profile), `c:PATH` (a shared library with
/// the C ABI of `oils.h`) or `external` (a client started by hand on the run's services).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum FswSpec {
    /// The reference descent GNC.
    #[default]
    Gnc,
    /// Open-loop playback of a thrust-command profile CSV.
    Playback,
    /// Flight code in a shared library with the C ABI of `oils.h`.
    CLibrary(PathBuf),
    /// A client of the run's services started outside the bench (C, Python, ...).
    External,
}

impl FswSpec {
    /// Short name for reports: `gnc`, `playback`, `c`, `external`.
    pub fn kind_name(&self) -> &'static str {
        match self {
            FswSpec::Gnc => "gnc",
            FswSpec::Playback => "playback",
            FswSpec::CLibrary(_) => "c",
            FswSpec::External => "external",
        }
    }
}

impl fmt::Display for FswSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FswSpec::CLibrary(p) => write!(f, "c:{}", p.display()),
            other => f.write_str(other.kind_name()),
        }
    }
}

impl FromStr for FswSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "gnc" => Ok(FswSpec::Gnc),
            "playback" => Ok(FswSpec::Playback),
            "external" => Ok(FswSpec::External),
            _ => match s.strip_prefix("c:") {
                Some(path) if !path.is_empty() => Ok(FswSpec::CLibrary(PathBuf::from(path))),
                _ => Err(format!(
                    "unknown flight software `{s}` (expected gnc, playback, c:PATH or external)"
                )),
            },
        }
    }
}

impl TryFrom<String> for FswSpec {
    type Error = String;
    fn try_from(s: String) -> Result<Self, Self::Error> {
        s.parse()
    }
}

impl From<FswSpec> for String {
    fn from(f: FswSpec) -> String {
        f.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_round_trips_through_its_text() {
        for s in ["gnc", "playback", "external", "c:/tmp/libfsw.so"] {
            assert_eq!(s.parse::<FswSpec>().unwrap().to_string(), s);
        }
        assert!("c:".parse::<FswSpec>().is_err());
        assert!("python".parse::<FswSpec>().is_err());
    }
}
