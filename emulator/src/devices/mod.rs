//! The devices stage of a cycle: what turns the plant's truth into the telemetry the
//! flight software reads. The plant integrates physics and knows nothing of packets;
//! here live the device models on board ([`SensorSuite`]), the imaging devices
//! ([`FrameRack`], protocol v4 frames), the ideal navigation source and its noise, and
//! the ground's state-vector uplink.
//!
//! Two calls drive it, both allocation-free once built:
//! * [`Devices::after_plant_step`] after every plant step that integrated: the sensors
//!   take the step's truth; then [`Devices::render_frames`]: each imaging device whose
//!   exposure ended renders into the link's frame buffer and is published;
//! * [`Devices::telemetry_into`] at each flight-software cycle: the plant's readings
//!   (propulsion, footpad contact), then the device samples, the state vector or the
//!   ideal navigation, as the run's telemetry kind asks.

pub mod nav_noise;

use crate::config::ScenarioConfig;
use crate::link::ExchangeError;
use crate::plant::Plant;
use crate::sensors::{FrameRack, FrameSink, SensorSuite};
use nav_noise::{NavNoise, StateVectorUplink};
use oils_shared::link::FrameSpec;
use oils_shared::{
    NavState, PacketHeader, Telemetry, TLM_FLAG_COMPUTER_RESET, TLM_FLAG_IDEAL_NAV,
    TLM_FLAG_NAV_NOISE, TLM_FLAG_SENSORS, TLM_FLAG_STATE_VECTOR,
};

/// Everything on board between the truth and the telemetry.
#[derive(Debug)]
pub struct Devices {
    /// The navigation noise on the ideal source, when configured.
    noise: Option<NavNoise>,
    /// Whether the telemetry carries the ideal navigation source.
    ideal_nav: bool,
    /// The ground's state vector, sent on the first telemetry with the devices on and
    /// after each computer reset.
    state_vector: StateVectorUplink,
    /// A state vector is due on the next telemetry (with the devices on).
    state_vector_due: bool,
    /// The sensors on board, when the telemetry carries them.
    sensors: Option<Box<SensorSuite>>,
    /// The imaging devices on board, whatever the telemetry carries: rendered after the
    /// step that ends an exposure, announced in the next telemetry.
    frames: Option<Box<FrameRack>>,
}

impl Devices {
    /// The devices of a scenario for run `seed`: the ideal navigation on (with its noise
    /// if configured), no sensors until [`Devices::attach_sensors`].
    pub fn new(cfg: &ScenarioConfig, seed: u64) -> Self {
        Self {
            noise: cfg
                .nav_noise
                .enabled
                .then(|| NavNoise::new(&cfg.nav_noise, seed)),
            ideal_nav: true,
            state_vector: StateVectorUplink::new(&cfg.state_vector, seed),
            state_vector_due: true,
            sensors: None,
            frames: None,
        }
    }

    /// Whether the telemetry fills the ideal navigation source (`nav`,
    /// `accel_body_m_s2`, `altitude_m`, [`TLM_FLAG_IDEAL_NAV`]); on unless told. Off, the
    /// fields are zero and the navigation noise stream is not drawn.
    pub fn set_ideal_nav(&mut self, on: bool) {
        self.ideal_nav = on;
    }

    /// Puts the sensors on board: from now on every step feeds them the truth and every
    /// telemetry carries their samples (`TLM_FLAG_SENSORS`).
    pub fn attach_sensors(&mut self, suite: SensorSuite) {
        self.sensors = Some(Box::new(suite));
    }

    /// The sensors on board, if attached (for their faults and their report).
    pub fn sensors_mut(&mut self) -> Option<&mut SensorSuite> {
        self.sensors.as_deref_mut()
    }

    /// The sensors on board, if attached.
    pub fn sensors(&self) -> Option<&SensorSuite> {
        self.sensors.as_deref()
    }

