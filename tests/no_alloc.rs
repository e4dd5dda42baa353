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
use oils_emulator::faults::{FaultPlan, FaultSpec};
use oils_emulator::link::{BoundLink, InProcLink, Link};
use oils_emulator::plant::Plant;
use oils_emulator::propulsion::{build, PropulsionKind, PropulsionSpec};
use oils_emulator::recorder::Recorder;
use oils_emulator::scheduler::{run_observed, MissPolicy, Outcome, SchedulerConfig};
use oils_emulator::sensors::{FrameRack, SensorsConfig, TestCardConfig};
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

/// The test card at its defaults (1024 x 1024 u16, 2 MiB, 1 Hz): a frame device whose
/// frames go through the link's frame buffers.
fn test_card() -> FrameRack {
    let cfg = SensorsConfig {
        test_card: TestCardConfig {
            enabled: true,
            ..Default::default()
        },
        ..Default::default()
    };
    // No camera: the ground and the sun light nothing here.
    let ground = oils_emulator::plant::ground::Ground::Sphere {
        radius_m: 1_737_400.0,
    };
    FrameRack::from_config(&cfg, 1, &ground, nalgebra::Vector3::x(), 1_737_400.0)
        .unwrap()
        .unwrap()
}

/// Frames the test card has published by simulated time `t_ns` (one at each whole
/// second).
fn test_card_frames_by(t_ns: i64) -> u64 {
    (t_ns / 1_000_000_000) as u64
}

/// Runs a whole lockstep descent over `link` with a log (and the test card on board
/// when `frames`); returns (allocations after step `from`, allocations after the last
/// step, last step index, outcome, frames published between the two).
fn allocations_over<L: Link + ?Sized>(
    link: &mut L,
    run_id: u64,
    from: u64,
    counter: &'static AtomicU64,
    faults: &mut FaultPlan,
    (dt_ns, fsw_period_ns): (u64, u64),
) -> (u64, u64, u64, Outcome) {
    let (a, b, c, d, _) = allocations_with_frames(
        link,
        run_id,
        from,
        counter,
        faults,
        (dt_ns, fsw_period_ns),
        false,
    );
    (a, b, c, d)
}

