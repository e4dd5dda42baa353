//! Fault declarations: the plain value a run configuration (`[[faults]]`), the command
//! line (`--fault SPEC`) and a Monte Carlo campaign use, and its short text syntax.
//!
//! ```text
//! KIND[:TARGET][,PARAM=VALUE...]@TRIGGER[,for=SECONDS]
//! engine-off:2@t=400                  engine 2 fails off at t = 400 s
//! thrust-degraded:1,factor=0.7@alt=5000   engine 1 at 70 % once below 5 km
//! sensor-bias:altitude_m,value=50@t=500,for=30
//! command-drop@random,p=0.2,window=100..800,for=2
//! sensor-inhibit:laser-altimeter@t=0      a device (docs/sensors.md) rather than a field
//! sensor-spike:laser-altimeter,value=-300@alt=2000
//! sensor-dead-quadrant:lidar,quadrant=2@alt=1500   a frame device's quadrant reads 0
//! sensor-blinding:camera,level=2@t=900,for=5        the sun's glare across the image
//! thrust-scaled:3,factor=1.1@t=700       engine 3 delivers 10 % more than it should
//! computer-reset@alt=14000,for=2          the onboard computer down for 2 s below 14 km
//! ```
//! Engines are numbered 1-4, as in the CSV export. Triggers: `t=S` (simulated time),
//! `alt=M` (true altitude below M metres), `step=K`, or `random,p=P,window=A..B` (fires
//! with probability P at a time drawn uniformly in [A, B] s, from the run's seed and the
//! fault's position in the list only).

use crate::sensors::SensorTarget;
use oils_shared::{
    frame_device_name, FRAME_DEVICE_CAMERA, FRAME_DEVICE_LIDAR, FRAME_DEVICE_TEST_CARD,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

/// What fails.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultKind {
    /// Engine fails off (target: engine 1-4).
    EngineOff,
    /// Engine stuck at the throttle it had when the fault fired (target: engine).
    EngineStuck,
    /// Engine thrust degraded (target: engine; `factor` in [0, 1)).
    ThrustDegraded,
    /// Engine delivers `factor` times what it would (target: engine; `factor` in
    /// (0, 2]: above 1, an engine hotter than its calibration).
    ThrustScaled,
    /// Throttle valves of an engine stuck where they are (hifi; target: engine).
    ValveStuck,
    /// Throttle valves of an engine slowed (hifi; target: engine; `factor` in (0, 1)).
    ValveSlow,
    /// Pressure regulator failed wide open (hifi).
    RegulatorOpen,
    /// Pressure regulator failed shut (hifi).
    RegulatorClosed,
    /// Regulator set point drifting (hifi; `rate_pa_s`, either sign).
    RegulatorDrift,
    /// Helium leaking from the pressurant bottle (hifi; `area_mm2`, the leak's flow area).
    PressurantLeak,
    /// Propellant leaking from a tank (hifi; target `fuel` or `ox`; `kg_s`).
    PropellantLeak,
    /// A constant added to a telemetry field (target: field; `value`).
    SensorBias,
    /// Extra Gaussian noise on a telemetry field (target: field; `sigma`).
    SensorNoise,
    /// A telemetry field stops updating: the last value before the fault repeats.
    SensorDropout,
    /// A telemetry field frozen at its value when the fault fired.
    SensorFrozen,
    /// A device's first sample after the fault fires carries an outlier (target: a
    /// device; `value`).
    SensorSpike,
    /// A device inhibited: its samples arrive invalid, flagged (target: a device).
    SensorInhibit,
    /// Stray light over a camera's image, the sun in or near its view (target: a
    /// 16-bit frame device, `camera`; `level`, the glare's peak in full scales).
    SensorBlinding,
    /// One quadrant of a frame device reads zero (target: `lidar` or `camera`;
    /// `quadrant` 1-4: top left, top right, bottom left, bottom right).
    SensorDeadQuadrant,
    /// Commands lost on the link: the last applied command holds.
    CommandDrop,
    /// Commands arrive `steps` steps late.
    CommandDelay,
    /// Each command also arrives a second time, a step later (a stale duplicate).
    CommandDuplicate,
    /// `bits` random bits of each command's payload flipped (the sanitiser must catch
    /// what is unusable).
    CommandCorrupt,
    /// Telemetry lost: the flight software does not see the step and cannot answer it.
    TelemetryDrop,
    /// The flight software paused: it sees no telemetry for the fault's duration (in
    /// realtime each step is a deadline miss).
    StubPause,
    /// The onboard computer resets for the fault's duration: telemetry carries
    /// `TLM_FLAG_COMPUTER_RESET`, the flight software loses its state, commands are
    /// ignored (the main engines hold, no attitude torque); at the end the ground
    /// uplinks a fresh state vector.
    ComputerReset,
}

