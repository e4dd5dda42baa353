//! Camera, lidar and test-card frames in an MCAP log, as Foxglove's `foxglove.RawImage`
//! in protobuf (Foxglove's Image panel shows them; any protobuf reader decodes them
//! with the schema the file carries).
//!
//! | device | topic | encoding | pixels |
//! |---|---|---|---|
//! | camera | `/camera/image` | `16UC1` | DN shifted up to 16 bits (12-bit DN x 16), as `oils export --frames` |
//! | lidar | `/lidar/range` | `32FC1` | range, m (0: no return), as announced |
//! | test card | `/test-card/image` | `16UC1` | as announced |
//!
//! Both encodings are little-endian, as the frames are on the wire. A message's log
//! time is the frame's time of validity (mid-exposure); `frame_id` is the device's name.
//! The schema is `foxglove/RawImage.proto` (field numbers as Foxglove's schemas give
//! them) with its one import, `google/protobuf/timestamp.proto`, as a serialised
//! `FileDescriptorSet`, the form MCAP's protobuf profile asks for.

use oils_shared::{
    frame_device_name, FrameAnnouncement, FRAME_DEVICE_CAMERA, FRAME_FORMAT_F32_LE_M,
    FRAME_FORMAT_U16_LE,
};
use prost::Message;
use prost_types::field_descriptor_proto::{Label, Type};
use prost_types::{DescriptorProto, FieldDescriptorProto, FileDescriptorProto, FileDescriptorSet};

/// Foxglove's raw image (`foxglove/RawImage.proto`).
#[derive(Clone, PartialEq, Message)]
pub struct RawImage {
    /// Time of validity.
    #[prost(message, optional, tag = "1")]
    pub timestamp: Option<prost_types::Timestamp>,
    /// The device's name.
    #[prost(string, tag = "7")]
    pub frame_id: String,
    /// Pixels per row.
    #[prost(fixed32, tag = "2")]
    pub width: u32,
    /// Rows.
    #[prost(fixed32, tag = "3")]
    pub height: u32,
    /// `16UC1` or `32FC1`.
    #[prost(string, tag = "4")]
    pub encoding: String,
    /// Bytes per row.
    #[prost(fixed32, tag = "5")]
    pub step: u32,
    /// Row-major pixels, top row first.
    #[prost(bytes = "vec", tag = "6")]
    pub data: Vec<u8>,
}

/// The schema's name.
pub const SCHEMA_NAME: &str = "foxglove.RawImage";

/// The topic of a frame device's images.
pub fn topic(device: u32) -> String {
    match device {
        oils_shared::FRAME_DEVICE_LIDAR => "/lidar/range".into(),
        d => format!("/{}/image", frame_device_name(d).unwrap_or("frame")),
    }
}

fn field(name: &str, number: i32, ty: Type, type_name: Option<&str>) -> FieldDescriptorProto {
    FieldDescriptorProto {
        name: Some(name.into()),
        number: Some(number),
        label: Some(Label::Optional as i32),
        r#type: Some(ty as i32),
        type_name: type_name.map(str::to_string),
        json_name: Some(name.into()),
        ..Default::default()
    }
}

/// `foxglove/RawImage.proto` and `google/protobuf/timestamp.proto` as a serialised
/// `FileDescriptorSet` (the MCAP schema's data).
pub fn schema() -> Vec<u8> {
    let timestamp = FileDescriptorProto {
        name: Some("google/protobuf/timestamp.proto".into()),
        package: Some("google.protobuf".into()),
        message_type: vec![DescriptorProto {
            name: Some("Timestamp".into()),
            field: vec![
                field("seconds", 1, Type::Int64, None),
                field("nanos", 2, Type::Int32, None),
            ],
            ..Default::default()
        }],
        syntax: Some("proto3".into()),
        ..Default::default()
    };
    let raw_image = FileDescriptorProto {
        name: Some("foxglove/RawImage.proto".into()),
        package: Some("foxglove".into()),
        dependency: vec!["google/protobuf/timestamp.proto".into()],
        message_type: vec![DescriptorProto {
            name: Some("RawImage".into()),
            field: vec![
                field(
                    "timestamp",
                    1,
                    Type::Message,
                    Some(".google.protobuf.Timestamp"),
                ),
                field("frame_id", 7, Type::String, None),
                field("width", 2, Type::Fixed32, None),
                field("height", 3, Type::Fixed32, None),
                field("encoding", 4, Type::String, None),
                field("step", 5, Type::Fixed32, None),
                field("data", 6, Type::Bytes, None),
            ],
            ..Default::default()
        }],
        syntax: Some("proto3".into()),
        ..Default::default()
    };
    FileDescriptorSet {
        file: vec![timestamp, raw_image],
    }
    .encode_to_vec()
}

