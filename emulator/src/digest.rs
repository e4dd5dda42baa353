//! The run digest: one BLAKE3 hash over every packet exchanged, in order.
//!
//! Fields that legitimately differ between identical runs are zeroed before hashing:
//! the run id (it names the services) and the stub's measured compute time (wall clock).
//! Everything else, every nav value, every command, is in: same inputs, same digest.
//!
//! The packets' bytes are gathered in a buffer and hashed a buffer at a time: BLAKE3
//! hashes many 1 KiB chunks side by side (SIMD) when it is given them together, while a
//! packet at a time it compresses one 64-byte block after another. The hash is over the
//! same byte stream either way, so the digest is the same; per packet it costs about a
//! quarter as much. The buffer is allocated once, in `new`.

use oils_shared::{AsBytes, Command, Telemetry};

/// Bytes gathered before they are hashed: a multiple of BLAKE3's 1 KiB chunk, and
/// enough chunks for the widest SIMD degree many times over.
const BUFFER_LEN: usize = 64 * 1024;

/// Running digest of a run's packets.
pub struct RunDigest {
    hasher: blake3::Hasher,
    /// Bytes not yet hashed (never more than `BUFFER_LEN`).
    pending: Vec<u8>,
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
            pending: Vec::with_capacity(BUFFER_LEN),
            packets: 0,
        }
    }

    /// Appends bytes to the stream, hashing every full buffer. No allocation.
    fn feed(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            let room = BUFFER_LEN - self.pending.len();
            let (now, later) = bytes.split_at(room.min(bytes.len()));
            self.pending.extend_from_slice(now);
            if self.pending.len() == BUFFER_LEN {
                self.hasher.update(&self.pending);
                self.pending.clear();
            }
            bytes = later;
        }
    }

    /// Adds a telemetry packet.
    pub fn add_telemetry(&mut self, tlm: &Telemetry) {
        let mut t = *tlm;
        t.header.run_id = 0;
        self.feed(b"T");
        self.feed(t.as_bytes());
        self.packets += 1;
    }

    /// Adds a command packet, as received (before sanitising).
    pub fn add_command(&mut self, cmd: &Command) {
        let mut c = *cmd;
        c.header.run_id = 0;
        c.stub_compute_ns = 0;
        // Wall-clock figures the flight software reports of itself: not behaviour.
        c.fsw.group_compute_ns = [0; oils_shared::RATE_GROUPS];
        c.fsw.cycle_slips = 0;
        self.feed(b"C");
        self.feed(c.as_bytes());
        self.packets += 1;
    }

    /// Packets hashed so far.
    pub fn packets(&self) -> u64 {
        self.packets
    }

    /// The digest as lowercase hex.
    pub fn hex(&self) -> String {
        let mut h = self.hasher.clone();
        h.update(&self.pending);
        h.finalize().to_hex().to_string()
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

    #[test]
    fn buffering_hashes_the_same_stream() {
        // Enough packets to fill the buffer several times, at an uneven offset.
        let mut d = RunDigest::new();
        let mut plain = blake3::Hasher::new();
        for k in 0..1000u64 {
            let mut t = Telemetry::default();
            t.header.step = k;
            t.altitude_m = k as f64;
            let mut c = Command::default();
            c.header.step = k;
            d.add_telemetry(&t);
            d.add_command(&c);
            plain.update(b"T");
            plain.update(t.as_bytes());
            plain.update(b"C");
            plain.update(c.as_bytes());
            if k == 3 {
                assert_eq!(d.hex(), plain.finalize().to_hex().to_string());
            }
        }
        assert_eq!(d.hex(), plain.finalize().to_hex().to_string());
        assert!(d.pending.capacity() == BUFFER_LEN);
    }
}
