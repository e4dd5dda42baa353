//! The test card: a frame device that renders a deterministic pattern with its frame
//! counter burnt in, for checking a frame path end to end (a flight software's frame
//! reader, a PNG export, a transport) before any real imaging device is on. Enabled with
//! `[sensors.test_card] enabled = true` (`docs/sensors.md`).
//!
//! The frame is `FRAME_FORMAT_U16_LE`, `width x height`, and a function of `(width,
//! height, seq)` alone, never of the truth or a random stream:
//! * pixels 0..4 of row 0 hold `seq` as four little-endian `u16` words, low word first
//!   (machine-readable: a reader checks it has the frame it was announced);
//! * the upper half is a horizontal ramp, `((x + 4 seq) mod 256) * 256`, scrolling four
//!   pixels a frame; the lower half a 64-pixel checkerboard of 16384 and 49152 whose
//!   phase flips every frame;
//! * the decimal `seq` is drawn from row 8, column 8, in a 3 x 5 font scaled to
//!   `max(1, width / 128)` pixels a dot, white (65535) on black (0).

use super::config::{ms_to_ns, TestCardConfig};
use super::frame_source::{FrameMeta, FrameSource};
use super::SensorTruth;
use crate::config::ConfigError;
use oils_shared::{FRAME_DEVICE_TEST_CARD, FRAME_FORMAT_U16_LE};

/// The test-card device.
#[derive(Debug, Clone)]
pub struct TestCard {
    width: u32,
    height: u32,
    period_ns: i64,
    exposure_ns: u64,
}

impl TestCard {
    /// A test card as configured (validated here).
    pub fn new(cfg: &TestCardConfig) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            width: cfg.width,
            height: cfg.height,
            period_ns: ms_to_ns(cfg.period_ms),
            exposure_ns: ms_to_ns(cfg.exposure_ms) as u64,
        })
    }
}

impl FrameSource for TestCard {
    fn device(&self) -> u32 {
        FRAME_DEVICE_TEST_CARD
    }
    fn format(&self) -> u32 {
        FRAME_FORMAT_U16_LE
    }
    fn width(&self) -> u32 {
        self.width
    }
    fn height(&self) -> u32 {
        self.height
    }
    fn period_ns(&self) -> i64 {
        self.period_ns
    }
    fn exposure_ns(&self) -> u64 {
        self.exposure_ns
    }
    fn render(&mut self, _truth: &SensorTruth<'_>, seq: u64, out: &mut [u8]) -> FrameMeta {
        pattern(self.width, self.height, seq, out);
        FrameMeta::default()
    }
}

/// 3 x 5 dot glyphs of the decimal digits, one row per `u8` (bit 2 is the left column).
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b010, 0b010, 0b010],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// Writes the test card's frame `seq` into `out` (`width * height * 2` bytes; every byte
/// written). Pure: the same arguments give the same bytes.
pub fn pattern(width: u32, height: u32, seq: u64, out: &mut [u8]) {
    let (w, h) = (width as usize, height as usize);
    debug_assert_eq!(out.len(), w * h * 2);
    let put = |out: &mut [u8], x: usize, y: usize, v: u16| {
        let i = 2 * (y * w + x);
        if i + 1 < out.len() {
            out[i..i + 2].copy_from_slice(&v.to_le_bytes());
        }
    };
    let shift = (seq.wrapping_mul(4) % 256) as usize;
    let phase = (seq % 2) as usize;
    for (y, row) in out.chunks_exact_mut(2 * w.max(1)).enumerate().take(h) {
        for (x, px) in row.chunks_exact_mut(2).enumerate() {
            let v = if y < h / 2 {
                (((x + shift) % 256) * 256) as u16
            } else if (x / 64 + y / 64 + phase).is_multiple_of(2) {
                16384
            } else {
                49152
            };
            px.copy_from_slice(&v.to_le_bytes());
        }
    }
    // The decimal counter, on a black box.
    let dot = (w / 128).max(1);
    let mut digits = [0u8; 20];
    let mut n = 0;
    let mut rest = seq;
    loop {
        digits[n] = (rest % 10) as u8;
        n += 1;
        rest /= 10;
        if rest == 0 {
            break;
        }
    }
    let (x0, y0) = (8, 8);
    let (box_w, box_h) = ((4 * n + 1) * dot, 7 * dot);
    for y in y0..(y0 + box_h).min(h) {
        for x in x0..(x0 + box_w).min(w) {
            put(out, x, y, 0);
        }
    }
    for (i, d) in digits[..n].iter().rev().enumerate() {
        let glyph = &DIGITS[*d as usize];
        for (gy, bits) in glyph.iter().enumerate() {
            for gx in 0..3 {
                if bits & (0b100 >> gx) == 0 {
                    continue;
                }
                let px = x0 + (1 + 4 * i + gx) * dot;
                let py = y0 + (1 + gy) * dot;
                for y in py..(py + dot).min(h) {
                    for x in px..(px + dot).min(w) {
                        put(out, x, y, u16::MAX);
                    }
                }
            }
        }
    }
    // The machine-readable counter, last: nothing overwrites it.
    for word in 0..4.min(w) {
        put(out, word, 0, (seq >> (16 * word)) as u16);
    }
}

