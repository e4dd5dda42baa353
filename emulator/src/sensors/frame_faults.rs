//! Faults on the imaging devices (`docs/faults.md`, "Camera and lidar"): what the frame
//! rack does to a device's frames while a fault is active.
//!
//! ```text
//! dropout        no frame at all: nothing rendered, published or announced
//! frozen         the device's last good frame again, bytes and flags, with a new
//!                sequence number and time of validity (as a stuck readout would)
//! inhibited      a blank frame flagged FRAME_FLAG_OUTAGE (the device says it is off)
//! blinding       stray light over the image (the sun in or near the field of view):
//!                DN += level * full_scale / (1 + (r / r_core)^2),  r_core = w_min / 10,
//!                r from the image centre, clipped at full scale, FRAME_FLAG_SATURATED
//!                when a pixel clips
//! dead quadrant  one quadrant's pixels read 0 (a failed readout channel; for the lidar
//!                0.0 m, its "no return")
//! ```
//! Quadrants are numbered as the image is read, rows top first: 1 top left, 2 top
//! right, 3 bottom left, 4 bottom right. The glare's Lorentzian falloff is assumed (the
//! shape of a veiling-glare point-spread function's wings, ~1/r^2); its centre is the
//! image's, since the fault stands for light the optics scatter, wherever its source.

use oils_shared::{FRAME_FORMAT_F32_LE_M, FRAME_FORMAT_U16_LE};

/// A fault inside an imaging device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameFault {
    /// No frames while active.
    Dropout,
    /// The last good frame repeats.
    Frozen,
    /// Blank frames flagged as an outage.
    Inhibited,
    /// Stray light of `level` times the full scale at the image centre (16-bit frames).
    Blinding {
        /// Peak glare in units of the device's full scale (> 0; at 1 the centre
        /// saturates).
        level: f64,
    },
    /// Quadrant 1-4 reads zero.
    DeadQuadrant {
        /// 1 top left, 2 top right, 3 bottom left, 4 bottom right.
        quadrant: u8,
    },
}

/// The faults active on one device. Counts, so overlapping faults of one kind clear one
/// at a time.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct FrameFaultState {
    dropout: u32,
    frozen: u32,
    inhibited: u32,
    /// Sum of the active blinding levels.
    glare_level: f64,
    /// Active dead-quadrant faults per quadrant.
    dead: [u32; 4],
}

/// What the rack does with a due frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FrameMode {
    /// Render it (then [`FrameFaultState::degrade`]).
    Render,
    /// Publish nothing.
    Skip,
    /// Publish the last good frame again.
    Repeat,
    /// Publish a blank outage frame.
    Blank,
}

impl FrameFaultState {
    pub(crate) fn set(&mut self, fault: FrameFault, active: bool) {
        let count = |c: &mut u32| {
            *c = if active {
                c.saturating_add(1)
            } else {
                c.saturating_sub(1)
            }
        };
        match fault {
            FrameFault::Dropout => count(&mut self.dropout),
            FrameFault::Frozen => count(&mut self.frozen),
            FrameFault::Inhibited => count(&mut self.inhibited),
            FrameFault::Blinding { level } => {
                self.glare_level += if active { level } else { -level };
                if self.glare_level < 1e-12 {
                    self.glare_level = 0.0;
                }
            }
            FrameFault::DeadQuadrant { quadrant } => {
                if let Some(c) = self.dead.get_mut(usize::from(quadrant.wrapping_sub(1))) {
                    count(c)
                }
            }
        }
    }

    /// Dropout before an outage before a frozen readout: the first that applies wins.
    pub(crate) fn mode(&self) -> FrameMode {
        if self.dropout > 0 {
            FrameMode::Skip
        } else if self.inhibited > 0 {
            FrameMode::Blank
        } else if self.frozen > 0 {
            FrameMode::Repeat
        } else {
            FrameMode::Render
        }
    }

    /// Applies the glare and the dead quadrants to a rendered frame of `format`,
    /// `width` x `height`, whose full scale is `full_scale_dn` (16-bit formats). Returns
    /// whether the glare saturated a pixel. No allocation.
    pub(crate) fn degrade(
        &self,
        format: u32,
        width: u32,
        height: u32,
        full_scale_dn: u16,
        out: &mut [u8],
    ) -> bool {
        let (w, h) = (width as usize, height as usize);
        let mut saturated = false;
        if self.glare_level > 0.0 && format == FRAME_FORMAT_U16_LE {
            saturated = add_glare(w, h, self.glare_level, full_scale_dn, out);
        }
        for (q, n) in self.dead.iter().enumerate() {
            if *n > 0 {
                zero_quadrant(format, w, h, q as u8 + 1, out);
            }
        }
        saturated
    }
}

/// Adds the blinding glare (module doc) to a little-endian u16 frame; whether any pixel
/// clipped at `full_scale_dn`.
fn add_glare(w: usize, h: usize, level: f64, full_scale_dn: u16, out: &mut [u8]) -> bool {
    let fs = f64::from(full_scale_dn);
    let r_core = (w.min(h) as f64 / 10.0).max(1.0);
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let mut saturated = false;
    for (row, line) in out.chunks_exact_mut(2 * w).take(h).enumerate() {
        let dy = (row as f64 + 0.5 - cy) / r_core;
        for (col, px) in line.chunks_exact_mut(2).enumerate() {
            let dx = (col as f64 + 0.5 - cx) / r_core;
            let glare = level * fs / (1.0 + dx * dx + dy * dy);
            let dn = f64::from(u16::from_le_bytes([px[0], px[1]])) + glare;
            let dn = if dn >= fs {
                saturated = true;
                full_scale_dn
            } else {
                dn.round() as u16
            };
            px.copy_from_slice(&dn.to_le_bytes());
        }
    }
    saturated
}

