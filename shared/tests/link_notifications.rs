//! The emulator's side of the link tells a peer that notifies from one that does not
//! (a foreign client ignoring `oils.wait`), so the bench can warn about the second.

use oils_shared::clock::monotonic_ns;
use oils_shared::link::{create_node, EmulatorLink, StubLink, WaitStrategy};
use oils_shared::{Command, PacketHeader, Telemetry};
use std::sync::atomic::AtomicBool;

/// Two steps in one thread: the stub answers each telemetry after the emulator has
/// slept once on its event (a 2 ms wait with nothing there).
fn emulator_wake_counts(tag: u64, stub_wait: WaitStrategy) -> oils_shared::link::WakeCounts {
    let stop = AtomicBool::new(false);
    let run_id = (std::process::id() as u64) << 24 | 0x22_0000 | tag;
    let node = create_node("link-notifications-emulator").unwrap();
    let emulator = EmulatorLink::create(&node, run_id, WaitStrategy::Event).unwrap();
    let stub_node = create_node("link-notifications-stub").unwrap();
    let stub = StubLink::open(&stub_node, run_id, Some(stub_wait), 1000, &stop).unwrap();
    emulator.wait_for_peer(1000, &stop).unwrap();
    for k in 0..2 {
        emulator
            .publish(&Telemetry {
                header: PacketHeader::new(run_id, k, 0),
                ..Default::default()
            })
            .unwrap();
        let tlm = stub
            .receive_until(monotonic_ns() + 1_000_000_000, &stop)
            .unwrap()
            .expect("telemetry");
        assert_eq!(tlm.header.step, k);
        let nothing = emulator
            .receive_until(monotonic_ns() + 2_000_000, &stop)
            .unwrap();
        assert!(nothing.is_none());
        stub.publish(&Command {
            header: PacketHeader::new(run_id, k, 0),
            ..Default::default()
        })
        .unwrap();
        let cmd = emulator
            .receive_until(monotonic_ns() + 1_000_000_000, &stop)
            .unwrap()
            .expect("command");
        assert_eq!(cmd.header.step, k);
    }
    emulator.wake_counts()
}

#[test]
fn a_peer_that_never_notifies_is_seen() {
    // A busy-polling stub never notifies command-ready.
    let counts = emulator_wake_counts(1, WaitStrategy::BusyPoll);
    assert!(counts.sleeps >= 2, "{counts:?}");
    assert_eq!(counts.notifications, 0);
    assert!(counts.peer_never_notified());
}

#[test]
fn a_peer_that_notifies_is_seen_too() {
    // An event stub notifies after each command: the emulator's next sleep sees it.
    let counts = emulator_wake_counts(2, WaitStrategy::Event);
    assert!(counts.sleeps >= 2, "{counts:?}");
    assert!(counts.notifications >= 1, "{counts:?}");
    assert!(!counts.peer_never_notified());
}
