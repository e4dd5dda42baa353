//! The run as a plain value: [`RunConfig`] holds everything one bench run needs
//! (scenario, propulsion and its parameters, flight software, link, pacing, step,
//! duration, seed, wait strategy, timing thresholds, log settings). It is what the
//! command line builds, what `--config FILE.toml` reads, what the report and the log
//! header carry (so any run can be repeated from its report), and what a Monte Carlo
//! campaign will vary. No clap here: binaries turn flags into a `RunConfig`.

use crate::config::{ConfigError, ScenarioConfig};
use crate::faults::{FaultSpec, MAX_FAULTS};
use crate::propulsion::hifi::HifiParams;
use crate::propulsion::{PropulsionKind, PropulsionSpec};
use crate::scheduler::{MissPolicy, Mode};
use crate::timing::TimingThresholds;
use oils_shared::fsw::FswSpec;
use oils_shared::link::WaitStrategy;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// How Telemetry(k) reaches the flight software and Command(k) comes back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LinkKind {
    /// iceoryx2 shared memory between the emulator and a separate onboard process: the
    /// bench itself, with timing figures.
    #[default]
    Iceoryx2,
    /// The flight software called in the emulator's thread: no IPC, no second process,
    /// same digest. For campaigns and regression.
    Inproc,
}

impl LinkKind {
    /// Name as on the command line.
    pub fn as_str(&self) -> &'static str {
        match self {
            LinkKind::Iceoryx2 => "iceoryx2",
            LinkKind::Inproc => "inproc",
        }
    }
}

impl std::str::FromStr for LinkKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "iceoryx2" => Ok(LinkKind::Iceoryx2),
            "inproc" => Ok(LinkKind::Inproc),
            other => Err(format!(
                "unknown link `{other}` (expected iceoryx2 or inproc)"
            )),
        }
    }
}

/// What the telemetry carries for the flight software to navigate from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TelemetrySource {
    /// The ideal navigation source only: the true state plus seeded noise in `nav`,
    /// `accel_body_m_s2` and `altitude_m` (`TLM_FLAG_IDEAL_NAV`); no device samples. For
    /// flight software without navigation of its own (the reference GNC today).
    #[default]
    Nav,
    /// The devices only: every sensor sample since the last cycle in `sensors`
    /// (`TLM_FLAG_SENSORS`); the ideal navigation fields are zero.
    Sensors,
    /// Both: the devices, and the ideal navigation source beside them (to compare a
    /// navigation filter with, or to log the devices under a GNC that needs `nav`).
    Both,
}

impl TelemetrySource {
    /// Name as on the command line.
    pub fn as_str(&self) -> &'static str {
        match self {
            TelemetrySource::Nav => "nav",
            TelemetrySource::Sensors => "sensors",
            TelemetrySource::Both => "both",
        }
    }

    /// Whether the ideal navigation fields are filled.
    pub fn ideal_nav(&self) -> bool {
        matches!(self, TelemetrySource::Nav | TelemetrySource::Both)
    }

    /// Whether the devices run and fill the sensor frame.
    pub fn sensors(&self) -> bool {
        matches!(self, TelemetrySource::Sensors | TelemetrySource::Both)
    }

    fn is_default(&self) -> bool {
        *self == TelemetrySource::Nav
    }
}

impl std::str::FromStr for TelemetrySource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "nav" => Ok(TelemetrySource::Nav),
            "sensors" => Ok(TelemetrySource::Sensors),
            "both" => Ok(TelemetrySource::Both),
            other => Err(format!(
                "unknown telemetry source `{other}` (expected nav, sensors or both)"
            )),
        }
    }
}

/// How a process waits for its peer's next packet (iceoryx2 link only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WaitKind {
    /// Spin on the subscriber (fastest, burns a core).
    Busy,
    /// Sleep on an iceoryx2 event.
    Event,
    /// Spin briefly, then sleep on the event.
    Hybrid,
}

