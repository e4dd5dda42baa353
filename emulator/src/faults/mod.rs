//! Fault injection: what a run configuration declares ([`spec`]) and what the scheduler
//! does with it ([`FaultPlan`]): fire each fault at its trigger, clear it after its
//! duration, and act on the propulsion model (physically where the model can), on the
//! telemetry the flight software sees (never on the truth), and on the link.
//!
//! Everything random (random triggers, sensor noise, corrupted bits) comes from one
//! seeded stream per fault, derived from the run's seed and the fault's position in the
//! list only: same configuration and seed, same faults, same digest.

pub mod spec;

pub use spec::{FaultKind, FaultSpec, Trigger};

use crate::propulsion::PropulsionFault;
use oils_shared::{Command, Telemetry};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;

/// ChaCha stream ids of faults start here (fault i uses `FAULT_STREAM + i`).
const FAULT_STREAM: u64 = 0x6661_756c_7400_0000; // "fault"
/// Most faults one run may declare (the active set is a 64-bit mask in the log).
pub const MAX_FAULTS: usize = 64;

/// What a fault does to the plant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlantFault {
    /// The engine is commanded off whatever the flight software asks (0-based).
    EngineOff(usize),
    /// The engine's command holds at what it was when the fault fired (0-based).
    EngineStuck(usize),
    /// A failure inside the propulsion system.
    Propulsion(PropulsionFault),
}

impl PlantFault {
    /// The plant-side fault of a spec, if it acts on the plant.
    pub fn of(spec: &FaultSpec) -> Option<Self> {
        let e = spec.engine();
        Some(match spec.kind {
            FaultKind::EngineOff => PlantFault::EngineOff(e),
            FaultKind::EngineStuck => PlantFault::EngineStuck(e),
            FaultKind::ThrustDegraded => PlantFault::Propulsion(PropulsionFault::ThrustDegraded {
                engine: e,
                factor: spec.param("factor"),
            }),
            FaultKind::ValveStuck => {
                PlantFault::Propulsion(PropulsionFault::ValveStuck { engine: e })
            }
            FaultKind::ValveSlow => PlantFault::Propulsion(PropulsionFault::ValveSlow {
                engine: e,
                factor: spec.param("factor"),
            }),
            FaultKind::RegulatorOpen => PlantFault::Propulsion(PropulsionFault::RegulatorOpen),
            FaultKind::RegulatorClosed => PlantFault::Propulsion(PropulsionFault::RegulatorClosed),
            FaultKind::RegulatorDrift => PlantFault::Propulsion(PropulsionFault::RegulatorDrift {
                rate_pa_s: spec.param("rate_pa_s"),
            }),
            FaultKind::PressurantLeak => PlantFault::Propulsion(PropulsionFault::PressurantLeak {
                area_m2: spec.param("area_mm2") * 1e-6,
            }),
            FaultKind::PropellantLeak => PlantFault::Propulsion(PropulsionFault::PropellantLeak {
                side: usize::from(spec.target.as_deref() == Some("ox")),
                kg_s: spec.param("kg_s"),
            }),
            _ => return None,
        })
    }
}

/// One activation of a fault, as reported.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FaultReport {
    /// Kind, as written in the spec.
    pub kind: String,
    /// Target, if any.
    pub target: Option<String>,
    /// The whole spec, as text.
    pub spec: String,
    /// Simulated time it fired, seconds.
    pub t_s: f64,
    /// Step it fired at.
    pub step: u64,
    /// Simulated time it was cleared, seconds (none: active to the end).
    pub cleared_t_s: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Pending,
    Active { since_ns: i64 },
    Done,
}

