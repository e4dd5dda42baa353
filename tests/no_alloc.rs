//! Hot-loop hygiene, proven: our step paths (emulator and stub) do not allocate.
//!
//! Both sides run in this process (the stub on a thread, over real iceoryx2 services;
//! then the in-process link), through the real scheduler, link, sanitiser, plant,
//! propulsion, digest, recorder (with the true state) and reference GNC. A counting global allocator counts the allocations of the two stepping threads (emulator and stub).
//!
//! One allocation per step is not ours and cannot be avoided from outside: iceoryx2 0.10's
//! `Publisher::loan_uninit` (and so `send_copy`) puts a 48-byte shared-state handle for
//! each loaned sample on the heap (`ChunkMutSharedState::new`). The first test pins that
//! cost exactly (one allocation per publish, none per receive), so an iceoryx2 upgrade
//! that changes it makes the test fail and this proof gets tightened. The second test
//! then accounts for every allocation of a whole descent after its first 1000 steps (by
//! then iceoryx2 has made its lazy connections): between the counter sampled after step
//! 1000 and after the last step, the only allocations allowed are iceoryx2's, one per
//! packet, two packets per step. Any allocation of ours breaks the equation. The snapshot
//! is clean because in lockstep, after step k, the stub has sent Command(k) and waits.

use oils_emulator::clock::LockstepClock;
use oils_emulator::config::{NavNoiseConfig, ScenarioConfig};
use oils_emulator::faults::FaultPlan;
use oils_emulator::link::{BoundLink, InProcLink, Link};
use oils_emulator::plant::Plant;
use oils_emulator::propulsion::{build, PropulsionKind, PropulsionSpec};
use oils_emulator::recorder::Recorder;
use oils_emulator::scheduler::{run_observed, MissPolicy, Outcome, SchedulerConfig};
use oils_emulator::timing::TimingThresholds;
use oils_onboard_stub::gnc::{GncConfig, ReferenceGnc};
use oils_onboard_stub::runner::serve;
use oils_shared::link::{create_node, EmulatorLink, StubLink, WaitStrategy};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

