//! The hifi model's `step` must not allocate: a counting global allocator watches
//! many steps after construction (starts, throttle moves, shutdowns, odd step sizes).

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::{HifiParams, HifiPropulsion};
use oils_emulator::propulsion::{EngineCommand, Propulsion};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

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
    let before = ALLOCS.load(Ordering::Relaxed);
    let mut total = 0.0;
    for (k, cmd) in commands.iter().enumerate() {
        let dt = if k % 3 == 0 { 16_000_000 } else { 10_000_000 };
        let out = m.step(cmd, dt);
        total += out.mean_thrust_n[0];
        let _ = m.detail();
        let _ = m.propellant_balance();
    }
    let after = ALLOCS.load(Ordering::Relaxed);
    assert!(total > 0.0);
    assert_eq!(after - before, 0, "step allocated {} times", after - before);
}
