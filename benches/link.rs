//! Round trip between two processes, busy-polling, with the bench's packet sizes
//! (304-byte telemetry out, 120-byte command back):
//!
//! * `bare_iceoryx2_pingpong`: plain iceoryx2 publish-subscribe, nothing else: the floor;
//! * `oils_link_pingpong`: the same exchange through `oils_shared::link` (what lockstep
//!   runs use), with the stub's stamping of the header.
//!
//! * `oils_link_frame_2mib`: the same exchange with a 2 MiB frame (a 1024 x 1024 u16
//!   camera frame) published on its frame service before each telemetry, which announces
//!   it, and read in place by the echo before it answers (protocol v4, zero-copy: a loan
//!   written in place on one side, the sample read in place on the other);
//! * `memcpy_2mib` and `xxh3_64_2mib`: what one copy of such a frame would cost, and
//!   what the stub's check of its hash costs.
//!
//! The echo side is this same executable started again with `OILS_BENCH_ECHO` set, so
//! the round trips cross a real process boundary. Compare `oils run`'s transport p50 with
//! the bare median (the 1.25x criterion), and the frame round trip with the plain
//! one (docs/performance.md, "Frames").

use criterion::{criterion_group, Criterion};
use iceoryx2::prelude::*;
use oils_shared::link::{create_node, EmulatorLink, FrameSpec, StubLink, WaitStrategy};
use oils_shared::{Command, FrameAnnouncement, PacketHeader, Telemetry, FRAME_DEVICE_TEST_CARD};
use std::process::{Child, Command as Process};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.bench.Ping")]
struct Ping {
    seq: u64,
    body: [u64; 174],
}

#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.bench.Pong")]
struct Pong {
    seq: u64,
    body: [u64; 41],
}

const _: () = assert!(core::mem::size_of::<Ping>() == core::mem::size_of::<Telemetry>());
const _: () = assert!(core::mem::size_of::<Pong>() == core::mem::size_of::<Command>());

const STOP: u64 = u64::MAX;

fn names(id: u64) -> (ServiceName, ServiceName) {
    (
        ServiceName::new(&format!("oils-bench/{id:016x}/ping")).unwrap(),
        ServiceName::new(&format!("oils-bench/{id:016x}/pong")).unwrap(),
    )
}

fn bare_echo(id: u64) {
    let node = create_node("bench-echo").unwrap();
    let (ping, pong) = names(id);
    let ping = node
        .service_builder(&ping)
        .publish_subscribe::<Ping>()
        .open_or_create()
        .unwrap();
    let pong = node
        .service_builder(&pong)
        .publish_subscribe::<Pong>()
        .open_or_create()
        .unwrap();
    let sub = ping.subscriber_builder().create().unwrap();
    let publ = pong.publisher_builder().create().unwrap();
    loop {
        if let Some(s) = sub.receive().unwrap() {
            let seq = s.seq;
            if seq == STOP {
                return;
            }
            publ.send_copy(Pong { seq, body: [0; 41] }).unwrap();
        } else {
            core::hint::spin_loop();
        }
    }
}

fn link_echo(id: u64) {
    let stop = AtomicBool::new(false);
    let node = create_node("bench-link-echo").unwrap();
    let link = StubLink::open(&node, id, Some(WaitStrategy::BusyPoll), 10_000, &stop).unwrap();
    loop {
        let Some(t) = link.receive_until(u64::MAX, &stop).unwrap() else {
            return;
        };
        if t.header.step == STOP {
            return;
        }
        let cmd = Command {
            header: PacketHeader::new(t.header.run_id, t.header.step, t.header.t_ns),
            ..Default::default()
        };
        link.publish(&cmd).unwrap();
    }
}

/// A camera frame's size: 1024 x 1024 u16.
const FRAME_BYTES: usize = 1024 * 1024 * 2;

fn frame_echo(id: u64) {
    let stop = AtomicBool::new(false);
    let node = create_node("bench-frame-echo").unwrap();
    let link = StubLink::open(&node, id, Some(WaitStrategy::BusyPoll), 10_000, &stop).unwrap();
    loop {
        let Some(t) = link.receive_until(u64::MAX, &stop).unwrap() else {
            return;
        };
        if t.header.step == STOP {
            return;
        }
        for ann in oils_shared::fsw::announced_frames(&t) {
            // Read in place: the first and last bytes, so the pages are touched.
            let read = link
                .with_frame(ann, |_, px| {
                    std::hint::black_box(px[0]) ^ std::hint::black_box(px[px.len() - 1])
                })
                .unwrap();
            assert!(read.is_some(), "frame {} missing", ann.seq);
        }
        let cmd = Command {
            header: PacketHeader::new(t.header.run_id, t.header.step, t.header.t_ns),
            ..Default::default()
        };
        link.publish(&cmd).unwrap();
    }
}

fn spawn_echo(kind: &str, id: u64) -> Child {
    Process::new(std::env::current_exe().unwrap())
        .env("OILS_BENCH_ECHO", format!("{kind}:{id:x}"))
        .spawn()
        .unwrap()
}