/// Every kind with its text name, parameters (name, meaning) and target meaning.
const KINDS: &[(FaultKind, &str, &[&str], Target)] = &[
    (FaultKind::EngineOff, "engine-off", &[], Target::Engine),
    (FaultKind::EngineStuck, "engine-stuck", &[], Target::Engine),
    (
        FaultKind::ThrustDegraded,
        "thrust-degraded",
        &["factor"],
        Target::Engine,
    ),
    (
        FaultKind::ThrustScaled,
        "thrust-scaled",
        &["factor"],
        Target::Engine,
    ),
    (FaultKind::ValveStuck, "valve-stuck", &[], Target::Engine),
    (
        FaultKind::ValveSlow,
        "valve-slow",
        &["factor"],
        Target::Engine,
    ),
    (
        FaultKind::RegulatorOpen,
        "regulator-open",
        &[],
        Target::None,
    ),
    (
        FaultKind::RegulatorClosed,
        "regulator-closed",
        &[],
        Target::None,
    ),
    (
        FaultKind::RegulatorDrift,
        "regulator-drift",
        &["rate_pa_s"],
        Target::None,
    ),
    (
        FaultKind::PressurantLeak,
        "pressurant-leak",
        &["area_mm2"],
        Target::None,
    ),
    (
        FaultKind::PropellantLeak,
        "propellant-leak",
        &["kg_s"],
        Target::Side,
    ),
    (
        FaultKind::SensorBias,
        "sensor-bias",
        &["value"],
        Target::Field,
    ),
    (
        FaultKind::SensorNoise,
        "sensor-noise",
        &["sigma"],
        Target::Field,
    ),
    (
        FaultKind::SensorDropout,
        "sensor-dropout",
        &[],
        Target::Field,
    ),
    (FaultKind::SensorFrozen, "sensor-frozen", &[], Target::Field),
    (
        FaultKind::SensorSpike,
        "sensor-spike",
        &["value"],
        Target::Field,
    ),
    (
        FaultKind::SensorInhibit,
        "sensor-inhibit",
        &[],
        Target::Field,
    ),
    (
        FaultKind::SensorBlinding,
        "sensor-blinding",
        &["level"],
        Target::Field,
    ),
    (
        FaultKind::SensorDeadQuadrant,
        "sensor-dead-quadrant",
        &["quadrant"],
        Target::Field,
    ),
    (FaultKind::CommandDrop, "command-drop", &[], Target::None),
    (
        FaultKind::CommandDelay,
        "command-delay",
        &["steps"],
        Target::None,
    ),
    (
        FaultKind::CommandDuplicate,
        "command-duplicate",
        &[],
        Target::None,
    ),
    (
        FaultKind::CommandCorrupt,
        "command-corrupt",
        &["bits"],
        Target::None,
    ),
    (
        FaultKind::TelemetryDrop,
        "telemetry-drop",
        &[],
        Target::None,
    ),
    (FaultKind::StubPause, "stub-pause", &[], Target::None),
    (
        FaultKind::ComputerReset,
        "computer-reset",
        &[],
        Target::None,
    ),
];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Target {
    None,
    Engine,
    Side,
    Field,
}