/// Zeroes quadrant `q` (1-4) of a frame of `format`.
fn zero_quadrant(format: u32, w: usize, h: usize, q: u8, out: &mut [u8]) {
    let bpp = match format {
        FRAME_FORMAT_U16_LE => 2,
        FRAME_FORMAT_F32_LE_M => 4,
        _ => oils_shared::frame_format_bytes_per_pixel(format).unwrap_or(1),
    };
    let (half_w, half_h) = (w / 2, h / 2);
    let (cols, rows) = match q {
        1 => (0..half_w, 0..half_h),
        2 => (half_w..w, 0..half_h),
        3 => (0..half_w, half_h..h),
        _ => (half_w..w, half_h..h),
    };
    for row in rows {
        let start = (row * w + cols.start) * bpp;
        let end = (row * w + cols.end) * bpp;
        if let Some(span) = out.get_mut(start..end) {
            span.fill(0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame_u16(w: usize, h: usize, dn: u16) -> Vec<u8> {
        (0..w * h).flat_map(|_| dn.to_le_bytes()).collect()
    }

    fn px(out: &[u8], w: usize, col: usize, row: usize) -> u16 {
        let i = 2 * (row * w + col);
        u16::from_le_bytes([out[i], out[i + 1]])
    }

    #[test]
    fn the_glare_follows_its_lorentzian_and_clips_at_full_scale() {
        let (w, h) = (40, 20);
        let mut out = frame_u16(w, h, 100);
        let mut s = FrameFaultState::default();
        s.set(FrameFault::Blinding { level: 0.5 }, true);
        assert!(!s.degrade(FRAME_FORMAT_U16_LE, w as u32, h as u32, 4095, &mut out));
        // r_core = 2 px. Pixel (0, 0) centre (0.5, 0.5) is (19.5, 9.5) px from (20, 10).
        let r2 = (19.5f64 / 2.0).powi(2) + (9.5f64 / 2.0).powi(2);
        let expect = 100.0 + 0.5 * 4095.0 / (1.0 + r2);
        assert_eq!(px(&out, w, 0, 0), expect.round() as u16);
        let centre = 100.0 + 0.5 * 4095.0 / (1.0 + 2.0 * 0.25f64.powi(2));
        assert_eq!(px(&out, w, 20, 10), centre.round() as u16);
        // Twice as bright saturates the centre; clearing one leaves the other.
        s.set(FrameFault::Blinding { level: 0.6 }, true);
        let mut out = frame_u16(w, h, 100);
        assert!(s.degrade(FRAME_FORMAT_U16_LE, w as u32, h as u32, 4095, &mut out));
        assert_eq!(px(&out, w, 20, 10), 4095);
        s.set(FrameFault::Blinding { level: 0.6 }, false);
        s.set(FrameFault::Blinding { level: 0.5 }, false);
        let mut out = frame_u16(w, h, 100);
        assert!(!s.degrade(FRAME_FORMAT_U16_LE, w as u32, h as u32, 4095, &mut out));
        assert_eq!(out, frame_u16(w, h, 100), "no glare once both cleared");
    }

    #[test]
    fn a_dead_quadrant_zeroes_exactly_its_quarter() {
        let (w, h) = (6, 4);
        for q in 1..=4u8 {
            let mut out: Vec<u8> = (0..w * h).flat_map(|_| 7.5f32.to_le_bytes()).collect();
            let mut s = FrameFaultState::default();
            s.set(FrameFault::DeadQuadrant { quadrant: q }, true);
            s.degrade(FRAME_FORMAT_F32_LE_M, w as u32, h as u32, 0, &mut out);
            for row in 0..h {
                for col in 0..w {
                    let i = 4 * (row * w + col);
                    let v = f32::from_le_bytes(out[i..i + 4].try_into().unwrap());
                    let quadrant = 1 + u8::from(col >= w / 2) + 2 * u8::from(row >= h / 2);
                    let want = if quadrant == q { 0.0 } else { 7.5 };
                    assert_eq!(v, want, "q{q} ({col}, {row})");
                }
            }
        }
    }

    #[test]
    fn dropout_outranks_an_outage_which_outranks_a_frozen_readout() {
        let mut s = FrameFaultState::default();
        assert_eq!(s.mode(), FrameMode::Render);
        s.set(FrameFault::Frozen, true);
        assert_eq!(s.mode(), FrameMode::Repeat);
        s.set(FrameFault::Inhibited, true);
        assert_eq!(s.mode(), FrameMode::Blank);
        s.set(FrameFault::Dropout, true);
        assert_eq!(s.mode(), FrameMode::Skip);
        s.set(FrameFault::Dropout, false);
        s.set(FrameFault::Inhibited, false);
        assert_eq!(s.mode(), FrameMode::Repeat);
        s.set(FrameFault::Frozen, false);
        assert_eq!(s, FrameFaultState::default());
    }
}