/// One declared fault, armed for a run.
#[derive(Debug, Clone)]
struct Armed {
    spec: FaultSpec,
    /// Resolved start: a time (ns), a step, or an altitude; never for a random fault
    /// that drew "no".
    start: Start,
    duration_ns: Option<i64>,
    state: State,
    rng: ChaCha8Rng,
    /// Telemetry held by dropout / frozen sensor faults.
    held: Telemetry,
    /// Delay line of a command-delay fault.
    delayed: std::collections::VecDeque<Command>,
    fired_at: Option<(i64, u64)>,
    cleared_at_ns: Option<i64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Start {
    Time(i64),
    Step(u64),
    AltitudeBelow(f64),
    Never,
}

/// The faults of one run, ready before tick 0. Nothing in [`FaultPlan::advance`] or the
/// per-step calls allocates: delay lines and holds are sized here.
#[derive(Debug, Clone)]
pub struct FaultPlan {
    armed: Vec<Armed>,
    /// The telemetry of the previous step, as the flight software saw it.
    last_tlm: Option<Telemetry>,
    /// A duplicated command waiting to arrive (stale) at the next step.
    duplicate: Option<Command>,
    /// Any sensor fault declared: without one, the telemetry is never touched or kept.
    has_sensor_faults: bool,
}

impl FaultPlan {
    /// Arms `specs` for a run with `seed`. Specs must be valid ([`FaultSpec::validate`]).
    pub fn new(specs: &[FaultSpec], seed: u64) -> Self {
        let armed = specs
            .iter()
            .enumerate()
            .map(|(i, spec)| {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                rng.set_stream(FAULT_STREAM + i as u64);
                let start = match spec.trigger {
                    Trigger::Time(t) => Start::Time((t * 1e9).round() as i64),
                    Trigger::Step(k) => Start::Step(k),
                    Trigger::AltitudeBelow(a) => Start::AltitudeBelow(a),
                    Trigger::Random {
                        probability,
                        from_s,
                        to_s,
                    } => {
                        // Two draws, always both, so the stream's later use is fixed.
                        let happens = rng.gen::<f64>() < probability;
                        let at_s = from_s + (to_s - from_s) * rng.gen::<f64>();
                        if happens {
                            Start::Time((at_s * 1e9).round() as i64)
                        } else {
                            Start::Never
                        }
                    }
                };
                let steps = if spec.kind == FaultKind::CommandDelay {
                    spec.param("steps") as usize + 1
                } else {
                    0
                };
                Armed {
                    spec: spec.clone(),
                    start,
                    duration_ns: spec.duration_s.map(|d| (d * 1e9).round() as i64),
                    state: State::Pending,
                    rng,
                    held: Telemetry::default(),
                    delayed: std::collections::VecDeque::with_capacity(steps),
                    fired_at: None,
                    cleared_at_ns: None,
                }
            })
            .collect();
        Self {
            has_sensor_faults: specs.iter().any(|f| {
                matches!(
                    f.kind,
                    FaultKind::SensorBias
                        | FaultKind::SensorNoise
                        | FaultKind::SensorDropout
                        | FaultKind::SensorFrozen
                )
            }),
            armed,
            last_tlm: None,
            duplicate: None,
        }
    }

    /// No faults at all.
    pub fn is_empty(&self) -> bool {
        self.armed.is_empty()
    }

    /// Fires and clears faults for step `k` at `t_ns` with the true altitude. Returns
    /// the faults that fired (bit i) and those that cleared, as masks.
    pub fn advance(&mut self, k: u64, t_ns: i64, altitude_m: f64) -> (u64, u64) {
        let (mut fired, mut cleared) = (0u64, 0u64);
        for (i, a) in self.armed.iter_mut().enumerate() {
            match a.state {
                State::Pending => {
                    let due = match a.start {
                        Start::Time(at) => t_ns >= at,
                        Start::Step(at) => k >= at,
                        Start::AltitudeBelow(h) => altitude_m < h,
                        Start::Never => false,
                    };
                    if due {
                        a.state = State::Active { since_ns: t_ns };
                        a.fired_at = Some((t_ns, k));
                        a.delayed.clear();
                        fired |= 1 << i;
                    }
                }
                State::Active { since_ns } => {
                    if a.duration_ns.is_some_and(|d| t_ns - since_ns >= d) {
                        a.state = State::Done;
                        a.cleared_at_ns = Some(t_ns);
                        cleared |= 1 << i;
                    }
                }
                State::Done => {}
            }
        }
        (fired, cleared)
    }

    /// Mask of the faults active now.
    pub fn active_mask(&self) -> u64 {
        self.armed
            .iter()
            .enumerate()
            .filter(|(_, a)| matches!(a.state, State::Active { .. }))
            .fold(0, |m, (i, _)| m | 1 << i)
    }

    fn active(&self, kind: FaultKind) -> bool {
        self.armed
            .iter()
            .any(|a| a.spec.kind == kind && matches!(a.state, State::Active { .. }))
    }

    /// The spec of fault `i`.
    pub fn spec(&self, i: usize) -> &FaultSpec {
        &self.armed[i].spec
    }

    /// Number of faults declared.
    pub fn len(&self) -> usize {
        self.armed.len()
    }

    /// Sensor faults on the telemetry the flight software is about to see (the truth is
    /// untouched). `fired` is the mask of faults that fired this step.
    pub fn apply_sensors(&mut self, tlm: &mut Telemetry, fired: u64) {
        if !self.has_sensor_faults {
            return;
        }
        let before = *tlm;
        for (i, a) in self.armed.iter_mut().enumerate() {
            if !matches!(a.state, State::Active { .. }) {
                continue;
            }
            let Some(field) = a.spec.target.as_deref() else {
                continue;
            };
            match a.spec.kind {
                FaultKind::SensorBias => {
                    let v = a.spec.param("value");
                    for x in field_mut(tlm, field) {
                        *x += v;
                    }
                }
                FaultKind::SensorNoise => {
                    let sigma = a.spec.param("sigma");
                    for x in field_mut(tlm, field) {
                        *x += sigma * a.rng.sample::<f64, _>(StandardNormal);
                    }
                }
                FaultKind::SensorDropout | FaultKind::SensorFrozen => {
                    if fired & (1 << i) != 0 {
                        // Dropout repeats the last value seen before; frozen sticks at
                        // the value of the step it fired.
                        a.held = match (a.spec.kind, self.last_tlm) {
                            (FaultKind::SensorDropout, Some(last)) => last,
                            _ => before,
                        };
                    }
                    let mut held = [0.0; 4];
                    let src = field_mut(&mut a.held, field);
                    let n = src.len();
                    held[..n].copy_from_slice(src);
                    field_mut(tlm, field).copy_from_slice(&held[..n]);
                }
                _ => {}
            }
        }
        self.last_tlm = Some(*tlm);
    }

