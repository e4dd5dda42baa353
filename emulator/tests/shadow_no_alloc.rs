//! Shadow mode's step (hifi + surrogate + divergence accumulation) allocates nothing:
//! a counting global allocator in its own test binary.

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, EngineCommand, PropulsionKind};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn shadow_step_does_not_allocate() {
    let mut model = build(PropulsionKind::Shadow, &PropulsionConfig::default());
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    model.step(&cmd, 10_000_000);
    let before = common::allocations();
    let mut sum = 0.0;
    for k in 0..1500 {
        cmd.thrust_cmd_n[k % 4] = 320.0 + (k % 480) as f64;
        // Engine switching takes the valve-refinement path of hifi too.
        cmd.on[3] = k % 700 < 600;
        sum += model.step(&cmd, 10_000_000).thrust_n[0];
    }
    let after = common::allocations();
    assert!(sum.is_finite());
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
    let d = model.diagnostics().unwrap().shadow.unwrap();
    assert_eq!(d.steps, 1501);
}
