//! A frame as a PNG file (`oils export LOG --frames DIR`): 16-bit grey, as a viewer and
//! an image tool read it.
//!
//! * camera (`FRAME_FORMAT_U16_LE` DN of `bits`): DN shifted up to 16 bits (a 12-bit DN
//!   times 16), so full well is white;
//! * lidar (`FRAME_FORMAT_F32_LE_M` range): 1/64 m a level, `round(64 range_m)` (0 to
//!   1024 m), 0 for no return;
//! * other `u16` frames (the test card): as they are.

use oils_shared::{
    FrameAnnouncement, FRAME_DEVICE_CAMERA, FRAME_FORMAT_F32_LE_M, FRAME_FORMAT_U16_LE,
};
use std::io::Write;

/// Range levels per metre in a lidar PNG.
pub const LIDAR_LEVELS_PER_M: f32 = 64.0;

/// Why a frame could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FramePngError {
    /// The bytes are not the announced frame.
    #[error("frame {seq} of device {device}: {got} bytes, the announcement says {want} ({width} x {height}, format {format})")]
    Size {
        /// `FRAME_DEVICE_*`.
        device: u32,
        /// Its sequence number.
        seq: u64,
        /// Bytes given.
        got: usize,
        /// Bytes announced.
        want: usize,
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
        /// `FRAME_FORMAT_*`.
        format: u32,
    },
    /// A format this encoder does not know.
    #[error("frame format {0} has no PNG form")]
    Format(u32),
    /// The encoder or the writer failed.
    #[error(transparent)]
    Png(#[from] png::EncodingError),
}

/// Writes the frame `ann` announces (`pixels` its bytes) to `out` as a 16-bit grey PNG;
/// `camera_bits`: the camera's ADC bits (from the run's configuration).
pub fn write_png<W: Write>(
    ann: &FrameAnnouncement,
    pixels: &[u8],
    camera_bits: u32,
    out: W,
) -> Result<(), FramePngError> {
    let n = ann.width as usize * ann.height as usize;
    let bpp = match ann.format {
        FRAME_FORMAT_U16_LE => 2,
        FRAME_FORMAT_F32_LE_M => 4,
        f => return Err(FramePngError::Format(f)),
    };
    if pixels.len() != n * bpp || ann.bytes as usize != pixels.len() {
        return Err(FramePngError::Size {
            device: ann.device,
            seq: ann.seq,
            got: pixels.len(),
            want: n * bpp,
            width: ann.width,
            height: ann.height,
            format: ann.format,
        });
    }
    let shift = if ann.device == FRAME_DEVICE_CAMERA {
        16u32.saturating_sub(camera_bits.clamp(1, 16))
    } else {
        0
    };
    // PNG's 16-bit samples are big-endian.
    let mut be = Vec::with_capacity(n * 2);
    if ann.format == FRAME_FORMAT_U16_LE {
        for c in pixels.chunks_exact(2) {
            let v = u16::from_le_bytes([c[0], c[1]]);
            be.extend_from_slice(&(v << shift).to_be_bytes());
        }
    } else {
        for c in pixels.chunks_exact(4) {
            let r = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
            let level = if r.is_finite() && r > 0.0 {
                (r * LIDAR_LEVELS_PER_M).round().min(65535.0) as u16
            } else {
                0
            };
            be.extend_from_slice(&level.to_be_bytes());
        }
    }
    let mut enc = png::Encoder::new(out, ann.width, ann.height);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Sixteen);
    let mut w = enc.write_header()?;
    w.write_image_data(&be)?;
    w.finish()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_shared::FRAME_DEVICE_LIDAR;

    fn read(bytes: &[u8]) -> (u32, u32, Vec<u16>) {
        let dec = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!(info.bit_depth, png::BitDepth::Sixteen);
        let px = buf[..info.buffer_size()]
            .chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect();
        (info.width, info.height, px)
    }

    #[test]
    fn a_camera_frame_reads_back_as_its_dn_shifted_to_16_bits() {
        let dn: Vec<u16> = vec![0, 1, 4095, 2048, 7, 100];
        let bytes: Vec<u8> = dn.iter().flat_map(|v| v.to_le_bytes()).collect();
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_CAMERA,
            format: FRAME_FORMAT_U16_LE,
            width: 3,
            height: 2,
            bytes: bytes.len() as u32,
            ..Default::default()
        };
        let mut out = Vec::new();
        write_png(&ann, &bytes, 12, &mut out).unwrap();
        let (w, h, px) = read(&out);
        assert_eq!((w, h), (3, 2));
        assert_eq!(px, dn.iter().map(|v| v << 4).collect::<Vec<_>>());
    }

    #[test]
    fn a_lidar_frame_reads_back_in_sixty_fourths_of_a_metre() {
        let r: Vec<f32> = vec![0.0, 1.0, 12.5, 2000.0];
        let bytes: Vec<u8> = r.iter().flat_map(|v| v.to_le_bytes()).collect();
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_LIDAR,
            format: FRAME_FORMAT_F32_LE_M,
            width: 2,
            height: 2,
            bytes: bytes.len() as u32,
            ..Default::default()
        };
        let mut out = Vec::new();
        write_png(&ann, &bytes, 12, &mut out).unwrap();
        assert_eq!(read(&out).2, vec![0, 64, 800, 65535]);
    }

    #[test]
    fn bytes_that_are_not_the_announced_frame_are_refused() {
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_CAMERA,
            format: FRAME_FORMAT_U16_LE,
            width: 4,
            height: 4,
            bytes: 32,
            ..Default::default()
        };
        let err = write_png(&ann, &[0; 30], 12, Vec::new()).unwrap_err();
        assert!(
            matches!(
                err,
                FramePngError::Size {
                    got: 30,
                    want: 32,
                    ..
                }
            ),
            "{err}"
        );
    }
}
