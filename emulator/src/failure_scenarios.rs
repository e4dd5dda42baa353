//! The named failure scenarios (issue #34): each one a way real descents have been lost,
//! flown by the reference GNC on its own navigation (`telemetry = "sensors"`,
//! `gnc.navigation = "sensors"`, plant step 5 ms) with the faults that make it. `oils
//! run --scenario NAME` applies one over the default scenario; `docs/gnc.md` says what
//! each shows, and `emulator/tests/failure_scenarios.rs` asserts each outcome.

use crate::faults::FaultSpec;
use crate::run_config::{RunConfig, RunConfigError, TelemetrySource};
use oils_shared::fsw::GncNavigation;

/// One named failure scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FailureScenario {
    /// Its name (`--scenario NAME`).
    pub name: &'static str,
    /// What happens, in one sentence.
    pub summary: &'static str,
    /// The faults, in the `--fault` grammar.
    pub faults: &'static [&'static str],
}

/// Every failure scenario.
pub const FAILURE_SCENARIOS: &[FailureScenario] = &[
    FailureScenario {
        name: "rim-jump",
        summary: "crossing a crater rim at 3 km, the laser altimeter's range drops by 250 m for 10 s (the rim's wall under the beam), then returns",
        faults: &["sensor-bias:laser-altimeter,value=-250@alt=3000,for=10"],
    },
    FailureScenario {
        name: "imu-reset",
        summary: "a gyro glitch (0.05 rad in one increment) just above 14 km, then the onboard computer resets for 2 s at 14 km: the flight software's state is lost and it restarts from the ground's state vector and the sensors",
        faults: &[
            "sensor-spike:imu-gyro,value=0.05@alt=14050",
            "computer-reset@alt=14000,for=2",
        ],
    },
    FailureScenario {
        name: "hot-engines",
        summary: "from fine braking on (7.4 km), all four engines deliver 10 % more thrust than commanded",
        faults: &[
            "thrust-scaled:1,factor=1.1@alt=7400",
            "thrust-scaled:2,factor=1.1@alt=7400",
            "thrust-scaled:3,factor=1.1@alt=7400",
            "thrust-scaled:4,factor=1.1@alt=7400",
        ],
    },
    FailureScenario {
        name: "altimeter-inhibited",
        summary: "the laser altimeter never reports valid data (inhibited from t = 0): the flight software navigates on the RF altimeter, velocimeter and star tracker, and declares the laser lost",
        faults: &["sensor-inhibit:laser-altimeter@t=0"],
    },
];

/// The failure scenario called `name`, if there is one.
pub fn failure_scenario(name: &str) -> Option<&'static FailureScenario> {
    FAILURE_SCENARIOS.iter().find(|s| s.name == name)
}

impl FailureScenario {
    /// Sets `cfg` up to fly it: devices on and the ideal navigation off, the reference
    /// GNC on its sensor navigation, the plant at 5 ms if it was at the default 10 ms,
    /// and the scenario's faults added after any already there.
    pub fn apply(&self, cfg: &mut RunConfig) -> Result<(), RunConfigError> {
        cfg.telemetry = TelemetrySource::Sensors;
        cfg.gnc.navigation = GncNavigation::Sensors;
        if cfg.dt_ms == 10 {
            cfg.dt_ms = 5;
        }
        for f in self.faults {
            let spec: FaultSpec = f.parse().map_err(|e: String| RunConfigError::Invalid {
                field: "faults",
                value: (*f).to_string(),
                why: e,
            })?;
            cfg.faults.push(spec);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_scenario_makes_a_valid_configuration() {
        for s in FAILURE_SCENARIOS {
            let mut cfg = RunConfig::default();
            s.apply(&mut cfg).unwrap();
            cfg.validate().unwrap_or_else(|e| panic!("{}: {e}", s.name));
            assert_eq!(cfg.faults.len(), s.faults.len());
        }
        assert!(failure_scenario("rim-jump").is_some());
        assert!(failure_scenario("default").is_none());
    }
}
