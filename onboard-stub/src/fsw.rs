//! The flight-software interface: one telemetry packet in, one command out.

use oils_shared::{Command, Telemetry};

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
}
