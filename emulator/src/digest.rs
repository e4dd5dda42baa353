//! The run digest: one BLAKE3 hash over every packet exchanged, in order.
//!
//! Fields that legitimately differ between identical runs are hashed as zeros: the run
//! id (it names the services) and the flight software's measured compute times and
//! cycle slips (wall clock). Everything else, every nav value, every command, is in:
//! same inputs, same digest.
//!
//! The packets' bytes are gathered in a buffer and hashed a buffer at a time: BLAKE3
//! hashes many 1 KiB chunks side by side (SIMD) when it is given them together, while a
//! packet at a time it compresses one 64-byte block after another. The hash is over the
//! same byte stream either way, so the digest is the same; per packet it costs about a
//! quarter as much. The buffer is allocated once, in `new`.

use core::mem::{offset_of, size_of};
use core::ops::Range;
use oils_shared::{AsBytes, Command, FswReport, PacketHeader, Telemetry, RATE_GROUPS};

/// The byte range of a field at `offset` of `size` bytes.
const fn field(offset: usize, size: usize) -> Range<usize> {
    offset..offset + size
}

/// Telemetry bytes hashed as zeros: the run id (it names the services).
const TELEMETRY_ZEROED: [Range<usize>; 1] = [field(
    offset_of!(Telemetry, header) + offset_of!(PacketHeader, run_id),
    size_of::<u64>(),
)];

/// Command bytes hashed as zeros: the run id, and the wall-clock figures the flight
/// software reports of itself (its compute time, its rate groups' compute times and
/// cycle slips), which are not behaviour. In offset order.
const COMMAND_ZEROED: [Range<usize>; 4] = [
    field(
        offset_of!(Command, header) + offset_of!(PacketHeader, run_id),
        size_of::<u64>(),
    ),
    field(offset_of!(Command, stub_compute_ns), size_of::<u64>()),
    field(
        offset_of!(Command, fsw) + offset_of!(FswReport, group_compute_ns),
        size_of::<u32>() * RATE_GROUPS,
    ),
    field(
        offset_of!(Command, fsw) + offset_of!(FswReport, cycle_slips),
        size_of::<u32>(),
    ),
];

/// Bytes gathered before they are hashed: a multiple of BLAKE3's 1 KiB chunk, and
/// enough chunks for the widest SIMD degree many times over.
const BUFFER_LEN: usize = 64 * 1024;
/// The buffer's capacity: room for the largest packet and its tag past `BUFFER_LEN`.
const CAPACITY: usize = BUFFER_LEN + 1 + max(size_of::<Telemetry>(), size_of::<Command>());

const fn max(a: usize, b: usize) -> usize {
    if a > b {
        a
    } else {
        b
    }
}

/// Running digest of a run's packets.
pub struct RunDigest {
    hasher: blake3::Hasher,
    /// Bytes not yet hashed (fewer than `BUFFER_LEN` between packets).
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
            pending: Vec::with_capacity(CAPACITY),
            packets: 0,
        }
    }

    /// Appends a packet's bytes to the stream after its tag, with the byte ranges
    /// `zeroed` hashed as zeros: the packet is copied once, into the buffer, and zeroed
    /// there (no copy of a whole packet per step). Every full buffer is hashed and what
    /// went past it moved to the front: BLAKE3 hashes a run of whole chunks side by
    /// side only when it starts on a chunk boundary, so updates stay `BUFFER_LEN`
    /// long. No allocation (the buffer has room for one packet past `BUFFER_LEN`).
    fn feed(&mut self, tag: u8, bytes: &[u8], zeroed: &[Range<usize>]) {
        self.pending.push(tag);
        let at = self.pending.len();
        self.pending.extend_from_slice(bytes);
        for r in zeroed {
            self.pending[at + r.start..at + r.end].fill(0);
        }
        if self.pending.len() >= BUFFER_LEN {
            self.hasher.update(&self.pending[..BUFFER_LEN]);
            self.pending.copy_within(BUFFER_LEN.., 0);
            self.pending.truncate(self.pending.len() - BUFFER_LEN);
        }
    }

    /// Adds a telemetry packet.
    pub fn add_telemetry(&mut self, tlm: &Telemetry) {
        self.feed(b'T', tlm.as_bytes(), &TELEMETRY_ZEROED);
        self.packets += 1;
    }

    /// Adds a command packet, as received (before sanitising).
    pub fn add_command(&mut self, cmd: &Command) {
        self.feed(b'C', cmd.as_bytes(), &COMMAND_ZEROED);
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
        c.header.run_id = 98;
        c.stub_compute_ns = 12345;
        c.fsw.group_compute_ns = [1, 2, 3, 4];
        c.fsw.cycle_slips = 5;
        b.add_telemetry(&t);
        b.add_command(&c);
        assert_eq!(a.hex(), b.hex());
        t.altitude_m = 1e-300;
        b.add_telemetry(&t);
        a.add_telemetry(&Telemetry::default());
        assert_ne!(a.hex(), b.hex());
        assert_eq!(a.packets(), 3);
    }

    /// The stream as it is defined: each packet copied, its ignored fields zeroed by
    /// name, and hashed after its tag.
    fn reference(packets: &[(Telemetry, Command)]) -> String {
        let mut h = blake3::Hasher::new();
        for (t, c) in packets {
            let mut t = *t;
            t.header.run_id = 0;
            h.update(b"T");
            h.update(t.as_bytes());
            let mut c = *c;
            c.header.run_id = 0;
            c.stub_compute_ns = 0;
            c.fsw.group_compute_ns = [0; RATE_GROUPS];
            c.fsw.cycle_slips = 0;
            h.update(b"C");
            h.update(c.as_bytes());
        }
        h.finalize().to_hex().to_string()
    }

    #[test]
    fn buffering_hashes_the_same_stream() {
        // Enough packets to fill the buffer several times, at an uneven offset, with
        // every ignored field set (so zeroing the wrong bytes shows).
        let mut d = RunDigest::new();
        let mut packets = Vec::new();
        for k in 0..1000u64 {
            let mut t = Telemetry::default();
            t.header.step = k;
            t.header.run_id = k + 7;
            t.altitude_m = k as f64;
            let mut c = Command::default();
            c.header.step = k;
            c.header.run_id = k + 7;
            c.stub_compute_ns = 3 * k;
            c.fsw.group_compute_ns = [k as u32; RATE_GROUPS];
            c.fsw.cycle_slips = k as u32;
            c.fsw.boot_count = k as u32;
            c.thrust_cmd_n[3] = -(k as f64);
            d.add_telemetry(&t);
            d.add_command(&c);
            packets.push((t, c));
            if k == 3 {
                assert_eq!(d.hex(), reference(&packets));
            }
        }
        assert_eq!(d.hex(), reference(&packets));
        assert_eq!(d.pending.capacity(), CAPACITY, "the buffer grew");
    }
}
