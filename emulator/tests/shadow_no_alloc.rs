//! Shadow mode's step (hifi + surrogate + divergence accumulation) allocates nothing:
//! a counting global allocator in its own test binary.

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::{build, EngineCommand, PropulsionKind};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
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
static GLOBAL: Counting = Counting;

#[test]
fn shadow_step_does_not_allocate() {
    let mut model = build(PropulsionKind::Shadow, &PropulsionConfig::default());
    let mut cmd = EngineCommand {
        thrust_cmd_n: [600.0; 4],
        on: [true; 4],
    };
    model.step(&cmd, 10_000_000);
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut sum = 0.0;
    for k in 0..1500 {
        cmd.thrust_cmd_n[k % 4] = 320.0 + (k % 480) as f64;
        // Engine switching takes the valve-refinement path of hifi too.
        cmd.on[3] = k % 700 < 600;
        sum += model.step(&cmd, 10_000_000).thrust_n[0];
    }
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(sum.is_finite());
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
    let d = model.diagnostics().unwrap().shadow.unwrap();
    assert_eq!(d.steps, 1501);
}
