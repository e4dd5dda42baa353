//! The OILSLOG record layout as data: where each CSV column's value sits in a record
//! (byte offset, numpy-style dtype), and how the CSV columns that are computed rather
//! than stored are computed. The log writes it into its own JSON header (`"layout"`, see
//! [`crate::session::log_header`]) and `oils export LOG --layout OUT.json` writes it to a
//! file, so a reader in another language (the Python package's `oils_fsw.data`) maps the
//! fixed-size records onto a structured array without a parser and without a copy of
//! any offset.
//!
//! It is made from the same table the CSV export uses ([`log_fields::FIELDS`]): the
//! columns are [`log_fields::csv_columns`], in order. Where a packet field lies is found
//! by probing the record codec itself (a byte set in an all-zero record, decoded, changes
//! exactly the field that holds it), so the description follows the wire packets
//! whatever their layout; where a slot field lies is its slot. A derived column the
//! description cannot describe makes [`layout`] fail with a typed error (and the tests).
//!
//! ```json
//! {"format":"oils-log-layout-1","byte_order":"little","magic":"OILSLOG6",
//!  "header_start":16,"record_size":1000,"trailer":{"magic":"OILSEND6","size":20},
//!  "end_of_run_flag":8,"flags_column":"command.record_flags",
//!  "columns":[{"name":"telemetry.header.step","kind":"u64","offset":40,"dtype":"<u8"},
//!             {"name":"telemetry.t_s","kind":"f64",
//!              "derive":{"op":"scale","of":"telemetry.header.t_ns","factor":1e-9}}, ...],
//!  "site":{...}}
//! ```
//!
//! Derivations (`derive.op`): `scale` (`of` as f64 times `factor`), `bit` (`of` AND
//! `mask` is not 0), `degrees` (`of` times 180/pi, as Rust's `to_degrees`), `site` (the
//! `quantity` of [`Derived::of`](crate::log_fields::Derived::of), element `index` of a
//! vector, from the inputs and the frame under `"site"`).

use crate::log_fields::{self, Access, Field, Kind, Site, Topic, Value, FIELDS};
use crate::recorder::{
    self, MAGIC, RECORD_SIZE, REC_COMMAND_RECEIVED, REC_DEADLINE_MISS, REC_END_OF_RUN,
    REC_REJECTED_VALUES, TRAILER_SIZE,
};
use serde_json::{json, Value as Json};
use thiserror::Error;

/// The description's format name; a reader refuses others.
pub const LAYOUT_FORMAT: &str = "oils-log-layout-1";

/// Bytes before a log's JSON header: magic, header length (u32), header CRC (u32).
pub const HEADER_START: usize = 16;

/// Why the layout cannot be described.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LayoutError {
    /// A packet field no byte of the record holds.
    #[error("log column {column}: no byte of the record holds it")]
    NotStored {
        /// The CSV column.
        column: String,
    },
    /// A packet field whose bytes are not one value of 1, 2, 4 or 8 bytes.
    #[error("log column {column}: its bytes ({bytes:?}) are not one value of 1, 2, 4 or 8 contiguous bytes")]
    Scattered {
        /// The CSV column.
        column: String,
        /// Offsets of the bytes that change it.
        bytes: Vec<usize>,
    },
    /// A column computed from the record that the description has no words for.
    #[error("derived log column {column} has no description (add it to log_layout::derivation)")]
    Undescribed {
        /// The CSV column.
        column: String,
    },
    /// A derivation's input is not a column of the table.
    #[error("the description of {column} names {input}, which is not a stored column")]
    MissingInput {
        /// The derived column.
        column: String,
        /// The input it names.
        input: String,
    },
}

/// Where a stored column lies in a record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stored {
    /// Byte offset within the record.
    pub offset: usize,
    /// numpy dtype string: `<f8`, `<u4`, `<u8`, `<i8`, ...
    pub dtype: String,
}

/// The kind as the description names it.
fn kind_name(kind: Kind) -> &'static str {
    match kind {
        Kind::F64 => "f64",
        Kind::Bool => "bool",
        Kind::U32 => "u32",
        Kind::U64 => "u64",
        Kind::I64 => "i64",
        Kind::Hex => "hex",
        Kind::OptU64 => "opt_u64",
        Kind::OptI64 => "opt_i64",
    }
}

/// Whether two values differ (floats by their bits).
fn differs(a: Value, b: Value) -> bool {
    match (a, b) {
        (Value::F64(x), Value::F64(y)) => x.to_bits() != y.to_bits(),
        (a, b) => a != b,
    }
}