    /// Whether Telemetry(k) is withheld from the flight software (telemetry dropped, or
    /// the flight software paused).
    pub fn telemetry_withheld(&self) -> bool {
        self.active(FaultKind::TelemetryDrop) || self.active(FaultKind::StubPause)
    }

    /// A stale duplicate due now (it arrives before this step's command and is
    /// discarded as late).
    pub fn take_duplicate(&mut self) -> Option<Command> {
        self.duplicate.take()
    }

    /// The link faults on a command received from the flight software: returns what
    /// reaches the sanitiser (`None`: nothing arrived).
    pub fn on_command(&mut self, cmd: Option<Command>) -> Option<Command> {
        let mut cmd = cmd;
        for a in self.armed.iter_mut() {
            if !matches!(a.state, State::Active { .. }) {
                continue;
            }
            match a.spec.kind {
                FaultKind::CommandDrop => cmd = None,
                FaultKind::CommandDelay => {
                    let steps = a.spec.param("steps") as usize;
                    if let Some(c) = cmd {
                        a.delayed.push_back(c);
                    }
                    cmd = if a.delayed.len() > steps {
                        a.delayed.pop_front()
                    } else {
                        None
                    };
                }
                FaultKind::CommandDuplicate => {
                    if let Some(c) = cmd {
                        self.duplicate = Some(c);
                    }
                }
                FaultKind::CommandCorrupt => {
                    if let Some(c) = cmd.as_mut() {
                        corrupt(c, a.spec.param("bits") as u32, &mut a.rng);
                    }
                }
                _ => {}
            }
        }
        cmd
    }

    /// What fired and cleared, for the report.
    pub fn report(&self) -> Vec<FaultReport> {
        self.armed
            .iter()
            .filter_map(|a| {
                let (t_ns, step) = a.fired_at?;
                Some(FaultReport {
                    kind: a.spec.kind.name().into(),
                    target: a.spec.target.clone(),
                    spec: a.spec.to_string(),
                    t_s: t_ns as f64 * 1e-9,
                    step,
                    cleared_t_s: a.cleared_at_ns.map(|t| t as f64 * 1e-9),
                })
            })
            .collect()
    }
}

/// Flips `bits` random bits of a command's payload (thrusts, switches, torques: bytes
/// 40..112), as a damaged packet would arrive.
fn corrupt(cmd: &mut Command, bits: u32, rng: &mut ChaCha8Rng) {
    use oils_shared::AsBytes;
    let mut bytes = [0u8; core::mem::size_of::<Command>()];
    bytes.copy_from_slice(cmd.as_bytes());
    for _ in 0..bits {
        let bit = rng.gen_range(40 * 8..112 * 8);
        bytes[bit / 8] ^= 1 << (bit % 8);
    }
    if let Some(c) = Command::from_bytes(&bytes) {
        *cmd = c;
    }
}

/// The values of a telemetry field a sensor fault acts on.
fn field_mut<'a>(tlm: &'a mut Telemetry, field: &str) -> &'a mut [f64] {
    let p = &mut tlm.propulsion;
    match field {
        "altitude_m" => std::slice::from_mut(&mut tlm.altitude_m),
        "position_m" => &mut tlm.nav.pos_mci_m,
        "velocity_m_s" => &mut tlm.nav.vel_mci_m_s,
        "attitude" => &mut tlm.nav.q_mci_from_body,
        "rate_rad_s" => &mut tlm.nav.rate_body_rad_s,
        "accel_m_s2" => &mut tlm.accel_body_m_s2,
        "mass_kg" => std::slice::from_mut(&mut tlm.mass_estimate_kg),
        "gas_pressure_pa" => std::slice::from_mut(&mut p.gas_pressure_pa),
        "fuel_tank_pressure_pa" => std::slice::from_mut(&mut p.fuel_tank_pressure_pa),
        "ox_tank_pressure_pa" => std::slice::from_mut(&mut p.ox_tank_pressure_pa),
        _ => {
            // thrust1_n .. thrust4_n, chamber_pressure1_pa .. chamber_pressure4_pa
            let engine = |prefix: &str, suffix: &str| {
                field
                    .strip_prefix(prefix)
                    .and_then(|r| r.strip_suffix(suffix))
                    .and_then(|n| n.parse::<usize>().ok())
                    .filter(|n| (1..=4).contains(n))
                    .map(|n| n - 1)
            };
            if let Some(e) = engine("thrust", "_n") {
                std::slice::from_mut(&mut p.engines[e].thrust_n)
            } else if let Some(e) = engine("chamber_pressure", "_pa") {
                std::slice::from_mut(&mut p.engines[e].chamber_pressure_pa)
            } else {
                &mut []
            }
        }
    }
}
