//! The plant's per-step paths (`step`, `telemetry`) must not touch the heap once built.
//! A counting global allocator in its own test binary proves it.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_shared::PacketHeader;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct CountingAlloc;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: CountingAlloc = CountingAlloc;

#[test]
fn step_and_telemetry_do_not_allocate_through_flight_and_touchdown() {
    let mut cfg = ScenarioConfig::default();
    cfg.initial.altitude_m = 20.0;
    cfg.initial.horizontal_speed_m_s = 0.5;
    cfg.initial.thrust_pitch_deg = 90.0;
    cfg.nav_noise.enabled = true;
    let mut plant = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion)), 7).unwrap();
    let cmd = ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [400.0; 4],
            on: [true, true, false, true],
        },
        torque_cmd_body_nm: [3.0, -2.0, 1.0],
    };

    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut touched = false;
    for k in 0..100_000u64 {
        let tlm = plant.telemetry(PacketHeader::new(1, k, plant.time_ns()));
        std::hint::black_box(&tlm);
        if let PlantStatus::Touchdown(td) = plant.step(&cmd, 10_000_000) {
            std::hint::black_box(td);
            touched = true;
            // One more call each after touchdown (frozen path).
            std::hint::black_box(plant.step(&cmd, 10_000_000));
            std::hint::black_box(plant.telemetry(PacketHeader::new(1, k + 1, 0)));
            break;
        }
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(touched, "the run should reach the contact search path");
    assert_eq!(
        after - before,
        0,
        "plant allocated {} times",
        after - before
    );
}