/// For every packet field element (in table order), the record bytes that hold it,
/// found by setting one byte at a time in an all-zero record and decoding it.
fn probe_packets() -> Vec<Vec<usize>> {
    let getters: Vec<(log_fields::Get, usize)> = FIELDS
        .iter()
        .filter_map(|f| match f.access {
            Access::Packet { get, .. } => Some((0..f.count()).map(move |i| (get, i))),
            _ => None,
        })
        .flatten()
        .collect();
    let mut owners = vec![Vec::new(); getters.len()];
    let Some(zero) = recorder::decode_unchecked(&mut [0u8; RECORD_SIZE]) else {
        return owners;
    };
    let base: Vec<Value> = getters.iter().map(|(g, i)| g(&zero, *i)).collect();
    // Bytes 4..8 are the record's CRC.
    for at in (0..4).chain(8..recorder::VALUES_START) {
        let mut bytes = [0u8; RECORD_SIZE];
        bytes[at] = 1;
        let Some(rec) = recorder::decode_unchecked(&mut bytes) else {
            continue;
        };
        for (k, (g, i)) in getters.iter().enumerate() {
            if differs(g(&rec, *i), base[k]) {
                owners[k].push(at);
            }
        }
    }
    owners
}

/// The dtype of a stored integer or float of `width` bytes and `kind`.
fn dtype(kind: Kind, width: usize) -> String {
    let letter = match kind {
        Kind::F64 => 'f',
        Kind::I64 | Kind::OptI64 => 'i',
        Kind::Bool | Kind::U32 | Kind::U64 | Kind::Hex | Kind::OptU64 => 'u',
    };
    format!("<{letter}{width}")
}

/// Where every stored column lies, by CSV column name, in table order; derived columns
/// are `None`.
pub fn stored_columns() -> Result<Vec<(String, Option<Stored>)>, LayoutError> {
    let mut probed = probe_packets().into_iter();
    let mut out = Vec::new();
    for f in FIELDS {
        for i in 0..f.count() {
            let column = f.column(i);
            let stored = match f.access {
                Access::Packet { .. } => {
                    let bytes = probed.next().unwrap_or_default();
                    let (Some(&first), Some(&last)) = (bytes.first(), bytes.last()) else {
                        return Err(LayoutError::NotStored { column });
                    };
                    let width = bytes.len();
                    if last + 1 - first != width || ![1, 2, 4, 8].contains(&width) {
                        return Err(LayoutError::Scattered { column, bytes });
                    }
                    Some(Stored {
                        offset: first,
                        dtype: dtype(f.kind, width),
                    })
                }
                Access::Slot { at, stride, .. } => Some(Stored {
                    offset: recorder::VALUES_START + 8 * (at + i * stride),
                    dtype: "<f8".into(),
                }),
                Access::Derived(_) | Access::Echo(_) => None,
            };
            if f.in_csv() {
                out.push((column, stored));
            }
        }
    }
    Ok(out)
}

/// The CSV column of element `i` of the field at (`topic`, `path`).
fn column_of(topic: Topic, path: &str, i: usize) -> Option<String> {
    FIELDS
        .iter()
        .find(|f| f.topic == topic && f.path == path && f.in_csv())
        .filter(|f| i < f.count())
        .map(|f| f.column(i))
}

/// How a derived column is computed, in the description's words.
fn derivation(f: &Field, i: usize) -> Option<Json> {
    let bit = |mask: u32| Some(json!({"op": "bit", "of": "command.record_flags", "mask": mask}));
    match (f.topic, f.path) {
        (Topic::Telemetry, "t_s") => Some(
            json!({"op": "scale", "of": column_of(Topic::Telemetry, "header.t_ns", 0)?, "factor": 1e-9}),
        ),
        (Topic::Command, "received") => bit(REC_COMMAND_RECEIVED),
        (Topic::Command, "deadline_miss") => bit(REC_DEADLINE_MISS),
        (Topic::Command, "rejected_values") => bit(REC_REJECTED_VALUES),
        (Topic::Truth, "rate_body_deg_s") => {
            Some(json!({"op": "degrees", "of": column_of(Topic::Truth, "rate_body_rad_s", i)?}))
        }
        (Topic::Truth, q @ ("vertical_speed_m_s" | "horizontal_speed_m_s" | "tilt_deg")) => {
            Some(json!({"op": "site", "quantity": q}))
        }
        (Topic::Truth, q @ ("pos_site_m" | "vel_site_m_s")) => {
            Some(json!({"op": "site", "quantity": q, "index": i}))
        }
        (
            Topic::Truth,
            q @ ("nav_error.pos_mci_m" | "nav_error.vel_mci_m_s" | "nav_error.altitude_m"),
        ) => {
            let (estimate, truth, index) = match q {
                "nav_error.pos_mci_m" => ("fsw.nav_pos_mci_m", "pos_mci_m", i),
                "nav_error.vel_mci_m_s" => ("fsw.nav_vel_mci_m_s", "vel_mci_m_s", i),
                _ => ("fsw.nav_altitude_m", "altitude_m", 0),
            };
            Some(json!({
                "op": "nav_error",
                "estimate": column_of(Topic::Command, estimate, index)?,
                "truth": column_of(Topic::Truth, truth, index)?,
                "flags": column_of(Topic::Command, "fsw.nav_flags", 0)?,
                "mask": oils_shared::NAV_FLAG_VALID,
            }))
        }
        _ => None,
    }
}

