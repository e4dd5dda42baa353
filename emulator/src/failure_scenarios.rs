//! The named failure scenarios (issue #34): each one a way real descents have been lost,
//! flown by the reference GNC on its own navigation (`telemetry = "sensors"`,
//! `gnc.navigation = "sensors"`, plant step 5 ms) with the faults that make it. `oils
//! run --scenario NAME` applies one over the default scenario; `docs/gnc.md` says what
//! each shows, and `emulator/tests/failure_scenarios.rs` asserts each outcome.

use crate::faults::FaultSpec;
use crate::run_config::{RunConfig, RunConfigError, TelemetrySource};
use oils_shared::fsw::GncNavigation;

/// One named failure scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailureScenario {
    /// Its name (`--scenario NAME`).
    pub name: &'static str,
    /// What happens, in one sentence.
    pub summary: &'static str,
    /// The faults, in the `--fault` grammar.
    pub faults: &'static [&'static str],
    /// Flown over the pinpoint scenario with terrain navigation on this map (made by
    /// `oils run` when the file is missing), instead of the default scenario.
    pub terrain: Option<TerrainRecipe>,
}

/// The onboard map a terrain-navigation failure scenario flies with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainRecipe {
    /// The map file (`gnc.map`), relative to the directory the run starts in.
    pub map_file: &'static str,
    /// `oils map --shift-feature E,N,R,DE,DN`: a wrong map.
    pub shift_feature: Option<[f64; 5]>,
}

/// Every failure scenario.
pub const FAILURE_SCENARIOS: &[FailureScenario] = &[
    FailureScenario {
        name: "rim-jump",
        summary: "crossing a crater rim at 3 km, the laser altimeter's range drops by 250 m for 10 s (the rim's wall under the beam), then returns",
        faults: &["sensor-bias:laser-altimeter,value=-250@alt=3000,for=10"],
        terrain: None,
    },
    FailureScenario {
        name: "imu-reset",
        summary: "a gyro glitch (0.05 rad in one increment) just above 14 km, then the onboard computer resets for 2 s at 14 km: the flight software's state is lost and it restarts from the ground's state vector and the sensors",
        faults: &[
            "sensor-spike:imu-gyro,value=0.05@alt=14050",
            "computer-reset@alt=14000,for=2",
        ],
        terrain: None,
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
        terrain: None,
    },
    FailureScenario {
        name: "altimeter-inhibited",
        summary: "the laser altimeter never reports valid data (inhibited from t = 0): the flight software navigates on the RF altimeter, velocimeter and star tracker, and declares the laser lost",
        faults: &["sensor-inhibit:laser-altimeter@t=0"],
        terrain: None,
    },
    FailureScenario {
        name: "camera-blinded",
        summary: "the pinpoint descent on terrain navigation; from 1.5 km the sun's glare saturates the camera (as a low sun ahead of the boresight would): no fix is taken from a blinded frame, the flight software declares terrain navigation lost after 10 s and lands on its inertial and altimeter estimate",
        faults: &["sensor-blinding:camera,level=4@alt=1500"],
        terrain: Some(TerrainRecipe {
            map_file: "oils-out/pinpoint.oilsmap",
            shift_feature: None,
        }),
    },
    FailureScenario {
        name: "false-fix",
        summary: "the pinpoint descent on terrain navigation with a wrong map: within 200 m of the site the map shows the ground 30 m east of where it is (a mis-registered map tile); the fixes over it disagree with the filter and are rejected by its gate, not flown",
        faults: &[],
        terrain: Some(TerrainRecipe {
            map_file: "oils-out/pinpoint-false-fix.oilsmap",
            shift_feature: Some([0.0, 0.0, 200.0, 30.0, 0.0]),
        }),
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
        if let Some(t) = &self.terrain {
            // The pinpoint scenario, its camera binned to 256 x 256 (the map made for
            // its 1024 x 1024 camera serves both; a frame costs a sixteenth).
            let noise = cfg.scenario.nav_noise.enabled;
            cfg.scenario = crate::run_config::load_scenario("pinpoint")?;
            cfg.scenario.nav_noise.enabled = noise;
            cfg.scenario.sensors.camera.width_px = 256;
            cfg.scenario.sensors.camera.height_px = 256;
            cfg.gnc.map = Some(t.map_file.into());
        }
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
