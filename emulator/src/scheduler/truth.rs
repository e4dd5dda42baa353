//! The truth stage: the plant integrates the held command over one flight-software
//! cycle, on the base tick, and the devices take each step's truth.

use super::{Abort, StepObserver};
use crate::devices::Devices;
use crate::faults::{PlantFault, MAX_FAULTS};
use crate::plant::{ActuatorCommand, Plant, PlantStatus};
use crate::sensors::FrameSink;

/// The plant's side of a cycle: its status, its steps, the faults it carries out.
pub(super) struct TruthStage {
    /// Where the landing stands after the last step.
    pub(super) status: PlantStatus,
    /// Plant steps integrated so far.
    pub(super) plant_steps: u64,
    /// Plant steps per flight-software cycle (the base ticks a command is held over).
    steps_per_cycle: u64,
    /// The base tick, ns.
    dt_ns: u64,
    /// The fault plan's plant faults, by fault index.
    plant_faults: [Option<PlantFault>; MAX_FAULTS],
}

impl TruthStage {
    pub(super) fn new(dt_ns: u64, fsw_period_ns: u64, faults: &crate::faults::FaultPlan) -> Self {
        let mut plant_faults = [None; MAX_FAULTS];
        for (i, slot) in plant_faults.iter_mut().enumerate().take(faults.len()) {
            *slot = faults.plant_fault(i);
        }
        Self {
            status: PlantStatus::Flying,
            plant_steps: 0,
            steps_per_cycle: (fsw_period_ns / dt_ns.max(1)).max(1),
            dt_ns,
            plant_faults,
        }
    }

    /// The faults' hook: sets or clears each plant fault whose bit fired or cleared.
    pub(super) fn apply_faults(&self, plant: &mut Plant, fired: u64, cleared: u64) {
        for (i, f) in self.plant_faults.iter().enumerate() {
            let bit = 1u64 << i;
            if let (true, Some(f)) = ((fired | cleared) & bit != 0, f) {
                plant.set_fault(f, fired & bit != 0);
            }
        }
    }

    /// Whether the lander is down (the landing judged).
    pub(super) fn touched_down(&self) -> bool {
        matches!(self.status, PlantStatus::Touchdown(_))
    }

    /// Holds `applied` over the cycle: the plant steps on the base tick until the next
    /// exchange (once, with the default periods), the devices sampling each step and the
    /// imaging devices rendering into `frames` (the link) when an exposure ends. Stops
    /// early at touchdown or when the physics fails (the abort, for the loop to end on).
    pub(super) fn advance<S: FrameSink + ?Sized>(
        &mut self,
        k: u64,
        plant: &mut Plant,
        devices: &mut Devices,
        frames: &mut S,
        applied: &ActuatorCommand,
        observer: &mut Option<StepObserver<'_>>,
    ) -> Option<Abort> {
        let mut abort = None;
        for _ in 0..self.steps_per_cycle {
            // Once the landing is over the plant is frozen: nothing more to sense.
            let moves = plant.touchdown().is_none();
            self.status = plant.step(applied, self.dt_ns);
            if moves {
                devices.after_plant_step(plant);
                // Once, at the end of the run: the message may allocate.
                if let Err(e) = devices.render_frames(plant, frames) {
                    abort = Some(Abort::Protocol(format!(
                        "a frame could not be published at step {k}: {e}"
                    )));
                    break;
                }
            }
            if let Some(what) = plant.first_non_finite() {
                abort = Some(Abort::NotFinite { step: k, what });
            } else if let Some(why) = plant.propulsion_failure() {
                abort = Some(Abort::PropulsionFailed { step: k, why });
            }
            if let Some(observe) = observer.as_mut() {
                observe(self.plant_steps, plant);
            }
            self.plant_steps += 1;
            if abort.is_some() || self.touched_down() {
                break;
            }
        }
        abort
    }
}