impl WaitKind {
    /// The link's strategy.
    pub fn strategy(self) -> WaitStrategy {
        match self {
            WaitKind::Busy => WaitStrategy::BusyPoll,
            WaitKind::Event => WaitStrategy::Event,
            WaitKind::Hybrid => WaitStrategy::Hybrid {
                spin_ns: WaitStrategy::DEFAULT_SPIN_NS,
            },
        }
    }
}

impl std::str::FromStr for WaitKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "busy" | "busy-poll" => Ok(WaitKind::Busy),
            "event" => Ok(WaitKind::Event),
            "hybrid" => Ok(WaitKind::Hybrid),
            other => Err(format!(
                "unknown wait strategy `{other}` (expected busy, event or hybrid)"
            )),
        }
    }
}

/// Timing bounds in the units users write (microseconds); a broken one fails the run.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThresholdConfig {
    /// Largest allowed p99 wake error, microseconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_wake_p99_us: Option<f64>,
    /// Largest allowed p99 round trip, microseconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_round_trip_p99_us: Option<f64>,
    /// Largest allowed p99 transport, microseconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_transport_p99_us: Option<f64>,
    /// Largest allowed number of deadline misses.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_deadline_misses: Option<u64>,
}

impl ThresholdConfig {
    /// The bounds in nanoseconds. Call after [`RunConfig::validate`].
    pub fn to_thresholds(&self) -> TimingThresholds {
        let ns = |v: Option<f64>| v.map(|us| (us * 1000.0).round() as u64);
        TimingThresholds {
            wake_error_p99_ns: ns(self.max_wake_p99_us),
            round_trip_p99_ns: ns(self.max_round_trip_p99_us),
            transport_p99_ns: ns(self.max_transport_p99_us),
            deadline_misses: self.max_deadline_misses,
        }
    }
}

/// Where the run's log goes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    /// Write a log at all.
    pub enabled: bool,
    /// The log file; default `oils-out/<run id>.oilslog` (`.mcap` for MCAP).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// The log's format: `oilslog` (OILSLOG6, the default) or `mcap`.
    #[serde(skip_serializing_if = "crate::recorder::LogFormat::is_default")]
    pub format: crate::recorder::LogFormat,
}

impl Default for LogConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            path: None,
            format: Default::default(),
        }
    }
}

/// The default plant step (the base tick), ms.
pub const DEFAULT_DT_MS: u64 = 10;
/// The plant step a run with the devices on takes when none was chosen: the IMU's
/// 5 ms period needs a base tick that divides it.
pub const DEVICES_DT_MS: u64 = 5;

