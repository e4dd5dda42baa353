//! The devices stage of a cycle: the faults' hook on the devices, the computer-reset
//! uplink, and Telemetry(k) composed from the truth ([`Devices::telemetry_into`]) with
//! the telemetry faults applied on top.

use crate::devices::Devices;
use crate::faults::{FaultPlan, SensorFaults};
use crate::plant::Plant;
use oils_shared::{PacketHeader, Telemetry, TLM_FLAG_COMPUTER_RESET};

/// The telemetry of the cycle, and what the stage remembers between cycles.
pub(super) struct DeviceStage {
    /// Telemetry(k), filled in place each cycle (a kilobyte not copied twice a step).
    pub(super) tlm: Telemetry,
    /// A computer reset was under way at the last cycle.
    was_resetting: bool,
}

impl DeviceStage {
    pub(super) fn new() -> Self {
        Self {
            tlm: Telemetry::default(),
            was_resetting: false,
        }
    }

    /// The faults' hook: device faults fired or cleared this cycle act in the devices.
    pub(super) fn apply_faults(
        faults: &mut FaultPlan,
        devices: &mut Devices,
        fired: u64,
        cleared: u64,
    ) {
        if fired | cleared == 0 {
            return;
        }
        if let Some(sensors) = devices.sensors_mut() {
            faults.apply_device_faults(fired, cleared, sensors);
        }
        if let Some(frames) = devices.frames_mut() {
            faults.apply_frame_faults(fired, cleared, frames);
        }
    }

    /// Composes Telemetry(k) at the plant's present state. `resetting`: the computer is
    /// resetting (the header says so; when it is back, the ground uplinks a fresh state
    /// vector). `fired`: the fault bits that fired this cycle (a telemetry fault acts
    /// from then on).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn compose(
        &mut self,
        run_id: u64,
        k: u64,
        resetting: bool,
        plant: &Plant,
        devices: &mut Devices,
        telemetry_faults: &mut SensorFaults,
        fired: u64,
    ) -> &Telemetry {
        let mut header = PacketHeader::new(run_id, k, plant.time_ns());
        if resetting {
            header.flags |= TLM_FLAG_COMPUTER_RESET;
        } else if self.was_resetting {
            devices.uplink_state_vector();
        }
        self.was_resetting = resetting;
        devices.telemetry_into(plant, header, &mut self.tlm);
        telemetry_faults.apply(&mut self.tlm, fired);
        &self.tlm
    }
}
