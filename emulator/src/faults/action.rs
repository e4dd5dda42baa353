//! What a fault does, compiled from its spec before tick 0: an enum carrying its numbers,
//! and for a sensor fault the telemetry field resolved once ([`TlmField`]), so nothing on
//! the step path looks a parameter or a field up by name.

use super::spec::{FaultKind, FaultSpec};
use super::PlantFault;
use crate::propulsion::PropulsionFault;
use crate::sensors::frame_faults::FrameFault;
use crate::sensors::{DeviceFault, SensorTarget};
use oils_shared::Telemetry;

/// A telemetry field a sensor fault acts on, resolved from its name before tick 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TlmField {
    /// `altitude_m`.
    Altitude,
    /// `position_m` (3 values).
    Position,
    /// `velocity_m_s` (3 values).
    Velocity,
    /// `attitude` (4 values).
    Attitude,
    /// `rate_rad_s` (3 values).
    Rate,
    /// `accel_m_s2` (3 values).
    Accel,
    /// `mass_kg`.
    Mass,
    /// `gas_pressure_pa`.
    GasPressure,
    /// `fuel_tank_pressure_pa`.
    FuelTankPressure,
    /// `ox_tank_pressure_pa`.
    OxTankPressure,
    /// `thrust1_n` .. `thrust4_n` (0-based engine).
    Thrust(usize),
    /// `chamber_pressure1_pa` .. `chamber_pressure4_pa` (0-based engine).
    ChamberPressure(usize),
}

impl TlmField {
    /// The field of a name in [`super::spec::SENSOR_FIELDS`].
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "altitude_m" => TlmField::Altitude,
            "position_m" => TlmField::Position,
            "velocity_m_s" => TlmField::Velocity,
            "attitude" => TlmField::Attitude,
            "rate_rad_s" => TlmField::Rate,
            "accel_m_s2" => TlmField::Accel,
            "mass_kg" => TlmField::Mass,
            "gas_pressure_pa" => TlmField::GasPressure,
            "fuel_tank_pressure_pa" => TlmField::FuelTankPressure,
            "ox_tank_pressure_pa" => TlmField::OxTankPressure,
            _ => {
                let engine = |prefix: &str, suffix: &str| {
                    name.strip_prefix(prefix)
                        .and_then(|r| r.strip_suffix(suffix))
                        .and_then(|n| n.parse::<usize>().ok())
                        .filter(|n| (1..=4).contains(n))
                        .map(|n| n - 1)
                };
                if let Some(e) = engine("thrust", "_n") {
                    TlmField::Thrust(e)
                } else if let Some(e) = engine("chamber_pressure", "_pa") {
                    TlmField::ChamberPressure(e)
                } else {
                    return None;
                }
            }
        })
    }

    /// The field's values in `tlm`.
    pub fn values_mut(self, tlm: &mut Telemetry) -> &mut [f64] {
        let p = &mut tlm.propulsion;
        match self {
            TlmField::Altitude => std::slice::from_mut(&mut tlm.altitude_m),
            TlmField::Position => &mut tlm.nav.pos_mci_m,
            TlmField::Velocity => &mut tlm.nav.vel_mci_m_s,
            TlmField::Attitude => &mut tlm.nav.q_mci_from_body,
            TlmField::Rate => &mut tlm.nav.rate_body_rad_s,
            TlmField::Accel => &mut tlm.accel_body_m_s2,
            TlmField::Mass => std::slice::from_mut(&mut tlm.mass_estimate_kg),
            TlmField::GasPressure => std::slice::from_mut(&mut p.gas_pressure_pa),
            TlmField::FuelTankPressure => std::slice::from_mut(&mut p.fuel_tank_pressure_pa),
            TlmField::OxTankPressure => std::slice::from_mut(&mut p.ox_tank_pressure_pa),
            TlmField::Thrust(e) => std::slice::from_mut(&mut p.engines[e].thrust_n),
            TlmField::ChamberPressure(e) => {
                std::slice::from_mut(&mut p.engines[e].chamber_pressure_pa)
            }
        }
    }
}

/// What a sensor fault does to its field of the telemetry the flight software sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SensorAction {
    /// A constant added.
    Bias {
        /// Added to each value.
        value: f64,
    },
    /// Gaussian noise added.
    Noise {
        /// Standard deviation.
        sigma: f64,
    },
    /// The last value before the fault repeats.
    Dropout,
    /// The value of the step it fired sticks.
    Frozen,
}

/// What a link fault does between the wire and the sanitiser.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkAction {
    /// Commands lost.
    CommandDrop,
    /// Commands arrive this many steps late.
    CommandDelay {
        /// Steps of delay.
        steps: usize,
    },
    /// Each command also arrives stale a step later.
    CommandDuplicate,
    /// Bits of each command's payload flipped.
    CommandCorrupt {
        /// Bits flipped per command.
        bits: u32,
    },
    /// Telemetry withheld from the flight software.
    TelemetryDrop,
    /// The flight software paused: telemetry withheld.
    StubPause,
    /// The onboard computer resetting: telemetry flagged, commands ignored.
    ComputerReset,
}

/// A fault's effect, typed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FaultAction {
    /// On the plant (propulsion model or engine command).
    Plant(PlantFault),
    /// On one telemetry field.
    Sensor(SensorAction, TlmField),
    /// On the link.
    Link(LinkAction),
    /// Inside a device of the sensor suite ([`crate::sensors::SensorSuite::set_fault`]).
    Device(SensorTarget, DeviceFault),
    /// Inside an imaging device (`FRAME_DEVICE_*`, [`crate::sensors::FrameRack::set_fault`]).
    Frame(u32, FrameFault),
}