impl FaultKind {
    /// The kind's text name.
    pub fn name(self) -> &'static str {
        KINDS.iter().find(|k| k.0 == self).map_or("?", |k| k.1)
    }

    fn entry(self) -> &'static (FaultKind, &'static str, &'static [&'static str], Target) {
        KINDS
            .iter()
            .find(|k| k.0 == self)
            .expect("every kind is in KINDS")
    }

    /// Whether the kind acts on the propulsion model.
    pub fn is_propulsion(self) -> bool {
        matches!(
            self,
            FaultKind::EngineOff
                | FaultKind::EngineStuck
                | FaultKind::ThrustDegraded
                | FaultKind::ThrustScaled
                | FaultKind::ValveStuck
                | FaultKind::ValveSlow
                | FaultKind::RegulatorOpen
                | FaultKind::RegulatorClosed
                | FaultKind::RegulatorDrift
                | FaultKind::PressurantLeak
                | FaultKind::PropellantLeak
        )
    }
}

impl FromStr for FaultKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        KINDS.iter().find(|k| k.1 == s).map(|k| k.0).ok_or_else(|| {
            let names: Vec<&str> = KINDS.iter().map(|k| k.1).collect();
            format!("unknown fault kind `{s}` (one of {})", names.join(", "))
        })
    }
}

/// The frame devices a sensor fault can target (`FRAME_DEVICE_*` names).
pub const FRAME_TARGETS: &[&str] = &["camera", "lidar", "test-card"];

/// Largest magnitude of a sensor fault's `value` or `sigma`: ten times the largest
/// quantity in the telemetry (the helium bottle's 3.1e7 Pa).
pub const MAX_SENSOR_FAULT_VALUE: f64 = 3.1e8;

/// Telemetry fields a sensor fault can act on.
pub const SENSOR_FIELDS: &[&str] = &[
    "altitude_m",
    "position_m",
    "velocity_m_s",
    "attitude",
    "rate_rad_s",
    "accel_m_s2",
    "mass_kg",
    "gas_pressure_pa",
    "fuel_tank_pressure_pa",
    "ox_tank_pressure_pa",
    "thrust1_n",
    "thrust2_n",
    "thrust3_n",
    "thrust4_n",
    "chamber_pressure1_pa",
    "chamber_pressure2_pa",
    "chamber_pressure3_pa",
    "chamber_pressure4_pa",
];

/// The parameters a sensor kind takes on a device target (they differ from the
/// telemetry-field form: noise is a scale of the device's own noise, `factor`), or why
/// the pair makes no sense.
fn device_params(
    kind: FaultKind,
    target: SensorTarget,
) -> Result<&'static [&'static str], &'static str> {
    let two_halves = target == SensorTarget::Imu;
    match kind {
        FaultKind::SensorBias | FaultKind::SensorSpike if two_halves => {
            Err("the IMU's bias and spike act on one half: target imu-gyro (rad/s) or imu-accel (m/s^2)")
        }
        FaultKind::SensorBias | FaultKind::SensorSpike => Ok(&["value"]),
        FaultKind::SensorNoise => Ok(&["factor"]),
        _ => Ok(&[]),
    }
}

/// The parameters a sensor kind takes on a frame device (`FRAME_DEVICE_*`), or why the
/// pair makes no sense.
fn frame_device_params(kind: FaultKind, device: u32) -> Result<&'static [&'static str], String> {
    let name = frame_device_name(device).unwrap_or("frame device");
    match kind {
        FaultKind::SensorDropout | FaultKind::SensorFrozen | FaultKind::SensorInhibit => Ok(&[]),
        FaultKind::SensorDeadQuadrant => Ok(&["quadrant"]),
        FaultKind::SensorBlinding if device != FRAME_DEVICE_LIDAR => Ok(&["level"]),
        FaultKind::SensorBlinding => Err(format!(
            "sensor-blinding acts on an image's pixel values: target camera, not {name}"
        )),
        _ => Err(format!(
            "the {name} takes sensor-dropout, sensor-frozen, sensor-inhibit, sensor-blinding \
             (camera) or sensor-dead-quadrant"
        )),
    }
}