/// Everything one bench run needs, as plain data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// How the flight software is reached.
    pub link: LinkKind,
    /// Pacing: lockstep (deterministic, as fast as possible) or realtime.
    pub mode: Mode,
    /// Realtime speed factor (2 = twice real time).
    pub speed: f64,
    /// Step, milliseconds (1-100): the plant's integration period, the schedule's base
    /// tick.
    pub dt_ms: u64,
    /// The flight-software cycle, milliseconds: one telemetry/command exchange per
    /// cycle, the command held over it, the plant stepping `fsw_period_ms / dt_ms` times.
    /// A whole multiple of `dt_ms`. Unset: the smallest multiple of `dt_ms` of at least
    /// 10 ms (10 ms for the default 10 ms step and for 1, 2 or 5 ms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fsw_period_ms: Option<u64>,
    /// Longest simulated time, seconds; the run ends `completed` if still flying.
    pub duration_s: f64,
    /// What the telemetry carries: `nav` (ideal navigation), `sensors` (device samples)
    /// or `both`.
    #[serde(skip_serializing_if = "TelemetrySource::is_default")]
    pub telemetry: TelemetrySource,
    /// The reference GNC's choices (`[gnc]`): `navigation = "bench" | "sensors"`,
    /// `attitude = "torque" | "thrusters"`.
    #[serde(skip_serializing_if = "oils_shared::fsw::GncOptions::is_default")]
    pub gnc: oils_shared::fsw::GncOptions,
    /// Seed of every random stream.
    pub seed: u64,
    /// Propulsion model.
    pub propulsion: PropulsionKind,
    /// The user's FMU, or its variable mapping TOML (`propulsion = "fmu"`, from
    /// `--propulsion fmu:PATH`): the program running the bench builds it (see
    /// [`crate::session::Extras::propulsion`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub propulsion_fmu: Option<PathBuf>,
    /// Surrogate model file (`surrogate`, `shadow`); none: the committed model.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<PathBuf>,
    /// Hifi parameters (`hifi`, `shadow`); none: `emulator/config/hifi.toml`'s values.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hifi: Option<HifiParams>,
    /// Flight software.
    pub fsw: FswSpec,
    /// Parameter file handed to a C flight software's `oils_fsw_init` (`fsw = "c:PATH"`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fsw_params: Option<PathBuf>,
    /// Thrust-command profile CSV for `fsw = "playback"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub profile: Option<PathBuf>,
    /// The vehicle, the Moon, the initial state, navigation noise, touchdown limits.
    pub scenario: ScenarioConfig,
    /// Wait strategy (iceoryx2 link); none: busy in lockstep, hybrid in realtime.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wait: Option<WaitKind>,
    /// Realtime: what a deadline miss does.
    pub miss_policy: MissPolicy,
    /// Realtime: a command must arrive within this fraction of a period.
    pub deadline_frac: f64,
    /// Realtime: spin this many microseconds before each step start.
    pub wake_spin_us: u64,
    /// The flight software is declared dead after this long without a command, ms.
    pub link_timeout_ms: u64,
    /// How long to wait for the flight software to connect, ms.
    pub startup_timeout_ms: u64,
    /// iceoryx2 link: let a new flight-software process take the run over when commands
    /// come from another process than the one that joined (a restarted stub). Off: such a
    /// command aborts the run. Each take-over is reported.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub allow_reattach: bool,
    /// SCHED_FIFO priority (1-99) with memory locked; needs root or CAP_SYS_NICE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rt_priority: Option<i32>,
    /// CPUs to pin the stepping threads to: `[EMULATOR]` or `[EMULATOR, STUB]` (the
    /// emulator's stepping thread on the first, the onboard stub's on the second; with
    /// one, the stub is not pinned). Empty: no pinning. Checked online before tick 0.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cpus: Vec<usize>,
    /// Timing bounds.
    pub thresholds: ThresholdConfig,
    /// Log settings.
    pub log: LogConfig,
    /// Faults to inject (`[[faults]]`; `--fault SPEC` on the command line).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<FaultSpec>,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            link: LinkKind::Iceoryx2,
            mode: Mode::Lockstep,
            speed: 1.0,
            dt_ms: DEFAULT_DT_MS,
            fsw_period_ms: None,
            duration_s: 2000.0,
            telemetry: TelemetrySource::Nav,
            gnc: Default::default(),
            seed: 0,
            propulsion: PropulsionKind::Surrogate,
            propulsion_fmu: None,
            model: None,
            hifi: None,
            fsw: FswSpec::Gnc,
            fsw_params: None,
            profile: None,
            scenario: ScenarioConfig {
                // The bench flies with navigation noise unless told otherwise.
                nav_noise: crate::config::NavNoiseConfig {
                    enabled: true,
                    ..Default::default()
                },
                ..Default::default()
            },
            wait: None,
            miss_policy: MissPolicy::Hold,
            deadline_frac: 0.5,
            wake_spin_us: 200,
            link_timeout_ms: 2000,
            startup_timeout_ms: 10_000,
            allow_reattach: false,
            rt_priority: None,
            cpus: Vec::new(),
            thresholds: ThresholdConfig::default(),
            log: LogConfig::default(),
            faults: Vec::new(),
        }
    }
}

