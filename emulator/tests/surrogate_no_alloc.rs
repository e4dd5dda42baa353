//! The surrogate's step allocates nothing: a counting global allocator in its own test
//! binary (so no other test's allocations interfere).

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, PropulsionKind, PropulsionSpec};

mod common;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn surrogate_step_does_not_allocate() {
    let mut model = build(&PropulsionSpec::new(
        PropulsionKind::Surrogate,
        &PropulsionConfig::default(),
    ))
    .unwrap();
    let n = common::allocations_over_varied_steps(model.as_mut(), 2000);
    assert_eq!(n, 0, "step allocated {n} times");
}
