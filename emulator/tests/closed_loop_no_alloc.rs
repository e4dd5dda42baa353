//! A whole powered descent (plant + reference GNC) without a single heap allocation
//! after construction: proves the no-allocation contract of `Plant::step`,
//! `Plant::telemetry` and `ReferenceGnc::step` (and `ProfilePlayback::step`).

use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_onboard_stub::fsw::FlightSoftware;
use oils_onboard_stub::gnc::{GncConfig, ReferenceGnc};
use oils_onboard_stub::playback::ProfilePlayback;
use oils_shared::profile::ThrustProfile;
use oils_shared::{Command, PacketHeader};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

fn actuator(cmd: &Command, cycle_start_ns: i64) -> ActuatorCommand {
    let mut engines = EngineCommand::default();
    for i in 0..4 {
        engines.thrust_cmd_n[i] = cmd.thrust_cmd_n[i].clamp(0.0, 800.0);
        engines.on[i] = cmd.engine_on[i] == 1;
    }
    ActuatorCommand {
        engines,
        torque_cmd_body_nm: cmd.torque_cmd_body_nm,
        use_thrusters: cmd.attitude_mode == oils_shared::ATTITUDE_MODE_THRUSTERS,
        thruster_on_time_ns: cmd.thruster_on_time_ns,
        cycle_start_ns,
    }
}

/// Steps `fsw` against a fresh plant to touchdown; returns the allocations counted in
/// the loop.
fn allocations_in_loop(fsw: &mut dyn FlightSoftware, cfg: &ScenarioConfig) -> usize {
    let mut plant = Plant::new(cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut devices = Devices::new(cfg, 3);
    let before = common::allocations();
    let mut landed = false;
    for k in 0..200_000u64 {
        let t_ns = plant.time_ns();
        let tlm = devices.telemetry(&plant, PacketHeader::new(1, k, t_ns));
        let cmd = fsw.step(&tlm);
        if let PlantStatus::Touchdown(td) = plant.step(&actuator(&cmd, t_ns), 10_000_000) {
            std::hint::black_box(td);
            landed = true;
            break;
        }
    }
    let after = common::allocations();
    assert!(landed, "the loop should reach touchdown");
    after - before
}

#[test]
fn a_whole_descent_allocates_nothing() {
    let mut cfg = ScenarioConfig::default();
    cfg.nav_noise.enabled = true;
    let mut gnc = ReferenceGnc::new(GncConfig::default()).unwrap();
    assert_eq!(allocations_in_loop(&mut gnc, &cfg), 0);
    // The same on the attitude thrusters (pulse on-times instead of the ideal torque).
    let mut pulsed = ReferenceGnc::new(GncConfig {
        attitude_actuator: oils_onboard_stub::fsw::GncAttitude::Thrusters,
        ..GncConfig::default()
    })
    .unwrap();
    assert_eq!(allocations_in_loop(&mut pulsed, &cfg), 0);

    let mut low = ScenarioConfig::default();
    low.initial.altitude_m = 30.0;
    low.initial.horizontal_speed_m_s = 0.0;
    low.initial.thrust_pitch_deg = 90.0;
    let profile = ThrustProfile::parse(
        "t,cmd1,cmd2,cmd3,cmd4,on1,on2,on3,on4\n0,400,400,400,400,1,1,1,1\n2,320,0,320,0,1,0,1,0\n",
    )
    .unwrap();
    let mut playback = ProfilePlayback::new(profile);
    assert_eq!(allocations_in_loop(&mut playback, &low), 0);
}