/// The frame counter a test-card frame carries in its first four pixels (`None`: fewer
/// than 8 bytes).
pub fn seq_of(frame: &[u8]) -> Option<u64> {
    let head = frame.get(..8)?;
    let mut seq = 0u64;
    for (i, w) in head.chunks_exact(2).enumerate() {
        seq |= u64::from(u16::from_le_bytes([w[0], w[1]])) << (16 * i);
    }
    Some(seq)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(w: u32, h: u32, seq: u64, fill: u8) -> Vec<u8> {
        let mut out = vec![fill; (w * h * 2) as usize];
        pattern(w, h, seq, &mut out);
        out
    }

    #[test]
    fn the_counter_is_burnt_in_and_read_back() {
        for seq in [0, 1, 9, 10, 65_535, 65_536, 123_456_789, u64::MAX] {
            assert_eq!(seq_of(&frame(256, 64, seq, 0)), Some(seq), "seq {seq}");
        }
        assert_eq!(seq_of(&[0u8; 6]), None);
    }

    #[test]
    fn every_byte_is_written_and_the_pattern_is_pure() {
        // Whatever the buffer held before (a loan may hold an earlier frame), the frame
        // is the same bytes.
        assert_eq!(frame(1024, 1024, 42, 0x00), frame(1024, 1024, 42, 0xa5));
        assert_ne!(frame(1024, 1024, 42, 0), frame(1024, 1024, 43, 0));
    }

    #[test]
    fn ramp_checkerboard_and_digits_where_documented() {
        let (w, h) = (1024u32, 1024u32);
        let f = frame(w, h, 1, 0);
        let px = |x: usize, y: usize| {
            let i = 2 * (y * w as usize + x);
            u16::from_le_bytes([f[i], f[i + 1]])
        };
        // Ramp (upper half, right of the counter box): ((x + 4) mod 256) * 256.
        assert_eq!(px(500, 300), ((504 % 256) * 256) as u16);
        assert_eq!(px(252, 400), 0);
        // Checkerboard (lower half), phase flipped for an odd frame.
        assert_eq!(px(0, 512), 49152);
        assert_eq!(px(64, 512), 16384);
        assert_eq!(px(0, 576), 16384);
        // The digit "1" at scale 8: its glyph row 0 is 0b010, so the middle dot is lit
        // and the left one dark (inside the black box).
        let dot = 8;
        let (x0, y0) = (8, 8);
        assert_eq!(px(x0 + 2 * dot + 1, y0 + dot + 1), u16::MAX);
        assert_eq!(px(x0 + dot + 1, y0 + dot + 1), 0);
    }

    #[test]
    fn a_tiny_card_still_writes_every_byte() {
        assert_eq!(frame(2, 2, 7, 0x11), frame(2, 2, 7, 0xee));
        assert_eq!(frame(1, 1, 7, 0x11), frame(1, 1, 7, 0xee));
    }
}
