//! Service names of one run.
//!
//! Every run has its own `run_id`, and every service name contains it, so two benches on
//! one machine never meet, and a run started after a crash never opens a dead run's
//! services. A flight-software author in C or Python opens exactly these names.

use core::fmt::Write;

/// Prefix of every oils service.
pub const SERVICE_PREFIX: &str = "oils";

/// The iceoryx2 version of the services (a client must use the same one; docs/protocol.md).
pub const ICEORYX2_VERSION: &str = "0.10.0";

/// Longest service name this module builds.
pub const MAX_SERVICE_NAME_LEN: usize = 64;

/// A service name built without heap allocation (the design card's `heapless`).
pub type ServiceNameBuf = heapless::String<MAX_SERVICE_NAME_LEN>;

/// The four services of run `run_id`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunServices {
    /// The run's identifier.
    pub run_id: u64,
}

impl RunServices {
    /// Services of run `run_id`.
    pub const fn new(run_id: u64) -> Self {
        Self { run_id }
    }

    /// Publish-subscribe service carrying [`crate::Telemetry`].
    pub fn telemetry(&self) -> ServiceNameBuf {
        self.name("telemetry")
    }

    /// Publish-subscribe service carrying [`crate::Command`].
    pub fn command(&self) -> ServiceNameBuf {
        self.name("command")
    }

    /// Event service: the emulator notifies after publishing telemetry.
    pub fn telemetry_event(&self) -> ServiceNameBuf {
        self.name("telemetry-ready")
    }

    /// Event service: the stub notifies after publishing a command.
    pub fn command_event(&self) -> ServiceNameBuf {
        self.name("command-ready")
    }

    /// What a flight software started by hand needs to join this run (printed by
    /// `oils run --no-stub`): the four services and what to do with each, the protocol
    /// version, schema hash and wait strategy, and two ready-made clients.
    pub fn client_guide(&self, wait: crate::link::WaitStrategy) -> String {
        let notify = if wait.notifies() {
            "notify after each command"
        } else {
            "do not notify (the emulator busy-polls)"
        };
        let woken = if wait.notifies() {
            "notified after each telemetry: wait on it"
        } else {
            "never notified (busy): poll the telemetry subscriber"
        };
        let id = self.run_id;
        let (telemetry, command) = payload_types();
        format!(
            "oils: run {id:016x} waits for flight software on its iceoryx2 {} services (ipc, in your oils domain: docs/protocol.md \"Domain\"):\n\
             \x20   {:<38} publish-subscribe {telemetry}: subscribe\n\
             \x20   {:<38} publish-subscribe {command}: publish\n\
             \x20   {:<38} event: {woken}\n\
             \x20   {:<38} event: {notify}\n\
             \x20 protocol v{}, schema hash {:#018x}, wait {} (docs/protocol.md). For example:\n\
             \x20   oils stub --run-id {id:016x} --fsw gnc|c:PATH/libmyfsw.so\n\
             \x20   PYTHONPATH=python python -m oils_fsw.examples.terminal_descent --run-id {id:016x}",
            ICEORYX2_VERSION,
            self.telemetry().as_str(),
            self.command().as_str(),
            self.telemetry_event().as_str(),
            self.command_event().as_str(),
            crate::PROTOCOL_VERSION,
            crate::SCHEMA_HASH,
            wait.as_str(),
        )
    }

    /// Publish-subscribe service carrying frame device `device_name`'s frames (protocol
    /// v4): dynamic `[u8]` slices with a [`crate::FrameAnnouncement`] user header.
    pub fn frame(&self, device_name: &str) -> ServiceNameBuf {
        let mut s = ServiceNameBuf::default();
        // Cannot overflow: 4 + 1 + 16 + "/frame/" + a device name of at most 32 bytes.
        let _ = write!(
            s,
            "{SERVICE_PREFIX}/{:016x}/frame/{device_name:.32}",
            self.run_id
        );
        s
    }

    fn name(&self, what: &str) -> ServiceNameBuf {
        let mut s = ServiceNameBuf::default();
        // Cannot overflow: prefix (4) + '/' + 16 hex digits + '/' + longest suffix (15).
        let _ = write!(s, "{SERVICE_PREFIX}/{:016x}/{what}", self.run_id);
        s
    }
}

/// The two services' payload types as a client must declare them: the iceoryx2 type
/// name each packet carries and its size (`oils.v4.Telemetry, 1400 bytes`), taken from
/// the types themselves.
pub fn payload_types() -> (String, String) {
    use iceoryx2::prelude::ZeroCopySend;
    // SAFETY: `type_name` is unsafe because iceoryx2 trusts it to tell payload types
    // apart; here it is only read, to be printed.
    let (tlm, cmd) = unsafe {
        (
            <crate::Telemetry as ZeroCopySend>::type_name(),
            <crate::Command as ZeroCopySend>::type_name(),
        )
    };
    (
        format!("{tlm}, {} bytes", core::mem::size_of::<crate::Telemetry>()),
        format!("{cmd}, {} bytes", core::mem::size_of::<crate::Command>()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_run_id() {
        let s = RunServices::new(0xabc);
        assert_eq!(s.telemetry().as_str(), "oils/0000000000000abc/telemetry");
        assert_eq!(s.command().as_str(), "oils/0000000000000abc/command");
        assert_eq!(
            s.telemetry_event().as_str(),
            "oils/0000000000000abc/telemetry-ready"
        );
        assert_eq!(
            s.command_event().as_str(),
            "oils/0000000000000abc/command-ready"
        );
        assert_eq!(
            s.frame("test-card").as_str(),
            "oils/0000000000000abc/frame/test-card"
        );
        assert_ne!(
            RunServices::new(1).telemetry(),
            RunServices::new(2).telemetry()
        );
    }

    #[test]
    fn client_guide_names_services_hash_and_what_to_notify() {
        use crate::link::WaitStrategy;
        let s = RunServices::new(0xabc);
        let busy = s.client_guide(WaitStrategy::BusyPoll);
        for part in [
            "oils/0000000000000abc/telemetry ",
            "oils/0000000000000abc/command ",
            "oils/0000000000000abc/telemetry-ready ",
            "oils/0000000000000abc/command-ready ",
            "iceoryx2 0.10.0",
            "wait busy",
            "do not notify",
            "--run-id 0000000000000abc",
        ] {
            assert!(busy.contains(part), "`{part}` missing from:\n{busy}");
        }
        assert!(busy.contains(&format!("{:#018x}", crate::SCHEMA_HASH)));
        // The payload types from the types: this protocol version's names and sizes.
        let v = format!("oils.v{}.", crate::PROTOCOL_VERSION);
        for (name, size) in [
            ("Telemetry", core::mem::size_of::<crate::Telemetry>()),
            ("Command", core::mem::size_of::<crate::Command>()),
        ] {
            let shown = format!("publish-subscribe {v}{name}, {size} bytes");
            assert!(busy.contains(&shown), "`{shown}` missing from:\n{busy}");
        }
        let event = s.client_guide(WaitStrategy::Event);
        assert!(event.contains("notify after each command") && event.contains("wait event"));
        assert!(!event.contains("do not notify"));
    }
}
