//! TEMPORARY placeholder until the reference GNC branch merges.

use crate::fsw::FlightSoftware;
use oils_shared::{Command, Telemetry};

/// Placeholder.
#[derive(Default)]
pub struct ReferenceGnc;

impl FlightSoftware for ReferenceGnc {
    fn name(&self) -> &'static str {
        "gnc"
    }
    fn step(&mut self, _tlm: &Telemetry) -> Command {
        Command::default()
    }
}