impl FaultAction {
    /// Compiles a validated spec. `None` only for a spec [`FaultSpec::validate`] refuses
    /// (a missing parameter or an unknown field).
    pub fn of(spec: &FaultSpec) -> Option<Self> {
        let p = |key: &str| spec.params.get(key).copied();
        let e = spec.engine();
        let field = || spec.target.as_deref().and_then(TlmField::from_name);
        if let Some(device) = spec.frame_target() {
            let fault = match spec.kind {
                FaultKind::SensorDropout => FrameFault::Dropout,
                FaultKind::SensorFrozen => FrameFault::Frozen,
                FaultKind::SensorInhibit => FrameFault::Inhibited,
                FaultKind::SensorBlinding => FrameFault::Blinding { level: p("level")? },
                FaultKind::SensorDeadQuadrant => FrameFault::DeadQuadrant {
                    quadrant: p("quadrant")? as u8,
                },
                _ => return None,
            };
            if spec.validate().is_err() {
                return None;
            }
            return Some(FaultAction::Frame(device, fault));
        }
        if let Some(device) = spec.device_target() {
            let fault = match spec.kind {
                FaultKind::SensorBias => DeviceFault::Bias { value: p("value")? },
                FaultKind::SensorNoise => DeviceFault::Noise {
                    factor: p("factor")?,
                },
                FaultKind::SensorDropout => DeviceFault::Dropout,
                FaultKind::SensorFrozen => DeviceFault::Frozen,
                FaultKind::SensorSpike => DeviceFault::Spike { value: p("value")? },
                FaultKind::SensorInhibit => DeviceFault::Inhibited,
                _ => return None,
            };
            if spec.validate().is_err() {
                return None;
            }
            return Some(FaultAction::Device(device, fault));
        }
        Some(match spec.kind {
            FaultKind::EngineOff => FaultAction::Plant(PlantFault::EngineOff(e)),
            FaultKind::EngineStuck => FaultAction::Plant(PlantFault::EngineStuck(e)),
            FaultKind::ThrustDegraded => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::ThrustDegraded {
                    engine: e,
                    factor: p("factor")?,
                }))
            }
            FaultKind::ThrustScaled => FaultAction::Plant(PlantFault::ThrustScaled {
                engine: e,
                factor: p("factor")?,
            }),
            FaultKind::ValveStuck => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::ValveStuck {
                    engine: e,
                }))
            }
            FaultKind::ValveSlow => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::ValveSlow {
                    engine: e,
                    factor: p("factor")?,
                }))
            }
            FaultKind::RegulatorOpen => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::RegulatorOpen))
            }
            FaultKind::RegulatorClosed => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::RegulatorClosed))
            }
            FaultKind::RegulatorDrift => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::RegulatorDrift {
                    rate_pa_s: p("rate_pa_s")?,
                }))
            }
            FaultKind::PressurantLeak => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::PressurantLeak {
                    area_m2: p("area_mm2")? * 1e-6,
                }))
            }
            FaultKind::PropellantLeak => {
                FaultAction::Plant(PlantFault::Propulsion(PropulsionFault::PropellantLeak {
                    side: usize::from(spec.target.as_deref() == Some("ox")),
                    kg_s: p("kg_s")?,
                }))
            }
            FaultKind::SensorBias => {
                FaultAction::Sensor(SensorAction::Bias { value: p("value")? }, field()?)
            }
            FaultKind::SensorNoise => {
                FaultAction::Sensor(SensorAction::Noise { sigma: p("sigma")? }, field()?)
            }
            FaultKind::SensorDropout => FaultAction::Sensor(SensorAction::Dropout, field()?),
            FaultKind::SensorFrozen => FaultAction::Sensor(SensorAction::Frozen, field()?),
            // Device-only kinds (handled above).
            FaultKind::SensorSpike
            | FaultKind::SensorInhibit
            | FaultKind::SensorBlinding
            | FaultKind::SensorDeadQuadrant => return None,
            FaultKind::CommandDrop => FaultAction::Link(LinkAction::CommandDrop),
            FaultKind::CommandDelay => FaultAction::Link(LinkAction::CommandDelay {
                steps: p("steps")? as usize,
            }),
            FaultKind::CommandDuplicate => FaultAction::Link(LinkAction::CommandDuplicate),
            FaultKind::CommandCorrupt => FaultAction::Link(LinkAction::CommandCorrupt {
                bits: p("bits")? as u32,
            }),
            FaultKind::TelemetryDrop => FaultAction::Link(LinkAction::TelemetryDrop),
            FaultKind::StubPause => FaultAction::Link(LinkAction::StubPause),
            FaultKind::ComputerReset => FaultAction::Link(LinkAction::ComputerReset),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::faults::spec::SENSOR_FIELDS;

    #[test]
    fn every_sensor_field_name_resolves_to_a_field_of_its_width() {
        for name in SENSOR_FIELDS {
            let f = TlmField::from_name(name).unwrap_or_else(|| panic!("{name}"));
            let width = f.values_mut(&mut Telemetry::default()).len();
            let expected = match *name {
                "position_m" | "velocity_m_s" | "rate_rad_s" | "accel_m_s2" => 3,
                "attitude" => 4,
                _ => 1,
            };
            assert_eq!(width, expected, "{name}");
        }
        assert_eq!(TlmField::from_name("thrust5_n"), None);
        assert_eq!(TlmField::from_name("warp"), None);
    }
}
