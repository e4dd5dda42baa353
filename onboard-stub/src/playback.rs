//! Open-loop playback of a thrust-command profile: the flight software for propulsion
//! tests, surrogate validation and excitation runs.

use crate::fsw::FlightSoftware;
use oils_shared::profile::ThrustProfile;
use oils_shared::{Command, Telemetry};

/// Commands the profile row in force at the telemetry time (held between rows; all
/// engines off before the first row; never any attitude-thruster torque).
#[derive(Debug, Clone)]
pub struct ProfilePlayback {
    profile: ThrustProfile,
}

impl ProfilePlayback {
    /// Plays `profile`.
    pub fn new(profile: ThrustProfile) -> Self {
        Self { profile }
    }

    /// The profile being played.
    pub fn profile(&self) -> &ThrustProfile {
        &self.profile
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
            for (on, &row_on) in cmd.engine_on.iter_mut().zip(row.on.iter()) {
                *on = u32::from(row_on);
            }
        }
        cmd
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_shared::PacketHeader;

    fn at(p: &mut ProfilePlayback, t_ns: i64) -> Command {
        let tlm = Telemetry {
            header: PacketHeader::new(1, 0, t_ns),
            ..Default::default()
        };
        p.step(&tlm)
    }

    #[test]
    fn holds_rows_and_is_off_before_the_first() {
        let text = "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n1,800,700,600,500,1,1,1,0\n2,320,320,320,320,0,1,0,1\n";
        let mut p = ProfilePlayback::new(ThrustProfile::parse(text).unwrap());
        let before = at(&mut p, 999_999_999);
        assert_eq!(before.engine_on, [0; 4]);
        assert_eq!(before.thrust_cmd_n, [0.0; 4]);
        let first = at(&mut p, 1_000_000_000);
        assert_eq!(first.thrust_cmd_n, [800.0, 700.0, 600.0, 500.0]);
        assert_eq!(first.engine_on, [1, 1, 1, 0]);
        assert_eq!(at(&mut p, 1_999_999_999), first);
        let second = at(&mut p, 50_000_000_000);
        assert_eq!(second.engine_on, [0, 1, 0, 1]);
        assert_eq!(second.torque_cmd_body_nm, [0.0; 3]);
    }
}