/// A run configuration that cannot run.
#[derive(Debug, Error)]
pub enum RunConfigError {
    /// A setting is out of range or inconsistent with another.
    #[error("invalid run configuration: {field} = {value} ({why})")]
    Invalid {
        /// The setting, as named in the TOML file.
        field: &'static str,
        /// Its value, printed.
        value: String,
        /// What is expected.
        why: String,
    },
    /// The scenario is invalid.
    #[error(transparent)]
    Scenario(#[from] ConfigError),
    /// The hifi parameters are invalid.
    #[error("invalid run configuration: hifi: {0}")]
    Hifi(String),
    /// A file could not be read or parsed.
    #[error("{path}: {why}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
}

fn invalid(field: &'static str, value: impl ToString, why: impl Into<String>) -> RunConfigError {
    RunConfigError::Invalid {
        field,
        value: value.to_string(),
        why: why.into(),
    }
}

/// Longest realtime period a run may ask for (`dt / speed`), seconds: beyond this a
/// "realtime" run is a stalled one.
pub const MAX_REALTIME_PERIOD_S: f64 = 60.0;
/// Largest link or start-up timeout, milliseconds (one day).
pub const MAX_TIMEOUT_MS: u64 = 86_400_000;

impl RunConfig {
    /// Checks every setting before any resource is taken.
    pub fn validate(&self) -> Result<(), RunConfigError> {
        if !(1..=100).contains(&self.dt_ms) {
            return Err(invalid("dt_ms", self.dt_ms, "1-100"));
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 1e6) {
            return Err(invalid(
                "duration_s",
                self.duration_s,
                "in (0, 1e6] seconds",
            ));
        }
        if let Some(ms) = self.fsw_period_ms {
            if !(1..=1000).contains(&ms) {
                return Err(invalid("fsw_period_ms", ms, "1-1000"));
            }
        }
        self.schedule().map_err(|e| {
            invalid(
                "fsw_period_ms",
                self.fsw_period_ns() / 1_000_000,
                e.to_string(),
            )
        })?;
        let period_s = self.fsw_period_ns() as f64 * 1e-9 / self.speed;
        if !(self.speed.is_finite()
            && self.speed > 0.0
            && self.speed <= 1e6
            && period_s <= MAX_REALTIME_PERIOD_S)
        {
            return Err(invalid(
                "speed",
                self.speed,
                format!("in (0, 1e6] with the flight-software period / speed at most {MAX_REALTIME_PERIOD_S} s a cycle"),
            ));
        }
        if !(self.deadline_frac.is_finite()
            && self.deadline_frac > 0.0
            && self.deadline_frac <= 1.0)
        {
            return Err(invalid("deadline_frac", self.deadline_frac, "in (0, 1]"));
        }
        if let MissPolicy::Abort { after: 0 } = self.miss_policy {
            return Err(invalid("miss_policy", "abort:0", "abort:N needs N >= 1"));
        }
        if self.wake_spin_us > 1_000_000 {
            return Err(invalid(
                "wake_spin_us",
                self.wake_spin_us,
                "at most 1 000 000",
            ));
        }
        for (field, v) in [
            ("link_timeout_ms", self.link_timeout_ms),
            ("startup_timeout_ms", self.startup_timeout_ms),
        ] {
            if !(1..=MAX_TIMEOUT_MS).contains(&v) {
                return Err(invalid(field, v, format!("1-{MAX_TIMEOUT_MS}")));
            }
        }
        if let Some(p) = self.rt_priority {
            if !(1..=99).contains(&p) {
                return Err(invalid("rt_priority", p, "1-99"));
            }
        }
        if self.cpus.len() > 2 {
            return Err(invalid(
                "cpus",
                format!("{:?}", self.cpus),
                "one or two CPUs: [EMULATOR] or [EMULATOR, STUB]",
            ));
        }
        let t = &self.thresholds;
        for (field, v) in [
            ("thresholds.max_wake_p99_us", t.max_wake_p99_us),
            ("thresholds.max_round_trip_p99_us", t.max_round_trip_p99_us),
            ("thresholds.max_transport_p99_us", t.max_transport_p99_us),
        ] {
            if let Some(us) = v {
                if !(us.is_finite() && (0.0..=60e6).contains(&us)) {
                    return Err(invalid(
                        field,
                        us,
                        "a finite number of microseconds in [0, 6e7]",
                    ));
                }
            }
        }
        self.scenario
            .sensors
            .check_frame_rates(self.dt_ns(), self.fsw_period_ns())
            .map_err(|e| {
                invalid(
                    "sensors",
                    e.to_string(),
                    "the frame devices' periods must fit the plant step and the flight-software cycle",
                )
            })?;
        if self.telemetry.sensors() {
            self.scenario
                .sensors
                .check_rates(self.dt_ns(), self.fsw_period_ns())
                .map_err(|e| {
                    invalid(
                        "telemetry",
                        format!("{} ({e})", self.telemetry.as_str()),
                        "the devices' periods must fit the plant step (--dt-ms 5 or 1 for the IMU's 200 Hz) and the flight-software cycle",
                    )
                })?;
        }
        use oils_shared::fsw::GncNavigation;
        if self.fsw == FswSpec::Gnc {
            match (self.gnc.navigation, self.telemetry) {
                (GncNavigation::Bench, TelemetrySource::Sensors) => {
                    return Err(invalid(
                        "telemetry",
                        "sensors",
                        "the reference GNC with gnc.navigation = \"bench\" navigates from the ideal navigation source: use telemetry = \"nav\" or \"both\", or --gnc-nav sensors to fly it on its Kalman filter",
                    ));
                }
                (GncNavigation::Sensors, TelemetrySource::Nav) => {
                    return Err(invalid(
                        "gnc.navigation",
                        "sensors",
                        "navigating from the sensors needs their samples: telemetry = \"sensors\" or \"both\" (--telemetry sensors)",
                    ));
                }
                _ => {}
            }
            if self.gnc.hazard_avoidance {
                if self.gnc.navigation != GncNavigation::Sensors {
                    return Err(invalid(
                        "gnc.hazard_avoidance",
                        "true",
                        "hazard avoidance is part of the sensor navigation: gnc.navigation = \"sensors\" (--gnc-nav sensors)",
                    ));
                }
                if !self.scenario.sensors.lidar.enabled {
                    return Err(invalid(
                        "gnc.hazard_avoidance",
                        "true",
                        "hazard detection maps the ground with the flash lidar: [scenario.sensors.lidar] enabled = true (the pinpoint scenario flies it)",
                    ));
                }
            }
            if let Some(map) = &self.gnc.map {
                if self.gnc.navigation != GncNavigation::Sensors {
                    return Err(invalid(
                        "gnc.map",
                        map.display().to_string(),
                        "terrain navigation is part of the sensor navigation: gnc.navigation = \"sensors\" (--gnc-nav sensors)",
                    ));
                }
                if !self.scenario.sensors.camera.enabled {
                    return Err(invalid(
                        "gnc.map",
                        map.display().to_string(),
                        "terrain navigation looks through the camera: [scenario.sensors.camera] enabled = true (the pinpoint scenario flies it)",
                    ));
                }
            }
        } else if !self.gnc.is_default() {
            return Err(invalid(
                "gnc",
                format!("{}/{}", self.gnc.navigation, self.gnc.attitude),
                "the [gnc] choices are the reference GNC's: use them with fsw = \"gnc\"",
            ));
        }
        match (&self.fsw, &self.profile) {
            (FswSpec::Playback, None) => {
                return Err(invalid(
                    "fsw",
                    "playback",
                    "needs a thrust profile: profile = \"CSV\" or --profile CSV",
                ))
            }
            (FswSpec::External, _) if self.link == LinkKind::Inproc => {
                return Err(invalid(
                    "fsw",
                    "external",
                    "an external client needs link = \"iceoryx2\"",
                ))
            }
            _ => {}
        }
        if self.link == LinkKind::Inproc && self.wait.is_some() {
            return Err(invalid(
                "wait",
                format!("{:?}", self.wait).to_lowercase(),
                "only the iceoryx2 link waits; leave it unset for link = \"inproc\"",
            ));
        }
        if self.faults.len() > MAX_FAULTS {
            return Err(invalid(
                "faults",
                self.faults.len(),
                format!("at most {MAX_FAULTS} faults"),
            ));
        }
        for f in &self.faults {
            if let (Some(device), false) = (f.device_target(), self.telemetry.sensors()) {
                return Err(invalid(
                    "faults",
                    f.to_string(),
                    format!(
                        "a fault on the {} acts inside the device, which runs only with telemetry = \"sensors\" or \"both\" (--telemetry)",
                        device.device().name()
                    ),
                ));
            }
            if let Some(device) = f.frame_target() {
                let sensors = &self.scenario.sensors;
                let (on, section) = match device {
                    oils_shared::FRAME_DEVICE_CAMERA => (sensors.camera.enabled, "camera"),
                    oils_shared::FRAME_DEVICE_LIDAR => (sensors.lidar.enabled, "lidar"),
                    _ => (sensors.test_card.enabled, "test_card"),
                };
                if !on {
                    return Err(invalid(
                        "faults",
                        f.to_string(),
                        format!(
                            "the scenario has no {} on board ([sensors.{section}] enabled = true; the pinpoint scenario flies the camera and the lidar)",
                            oils_shared::frame_device_name(device).unwrap_or("frame device")
                        ),
                    ));
                }
            }
            f.validate()
                .and_then(|()| f.check_can_fire(self.duration_s, self.dt_ns()))
                .map_err(|why| invalid("faults", f.to_string(), why))?;
        }
        match (self.propulsion, &self.propulsion_fmu) {
            (PropulsionKind::Fmu, None) => return Err(invalid(
                "propulsion",
                "fmu",
                "needs propulsion_fmu = \"MODEL.fmu\" (or its mapping TOML): --propulsion fmu:PATH",
            )),
            (kind, Some(p)) if kind != PropulsionKind::Fmu => {
                return Err(invalid(
                    "propulsion_fmu",
                    p.display(),
                    format!("only read with propulsion = \"fmu\", not {}", kind.as_str()),
                ))
            }
            _ => {}
        }
        self.scenario.validate()?;
        if let Some(h) = &self.hifi {
            h.validate()
                .map_err(|e| RunConfigError::Hifi(e.to_string()))?;
        }
        Ok(())
    }

