//! The plant's per-step paths (`step`, `telemetry`) must not touch the heap once built.
//! A counting global allocator in its own test binary proves it.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_shared::PacketHeader;

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn step_and_telemetry_do_not_allocate_through_flight_and_touchdown() {
    let mut cfg = ScenarioConfig::default();
    cfg.initial.altitude_m = 20.0;
    cfg.initial.horizontal_speed_m_s = 0.5;
    cfg.initial.thrust_pitch_deg = 90.0;
    cfg.nav_noise.enabled = true;
    let mut plant = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut devices = Devices::new(&cfg, 7);
    let cmd = ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [400.0; 4],
            on: [true, true, false, true],
        },
        torque_cmd_body_nm: [3.0, -2.0, 1.0],
        ..Default::default()
    };

    let before = common::allocations();
    let mut touched = false;
    for k in 0..100_000u64 {
        let tlm = devices.telemetry(&plant, PacketHeader::new(1, k, plant.time_ns()));
        std::hint::black_box(&tlm);
        if let PlantStatus::Touchdown(td) = plant.step(&cmd, 10_000_000) {
            std::hint::black_box(td);
            touched = true;
            // One more call each after touchdown (frozen path).
            std::hint::black_box(plant.step(&cmd, 10_000_000));
            std::hint::black_box(devices.telemetry(&plant, PacketHeader::new(1, k + 1, 0)));
            break;
        }
    }
    let after = common::allocations();
    assert!(touched, "the run should reach the contact search path");
    assert_eq!(
        after - before,
        0,
        "plant allocated {} times",
        after - before
    );
}

#[test]
fn thruster_path_does_not_allocate_through_flight_and_touchdown() {
    let mut cfg = ScenarioConfig::default();
    cfg.initial.altitude_m = 20.0;
    cfg.initial.horizontal_speed_m_s = 0.5;
    cfg.initial.thrust_pitch_deg = 90.0;
    let mut plant = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut devices = Devices::new(&cfg, 7);
    let cycle_ns = 20_000_000u64;
    let mut cmd = ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [400.0; 4],
            on: [true, true, false, true],
        },
        use_thrusters: true,
        ..Default::default()
    };

    let before = common::allocations();
    let mut touched = false;
    'run: for k in 0..50_000u64 {
        // Every on-time path: off, below the minimum, a pulse, the whole cycle; a
        // missed cycle every 7th (the command held, cycle start and all).
        if k % 7 != 6 {
            cmd.cycle_start_ns = (k * cycle_ns) as i64;
            for (i, t) in cmd.thruster_on_time_ns.iter_mut().enumerate() {
                *t = [0, 4_000_000, 12_000_000, cycle_ns][(i + k as usize) % 4];
            }
        }
        for _ in 0..2 {
            let tlm = devices.telemetry(&plant, PacketHeader::new(1, k, plant.time_ns()));
            std::hint::black_box(&tlm);
            std::hint::black_box(plant.thrusters().thrust_now_n());
            if let PlantStatus::Touchdown(td) = plant.step(&cmd, 10_000_000) {
                std::hint::black_box(td);
                touched = true;
                std::hint::black_box(plant.step(&cmd, 10_000_000));
                break 'run;
            }
        }
    }
    let after = common::allocations();
    assert!(touched, "the run should reach the contact search path");
    assert!(plant.rcs_propellant_used_kg() > 0.0, "the thrusters fired");
    assert_eq!(
        after - before,
        0,
        "plant allocated {} times",
        after - before
    );
}
