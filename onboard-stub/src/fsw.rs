//! The seam between the bench and flight software.

use oils_shared::{Command, Telemetry};

/// Flight software the stub can run: one call per step.
///
/// Contract: `step` does not allocate, lock, log or read the wall clock (time is
/// `tlm.header.t_ns`). It fills `thrust_cmd_n`, `engine_on` and `torque_cmd_body_nm`;
/// the stub's loop stamps the header and the measured compute time.
pub trait FlightSoftware: Send {
    /// Short name for reports.
    fn name(&self) -> &'static str;
    /// Computes Command(k) from Telemetry(k).
    fn step(&mut self, tlm: &Telemetry) -> Command;
}