    /// The flight-software cycle, nanoseconds (see `fsw_period_ms`).
    pub fn fsw_period_ns(&self) -> u64 {
        match self.fsw_period_ms {
            Some(ms) => ms * 1_000_000,
            None => self.dt_ns() * 10_000_000u64.div_ceil(self.dt_ns().max(1)),
        }
    }

    /// Sets what the telemetry carries, and the base tick the devices need: their
    /// periods (the IMU's 5 ms) need a plant step that divides them, so a plant step
    /// left at the default 10 ms (`dt_ms_chosen` false) becomes 5 ms with the devices
    /// on. The one place this rule lives (`oils run`, `oils mc`).
    pub fn set_telemetry(&mut self, telemetry: TelemetrySource, dt_ms_chosen: bool) {
        self.telemetry = telemetry;
        if telemetry.sensors() && !dt_ms_chosen && self.dt_ms == DEFAULT_DT_MS {
            self.dt_ms = DEVICES_DT_MS;
        }
    }

    /// The run's rate groups: the plant on the base tick, the flight software's cycle.
    pub fn schedule(&self) -> Result<crate::schedule::Schedule, crate::schedule::ScheduleError> {
        crate::schedule::Schedule::new(self.dt_ns()).with_group("fsw", self.fsw_period_ns())
    }