fn bench_bare(c: &mut Criterion) {
    let id = oils_emulator::session::fresh_run_id();
    let node = create_node("bench-bare").unwrap();
    let (ping, pong) = names(id);
    let ping = node
        .service_builder(&ping)
        .publish_subscribe::<Ping>()
        .open_or_create()
        .unwrap();
    let pong = node
        .service_builder(&pong)
        .publish_subscribe::<Pong>()
        .open_or_create()
        .unwrap();
    let publ = ping.publisher_builder().create().unwrap();
    let sub = pong.subscriber_builder().create().unwrap();
    let mut child = spawn_echo("bare", id);
    while ping.dynamic_config().number_of_subscribers() == 0
        || pong.dynamic_config().number_of_publishers() == 0
    {
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut seq = 0u64;
    let mut round_trip = || {
        seq += 1;
        publ.send_copy(Ping {
            seq,
            body: [0; 174],
        })
        .unwrap();
        loop {
            if let Some(s) = sub.receive().unwrap() {
                if s.seq == seq {
                    return;
                }
            }
            core::hint::spin_loop();
        }
    };
    round_trip(); // connection established both ways
    c.bench_function("bare_iceoryx2_pingpong", |b| b.iter(&mut round_trip));
    publ.send_copy(Ping {
        seq: STOP,
        body: [0; 174],
    })
    .unwrap();
    child.wait().unwrap();
}

fn bench_link(c: &mut Criterion) {
    let id = oils_emulator::session::fresh_run_id();
    let stop = AtomicBool::new(false);
    let node = create_node("bench-link").unwrap();
    let link = EmulatorLink::create(&node, id, WaitStrategy::BusyPoll).unwrap();
    let mut child = spawn_echo("link", id);
    link.wait_for_peer(10_000, &stop).unwrap();
    let mut step = 0u64;
    let mut round_trip = || {
        step += 1;
        let tlm = Telemetry {
            header: PacketHeader::new(id, step, 0),
            ..Default::default()
        };
        link.publish(&tlm).unwrap();
        loop {
            if let Some(c) = link.receive_until(u64::MAX, &stop).unwrap() {
                if c.header.step == step {
                    return;
                }
            }
        }
    };
    round_trip();
    c.bench_function("oils_link_pingpong", |b| b.iter(&mut round_trip));
    let end = Telemetry {
        header: PacketHeader::new(id, STOP, 0),
        ..Default::default()
    };
    link.publish(&end).unwrap();
    let until = Instant::now() + Duration::from_secs(5);
    while child.try_wait().unwrap().is_none() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(5));
    }
    let _ = child.kill();
}

fn bench_frame(c: &mut Criterion) {
    let id = oils_emulator::session::fresh_run_id();
    let stop = AtomicBool::new(false);
    let node = create_node("bench-frame").unwrap();
    let spec = FrameSpec {
        device: FRAME_DEVICE_TEST_CARD,
        max_bytes: FRAME_BYTES,
    };
    let mut link =
        EmulatorLink::create_with_frames(&node, id, WaitStrategy::BusyPoll, &[spec]).unwrap();
    let mut child = spawn_echo("frame", id);
    link.wait_for_peer(10_000, &stop).unwrap();
    let mut step = 0u64;
    let mut round_trip = || {
        step += 1;
        // The renderer's place: two bytes written in the loan (rendering is not the
        // transport's cost).
        let buf = link
            .frame_buffer(FRAME_DEVICE_TEST_CARD, FRAME_BYTES)
            .unwrap();
        buf[0] = step as u8;
        buf[FRAME_BYTES - 1] = step as u8;
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_TEST_CARD,
            seq: step,
            bytes: FRAME_BYTES as u32,
            width: 1024,
            height: 1024,
            format: oils_shared::FRAME_FORMAT_U16_LE,
            ..Default::default()
        };
        link.publish_frame(&ann).unwrap();
        let mut tlm = Telemetry {
            header: PacketHeader::new(id, step, 0),
            ..Default::default()
        };
        tlm.sensors.frame_count = 1;
        tlm.sensors.frames[0] = ann;
        link.publish(&tlm).unwrap();
        loop {
            if let Some(c) = link.receive_until(u64::MAX, &stop).unwrap() {
                if c.header.step == step {
                    return;
                }
            }
        }
    };
    round_trip();
    c.bench_function("oils_link_frame_2mib", |b| b.iter(&mut round_trip));
    let end = Telemetry {
        header: PacketHeader::new(id, STOP, 0),
        ..Default::default()
    };
    link.publish(&end).unwrap();
    let until = Instant::now() + Duration::from_secs(5);
    while child.try_wait().unwrap().is_none() && Instant::now() < until {
        std::thread::sleep(Duration::from_millis(5));
    }
    let _ = child.kill();

    let src: Vec<u8> = (0..FRAME_BYTES).map(|i| i as u8).collect();
    let mut dst = vec![0u8; FRAME_BYTES];
    c.bench_function("memcpy_2mib", |b| {
        b.iter(|| dst.copy_from_slice(std::hint::black_box(&src)))
    });
    c.bench_function("xxh3_64_2mib", |b| {
        b.iter(|| oils_shared::frame_hash(std::hint::black_box(&src)))
    });
}

criterion_group!(benches, bench_bare, bench_link, bench_frame);

fn main() {
    if let Ok(spec) = std::env::var("OILS_BENCH_ECHO") {
        let (kind, id) = spec.split_once(':').expect("kind:id");
        let id = u64::from_str_radix(id, 16).expect("hex id");
        match kind {
            "bare" => bare_echo(id),
            "frame" => frame_echo(id),
            _ => link_echo(id),
        }
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
