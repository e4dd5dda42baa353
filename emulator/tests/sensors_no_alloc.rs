//! The sensor suite's per-step paths (`after_plant_step`, `fill_frame`, `set_fault`)
//! must not touch the heap once built: a counting global allocator in its own test
//! binary proves it, on the plant's own truth over a cratered terrain down to touchdown.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_emulator::sensors::{DeviceFault, SensorSuite, SensorTarget};
use oils_emulator::world::terrain::{SyntheticSpec, TerrainSpec};
use oils_shared::SensorFrame;

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn after_plant_step_and_fill_frame_do_not_allocate() {
    let mut cfg = ScenarioConfig {
        terrain: TerrainSpec::Synthetic(SyntheticSpec {
            extent_m: 1000.0,
            spacing_m: 2.0,
            crater_min_diameter_m: 8.0,
            crater_max_diameter_m: 100.0,
            ..SyntheticSpec::default()
        }),
        ..ScenarioConfig::default()
    };
    cfg.initial.altitude_m = 400.0;
    cfg.initial.horizontal_speed_m_s = 5.0;
    cfg.initial.vertical_speed_m_s = -20.0;
    cfg.initial.thrust_pitch_deg = 80.0;
    cfg.initial.range_to_site_m = 0.0;
    cfg.sensors.star_tracker.outage_start_s = vec![1.0];
    cfg.sensors.star_tracker.outage_duration_s = vec![1.0];
    let mut plant = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut suite = SensorSuite::new(&cfg.sensors, 7).unwrap();
    let mut frame = SensorFrame::default();
    let cmd = ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [500.0; 4],
            on: [true; 4],
        },
        torque_cmd_body_nm: [1.0, -2.0, 0.5],
        ..Default::default()
    };
    let faults = [
        (SensorTarget::ImuGyro, DeviceFault::Bias { value: 1e-4 }),
        (SensorTarget::Imu, DeviceFault::Frozen),
        (
            SensorTarget::StarTracker,
            DeviceFault::Spike { value: 50.0 },
        ),
        (
            SensorTarget::LaserAltimeter,
            DeviceFault::Noise { factor: 3.0 },
        ),
        (SensorTarget::RfAltimeter, DeviceFault::Dropout),
        (SensorTarget::Velocimeter, DeviceFault::Inhibited),
    ];

    let before = common::allocations();
    let mut samples = 0u64;
    let mut locked = 0usize;
    let mut touched = false;
    for k in 1..=200_000i64 {
        let status = plant.step(&cmd, 1_000_000);
        suite.after_plant_step(&plant.sensor_truth());
        if k % 10 == 0 {
            suite.fill_frame(plant.time_ns(), &mut frame);
            samples +=
                u64::from(frame.imu_count + frame.laser_altimeter_count + frame.velocimeter_count);
            locked += frame.laser_altimeter[..frame.laser_altimeter_count as usize]
                .iter()
                .filter(|s| s.valid == 1)
                .count();
        }
        if k % 2000 == 0 {
            let (target, fault) = faults[(k / 2000) as usize % faults.len()];
            suite.set_fault(target, fault, (k / 2000) % 2 == 0);
        }
        if let PlantStatus::Touchdown(_) = status {
            touched = true;
            break;
        }
    }
    std::hint::black_box(suite.dropped());
    let after = common::allocations();
    assert!(touched, "the descent should reach the ground");
    assert!(samples > 1000, "{samples} samples");
    assert!(
        locked > 10,
        "the laser altimeter should see the terrain ({locked} returns)"
    );
    assert_eq!(
        after - before,
        0,
        "the suite allocated {} times",
        after - before
    );
}