/// When a fault fires.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub enum Trigger {
    /// At a simulated time, seconds.
    Time(f64),
    /// When the true altitude first falls below this, metres.
    AltitudeBelow(f64),
    /// At a step.
    Step(u64),
    /// With a probability, at a time drawn uniformly in a window (seconds).
    Random {
        /// Probability that the fault happens at all.
        probability: f64,
        /// Earliest time, seconds.
        from_s: f64,
        /// Latest time, seconds.
        to_s: f64,
    },
}

impl fmt::Display for Trigger {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Trigger::Time(t) => write!(f, "t={t}"),
            Trigger::AltitudeBelow(a) => write!(f, "alt={a}"),
            Trigger::Step(k) => write!(f, "step={k}"),
            Trigger::Random {
                probability,
                from_s,
                to_s,
            } => write!(f, "random,p={probability},window={from_s}..{to_s}"),
        }
    }
}

fn number(key: &str, v: &str) -> Result<f64, String> {
    let x: f64 = v.parse().map_err(|_| format!("{key}={v}: not a number"))?;
    if !x.is_finite() {
        return Err(format!("{key}={v}: not finite"));
    }
    Ok(x)
}

impl FromStr for Trigger {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let mut parts = s.split(',');
        let first = parts.next().unwrap_or("");
        if first == "random" {
            let (mut p, mut window) = (None, None);
            for kv in parts {
                match kv.split_once('=') {
                    Some(("p", v)) => p = Some(number("p", v)?),
                    Some(("window", v)) => {
                        let (a, b) = v
                            .split_once("..")
                            .ok_or_else(|| format!("window={v}: expected A..B seconds"))?;
                        window = Some((number("window", a)?, number("window", b)?));
                    }
                    _ => return Err(format!("random trigger: unknown part `{kv}`")),
                }
            }
            let probability = p.ok_or("random trigger needs p=PROBABILITY")?;
            let (from_s, to_s) = window.ok_or("random trigger needs window=A..B")?;
            if !(0.0..=1.0).contains(&probability) {
                return Err(format!("p={probability}: expected a probability in [0, 1]"));
            }
            if !(from_s >= 0.0 && to_s >= from_s) {
                return Err(format!("window={from_s}..{to_s}: expected 0 <= A <= B"));
            }
            return Ok(Trigger::Random {
                probability,
                from_s,
                to_s,
            });
        }
        if parts.next().is_some() {
            return Err(format!(
                "trigger `{s}`: one of t=S, alt=M, step=K, random,..."
            ));
        }
        match first.split_once('=') {
            Some(("t", v)) => {
                let t = number("t", v)?;
                if t < 0.0 {
                    return Err(format!("t={v}: expected >= 0"));
                }
                Ok(Trigger::Time(t))
            }
            Some(("alt", v)) => Ok(Trigger::AltitudeBelow(number("alt", v)?)),
            Some(("step", v)) => v
                .parse()
                .map(Trigger::Step)
                .map_err(|_| format!("step={v}: expected a step number")),
            _ => Err(format!(
                "trigger `{s}`: expected t=SECONDS, alt=METRES, step=K or random,p=P,window=A..B"
            )),
        }
    }
}

