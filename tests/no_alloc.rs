//! Hot-loop hygiene, proven: the emulator's and the stub's step paths do not allocate.
//!
//! Both sides run in this process (the stub on a thread, over real iceoryx2 services),
//! through the real scheduler, link, sanitiser, plant, propulsion, digest, recorder and
//! reference GNC. A counting global allocator counts every allocation on every thread.
//! Setup and teardown allocate a fixed amount whatever the run length, so a run of
//! 5 000 steps and a whole descent of more than 100 000 steps must allocate exactly the
//! same number of times: any per-step allocation would show up as a difference.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::plant::Plant;
use oils_emulator::propulsion::{build, PropulsionKind};
use oils_emulator::recorder::Recorder;
use oils_emulator::scheduler::{run, MissPolicy, Mode, Outcome, SchedulerConfig};
use oils_emulator::timing::TimingThresholds;
use oils_onboard_stub::gnc::{GncConfig, ReferenceGnc};
use oils_onboard_stub::runner::serve;
use oils_shared::link::{create_node, EmulatorLink, StubLink, WaitStrategy};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

struct Counting;
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made while the scheduler runs `duration_s` of simulated time (setup of
/// the plant, link and stub excluded; the scheduler's own setup included).
fn allocations_during_run(run_id: u64, duration_s: f64, wait: WaitStrategy) -> (u64, u64, Outcome) {
    let scenario = ScenarioConfig::default();
    let mut plant = Plant::new(
        &scenario,
        build(PropulsionKind::Ideal, &scenario.propulsion),
        1,
    )
    .unwrap();
    let stop = AtomicBool::new(false);
    let node = create_node("no-alloc-emulator").unwrap();
    let link = EmulatorLink::create(&node, run_id, wait).unwrap();
    let log = std::env::temp_dir().join(format!("oils-noalloc-{run_id:x}.oilslog"));
    let recorder = Recorder::create(&log, "{}").unwrap();
    let stub = std::thread::spawn(move || {
        let stop = AtomicBool::new(false);
        let node = create_node("no-alloc-stub").unwrap();
        let link = StubLink::open(&node, run_id, None, 10_000, &stop).unwrap();
        let mut gnc = ReferenceGnc::new(GncConfig::default()).unwrap();
        serve(&link, &mut gnc, 10_000, &stop).unwrap()
    });
    link.wait_for_peer(10_000, &stop).unwrap();
    let cfg = SchedulerConfig {
        mode: Mode::Lockstep,
        speed: 1.0,
        dt_ns: 10_000_000,
        max_duration_ns: (duration_s * 1e9) as i64,
        run_id,
        deadline_frac: 0.5,
        miss_policy: MissPolicy::Hold,
        link_timeout_ms: 10_000,
        startup_timeout_ms: 10_000,
        wake_spin_ns: 0,
        thresholds: TimingThresholds::default(),
    };
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let summary = run(&cfg, &scenario, &mut plant, &link, Some(&recorder), &stop).unwrap();
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    stub.join().unwrap();
    recorder.finish().unwrap();
    std::fs::remove_file(&log).ok();
    (after - before, summary.steps, summary.outcome)
}

#[test]
fn step_paths_do_not_allocate() {
    let base = (std::process::id() as u64) << 24;
    for (i, wait) in [
        WaitStrategy::BusyPoll,
        WaitStrategy::Hybrid { spin_ns: 20_000 },
    ]
    .into_iter()
    .enumerate()
    {
        let (short_allocs, short_steps, _) =
            allocations_during_run(base + 2 * i as u64, 50.0, wait);
        let (long_allocs, long_steps, outcome) =
            allocations_during_run(base + 2 * i as u64 + 1, 2000.0, wait);
        assert_eq!(short_steps, 5_000);
        assert_eq!(
            outcome,
            Outcome::Landed,
            "the long run covers every GNC phase down to touchdown"
        );
        assert!(long_steps > 20 * short_steps);
        assert_eq!(
            long_allocs, short_allocs,
            "{:?}: {} steps made {long_allocs} allocations, {} steps made {short_allocs}",
            wait, long_steps, short_steps
        );
    }
}
