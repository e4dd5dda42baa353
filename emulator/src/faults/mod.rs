//! Fault injection: what a run configuration declares ([`spec`]), compiled before tick 0
//! into a [`FaultPlan`]: a schedule of triggers, and per fault a typed action
//! ([`action`]). The scheduler fires and clears faults by simulated time, step or true
//! altitude, and hands each kind to where it acts: the propulsion model or engine command
//! (physically where the model can), the telemetry the flight software sees (never the
//! truth; [`sensors`]), and the link, as a wrapper around it ([`link::FaultyLink`]).
//!
//! Everything random (random triggers, sensor noise, corrupted bits) comes from one
//! seeded stream per fault, derived from the run's seed and the fault's position in the
//! list only: same configuration and seed, same faults, same digest. Nothing here reads
//! the wall clock.

pub mod action;
pub mod link;
pub mod sensors;
pub mod spec;

pub use action::{FaultAction, LinkAction, SensorAction, TlmField};
pub use link::{FaultyLink, LinkFaults};
pub use sensors::SensorFaults;
pub use spec::{FaultKind, FaultSpec, Trigger};

use crate::propulsion::PropulsionFault;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
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
    /// The engine delivers `factor` times its output (any model: a scale on what it
    /// delivers, like a calibration error).
    ThrustScaled {
        /// Engine, 0-based.
        engine: usize,
        /// Output factor.
        factor: f64,
    },
}