    /// Step, nanoseconds.
    pub fn dt_ns(&self) -> u64 {
        self.dt_ms * 1_000_000
    }

    /// The propulsion model this run flies, stepped at the bench step.
    pub fn propulsion_spec(&self) -> PropulsionSpec {
        PropulsionSpec {
            kind: self.propulsion,
            engines: self.scenario.propulsion.clone(),
            surrogate_model: self.model.clone(),
            hifi: self.hifi.clone().unwrap_or_default(),
            step_ns: Some(self.dt_ns()),
        }
    }

    /// Whether the stepping threads lock memory and prefault their stacks before tick 0:
    /// in realtime runs, and whenever `rt_priority` is set.
    pub fn realtime_memory(&self) -> bool {
        self.mode == Mode::Realtime || self.rt_priority.is_some()
    }

    /// The CPU the emulator's stepping thread is pinned to (`cpus[0]`).
    pub fn emulator_cpu(&self) -> Option<usize> {
        self.cpus.first().copied()
    }

    /// The CPU the onboard stub's stepping thread is pinned to (`cpus[1]`).
    pub fn stub_cpu(&self) -> Option<usize> {
        self.cpus.get(1).copied()
    }

    /// The wait strategy: as set, else busy-poll in lockstep (the two processes take
    /// turns, so each spins only while the other works) and hybrid in realtime (leaves
    /// the core free between steps).
    pub fn wait_strategy(&self) -> WaitStrategy {
        match self.wait {
            Some(w) => w.strategy(),
            None => match self.mode {
                Mode::Lockstep => WaitStrategy::BusyPoll,
                Mode::Realtime => WaitStrategy::Hybrid {
                    spin_ns: WaitStrategy::DEFAULT_SPIN_NS,
                },
            },
        }
    }