    /// Puts imaging devices on board: from now on [`Devices::render_frames`] renders
    /// them and every telemetry announces the frames published since the last.
    pub fn attach_frames(&mut self, rack: FrameRack) {
        self.frames = Some(Box::new(rack));
    }

    /// The imaging devices on board, if attached.
    pub fn frames(&self) -> Option<&FrameRack> {
        self.frames.as_deref()
    }

    /// The imaging devices on board, if attached (for their faults).
    pub fn frames_mut(&mut self) -> Option<&mut FrameRack> {
        self.frames.as_deref_mut()
    }

    /// The frame services the imaging devices need, for the link before tick 0 (none
    /// without them).
    pub fn frame_specs(&self) -> Vec<FrameSpec> {
        self.frames.as_ref().map(|f| f.specs()).unwrap_or_default()
    }

    /// After [`Devices::after_plant_step`]: each imaging device whose exposure ended in
    /// the step renders into `sink`'s buffer (an iceoryx2 loan across processes) and is
    /// published, before the telemetry that announces it ([`FrameRack`]). Nothing without
    /// imaging devices. No allocation.
    pub fn render_frames<S: FrameSink + ?Sized>(
        &mut self,
        plant: &Plant,
        sink: &mut S,
    ) -> Result<(), ExchangeError> {
        match self.frames.as_mut() {
            Some(frames) => frames.after_plant_step(&plant.sensor_truth(), sink),
            None => Ok(()),
        }
    }

    /// A computer reset ended: the ground uplinks a fresh state vector on the next
    /// telemetry (with the devices on).
    pub fn uplink_state_vector(&mut self) {
        self.state_vector_due = true;
    }

    /// Feeds the sensors the truth of the plant step just integrated. Call after each
    /// [`Plant::step`] that moved time (not once the landing is over).
    pub fn after_plant_step(&mut self, plant: &Plant) {
        if let Some(sensors) = self.sensors.as_mut() {
            sensors.after_plant_step(&plant.sensor_truth());
        }
    }

    /// The telemetry at the plant's present state (a fresh packet; see
    /// [`Devices::telemetry_into`]).
    pub fn telemetry(&mut self, plant: &Plant, header: PacketHeader) -> Telemetry {
        let mut tlm = Telemetry::default();
        self.telemetry_into(plant, header, &mut tlm);
        tlm
    }

    /// Writes every field of `tlm`: the plant's readings, then what the devices give.
    /// The run's loop keeps one packet and fills it each step.
    pub fn telemetry_into(&mut self, plant: &Plant, header: PacketHeader, tlm: &mut Telemetry) {
        plant.readings_into(header, tlm);
        if let Some(frames) = self.frames.as_mut() {
            frames.announce_into(&mut tlm.sensors);
        }
        if let Some(sensors) = self.sensors.as_mut() {
            sensors.fill_frame(header.t_ns, &mut tlm.sensors);
            tlm.header.flags |= TLM_FLAG_SENSORS;
            // Only when the ideal navigation is off: with it on (`both`), it is what a
            // flight software starts from.
            if !self.ideal_nav
                && self.state_vector_due
                && header.flags & TLM_FLAG_COMPUTER_RESET == 0
            {
                // The ground's state vector in place of the ideal navigation: the truth
                // plus the orbit determination's error (docs/sensors.md).
                self.state_vector_due = false;
                tlm.accel_body_m_s2 = [0.0; 3];
                tlm.altitude_m = 0.0;
                self.state_vector.apply(&mut tlm.nav);
                tlm.header.flags |= TLM_FLAG_STATE_VECTOR;
                return;
            }
        }
        if !self.ideal_nav {
            tlm.nav = NavState::default();
            tlm.accel_body_m_s2 = [0.0; 3];
            tlm.altitude_m = 0.0;
            return;
        }
        tlm.header.flags |= TLM_FLAG_IDEAL_NAV;
        if let Some(noise) = self.noise.as_mut() {
            noise.apply(tlm);
            tlm.header.flags |= TLM_FLAG_NAV_NOISE;
        }
    }
}