impl TryFrom<String> for Trigger {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<Trigger> for String {
    fn from(t: Trigger) -> String {
        t.to_string()
    }
}

/// One declared fault. In TOML:
/// ```toml
/// [[faults]]
/// kind = "thrust-degraded"
/// target = "1"              # engine 1-4, `fuel`/`ox`, or a telemetry field
/// params = { factor = 0.7 }
/// trigger = "t=300"         # or "alt=5000", "step=100", "random,p=0.5,window=100..600"
/// duration_s = 20           # optional: cleared after this long
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FaultSpec {
    /// What fails.
    pub kind: FaultKind,
    /// What it fails on (engine 1-4, `fuel`/`ox`, or a telemetry field), if the kind
    /// takes one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// The kind's numbers.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, f64>,
    /// When it fires.
    pub trigger: Trigger,
    /// How long it lasts once fired, seconds; none: to the end of the run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
}

impl FaultSpec {
    /// Checks the kind's target and parameters (not yet against a propulsion model).
    pub fn validate(&self) -> Result<(), String> {
        let (_, name, mut params, target) = *self.kind.entry();
        let ctx = |m: String| format!("fault `{self}`: {m}");
        let device = self.device_target();
        let frame = self.frame_target();
        if let Some(d) = device {
            params = device_params(self.kind, d).map_err(|m| ctx(m.into()))?;
        } else if let Some(d) = frame {
            params = frame_device_params(self.kind, d).map_err(ctx)?;
        } else if matches!(self.kind, FaultKind::SensorSpike | FaultKind::SensorInhibit) {
            return Err(ctx(format!(
                "{name} acts on a device: target one of {}, {}",
                SensorTarget::NAMES.join(", "),
                FRAME_TARGETS.join(", ")
            )));
        } else if matches!(
            self.kind,
            FaultKind::SensorBlinding | FaultKind::SensorDeadQuadrant
        ) {
            return Err(ctx(format!(
                "{name} acts on a frame device: target one of {}",
                FRAME_TARGETS.join(", ")
            )));
        }
        match (target, &self.target) {
            (Target::None, Some(t)) => {
                return Err(ctx(format!("{name} takes no target, got `{t}`")))
            }
            (Target::None, None) => {}
            (_, None) => return Err(ctx(format!("{name} needs a target"))),
            (Target::Engine, Some(t)) => {
                if !matches!(t.as_str(), "1" | "2" | "3" | "4") {
                    return Err(ctx(format!("engine `{t}`: expected 1, 2, 3 or 4")));
                }
            }
            (Target::Side, Some(t)) => {
                if !matches!(t.as_str(), "fuel" | "ox") {
                    return Err(ctx(format!("tank `{t}`: expected fuel or ox")));
                }
            }
            (Target::Field, Some(t)) => {
                if device.is_none() && frame.is_none() && !SENSOR_FIELDS.contains(&t.as_str()) {
                    return Err(ctx(format!(
                        "target `{t}`: a device ({}, {}) or a telemetry field ({})",
                        SensorTarget::NAMES.join(", "),
                        FRAME_TARGETS.join(", "),
                        SENSOR_FIELDS.join(", ")
                    )));
                }
            }
        }
        for key in self.params.keys() {
            if !params.contains(&key.as_str()) {
                return Err(ctx(format!(
                    "unknown parameter `{key}` (takes: {})",
                    if params.is_empty() {
                        "none".to_string()
                    } else {
                        params.join(", ")
                    }
                )));
            }
        }
        for key in params {
            let v = *self
                .params
                .get(*key)
                .ok_or_else(|| ctx(format!("needs {key}=VALUE")))?;
            let ok = v.is_finite()
                && match *key {
                    "factor" if self.kind == FaultKind::ThrustDegraded => (0.0..1.0).contains(&v),
                    "factor" if self.kind == FaultKind::ThrustScaled => v > 0.0 && v <= 2.0,
                    "factor" if self.kind == FaultKind::SensorNoise => v > 0.0 && v <= 1e6,
                    "factor" => v > 0.0 && v < 1.0,
                    "area_mm2" => v > 0.0 && v <= 100.0,
                    "kg_s" => v > 0.0 && v <= 10.0,
                    "rate_pa_s" => v.abs() <= 1e6,
                    // A bias, spike or noise beyond any quantity the bench measures
                    // (the bottle's 3.1e7 Pa, positions 1.7e6 m from the Moon's
                    // centre) is no sensor's failure; the bound also keeps sums of
                    // several faults finite.
                    "value" => v.abs() <= MAX_SENSOR_FAULT_VALUE,
                    "sigma" => (0.0..=MAX_SENSOR_FAULT_VALUE).contains(&v),
                    "steps" => (1.0..=1000.0).contains(&v) && v.fract() == 0.0,
                    "bits" => (1.0..=64.0).contains(&v) && v.fract() == 0.0,
                    // A glare a thousand times the full scale saturates the whole image.
                    "level" => v > 0.0 && v <= 1000.0,
                    "quadrant" => (1.0..=4.0).contains(&v) && v.fract() == 0.0,
                    _ => true,
                };
            if !ok {
                return Err(ctx(format!("{key} = {v} is out of its range")));
            }
        }
        if let Some(d) = self.duration_s {
            if !(d.is_finite() && d > 0.0) {
                return Err(ctx(format!("for={d}: expected a positive duration")));
            }
        }
        if self.kind == FaultKind::StubPause && self.duration_s.is_none() {
            return Err(ctx("stub-pause needs for=SECONDS".into()));
        }
        if self.kind == FaultKind::ComputerReset && self.duration_s.is_none() {
            return Err(ctx(
                "computer-reset needs for=SECONDS (how long the computer is down)".into(),
            ));
        }
        Ok(())
    }

