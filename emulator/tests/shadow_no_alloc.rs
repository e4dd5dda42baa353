//! Shadow mode's step (hifi + surrogate + divergence accumulation) allocates nothing:
//! a counting global allocator in its own test binary.

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, PropulsionKind, PropulsionSpec};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn shadow_step_does_not_allocate() {
    let mut model = build(&PropulsionSpec::new(
        PropulsionKind::Shadow,
        &PropulsionConfig::default(),
    ))
    .unwrap();
    // Engine switching takes the valve-refinement path of hifi too.
    let n = common::allocations_over_varied_steps(model.as_mut(), 1500);
    assert_eq!(n, 0, "step allocated {n} times");
    let d = model.diagnostics().unwrap().shadow.unwrap();
    assert_eq!(d.steps, 1501);
}