    /// Reads a run configuration TOML (any subset of fields; the rest default).
    pub fn load_toml(path: &Path) -> Result<Self, RunConfigError> {
        let text = read_capped(path)?;
        toml::from_str(&text).map_err(|e| RunConfigError::File {
            path: path.to_path_buf(),
            why: e.to_string(),
        })
    }

    /// The configuration of an earlier run, from its JSON report (`config` key) or from
    /// a run configuration JSON file.
    pub fn load_from_report(path: &Path) -> Result<Self, RunConfigError> {
        let text = read_capped(path)?;
        let file_err = |why: String| RunConfigError::File {
            path: path.to_path_buf(),
            why,
        };
        // Exactly as written: serde_json's own parser may read a float one ulp off.
        let value = crate::exact_json::value_from_str(&text)
            .map_err(|e| file_err(format!("not JSON: {e}")))?;
        let config = match value.get("config") {
            Some(c) => c.clone(),
            None => value,
        };
        serde_json::from_value(config).map_err(|e| file_err(format!("run configuration: {e}")))
    }

    /// The configuration as TOML (what `--config` reads back).
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot serialise: {e}\n"))
    }
}

/// Configuration files are small; a larger one is a mistake, refused before parsing.
const MAX_CONFIG_BYTES: u64 = 16 << 20;

fn read_capped(path: &Path) -> Result<String, RunConfigError> {
    let file_err = |why: String| RunConfigError::File {
        path: path.to_path_buf(),
        why,
    };
    let meta = std::fs::metadata(path).map_err(|e| file_err(e.to_string()))?;
    if meta.len() > MAX_CONFIG_BYTES {
        return Err(file_err(format!(
            "{} bytes; a configuration file is at most {MAX_CONFIG_BYTES}",
            meta.len()
        )));
    }
    std::fs::read_to_string(path).map_err(|e| file_err(e.to_string()))
}

/// Named scenarios shipped with the bench (`--scenario NAME`), compiled in.
pub const NAMED_SCENARIOS: &[(&str, &str)] = &[
    ("default", include_str!("../config/scenario.toml")),
    (
        "terminal-descent",
        include_str!("../config/scenarios/terminal-descent.toml"),
    ),
    (
        "pinpoint",
        include_str!("../config/scenarios/pinpoint.toml"),
    ),
    (
        "hazardous-site",
        include_str!("../config/scenarios/hazardous-site.toml"),
    ),
];