struct Counting;
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
/// Allocations made on the threads that step: the emulator's and the stub's (in process,
/// one thread runs both). The log writer's thread is off the step path, and the test
/// harness's own threads (its slow-test timer, on a loaded host) are not ours.
static STEPPING_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static STEPPING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    if STEPPING.with(|s| s.get()) {
        STEPPING_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn scenario() -> ScenarioConfig {
    ScenarioConfig {
        nav_noise: NavNoiseConfig {
            enabled: true,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Runs a whole lockstep descent over `link` with a log; returns (allocations after
/// step `from`, allocations after the last step, last step index, outcome).
fn allocations_over<L: Link + ?Sized>(
    link: &mut L,
    run_id: u64,
    from: u64,
    counter: &'static AtomicU64,
    faults: &mut FaultPlan,
    (dt_ns, fsw_period_ns): (u64, u64),
) -> (u64, u64, u64, Outcome) {
    let scenario = scenario();
    let mut plant = Plant::new(
        &scenario,
        build(&PropulsionSpec::new(
            PropulsionKind::Ideal,
            &scenario.propulsion,
        ))
        .unwrap(),
    )
    .unwrap();
    let mut devices = oils_emulator::devices::Devices::new(&scenario, 1);
    let stop = AtomicBool::new(false);
    let log = std::env::temp_dir().join(format!("oils-noalloc-{run_id:x}.oilslog"));
    let recorder = Recorder::create(&log, "{}").unwrap();
    let cfg = SchedulerConfig {
        dt_ns,
        fsw_period_ns,
        max_duration_ns: 2_000_000_000_000,
        run_id,
        miss_policy: MissPolicy::Hold,
        link_timeout_ms: 10_000,
        max_thrust_n: scenario.propulsion.max_thrust_n,
        thresholds: TimingThresholds::default(),
        time_exchanges: true,
    };
    let (mut at_from, mut at_last, mut last) = (0u64, 0u64, 0u64);
    let mut observe = |k: u64, _: &oils_emulator::plant::Plant| {
        let now = counter.load(Ordering::SeqCst);
        if k == from {
            at_from = now;
        }
        at_last = now;
        last = k;
    };
    let summary = run_observed(
        &cfg,
        &mut plant,
        &mut devices,
        link,
        &mut LockstepClock::new(10_000),
        faults,
        Some(&recorder),
        &stop,
        Some(&mut observe),
    )
    .unwrap();
    recorder.finish().unwrap();
    std::fs::remove_file(&log).ok();
    (at_from, at_last, last, summary.outcome)
}

/// A whole descent over iceoryx2 with the stub on a thread of this process.
fn allocations_through_descent(
    run_id: u64,
    wait: WaitStrategy,
    from: u64,
) -> (u64, u64, u64, Outcome) {
    let stop = AtomicBool::new(false);
    let node = create_node("no-alloc-emulator").unwrap();
    let link = EmulatorLink::create(&node, run_id, wait).unwrap();
    let stub = std::thread::spawn(move || {
        let stop = AtomicBool::new(false);
        let node = create_node("no-alloc-stub").unwrap();
        let link = StubLink::open(&node, run_id, None, 10_000, &stop).unwrap();
        let mut gnc = ReferenceGnc::new(GncConfig::default()).unwrap();
        STEPPING.with(|s| s.set(true));
        serve(&link, &mut gnc, 10_000, &stop).unwrap()
    });
    let joined = link.wait_for_peer(10_000, &stop).unwrap();
    // As a session runs it: bound to the stub that joined (checked on every command).
    let mut link = BoundLink::new(link, joined, false);
    STEPPING.with(|s| s.set(true));
    let out = allocations_over(
        &mut link,
        run_id,
        from,
        &STEPPING_ALLOCATIONS,
        &mut FaultPlan::none(),
        (10_000_000, 10_000_000),
    );
    STEPPING.with(|s| s.set(false));
    stub.join().unwrap();
    out
}

/// Allocations of one `publish` and of one `try_receive`, measured on a live link with
/// each packet received before the next is sent (as in a run).
fn iceoryx2_cost_per_publish_and_receive() -> (u64, u64) {
    let run_id = 0xfeed_0000_0000 + std::process::id() as u64;
    let stop = AtomicBool::new(false);
    let node = create_node("probe-emulator").unwrap();
    let emulator = EmulatorLink::create(&node, run_id, WaitStrategy::BusyPoll).unwrap();
    let stub_node = create_node("probe-stub").unwrap();
    let stub = StubLink::open(&stub_node, run_id, None, 1000, &stop).unwrap();
    emulator.wait_for_peer(1000, &stop).unwrap();
    let tlm = oils_shared::Telemetry::default();
    for _ in 0..10 {
        emulator.publish(&tlm).unwrap();
        stub.try_receive().unwrap().unwrap();
    }
    const N: u64 = 1000;
    let (mut publish_allocs, mut receive_allocs) = (0, 0);
    for _ in 0..N {
        let a0 = ALLOCATIONS.load(Ordering::SeqCst);
        emulator.publish(&tlm).unwrap();
        let a1 = ALLOCATIONS.load(Ordering::SeqCst);
        stub.try_receive().unwrap().unwrap();
        let a2 = ALLOCATIONS.load(Ordering::SeqCst);
        publish_allocs += a1 - a0;
        receive_allocs += a2 - a1;
    }
    assert_eq!(
        publish_allocs % N,
        0,
        "{publish_allocs} allocations for {N} publishes"
    );
    (publish_allocs / N, receive_allocs)
}

/// One test, run serially: the allocation counter is global to the process.
#[test]
fn step_paths_do_not_allocate() {
    let (per_publish, receive_allocs) = iceoryx2_cost_per_publish_and_receive();
    assert_eq!(
        per_publish, 1,
        "iceoryx2's per-loan allocation changed: tighten this proof"
    );
    assert_eq!(receive_allocs, 0, "receiving must not allocate");
    const FROM: u64 = 1000;
    let base = (std::process::id() as u64) << 24;
    for (i, wait) in [
        WaitStrategy::BusyPoll,
        WaitStrategy::Hybrid { spin_ns: 20_000 },
    ]
    .into_iter()
    .enumerate()
    {
        let (at_from, at_last, last, outcome) =
            allocations_through_descent(base + i as u64, wait, FROM);
        assert_eq!(
            outcome,
            Outcome::Landed,
            "the run covers every GNC phase down to touchdown"
        );
        assert!(last > 50_000, "{last} steps");
        // Two packets per step (Telemetry(k+1) and Command(k+1)), one iceoryx2 loan each.
        let steps = last - FROM;
        assert_eq!(
            at_last - at_from,
            2 * per_publish * steps,
            "{wait:?}: steps {FROM}..{last} made {} allocations; iceoryx2's loans account for {}",
            at_last - at_from,
            2 * per_publish * steps
        );
    }
    // In process there is no iceoryx2 loan: not a single allocation on the stepping
    // thread, which runs the emulator and the flight software.
    let mut link = InProcLink::new(Box::new(ReferenceGnc::new(GncConfig::default()).unwrap()));
    STEPPING.with(|s| s.set(true));
    let (at_from, at_last, last, outcome) = allocations_over(
        &mut link,
        base + 7,
        FROM,
        &STEPPING_ALLOCATIONS,
        &mut FaultPlan::none(),
        (10_000_000, 10_000_000),
    );
    STEPPING.with(|s| s.set(false));
    assert_eq!(outcome, Outcome::Landed);
    assert!(last > 50_000, "{last} steps");
    assert_eq!(
        at_last - at_from,
        0,
        "in-process steps {FROM}..{last} allocated"
    );
    // The compiled faults on the step path: sensor, link (the `FaultyLink` wrapper:
    // delay line, duplicate, corruption, withheld telemetry) and plant faults fire and
    // clear after step FROM without an allocation.
    let specs: Vec<oils_emulator::faults::FaultSpec> = [
        "sensor-noise:altitude_m,sigma=0.5@t=20,for=5",
        "sensor-frozen:rate_rad_s@t=22,for=1",
        "sensor-dropout:velocity_m_s@t=24,for=1",
        "command-delay,steps=3@t=30,for=2",
        "command-duplicate@t=34,for=1",
        "command-corrupt,bits=2@t=36,for=1",
        "telemetry-drop@t=40,for=0.5",
        "stub-pause@t=42,for=0.5",
        "command-drop@t=44,for=0.2",
        "thrust-degraded:3,factor=0.9@t=46,for=2",
    ]
    .iter()
    .map(|f| f.parse().unwrap())
    .collect();
    let mut faults = FaultPlan::compile(&specs, 5).unwrap();
    let mut link = InProcLink::new(Box::new(ReferenceGnc::new(GncConfig::default()).unwrap()));
    STEPPING.with(|s| s.set(true));
    let (at_from, at_last, last, _) = allocations_over(
        &mut link,
        base + 8,
        FROM,
        &STEPPING_ALLOCATIONS,
        &mut faults,
        (10_000_000, 10_000_000),
    );
    STEPPING.with(|s| s.set(false));
    assert!(last > 5_000, "{last} steps");
    assert_eq!(faults.report().len(), specs.len(), "every fault fired");
    assert_eq!(
        at_last - at_from,
        0,
        "in-process steps {FROM}..{last} with faults allocated"
    );
    // Multi-rate: the plant at 5 ms, the flight software every 20 ms (four plant steps
    // a cycle, the command held over them) allocates nothing either. The observer counts
    // plant steps.
    let mut link = InProcLink::new(Box::new(ReferenceGnc::new(GncConfig::default()).unwrap()));
    STEPPING.with(|s| s.set(true));
    let (at_from, at_last, last, _) = allocations_over(
        &mut link,
        base + 9,
        4 * FROM,
        &STEPPING_ALLOCATIONS,
        &mut FaultPlan::none(),
        (5_000_000, 20_000_000),
    );
    STEPPING.with(|s| s.set(false));
    assert!(last > 8 * FROM, "{last} plant steps");
    assert_eq!(
        at_last - at_from,
        0,
        "multi-rate plant steps {}..{last} allocated",
        4 * FROM
    );
}