    /// Refuses a trigger that can never fire in a run of `duration_s` simulated seconds
    /// with steps of `dt_ns`: a time or step at or beyond the end, a random window that
    /// opens at or after it, or an altitude at or below the ground (touchdown ends the
    /// run first). A fault that cannot fire is a mistake in the configuration, not a
    /// quiet no-op (issue #36).
    pub fn check_can_fire(&self, duration_s: f64, dt_ns: u64) -> Result<(), String> {
        let ctx = |m: String| format!("fault `{self}`: {m}");
        match self.trigger {
            Trigger::Time(t) if t >= duration_s => Err(ctx(format!(
                "trigger t={t} s is at or beyond the run's duration of {duration_s} s: it can never fire"
            ))),
            Trigger::Step(k) if (k as f64) * (dt_ns as f64) * 1e-9 >= duration_s => {
                Err(ctx(format!(
                    "trigger step={k} is at or beyond the run's last step ({duration_s} s at {} ms): it can never fire",
                    dt_ns as f64 * 1e-6
                )))
            }
            Trigger::AltitudeBelow(a) if a <= 0.0 => Err(ctx(format!(
                "trigger alt={a} m: the true altitude never falls below {a} m (touchdown ends the run at 0 m): it can never fire"
            ))),
            Trigger::Random { from_s, .. } if from_s >= duration_s => Err(ctx(format!(
                "trigger window opens at {from_s} s, at or beyond the run's duration of {duration_s} s: it can never fire"
            ))),
            _ => Ok(()),
        }
    }

    /// The frame device (`FRAME_DEVICE_*`) a sensor fault targets (`camera`, `lidar`,
    /// `test-card`), if it targets one.
    pub fn frame_target(&self) -> Option<u32> {
        let sensor_kind = matches!(
            self.kind,
            FaultKind::SensorBias
                | FaultKind::SensorNoise
                | FaultKind::SensorDropout
                | FaultKind::SensorFrozen
                | FaultKind::SensorSpike
                | FaultKind::SensorInhibit
                | FaultKind::SensorBlinding
                | FaultKind::SensorDeadQuadrant
        );
        if !sensor_kind {
            return None;
        }
        match self.target.as_deref()? {
            "camera" => Some(FRAME_DEVICE_CAMERA),
            "lidar" => Some(FRAME_DEVICE_LIDAR),
            "test-card" => Some(FRAME_DEVICE_TEST_CARD),
            _ => None,
        }
    }

    /// The device a sensor fault targets, if its target names one (not a telemetry
    /// field).
    pub fn device_target(&self) -> Option<SensorTarget> {
        let sensor_kind = matches!(
            self.kind,
            FaultKind::SensorBias
                | FaultKind::SensorNoise
                | FaultKind::SensorDropout
                | FaultKind::SensorFrozen
                | FaultKind::SensorSpike
                | FaultKind::SensorInhibit
        );
        if !sensor_kind {
            return None;
        }
        self.target.as_deref().and_then(SensorTarget::from_name)
    }

    /// A parameter (present after `validate`).
    pub fn param(&self, key: &str) -> f64 {
        self.params.get(key).copied().unwrap_or(f64::NAN)
    }