/// [`allocations_over`], with the test card on board when `frames`.
#[allow(clippy::too_many_arguments)]
fn allocations_with_frames<L: Link + ?Sized>(
    link: &mut L,
    run_id: u64,
    from: u64,
    counter: &'static AtomicU64,
    faults: &mut FaultPlan,
    (dt_ns, fsw_period_ns): (u64, u64),
    frames: bool,
) -> (u64, u64, u64, Outcome, u64) {
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
    if frames {
        devices.attach_frames(test_card());
    }
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
    let (mut frames_from, mut frames_last) = (0u64, 0u64);
    let mut observe = |k: u64, plant: &oils_emulator::plant::Plant| {
        let now = counter.load(Ordering::SeqCst);
        if k == from {
            at_from = now;
            frames_from = test_card_frames_by(plant.time_ns());
        }
        at_last = now;
        frames_last = test_card_frames_by(plant.time_ns());
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
    if frames {
        let published: Vec<(u32, u64)> = devices.frames().unwrap().published().collect();
        assert_eq!(published[0].1, frames_last, "one test-card frame a second");
    }
    (
        at_from,
        at_last,
        last,
        summary.outcome,
        frames_last - frames_from,
    )
}

/// A whole descent over iceoryx2 with the stub on a thread of this process (with the
/// test card's frames on their own service when `frames`).
fn allocations_through_descent(
    run_id: u64,
    wait: WaitStrategy,
    from: u64,
    frames: bool,
) -> (u64, u64, u64, Outcome, u64) {
    let stop = AtomicBool::new(false);
    let node = create_node("no-alloc-emulator").unwrap();
    let specs = if frames { test_card().specs() } else { vec![] };
    let link = EmulatorLink::create_with_frames(&node, run_id, wait, &specs).unwrap();
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
    let out = allocations_with_frames(
        &mut link,
        run_id,
        from,
        &STEPPING_ALLOCATIONS,
        &mut FaultPlan::none(),
        (10_000_000, 10_000_000),
        frames,
    );
    STEPPING.with(|s| s.set(false));
    let served = stub.join().unwrap();
    if frames {
        assert_eq!(served.frames_missed, 0);
        assert!(served.frames > 900, "{} frames checked", served.frames);
    }
    out
}

/// Allocations of one frame's loan, render-free publish and in-place read (2 MiB over
/// a frame service), measured as [`iceoryx2_cost_per_publish_and_receive`].
fn iceoryx2_cost_per_frame() -> u64 {
    let run_id = 0xfeee_0000_0000 + std::process::id() as u64;
    let stop = AtomicBool::new(false);
    let node = create_node("probe-frames-emulator").unwrap();
    let specs = test_card().specs();
    let mut emulator =
        EmulatorLink::create_with_frames(&node, run_id, WaitStrategy::BusyPoll, &specs).unwrap();
    let stub_node = create_node("probe-frames-stub").unwrap();
    let stub = StubLink::open(&stub_node, run_id, None, 1000, &stop).unwrap();
    emulator.wait_for_peer(1000, &stop).unwrap();
    let bytes = specs[0].max_bytes;
    let mut one = |seq: u64| {
        let buf = emulator
            .frame_buffer(oils_shared::FRAME_DEVICE_TEST_CARD, bytes)
            .unwrap();
        buf[0] = seq as u8;
        let ann = oils_shared::FrameAnnouncement {
            device: oils_shared::FRAME_DEVICE_TEST_CARD,
            seq,
            bytes: bytes as u32,
            ..Default::default()
        };
        emulator.publish_frame(&ann).unwrap();
        let got = stub.with_frame(&ann, |h, px| (h.seq, px.len())).unwrap();
        assert_eq!(got, Some((seq, bytes)));
    };
    for seq in 0..10 {
        one(seq);
    }
    const N: u64 = 200;
    let a0 = ALLOCATIONS.load(Ordering::SeqCst);
    for seq in 10..10 + N {
        one(seq);
    }
    let allocs = ALLOCATIONS.load(Ordering::SeqCst) - a0;
    assert_eq!(allocs % N, 0, "{allocs} allocations for {N} frames");
    allocs / N
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
        let (at_from, at_last, last, outcome, _) =
            allocations_through_descent(base + i as u64, wait, FROM, false);
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
    // Frames (protocol v4): the test card's 2 MiB frames over their own service, loaned,
    // rendered in place, read in place and hash-checked by the stub: one iceoryx2 loan a
    // frame, like a packet's, and nothing of ours.
    let per_frame = iceoryx2_cost_per_frame();
    assert_eq!(
        per_frame, per_publish,
        "a frame's loan costs what a packet's does"
    );
    let (at_from, at_last, last, outcome, frames) =
        allocations_through_descent(base + 5, WaitStrategy::BusyPoll, FROM, true);
    assert_eq!(outcome, Outcome::Landed);
    assert!(frames > 900, "{frames} frames in the window");
    let steps = last - FROM;
    assert_eq!(
        at_last - at_from,
        2 * per_publish * steps + per_frame * frames,
        "with frames: steps {FROM}..{last} and {frames} frames made {} allocations",
        at_last - at_from
    );
    // In process there is no iceoryx2 loan: not a single allocation on the stepping
    // thread, which runs the emulator and the flight software (frames included, into
    // buffers allocated before tick 0).
    // With the frame faults that still publish (frozen, outage, glare, dead quadrant)
    // firing and clearing after step FROM: the frozen frame is repeated from the copy
    // kept since the rack was built.
    let frame_faults: Vec<FaultSpec> = [
        "sensor-blinding:test-card,level=0.5@t=100,for=3",
        "sensor-dead-quadrant:test-card,quadrant=4@t=110,for=3",
        "sensor-frozen:test-card@t=120,for=3",
        "sensor-inhibit:test-card@t=130,for=3",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let mut frame_faults = FaultPlan::compile(&frame_faults, 1).unwrap();
    let mut link = InProcLink::new(Box::new(ReferenceGnc::new(GncConfig::default()).unwrap()))
        .with_frames(&test_card().specs());
    STEPPING.with(|s| s.set(true));
    let (at_from, at_last, last, outcome, frames) = allocations_with_frames(
        &mut link,
        base + 6,
        FROM,
        &STEPPING_ALLOCATIONS,
        &mut frame_faults,
        (10_000_000, 10_000_000),
        true,
    );
    STEPPING.with(|s| s.set(false));
    assert_eq!(outcome, Outcome::Landed);
    assert!(frames > 900, "{frames} frames");
    assert_eq!(
        at_last - at_from,
        0,
        "in-process steps {FROM}..{last} with frames allocated"
    );
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