/// The inputs and frame of the `site` derivations ([`crate::log_fields::Derived::of`]):
/// the true state's columns, the site frame (rotation from Moon-fixed axes to east,
/// north, up, row-major, and its origin, Moon-fixed) and the Moon's rotation rate about
/// +Z (Moon-fixed from inertial at `t`: a rotation by `-rate * t` about Z).
fn site_description(site: &Site) -> Result<Json, LayoutError> {
    let col = |path: &str, i: usize| {
        column_of(Topic::Truth, path, i).ok_or_else(|| LayoutError::MissingInput {
            column: "truth (site derivations)".into(),
            input: format!("truth.{path}[{i}]"),
        })
    };
    let vec = |path: &str, n: usize| (0..n).map(|i| col(path, i)).collect::<Result<Vec<_>, _>>();
    let r = site.frame.rot_site_from_mcmf();
    let o = site.frame.origin_mcmf();
    Ok(json!({
        "t_ns": column_of(Topic::Telemetry, "header.t_ns", 0).ok_or_else(|| LayoutError::MissingInput {
            column: "truth (site derivations)".into(),
            input: "telemetry.header.t_ns".into(),
        })?,
        "pos_mci_m": vec("pos_mci_m", 3)?,
        "vel_mci_m_s": vec("vel_mci_m_s", 3)?,
        "q_mci_from_body": vec("q_mci_from_body", 4)?,
        "rot_site_from_mcmf": (0..3).map(|i| (0..3).map(|j| r[(i, j)]).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "origin_mcmf_m": [o.x, o.y, o.z],
        "moon_rotation_rate_rad_s": site.rotation.rate_rad_s,
    }))
}

/// The description of the records of a log whose run has `site`.
pub fn layout(site: &Site) -> Result<Json, LayoutError> {
    let stored = stored_columns()?;
    let names: std::collections::HashSet<&str> = stored
        .iter()
        .filter(|(_, s)| s.is_some())
        .map(|(n, _)| n.as_str())
        .collect();
    let mut columns = Vec::with_capacity(stored.len());
    let mut rows = stored.iter();
    for f in FIELDS.iter().filter(|f| f.in_csv()) {
        for i in 0..f.count() {
            let Some((name, place)) = rows.next() else {
                return Err(LayoutError::NotStored {
                    column: f.column(i),
                });
            };
            let kind = kind_name(f.kind);
            columns.push(match place {
                Some(s) => {
                    json!({"name": name, "kind": kind, "offset": s.offset, "dtype": s.dtype})
                }
                None => {
                    let derive = derivation(f, i).ok_or_else(|| LayoutError::Undescribed {
                        column: name.clone(),
                    })?;
                    if let Some(input) = derive["of"].as_str().filter(|n| !names.contains(n)) {
                        return Err(LayoutError::MissingInput {
                            column: name.clone(),
                            input: input.into(),
                        });
                    }
                    json!({"name": name, "kind": kind, "derive": derive})
                }
            });
        }
    }
    Ok(json!({
        "format": LAYOUT_FORMAT,
        "byte_order": "little",
        "magic": String::from_utf8_lossy(MAGIC),
        "header_start": HEADER_START,
        "record_size": RECORD_SIZE,
        "crc": {"offset": 4, "covers": "bytes 0..4 and 8..record_size (CRC-32, IEEE)"},
        "trailer": {"magic": String::from_utf8_lossy(crate::recorder::TRAILER_MAGIC), "size": TRAILER_SIZE},
        "frames": {
            "header_size": crate::recorder::FRAME_HEADER_SIZE,
            "header": "records u32, packed_len u32, CRC-32 of those 8 bytes",
            "max_records": crate::recorder::FRAME_RECORDS,
            "codec": "zstd",
            "packing": "the records' bytes as little-endian u64 words, each word's second difference along the frame's records (wrapping; the first two against zeros), as byte planes: byte b of word j of record r at (8 j + b) * records + r",
        },
        "end_of_run_flag": REC_END_OF_RUN,
        "flags_column": column_of(Topic::Command, "record_flags", 0),
        "columns": columns,
        "site": site_description(site)?,
    }))
}

/// The layout for a log header: the description, or `{"error": why}` when it cannot be
/// made (the tests keep that from happening).
pub fn layout_or_error(site: &Site) -> Json {
    layout(site).unwrap_or_else(|e| json!({"error": e.to_string()}))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::ScenarioConfig;

    fn site() -> Site {
        Site::of_scenario(&ScenarioConfig::default())
    }

    /// Every CSV column, in order, is in the description: stored, or derived with words.
    #[test]
    fn every_csv_column_is_described_in_order() {
        let l = layout(&site()).unwrap();
        let names: Vec<&str> = l["columns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["name"].as_str().unwrap())
            .collect();
        assert_eq!(names, log_fields::csv_columns());
        for c in l["columns"].as_array().unwrap() {
            assert!(
                c.get("offset").is_some() != c.get("derive").is_some(),
                "{c}"
            );
        }
        assert_eq!(l["record_size"], RECORD_SIZE);
    }

    /// The probed offsets are the wire packets' (oils_shared's layout) and the slots'.
    #[test]
    fn offsets_are_the_packets_and_slots() {
        use core::mem::{offset_of, size_of};
        use oils_shared::{Command, Telemetry};
        let cols = stored_columns().unwrap();
        let at = |name: &str| {
            cols.iter()
                .find(|(n, _)| n == name)
                .and_then(|(_, s)| s.clone())
                .unwrap()
        };
        let tlm = 8;
        let cmd = 8 + size_of::<Telemetry>();
        assert_eq!(at("command.record_flags").offset, 0);
        assert_eq!(at("command.record_flags").dtype, "<u4");
        assert_eq!(
            at("telemetry.altitude_m").offset,
            tlm + offset_of!(Telemetry, altitude_m)
        );
        assert_eq!(at("telemetry.header.run_id").dtype, "<u8");
        assert_eq!(at("telemetry.header.t_ns").dtype, "<i8");
        assert_eq!(
            at("command.torque_cmd_body_nm[2]").offset,
            cmd + offset_of!(Command, torque_cmd_body_nm) + 16
        );
        assert_eq!(
            at("telemetry.propulsion.engines[1].valve_open").dtype,
            "<u4"
        );
        assert_eq!(
            at("truth.pos_mci_m[0]").offset,
            recorder::VALUES_START + 8 * 11
        );
        // Interleaved slots: fuel, ox, fuel, ...
        assert_eq!(
            at("propulsion.ox_valve_position[1]").offset,
            recorder::VALUES_START + 8 * 52
        );
    }

    /// The description says where each value is: a record's bytes at each stored
    /// column's offset are the value the CSV export writes.
    #[test]
    fn offsets_read_back_a_record() {
        let r = recorder::tests::distinct_record();
        let bytes = recorder::encode_record(&r);
        let d = log_fields::Derived::default();
        let s = log_fields::Sample {
            record: &r,
            derived: &d,
        };
        let mut values = FIELDS
            .iter()
            .filter(|f| f.in_csv())
            .flat_map(|f| (0..f.count()).map(move |i| (f, i)));
        for (name, place) in stored_columns().unwrap() {
            let (f, i) = values.next().unwrap();
            assert_eq!(f.column(i), name);
            let Some(p) = place else { continue };
            let b = &bytes[p.offset..];
            let want = f.kind.to_f64(f.get(&s, i));
            let got = match p.dtype.as_str() {
                "<f8" => f64::from_le_bytes(b[..8].try_into().unwrap()),
                "<u8" => u64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
                "<i8" => i64::from_le_bytes(b[..8].try_into().unwrap()) as f64,
                "<u4" => f64::from(u32::from_le_bytes(b[..4].try_into().unwrap())),
                other => panic!("{name}: dtype {other}"),
            };
            assert_eq!(got.to_bits(), want.to_bits(), "{name}");
        }
    }
}
