//! Service names of one run.
//!
//! Every run has its own `run_id`, and every service name contains it, so two benches on
//! one machine never meet, and a run started after a crash never opens a dead run's
//! services. A flight-software author in C or Python opens exactly these names.

use core::fmt::Write;

/// Prefix of every oils service.
pub const SERVICE_PREFIX: &str = "oils";

/// Longest service name this module builds.
pub const MAX_SERVICE_NAME_LEN: usize = 64;

/// A service name built without heap allocation.
pub type ServiceNameBuf = heapless_string::Buf;

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

    fn name(&self, what: &str) -> ServiceNameBuf {
        let mut s = ServiceNameBuf::default();
        // Cannot overflow: prefix (4) + '/' + 16 hex digits + '/' + longest suffix (15).
        let _ = write!(s, "{SERVICE_PREFIX}/{:016x}/{what}", self.run_id);
        s
    }
}

/// A tiny fixed-capacity string, so naming services needs no allocator (and no extra
/// dependency in the one crate flight-software authors must build).
pub mod heapless_string {
    use super::MAX_SERVICE_NAME_LEN;

    /// Fixed-capacity UTF-8 buffer.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub struct Buf {
        bytes: [u8; MAX_SERVICE_NAME_LEN],
        len: usize,
    }

    impl Default for Buf {
        fn default() -> Self {
            Self {
                bytes: [0; MAX_SERVICE_NAME_LEN],
                len: 0,
            }
        }
    }

    impl Buf {
        /// The text.
        pub fn as_str(&self) -> &str {
            // Only whole `&str`s are ever appended, so the bytes are valid UTF-8.
            core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("")
        }
    }

    impl core::fmt::Write for Buf {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            let end = self.len + s.len();
            if end > self.bytes.len() {
                return Err(core::fmt::Error);
            }
            self.bytes[self.len..end].copy_from_slice(s.as_bytes());
            self.len = end;
            Ok(())
        }
    }

    impl core::fmt::Display for Buf {
        fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            f.write_str(self.as_str())
        }
    }
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
        assert_ne!(
            RunServices::new(1).telemetry(),
            RunServices::new(2).telemetry()
        );
    }
}
