//! Frame services over real iceoryx2, both sides in this process: a frame written into
//! the emulator's loan is read in place by the stub with its announcement as the user
//! header; an older frame waiting is dropped on the way to the announced one; a lost one
//! is reported as lost; a frame whose bytes are not the announced ones fails the check.

use oils_shared::link::{create_node, EmulatorLink, FrameSpec, StubLink, WaitStrategy};
use oils_shared::{frame_hash, FrameAnnouncement, FRAME_DEVICE_TEST_CARD};
use std::sync::atomic::AtomicBool;

const BYTES: usize = 4096;

fn publish(emulator: &mut EmulatorLink, seq: u64, fill: u8) -> FrameAnnouncement {
    let buf = emulator
        .frame_buffer(FRAME_DEVICE_TEST_CARD, BYTES)
        .unwrap();
    buf.fill(fill);
    let ann = FrameAnnouncement {
        device: FRAME_DEVICE_TEST_CARD,
        seq,
        bytes: BYTES as u32,
        hash: frame_hash(buf),
        ..Default::default()
    };
    emulator.publish_frame(&ann).unwrap();
    ann
}

#[test]
fn frames_are_read_in_place_in_order_and_checked() {
    let stop = AtomicBool::new(false);
    let run_id = (std::process::id() as u64) << 24 | 0x33_0000;
    let node = create_node("frames-emulator").unwrap();
    let spec = FrameSpec {
        device: FRAME_DEVICE_TEST_CARD,
        max_bytes: BYTES,
    };
    let mut emulator =
        EmulatorLink::create_with_frames(&node, run_id, WaitStrategy::BusyPoll, &[spec]).unwrap();
    assert_eq!(emulator.frame_specs().collect::<Vec<_>>(), [spec]);
    let stub_node = create_node("frames-stub").unwrap();
    let stub = StubLink::open(&stub_node, run_id, None, 1000, &stop).unwrap();
    assert_eq!(
        stub.frame_devices().collect::<Vec<_>>(),
        [FRAME_DEVICE_TEST_CARD]
    );
    emulator.wait_for_peer(1000, &stop).unwrap();

    // Read in place: the header as published, the bytes as written, the hash matching.
    let a0 = publish(&mut emulator, 0, 7);
    let read = stub
        .with_frame(&a0, |h, px| (*h, px.len(), px[0], a0.matches(px)))
        .unwrap();
    assert_eq!(read, Some((a0, BYTES, 7, true)));

    // Two frames waiting, the second announced: the first is dropped on the way.
    let _a1 = publish(&mut emulator, 1, 8);
    let a2 = publish(&mut emulator, 2, 9);
    let read = stub.with_frame(&a2, |h, px| (h.seq, px[0])).unwrap();
    assert_eq!(read, Some((2, 9)));

    // Announced but never published (lost): none; then a later one is there.
    let lost = FrameAnnouncement { seq: 3, ..a2 };
    assert_eq!(stub.with_frame(&lost, |h, _| h.seq).unwrap(), None);
    publish(&mut emulator, 4, 10);
    assert_eq!(
        stub.with_frame(&lost, |h, _| h.seq).unwrap(),
        None,
        "4 > 3: lost"
    );

    // Bytes other than announced fail the check (what the stub refuses the run on).
    let a5 = publish(&mut emulator, 5, 11);
    let forged = FrameAnnouncement {
        hash: a5.hash ^ 1,
        ..a5
    };
    let read = stub
        .with_frame(&forged, |_, px| forged.matches(px))
        .unwrap();
    assert_eq!(read, Some(false));

    // A device without a service, a frame longer than the service's slices: refused.
    assert!(emulator
        .frame_buffer(oils_shared::FRAME_DEVICE_CAMERA, 16)
        .is_err());
    assert!(emulator
        .frame_buffer(FRAME_DEVICE_TEST_CARD, BYTES + 1)
        .is_err());
}