    /// The target engine, 0-based (for engine faults, after `validate`).
    pub fn engine(&self) -> usize {
        self.target
            .as_deref()
            .and_then(|t| t.parse::<usize>().ok())
            .map_or(0, |e| e.saturating_sub(1))
    }
}

impl fmt::Display for FaultSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.kind.name())?;
        if let Some(t) = &self.target {
            write!(f, ":{t}")?;
        }
        for (k, v) in &self.params {
            write!(f, ",{k}={v}")?;
        }
        write!(f, "@{}", self.trigger)?;
        if let Some(d) = self.duration_s {
            write!(f, ",for={d}")?;
        }
        Ok(())
    }
}

impl FromStr for FaultSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (what, when) = s
            .split_once('@')
            .ok_or_else(|| format!("fault `{s}`: expected KIND[:TARGET][,P=V...]@TRIGGER"))?;
        let mut parts = what.split(',');
        let head = parts.next().unwrap_or("");
        let (kind, target) = match head.split_once(':') {
            Some((k, t)) => (k, Some(t.to_string())),
            None => (head, None),
        };
        let kind: FaultKind = kind.parse().map_err(|e| format!("fault `{s}`: {e}"))?;
        let mut params = BTreeMap::new();
        for kv in parts {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| format!("fault `{s}`: parameter `{kv}` is not NAME=VALUE"))?;
            let value = number(k, v).map_err(|e| format!("fault `{s}`: {e}"))?;
            if params.insert(k.to_string(), value).is_some() {
                return Err(format!(
                    "fault `{s}`: parameter `{k}` is given twice (give it once)"
                ));
            }
        }
        if when.matches(",for=").count() > 1 {
            return Err(format!(
                "fault `{s}`: parameter `for` is given twice (give it once)"
            ));
        }
        // `for=S` closes the trigger part.
        let (trigger_text, duration_s) = match when.rsplit_once(",for=") {
            Some((t, d)) => (
                t,
                Some(number("for", d).map_err(|e| format!("fault `{s}`: {e}"))?),
            ),
            None => (when, None),
        };
        let trigger = trigger_text
            .parse()
            .map_err(|e| format!("fault `{s}`: {e}"))?;
        let spec = FaultSpec {
            kind,
            target,
            params,
            trigger,
            duration_s,
        };
        spec.validate()?;
        Ok(spec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_short_syntax_round_trips() {
        for s in [
            "engine-off:2@t=400",
            "thrust-degraded:1,factor=0.7@alt=5000",
            "sensor-bias:altitude_m,value=50@t=500,for=30",
            "command-drop@random,p=0.2,window=100..800,for=2",
            "propellant-leak:ox,kg_s=0.05@step=100",
            "stub-pause@t=10,for=2",
        ] {
            let f: FaultSpec = s.parse().unwrap();
            assert_eq!(f.to_string(), s);
            let toml_text = toml::to_string(&f).unwrap();
            assert_eq!(toml::from_str::<FaultSpec>(&toml_text).unwrap(), f);
        }
        let f: FaultSpec = "engine-off:2@t=400".parse().unwrap();
        assert_eq!(f.kind, FaultKind::EngineOff);
        assert_eq!(f.engine(), 1);
        assert_eq!(f.trigger, Trigger::Time(400.0));
    }

    #[test]
    fn frame_device_faults_parse_compile_and_refuse_what_makes_no_sense() {
        use crate::faults::FaultAction;
        use crate::sensors::FrameFault;
        for (s, want) in [
            (
                "sensor-dead-quadrant:lidar,quadrant=2@alt=1500",
                FaultAction::Frame(FRAME_DEVICE_LIDAR, FrameFault::DeadQuadrant { quadrant: 2 }),
            ),
            (
                "sensor-blinding:camera,level=2@t=900,for=5",
                FaultAction::Frame(FRAME_DEVICE_CAMERA, FrameFault::Blinding { level: 2.0 }),
            ),
            (
                "sensor-frozen:camera@t=1",
                FaultAction::Frame(FRAME_DEVICE_CAMERA, FrameFault::Frozen),
            ),
            (
                "sensor-dropout:lidar@t=1,for=3",
                FaultAction::Frame(FRAME_DEVICE_LIDAR, FrameFault::Dropout),
            ),
            (
                "sensor-inhibit:test-card@t=1",
                FaultAction::Frame(FRAME_DEVICE_TEST_CARD, FrameFault::Inhibited),
            ),
        ] {
            let f: FaultSpec = s.parse().unwrap_or_else(|e| panic!("{s}: {e}"));
            assert_eq!(f.to_string(), s);
            assert_eq!(FaultAction::of(&f), Some(want), "{s}");
        }
        for (s, needle) in [
            ("sensor-bias:camera,value=3@t=1", "takes sensor-dropout"),
            ("sensor-spike:lidar,value=3@t=1", "takes sensor-dropout"),
            (
                "sensor-blinding:lidar,level=1@t=1",
                "target camera, not lidar",
            ),
            (
                "sensor-blinding:altitude_m,level=1@t=1",
                "acts on a frame device",
            ),
            (
                "sensor-dead-quadrant:imu,quadrant=1@t=1",
                "acts on a frame device",
            ),
            (
                "sensor-dead-quadrant:lidar,quadrant=5@t=1",
                "out of its range",
            ),
            (
                "sensor-dead-quadrant:lidar,quadrant=1.5@t=1",
                "out of its range",
            ),
            ("sensor-dead-quadrant:lidar@t=1", "needs quadrant"),
            ("sensor-blinding:camera,level=0@t=1", "out of its range"),
            ("sensor-frozen:camera,level=1@t=1", "unknown parameter"),
        ] {
            let e = s.parse::<FaultSpec>().unwrap_err();
            assert!(e.contains(needle), "{s}: {e}");
        }
    }

    #[test]
    fn impossible_specs_are_refused_with_a_reason() {
        for (s, needle) in [
            ("engine-off:5@t=1", "engine `5`"),
            ("engine-off@t=1", "needs a target"),
            ("warp-core-breach@t=1", "unknown fault kind"),
            ("thrust-degraded:1@t=1", "needs factor"),
            ("thrust-degraded:1,factor=2@t=1", "out of its range"),
            ("engine-off:1,factor=0.5@t=1", "unknown parameter"),
            ("sensor-bias:warp_factor,value=1@t=1", "telemetry field"),
            ("engine-off:1@t=-5", "expected >= 0"),
            ("engine-off:1@t=nan", "not finite"),
            ("engine-off:1@random,p=2,window=0..10", "probability"),
            ("engine-off:1", "expected KIND"),
            ("stub-pause@t=1", "for=SECONDS"),
            ("regulator-open:1@t=1", "takes no target"),
            (
                "stub-pause@t=1,for=1,for=2",
                "parameter `for` is given twice",
            ),
            (
                "thrust-degraded:1,factor=0.5,factor=0.6@t=1",
                "parameter `factor` is given twice",
            ),
        ] {
            let e = s.parse::<FaultSpec>().unwrap_err();
            assert!(e.contains(needle), "{s}: {e}");
        }
    }

    #[test]
    fn triggers_that_can_never_fire_are_refused_naming_the_fault_and_trigger() {
        let dt_ns = 10_000_000;
        for (s, needle) in [
            ("engine-off:1@t=1e9", "t=1000000000"),
            ("engine-off:1@t=800", "t=800"),
            ("engine-off:1@alt=-5", "alt=-5"),
            ("engine-off:1@alt=0", "alt=0"),
            ("engine-off:1@step=80000", "step=80000"),
            (
                "engine-off:1@random,p=1,window=900..950",
                "window opens at 900",
            ),
        ] {
            let f: FaultSpec = s.parse().unwrap();
            let e = f.check_can_fire(800.0, dt_ns).unwrap_err();
            assert!(
                e.contains(needle) && e.contains("never fire") && e.contains("engine-off"),
                "{s}: {e}"
            );
        }
        for s in [
            "engine-off:1@t=799.99",
            "engine-off:1@alt=0.5",
            "engine-off:1@step=79999",
            "engine-off:1@random,p=1,window=700..950",
        ] {
            let f: FaultSpec = s.parse().unwrap();
            assert_eq!(f.check_can_fire(800.0, dt_ns), Ok(()), "{s}");
        }
    }
}
