//! The hifi model's `step` must not allocate: a counting global allocator watches
//! many steps after construction (starts, throttle moves, shutdowns, odd step sizes).

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::{HifiParams, HifiPropulsion};
use oils_emulator::propulsion::{EngineCommand, Propulsion};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn step_does_not_allocate() {
    let mut m = HifiPropulsion::new(&HifiParams::default(), &PropulsionConfig::default()).unwrap();
    let mut commands = Vec::new();
    for k in 0..400 {
        let f = 320.0 + (k % 7) as f64 * 80.0;
        let on = [k % 50 < 45, true, k % 120 < 100, true];
        commands.push(EngineCommand {
            thrust_cmd_n: [f, 800.0 - (f - 320.0), 560.0, f],
            on,
        });
    }
    let before = common::allocations();
    let mut total = 0.0;
    for (k, cmd) in commands.iter().enumerate() {
        let dt = if k % 3 == 0 { 16_000_000 } else { 10_000_000 };
        let out = m.step(cmd, dt);
        total += out.mean_thrust_n[0];
        let _ = m.detail();
        let _ = m.propellant_balance();
    }
    let after = common::allocations();
    assert!(total > 0.0);
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
}