/// A scenario by name (see [`NAMED_SCENARIOS`]) or from a TOML file.
pub fn load_scenario(name_or_path: &str) -> Result<ScenarioConfig, RunConfigError> {
    let (what, text) = match NAMED_SCENARIOS.iter().find(|(n, _)| *n == name_or_path) {
        Some((_, text)) => (PathBuf::from(name_or_path), (*text).to_string()),
        None => {
            let path = Path::new(name_or_path);
            if !path.exists() {
                let names: Vec<&str> = NAMED_SCENARIOS.iter().map(|(n, _)| *n).collect();
                return Err(RunConfigError::File {
                    path: path.to_path_buf(),
                    why: format!(
                        "no such file, and not a named scenario ({})",
                        names.join(", ")
                    ),
                });
            }
            (path.to_path_buf(), read_capped(path)?)
        }
    };
    toml::from_str(&text).map_err(|e| RunConfigError::File {
        path: what,
        why: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_round_trips_through_toml_and_json() {
        let cfg = RunConfig::default();
        cfg.validate().unwrap();
        let back: RunConfig = toml::from_str(&cfg.to_toml()).unwrap();
        assert_eq!(back, cfg);
        let json = serde_json::to_string(&cfg).unwrap();
        let back: RunConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, cfg);
    }

    #[test]
    fn cpus_read_as_emulator_then_stub() {
        let cfg: RunConfig = toml::from_str("cpus = [0, 1]\n").unwrap();
        assert_eq!((cfg.emulator_cpu(), cfg.stub_cpu()), (Some(0), Some(1)));
        let cfg: RunConfig = toml::from_str("cpus = [1]\n").unwrap();
        assert_eq!((cfg.emulator_cpu(), cfg.stub_cpu()), (Some(1), None));
        let cfg = RunConfig::default();
        assert_eq!((cfg.emulator_cpu(), cfg.stub_cpu()), (None, None));
        assert!(!cfg.to_toml().contains("cpus"));
        assert!(!cfg.realtime_memory());
        let rt = RunConfig {
            mode: Mode::Realtime,
            ..RunConfig::default()
        };
        assert!(rt.realtime_memory());
    }

    #[test]
    fn a_partial_file_overrides_only_what_it_names() {
        let cfg: RunConfig = toml::from_str(
            "link = \"inproc\"\npropulsion = \"hifi\"\nseed = 7\n[scenario.initial]\naltitude_m = 20000.0\n",
        )
        .unwrap();
        assert_eq!(cfg.link, LinkKind::Inproc);
        assert_eq!(cfg.propulsion, PropulsionKind::Hifi);
        assert_eq!(cfg.seed, 7);
        assert_eq!(cfg.scenario.initial.altitude_m, 20000.0);
        assert_eq!(cfg.dt_ms, 10);
        assert!(toml::from_str::<RunConfig>("sede = 7").is_err());
    }

    #[test]
    fn bad_settings_are_named() {
        let bad = |f: &dyn Fn(&mut RunConfig), field: &str| {
            let mut c = RunConfig::default();
            f(&mut c);
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{e}");
        };
        bad(&|c| c.dt_ms = 0, "dt_ms");
        bad(&|c| c.duration_s = f64::NAN, "duration_s");
        bad(&|c| c.speed = 1e-6, "speed");
        bad(&|c| c.deadline_frac = 0.0, "deadline_frac");
        bad(&|c| c.link_timeout_ms = u64::MAX, "link_timeout_ms");
        bad(&|c| c.cpus = vec![0, 1, 0], "cpus");
        bad(
            &|c| c.thresholds.max_wake_p99_us = Some(f64::NAN),
            "max_wake_p99_us",
        );
        bad(
            &|c| c.thresholds.max_round_trip_p99_us = Some(-1.0),
            "max_round_trip_p99_us",
        );
        bad(&|c| c.fsw = FswSpec::Playback, "playback");
        bad(
            &|c| {
                c.link = LinkKind::Inproc;
                c.fsw = FswSpec::External
            },
            "external",
        );
        bad(
            &|c| c.scenario.initial.altitude_m = f64::INFINITY,
            "altitude_m",
        );
        bad(
            &|c| c.faults = vec!["sensor-frozen:camera@t=1".parse().unwrap()],
            "no camera on board",
        );
    }

    #[test]
    fn a_fault_on_a_frame_device_on_board_is_taken() {
        let mut c = RunConfig::default();
        c.scenario.sensors.lidar.enabled = true;
        c.faults = vec!["sensor-dead-quadrant:lidar,quadrant=3@t=1".parse().unwrap()];
        c.validate().unwrap();
    }

    #[test]
    fn named_scenarios_parse_and_unknown_names_are_refused() {
        for (name, _) in NAMED_SCENARIOS {
            load_scenario(name).unwrap().validate().unwrap();
        }
        let e = load_scenario("no-such-scenario").unwrap_err().to_string();
        assert!(e.contains("named scenario"), "{e}");
    }
}