/// Why a frame has no image message.
#[derive(Debug, thiserror::Error)]
pub enum FrameImageError {
    /// The bytes are not the announced frame's.
    #[error("frame {seq} of device {device}: {got} bytes, the announcement says {want}")]
    Length {
        /// Device.
        device: u32,
        /// Frame counter.
        seq: u64,
        /// Bytes handed over.
        got: usize,
        /// Bytes announced.
        want: usize,
    },
    /// A pixel format with no RawImage encoding here.
    #[error("frame format {0} has no RawImage encoding")]
    Format(u32),
}

/// The image message of frame `ann` (`pixels` its bytes), a camera's DN of `camera_bits`
/// shifted to 16 bits; encoded into `out` (cleared first).
pub fn encode(
    ann: &FrameAnnouncement,
    pixels: &[u8],
    camera_bits: u32,
    out: &mut Vec<u8>,
) -> Result<(), FrameImageError> {
    let want = ann.width as usize * ann.height as usize;
    let (encoding, bpp) = match ann.format {
        FRAME_FORMAT_U16_LE => ("16UC1", 2),
        FRAME_FORMAT_F32_LE_M => ("32FC1", 4),
        f => return Err(FrameImageError::Format(f)),
    };
    if pixels.len() != want * bpp || ann.bytes as usize != pixels.len() {
        return Err(FrameImageError::Length {
            device: ann.device,
            seq: ann.seq,
            got: pixels.len(),
            want: ann.bytes as usize,
        });
    }
    let data = if ann.device == FRAME_DEVICE_CAMERA && ann.format == FRAME_FORMAT_U16_LE {
        let shift = 16u32.saturating_sub(camera_bits.clamp(1, 16));
        pixels
            .chunks_exact(2)
            .flat_map(|p| (u16::from_le_bytes([p[0], p[1]]) << shift).to_le_bytes())
            .collect()
    } else {
        pixels.to_vec()
    };
    let t = ann.t_ns.max(0);
    let msg = RawImage {
        timestamp: Some(prost_types::Timestamp {
            seconds: t / 1_000_000_000,
            nanos: (t % 1_000_000_000) as i32,
        }),
        frame_id: frame_device_name(ann.device).unwrap_or("frame").into(),
        width: ann.width,
        height: ann.height,
        encoding: encoding.into(),
        step: ann.width * bpp as u32,
        data,
    };
    out.clear();
    msg.encode(out).expect("a Vec grows as needed");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_camera_frame_decodes_back_with_its_dn_shifted_and_its_time() {
        let pixels: Vec<u8> = [1u16, 4095, 0, 2048, 7, 9]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let ann = FrameAnnouncement {
            device: FRAME_DEVICE_CAMERA,
            format: FRAME_FORMAT_U16_LE,
            width: 3,
            height: 2,
            seq: 4,
            t_ns: 12_345_000_000_123,
            bytes: 12,
            ..Default::default()
        };
        let mut buf = Vec::new();
        encode(&ann, &pixels, 12, &mut buf).unwrap();
        let msg = RawImage::decode(buf.as_slice()).unwrap();
        assert_eq!((msg.width, msg.height, msg.step), (3, 2, 6));
        assert_eq!(msg.encoding, "16UC1");
        assert_eq!(msg.frame_id, "camera");
        let ts = msg.timestamp.unwrap();
        assert_eq!((ts.seconds, ts.nanos), (12_345, 123));
        let dn: Vec<u16> = msg
            .data
            .chunks_exact(2)
            .map(|p| u16::from_le_bytes([p[0], p[1]]))
            .collect();
        assert_eq!(dn, [16, 65520, 0, 32768, 112, 144]);
        let short = FrameAnnouncement { bytes: 10, ..ann };
        assert!(encode(&short, &pixels[..10], 12, &mut buf).is_err());
    }

    #[test]
    fn the_schema_names_rawimage_with_foxgloves_field_numbers() {
        let set = FileDescriptorSet::decode(schema().as_slice()).unwrap();
        let file = set
            .file
            .iter()
            .find(|f| f.name() == "foxglove/RawImage.proto")
            .unwrap();
        let msg = &file.message_type[0];
        assert_eq!(format!("{}.{}", file.package(), msg.name()), SCHEMA_NAME);
        let numbers: Vec<(&str, i32)> = msg.field.iter().map(|f| (f.name(), f.number())).collect();
        assert_eq!(
            numbers,
            [
                ("timestamp", 1),
                ("frame_id", 7),
                ("width", 2),
                ("height", 3),
                ("encoding", 4),
                ("step", 5),
                ("data", 6)
            ]
        );
    }
}
