//! Open-loop playback of a thrust-command profile.

use crate::fsw::FlightSoftware;
use oils_shared::profile::ThrustProfile;
use oils_shared::{Command, Telemetry};

/// Commands the profile row in force at the telemetry's time (all off before the first).
pub struct ProfilePlayback {
    profile: ThrustProfile,
}

impl ProfilePlayback {
    /// Plays `profile`.
    pub fn new(profile: ThrustProfile) -> Self {
        Self { profile }
    }
}

impl FlightSoftware for ProfilePlayback {
    fn name(&self) -> &'static str {
        "playback"
    }

    fn step(&mut self, tlm: &Telemetry) -> Command {
        let mut cmd = Command::default();
        if let Some(row) = self.profile.at(tlm.header.t_ns) {
            cmd.thrust_cmd_n = row.thrust_cmd_n;
            cmd.engine_on = row.on.map(u32::from);
        }
        cmd
    }
}
