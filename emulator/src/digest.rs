//! The run digest: one BLAKE3 hash over every packet exchanged, in order.
//!
//! Fields that legitimately differ between identical runs are zeroed before hashing:
//! the run id (it names the services) and the stub's measured compute time (wall clock).
//! Everything else, every nav value, every command, is in: same inputs, same digest.

use oils_shared::{AsBytes, Command, Telemetry};

/// Running digest of a run's packets.
pub struct RunDigest {
    hasher: blake3::Hasher,
    packets: u64,
}

impl Default for RunDigest {
    fn default() -> Self {
        Self::new()
    }
}

impl RunDigest {
    /// Empty digest.
    pub fn new() -> Self {
        Self {
            hasher: blake3::Hasher::new(),
            packets: 0,
        }
    }

    /// Adds a telemetry packet.
    pub fn add_telemetry(&mut self, tlm: &Telemetry) {
        let mut t = *tlm;
        t.header.run_id = 0;
        self.hasher.update(b"T");
        self.hasher.update(t.as_bytes());
        self.packets += 1;
    }

    /// Adds a command packet, as received (before sanitising).
    pub fn add_command(&mut self, cmd: &Command) {
        let mut c = *cmd;
        c.header.run_id = 0;
        c.stub_compute_ns = 0;
        self.hasher.update(b"C");
        self.hasher.update(c.as_bytes());
        self.packets += 1;
    }

    /// Packets hashed so far.
    pub fn packets(&self) -> u64 {
        self.packets
    }

    /// The digest as lowercase hex.
    pub fn hex(&self) -> String {
        self.hasher.finalize().to_hex().to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ignores_run_id_and_compute_time_but_nothing_else() {
        let mut a = RunDigest::new();
        let mut b = RunDigest::new();
        let mut t = Telemetry::default();
        let mut c = Command::default();
        a.add_telemetry(&t);
        a.add_command(&c);
        t.header.run_id = 99;
        c.stub_compute_ns = 12345;
        b.add_telemetry(&t);
        b.add_command(&c);
        assert_eq!(a.hex(), b.hex());
        t.altitude_m = 1e-300;
        b.add_telemetry(&t);
        a.add_telemetry(&Telemetry::default());
        assert_ne!(a.hex(), b.hex());
        assert_eq!(a.packets(), 3);
    }
}