impl PlantFault {
    /// The plant-side fault of a spec, if it acts on the plant.
    pub fn of(spec: &FaultSpec) -> Option<Self> {
        match FaultAction::of(spec)? {
            FaultAction::Plant(f) => Some(f),
            _ => None,
        }
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

/// A spec the plan cannot compile (one [`FaultSpec::validate`] would refuse).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("fault `{spec}` cannot be compiled: {why}")]
pub struct FaultCompileError {
    /// The spec, as text.
    pub spec: String,
    /// What is wrong.
    pub why: String,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum State {
    Pending,
    Active { since_ns: i64 },
    Done,
}

/// When a fault starts, resolved before tick 0 (a random trigger drawn).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Start {
    Time(i64),
    Step(u64),
    AltitudeBelow(f64),
    Never,
}

/// One fault's place in the schedule.
#[derive(Debug, Clone)]
struct Timing {
    start: Start,
    duration_ns: Option<i64>,
    state: State,
    fired_at: Option<(i64, u64)>,
    cleared_at_ns: Option<i64>,
}

/// The faults of one run, compiled before tick 0: triggers, typed actions, and the
/// sensor and link stages with their state (delay lines and holds sized here). Nothing
/// on the step path allocates or looks anything up by name.
#[derive(Debug, Clone)]
pub struct FaultPlan {
    /// The declared specs, for the report only.
    specs: Vec<FaultSpec>,
    timings: Vec<Timing>,
    actions: Vec<FaultAction>,
    active: u64,
    sensors: SensorFaults,
    link: LinkFaults,
}

impl FaultPlan {
    /// No faults at all.
    pub fn none() -> Self {
        Self {
            specs: Vec::new(),
            timings: Vec::new(),
            actions: Vec::new(),
            active: 0,
            sensors: SensorFaults::default(),
            link: LinkFaults::default(),
        }
    }

    /// Compiles `specs` for a run with `seed`. Specs are validated ([`FaultSpec::validate`],
    /// and the horizon check of the run configuration) before this.
    pub fn compile(specs: &[FaultSpec], seed: u64) -> Result<Self, FaultCompileError> {
        if specs.len() > MAX_FAULTS {
            return Err(FaultCompileError {
                spec: specs[MAX_FAULTS].to_string(),
                why: format!("at most {MAX_FAULTS} faults"),
            });
        }
        let mut plan = Self::none();
        for (i, spec) in specs.iter().enumerate() {
            let action = FaultAction::of(spec).ok_or_else(|| FaultCompileError {
                spec: spec.to_string(),
                why: spec
                    .validate()
                    .err()
                    .unwrap_or_else(|| "its parameters do not fit its kind".into()),
            })?;
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
            plan.timings.push(Timing {
                start,
                duration_ns: spec.duration_s.map(|d| (d * 1e9).round() as i64),
                state: State::Pending,
                fired_at: None,
                cleared_at_ns: None,
            });
            match action {
                FaultAction::Plant(_) => {}
                FaultAction::Sensor(a, field) => plan.sensors.add(i, a, field, rng),
                FaultAction::Link(a) => plan.link.add(i, a, rng),
                FaultAction::Device(..) | FaultAction::Frame(..) => {}
            }
            plan.actions.push(action);
            plan.specs.push(spec.clone());
        }
        Ok(plan)
    }

    /// No faults at all.
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }

    /// Fires and clears faults for step `k` at `t_ns` with the true altitude. Returns
    /// the faults that fired (bit i) and those that cleared, as masks.
    pub fn advance(&mut self, k: u64, t_ns: i64, altitude_m: f64) -> (u64, u64) {
        let (mut fired, mut cleared) = (0u64, 0u64);
        for (i, a) in self.timings.iter_mut().enumerate() {
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
        self.active = (self.active | fired) & !cleared;
        self.sensors.set_active(self.active);
        // The link faults while a run holds them: its FaultyLink is told instead.
        self.link.set_active(self.active, fired);
        (fired, cleared)
    }

    /// Mask of the faults active now.
    pub fn active_mask(&self) -> u64 {
        self.active
    }

    /// The plant-side effect of fault `i`, if it has one.
    pub fn plant_fault(&self, i: usize) -> Option<PlantFault> {
        match self.actions.get(i)? {
            FaultAction::Plant(f) => Some(*f),
            _ => None,
        }
    }

    /// The device-side effect of fault `i`, if it acts inside a sensor device.
    pub fn device_fault(
        &self,
        i: usize,
    ) -> Option<(crate::sensors::SensorTarget, crate::sensors::DeviceFault)> {
        match self.actions.get(i)? {
            FaultAction::Device(target, fault) => Some((*target, *fault)),
            _ => None,
        }
    }

    /// Hands the device faults that fired and cleared this step (the masks
    /// [`Self::advance`] returned) to the sensor suite. No allocation.
    pub fn apply_device_faults(
        &self,
        fired: u64,
        cleared: u64,
        suite: &mut crate::sensors::SensorSuite,
    ) {
        for (i, action) in self.actions.iter().enumerate() {
            if let FaultAction::Device(target, fault) = *action {
                let bit = 1u64 << i;
                if fired & bit != 0 {
                    suite.set_fault(target, fault, true);
                }
                if cleared & bit != 0 {
                    suite.set_fault(target, fault, false);
                }
            }
        }
    }

    /// Hands the imaging-device faults that fired and cleared this step to the frame
    /// rack. No allocation.
    pub fn apply_frame_faults(
        &self,
        fired: u64,
        cleared: u64,
        rack: &mut crate::sensors::FrameRack,
    ) {
        for (i, action) in self.actions.iter().enumerate() {
            if let FaultAction::Frame(device, fault) = *action {
                let bit = 1u64 << i;
                if fired & bit != 0 {
                    rack.set_fault(device, fault, true);
                }
                if cleared & bit != 0 {
                    rack.set_fault(device, fault, false);
                }
            }
        }
    }

    /// The compiled action of fault `i`.
    pub fn action(&self, i: usize) -> Option<&FaultAction> {
        self.actions.get(i)
    }

    /// The spec of fault `i`.
    pub fn spec(&self, i: usize) -> &FaultSpec {
        &self.specs[i]
    }

    /// Number of faults declared.
    pub fn len(&self) -> usize {
        self.actions.len()
    }

    /// The telemetry faults' stage.
    pub fn telemetry_faults(&mut self) -> &mut SensorFaults {
        &mut self.sensors
    }

    /// Moves the link faults out, for the [`FaultyLink`] a run wraps its link in (it
    /// follows [`FaultPlan::active_mask`] from then on, through
    /// [`FaultyLink::set_active`]); [`FaultPlan::put_back_link_faults`] returns them.
    pub fn take_link_faults(&mut self) -> LinkFaults {
        std::mem::take(&mut self.link)
    }

    /// Returns the link faults [`FaultPlan::take_link_faults`] moved out.
    pub fn put_back_link_faults(&mut self, link: LinkFaults) {
        self.link = link;
    }

    /// What fired and cleared, for the report.
    pub fn report(&self) -> Vec<FaultReport> {
        self.specs
            .iter()
            .zip(&self.timings)
            .filter_map(|(spec, a)| {
                let (t_ns, step) = a.fired_at?;
                Some(FaultReport {
                    kind: spec.kind.name().into(),
                    target: spec.target.clone(),
                    spec: spec.to_string(),
                    t_s: t_ns as f64 * 1e-9,
                    step,
                    cleared_t_s: a.cleared_at_ns.map(|t| t as f64 * 1e-9),
                })
            })
            .collect()
    }
}
