//! Shared by the allocation-proof test binaries: a global allocator that counts every
//! allocation and reallocation (per thread). Each binary installs it with
//! `#[global_allocator] static GLOBAL: common::CountingAlloc = common::CountingAlloc;`
//! (a global allocator is per binary, so it cannot live in the library).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting.
pub struct CountingAlloc;

thread_local! {
    /// Allocations and reallocations made by this thread. Per thread, because the test
    /// harness's own threads allocate too (on a loaded machine, inside a test's counting
    /// window: a process-wide count once failed `surrogate_no_alloc` with 4 allocations
    /// no step made). Every step path under test runs on the test's thread. A const
    /// `Cell` without a destructor: reading it never allocates.
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn count_one() {
    // `try_with`: during a thread's teardown the counter may already be gone.
    let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
}

/// Allocations and reallocations so far by the calling thread.
pub fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

// SAFETY: every call is forwarded unchanged to the system allocator.
unsafe impl GlobalAlloc for CountingAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Allocations made by `steps` 10 ms steps of a propulsion model (after one warm-up step
/// outside the count) under commands that exercise its paths: a throttle sweep on every
/// engine, engine 4 switching off and on, and a pulse below the throttle range on engine
/// 3 every 5 s (the surrogate's out-of-envelope clamp).
// Not every test binary that includes this module drives a propulsion model.
#[allow(dead_code)]
pub fn allocations_over_varied_steps(
    model: &mut dyn oils_emulator::propulsion::Propulsion,
    steps: usize,
) -> usize {
    let mut cmd = oils_emulator::propulsion::EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    model.step(&cmd, 10_000_000);
    let before = allocations();
    let mut sum = 0.0;
    for k in 0..steps {
        cmd.thrust_cmd_n[k % 4] = 320.0 + (k % 480) as f64;
        cmd.on[3] = k % 700 < 600;
        cmd.thrust_cmd_n[2] = if k % 500 == 0 { 50.0 } else { 600.0 };
        sum += model.step(&cmd, 10_000_000).thrust_n[0];
    }
    let after = allocations();
    assert!(sum.is_finite(), "the model produced a non-finite thrust");
    after - before
}
