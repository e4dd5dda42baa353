//! The surrogate's step allocates nothing: a counting global allocator in its own test
//! binary (so no other test's allocations interfere).

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, EngineCommand, PropulsionKind};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn surrogate_step_does_not_allocate() {
    let mut model = build(PropulsionKind::Surrogate, &PropulsionConfig::default());
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    // Warm up once outside the counted window.
    model.step(&cmd, 10_000_000);
    let before = common::allocations();
    let mut sum = 0.0;
    for k in 0..2000 {
        cmd.thrust_cmd_n[k % 4] = 320.0 + (k % 480) as f64;
        cmd.on[3] = k % 700 < 600;
        // Out-of-envelope commands take the clamping path too.
        cmd.thrust_cmd_n[2] = if k % 500 == 0 { 50.0 } else { 600.0 };
        sum += model.step(&cmd, 10_000_000).thrust_n[0];
    }
    let after = common::allocations();
    assert!(sum.is_finite());
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
}
