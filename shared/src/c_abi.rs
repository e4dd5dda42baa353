//! The C ABI of flight software loaded as a shared library (`oils stub --fsw c:PATH`),
//! and the generator of its header `shared/include/oils.h`.
//!
//! A library exports five functions (declared in `oils.h`):
//!
//! | symbol | signature | |
//! |---|---|---|
//! | `oils_fsw_abi_version` | `uint32_t (void)` | [`FSW_ABI_VERSION`] it was built against |
//! | `oils_fsw_layout_hash` | `uint64_t (void)` | [`FSW_LAYOUT_HASH`] it was built against |
//! | `oils_fsw_init` | `void *(const oils_fsw_config *)` | a context, or NULL on failure |
//! | `oils_fsw_step` | `int32_t (void *ctx, const oils_telemetry *, oils_command *)` | [`FSW_STATUS_OK`] or an error code |
//! | `oils_fsw_fini` | `void (void *ctx)` | frees the context |
//! | `oils_fsw_frame` (optional) | `int32_t (void *ctx, const oils_frame_announcement *, const uint8_t *pixels, size_t len)` | a frame announced in the coming telemetry |
//!
//! `oils_fsw_frame` (ABI v2) is called before `oils_fsw_step` once per frame the telemetry
//! announces, with a pointer into the frame's shared memory (no copy), valid during the
//! call only; a library without it never sees frames.
//!
//! The loader checks the first two before calling anything else. The header is generated
//! from [`crate::SCHEMA`] and [`FSW_ABI_SCHEMA`] by [`c_header`], so it cannot drift from
//! the Rust layout; the test `c_header_is_current` regenerates and diffs it, and the header
//! `_Static_assert`s every size and offset where a C compiler reads it.

use crate::{
    ALTIMETER_SAMPLES_MAX, ATTITUDE_MODE_IDEAL_TORQUE, ATTITUDE_MODE_THRUSTERS, IMU_SAMPLES_MAX,
    SAMPLE_FLAG_INHIBITED, SAMPLE_FLAG_NO_LOCK, SAMPLE_FLAG_OUTAGE, SAMPLE_FLAG_SATURATED,
    STAR_TRACKER_SAMPLES_MAX, THRUSTER_COUNT, TLM_FLAG_IDEAL_NAV, TLM_FLAG_SENSORS,
    VELOCIMETER_BEAMS, VELOCIMETER_SAMPLES_MAX,
};
use crate::{ENGINE_COUNT, PROTOCOL_VERSION, SCHEMA, SCHEMA_HASH};
use crate::{
    FRAMES_MAX, FRAME_DEVICE_CAMERA, FRAME_DEVICE_LIDAR, FRAME_DEVICE_TEST_CARD, FRAME_FLAG_FROZEN,
    FRAME_FLAG_OUTAGE, FRAME_FLAG_SATURATED, FRAME_FORMAT_F32_LE_M, FRAME_FORMAT_U16_LE,
};
use crate::{
    NAV_FLAG_FROM_SENSORS, NAV_FLAG_HAZARD_MAPPED, NAV_FLAG_HAZARD_UNMAPPED, NAV_FLAG_LASER_LOST,
    NAV_FLAG_LASER_USED, NAV_FLAG_REINIT, NAV_FLAG_RF_USED, NAV_FLAG_STAR_TRACKER_USED,
    NAV_FLAG_TERRAIN_LOST, NAV_FLAG_TERRAIN_USED, NAV_FLAG_VALID, NAV_FLAG_VELOCIMETER_USED,
    RATE_GROUPS, TLM_FLAG_COMPUTER_RESET, TLM_FLAG_STATE_VECTOR,
};
use crate::{TLM_FLAG_END_OF_RUN, TLM_FLAG_FOOTPAD_CONTACT, TLM_FLAG_NAV_NOISE};
use core::ffi::c_char;
use std::fmt::Write;

/// Version of the C ABI (the five functions, the optional `oils_fsw_frame`, [`FswConfig`]
/// and the status codes); bump on any change to them. v2 added `oils_fsw_frame`.
pub const FSW_ABI_VERSION: u32 = 2;

/// Layout of the structs only the C ABI uses, in the same notation as [`crate::SCHEMA`]
/// (`ptr` is a `const char *`, 8 bytes: the ABI is for 64-bit targets).
pub const FSW_ABI_SCHEMA: &str =
    "FswConfig{abi_version:u32@0,protocol_version:u32@4,schema_hash:u64@8,run_id:u64@16,params:ptr@24,params_len:u64@32}=40|";

/// Hash of every layout a C flight software relies on: FNV-1a 64 over [`crate::SCHEMA`]
/// followed by [`FSW_ABI_SCHEMA`].
pub const FSW_LAYOUT_HASH: u64 = fnv1a_extend(SCHEMA_HASH, FSW_ABI_SCHEMA);

/// Continues an FNV-1a 64 hash over more text: `fnv1a_extend(schema_hash_of(a), b)` is
/// `schema_hash_of(a + b)`.
pub const fn fnv1a_extend(mut hash: u64, more: &str) -> u64 {
    let bytes = more.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

/// `oils_fsw_step` succeeded; the command is valid.
pub const FSW_STATUS_OK: i32 = 0;

/// What `oils_fsw_init` receives: the run it flies and its own parameters.
#[derive(Debug, Clone, Copy)]
#[repr(C)]
pub struct FswConfig {
    /// [`FSW_ABI_VERSION`] of the loader.
    pub abi_version: u32,
    /// [`PROTOCOL_VERSION`] of the loader.
    pub protocol_version: u32,
    /// [`SCHEMA_HASH`] of the loader.
    pub schema_hash: u64,
    /// The run id (also in every telemetry header).
    pub run_id: u64,
    /// The flight software's own parameters as text (the file given with
    /// `--fsw-params`), NUL-terminated; never NULL (empty when none were given). Valid
    /// until `oils_fsw_init` returns: copy what you keep.
    pub params: *const c_char,
    /// Length of `params` in bytes, without the NUL.
    pub params_len: u64,
}

/// C name of a schema struct.
fn c_name(rust: &str) -> String {
    let mut out = String::from("oils_");
    for (i, ch) in rust.chars().enumerate() {
        if ch.is_ascii_uppercase() {
            if i > 0 {
                out.push('_');
            }
            out.push(ch.to_ascii_lowercase());
        } else {
            out.push(ch);
        }
    }
    out
}

/// C type of a scalar schema type, or of a struct.
fn c_type(ty: &str) -> String {
    match ty {
        "u32" => "uint32_t".into(),
        "u64" => "uint64_t".into(),
        "i64" => "int64_t".into(),
        "f64" => "double".into(),
        "ptr" => "const char *".into(),
        other => c_name(other),
    }
}

/// One field of a schema entry.
struct Field<'a> {
    name: &'a str,
    ty: &'a str,
    len: Option<&'a str>,
    offset: &'a str,
}

/// Splits `Name{f:t@o,...}=size` into its parts.
fn parse_entry(entry: &str) -> (&str, Vec<Field<'_>>, &str) {
    let (name, rest) = entry.split_once('{').expect("schema entry has '{'");
    let (body, size) = rest.rsplit_once("}=").expect("schema entry has '}='");
    let mut fields = Vec::new();
    // Fields are separated by ',' outside brackets (an array type holds ';', not ',').
    for f in body.split(',') {
        let (fname, rest) = f.split_once(':').expect("field has ':'");
        let (ty, offset) = rest.rsplit_once('@').expect("field has '@'");
        let (ty, len) = match ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
            Some(arr) => {
                let (t, n) = arr.split_once(';').expect("array has ';'");
                (t, Some(n))
            }
            None => (ty, None),
        };
        fields.push(Field {
            name: fname,
            ty,
            len,
            offset,
        });
    }
    (name, fields, size)
}

fn entries(schema: &str) -> impl Iterator<Item = &str> {
    schema.split('|').filter(|e| !e.is_empty())
}

/// The text of `shared/include/oils.h`.
pub fn c_header() -> String {
    let mut h = String::new();
    let w = &mut h;
    let _ = writeln!(
        w,
        "/* oils.h: the oils bench's wire packets and flight-software C ABI, v{FSW_ABI_VERSION}.\n \
         *\n \
         * GENERATED from shared/src/lib.rs (SCHEMA) and shared/src/c_abi.rs; do not edit.\n \
         * Regenerate: cargo run -p oils-shared --example c_header > shared/include/oils.h\n \
         * Meaning of every field, units and frames: docs/protocol.md. Build your flight\n \
         * software as a shared library exporting the five oils_fsw_* functions below and fly\n \
         * it with `oils run --fsw c:PATH/libmyfsw.so` (or `oils stub --fsw c:PATH`).\n \
         * Targets: 64-bit little-endian; the _Static_asserts below check sizes and offsets. */"
    );
    let _ = writeln!(w, "#ifndef OILS_H\n#define OILS_H\n");
    let _ = writeln!(w, "#include <stdint.h>\n#include <stddef.h>\n");
    let _ = writeln!(w, "#ifdef __cplusplus\nextern \"C\" {{\n#endif\n");
    let _ = writeln!(
        w,
        "#define OILS_PROTOCOL_VERSION {PROTOCOL_VERSION}u\n\
         #define OILS_SCHEMA_HASH UINT64_C({SCHEMA_HASH:#018x})\n\
         #define OILS_FSW_ABI_VERSION {FSW_ABI_VERSION}u\n\
         #define OILS_FSW_LAYOUT_HASH UINT64_C({FSW_LAYOUT_HASH:#018x})\n\
         #define OILS_ENGINE_COUNT {ENGINE_COUNT}\n\
         #define OILS_TLM_FLAG_END_OF_RUN {TLM_FLAG_END_OF_RUN}u /* last telemetry: answer nothing */\n\
         #define OILS_TLM_FLAG_NAV_NOISE {TLM_FLAG_NAV_NOISE}u  /* nav values carry seeded noise */\n\
         #define OILS_TLM_FLAG_FOOTPAD_CONTACT {TLM_FLAG_FOOTPAD_CONTACT}u  /* a footpad touches the ground: engines off */\n\
         #define OILS_TLM_FLAG_IDEAL_NAV {TLM_FLAG_IDEAL_NAV}u  /* nav, accel_body_m_s2, altitude_m are filled */\n\
         #define OILS_TLM_FLAG_SENSORS {TLM_FLAG_SENSORS}u  /* sensors holds the device samples */\n\
         #define OILS_TLM_FLAG_STATE_VECTOR {TLM_FLAG_STATE_VECTOR}u  /* nav holds the ground's state vector to start from */\n\
         #define OILS_TLM_FLAG_COMPUTER_RESET {TLM_FLAG_COMPUTER_RESET}u  /* the computer is resetting: state is lost */\n\
         #define OILS_NAV_FLAG_VALID {NAV_FLAG_VALID}u\n\
         #define OILS_NAV_FLAG_FROM_SENSORS {NAV_FLAG_FROM_SENSORS}u\n\
         #define OILS_NAV_FLAG_STAR_TRACKER_USED {NAV_FLAG_STAR_TRACKER_USED}u\n\
         #define OILS_NAV_FLAG_LASER_USED {NAV_FLAG_LASER_USED}u\n\
         #define OILS_NAV_FLAG_RF_USED {NAV_FLAG_RF_USED}u\n\
         #define OILS_NAV_FLAG_VELOCIMETER_USED {NAV_FLAG_VELOCIMETER_USED}u\n\
         #define OILS_NAV_FLAG_LASER_LOST {NAV_FLAG_LASER_LOST}u\n\
         #define OILS_NAV_FLAG_REINIT {NAV_FLAG_REINIT}u\n\
         #define OILS_NAV_FLAG_TERRAIN_USED {NAV_FLAG_TERRAIN_USED}u\n\
         #define OILS_NAV_FLAG_TERRAIN_LOST {NAV_FLAG_TERRAIN_LOST}u\n\
         #define OILS_NAV_FLAG_HAZARD_MAPPED {NAV_FLAG_HAZARD_MAPPED}u\n\
         #define OILS_NAV_FLAG_HAZARD_UNMAPPED {NAV_FLAG_HAZARD_UNMAPPED}u\n\
         #define OILS_RATE_GROUPS {RATE_GROUPS}\n\
         #define OILS_THRUSTER_COUNT {THRUSTER_COUNT}\n\
         #define OILS_VELOCIMETER_BEAMS {VELOCIMETER_BEAMS}\n\
         #define OILS_IMU_SAMPLES_MAX {IMU_SAMPLES_MAX}\n\
         #define OILS_STAR_TRACKER_SAMPLES_MAX {STAR_TRACKER_SAMPLES_MAX}\n\
         #define OILS_ALTIMETER_SAMPLES_MAX {ALTIMETER_SAMPLES_MAX}\n\
         #define OILS_VELOCIMETER_SAMPLES_MAX {VELOCIMETER_SAMPLES_MAX}\n\
         #define OILS_SAMPLE_FLAG_SATURATED {SAMPLE_FLAG_SATURATED}u\n\
         #define OILS_SAMPLE_FLAG_NO_LOCK {SAMPLE_FLAG_NO_LOCK}u\n\
         #define OILS_SAMPLE_FLAG_INHIBITED {SAMPLE_FLAG_INHIBITED}u\n\
         #define OILS_SAMPLE_FLAG_OUTAGE {SAMPLE_FLAG_OUTAGE}u\n\
         #define OILS_FRAMES_MAX {FRAMES_MAX}\n\
         #define OILS_FRAME_DEVICE_CAMERA {FRAME_DEVICE_CAMERA}u\n\
         #define OILS_FRAME_DEVICE_LIDAR {FRAME_DEVICE_LIDAR}u\n\
         #define OILS_FRAME_DEVICE_TEST_CARD {FRAME_DEVICE_TEST_CARD}u\n\
         #define OILS_FRAME_FORMAT_U16_LE {FRAME_FORMAT_U16_LE}u  /* uint16 little-endian DN, row-major */\n\
         #define OILS_FRAME_FORMAT_F32_LE_M {FRAME_FORMAT_F32_LE_M}u  /* float32 little-endian range, metres; 0 = no return */\n\
         #define OILS_FRAME_FLAG_SATURATED {FRAME_FLAG_SATURATED}u\n\
         #define OILS_FRAME_FLAG_OUTAGE {FRAME_FLAG_OUTAGE}u\n\
         #define OILS_FRAME_FLAG_FROZEN {FRAME_FLAG_FROZEN}u\n\
         #define OILS_ATTITUDE_MODE_IDEAL_TORQUE {ATTITUDE_MODE_IDEAL_TORQUE}u\n\
         #define OILS_ATTITUDE_MODE_THRUSTERS {ATTITUDE_MODE_THRUSTERS}u\n\
         #define OILS_FSW_STATUS_OK {FSW_STATUS_OK} /* any other value from oils_fsw_step stops the run */\n"
    );
    let _ = writeln!(
        w,
        "/* The schema string whose FNV-1a 64 hash is OILS_SCHEMA_HASH. */\n#define OILS_SCHEMA \\"
    );
    let all: Vec<&str> = entries(SCHEMA).collect();
    for (i, e) in all.iter().enumerate() {
        let end = if i + 1 == all.len() { "" } else { " \\" };
        let _ = writeln!(w, "  \"{e}|\"{end}");
    }
    let _ = writeln!(w);

    let mut asserts = String::new();
    for entry in entries(SCHEMA).chain(entries(FSW_ABI_SCHEMA)) {
        let (name, fields, size) = parse_entry(entry);
        let cname = c_name(name);
        let _ = writeln!(w, "typedef struct {cname} {{");
        for f in &fields {
            let ty = c_type(f.ty);
            let sep = if ty.ends_with('*') { "" } else { " " };
            match f.len {
                Some(n) => {
                    let _ = writeln!(w, "  {ty}{sep}{}[{n}];", f.name);
                }
                None => {
                    let _ = writeln!(w, "  {ty}{sep}{};", f.name);
                }
            }
            let _ = writeln!(
                asserts,
                "OILS_STATIC_ASSERT(offsetof({cname}, {}) == {}, \"{cname}.{} offset\");",
                f.name, f.offset, f.name
            );
        }
        let _ = writeln!(w, "}} {cname};\n");
        let _ = writeln!(
            asserts,
            "OILS_STATIC_ASSERT(sizeof({cname}) == {size}, \"{cname} size\");"
        );
    }
    let _ = writeln!(
        w,
        "#ifdef __cplusplus\n#define OILS_STATIC_ASSERT(c, m) static_assert(c, m)\n#else\n\
         #define OILS_STATIC_ASSERT(c, m) _Static_assert(c, m)\n#endif"
    );
    let _ = writeln!(
        w,
        "OILS_STATIC_ASSERT(sizeof(double) == 8 && sizeof(void *) == 8, \"64-bit target\");"
    );
    w.push_str(&asserts);
    let _ = writeln!(
        w,
        "\n/* The flight-software ABI. Export these five from your shared library. */\n\
         \n/* Return OILS_FSW_ABI_VERSION and OILS_FSW_LAYOUT_HASH as compiled: the loader\n \
         * refuses a library built against another header. */\n\
         uint32_t oils_fsw_abi_version(void);\n\
         uint64_t oils_fsw_layout_hash(void);\n\
         \n/* Called once before tick 0: allocate everything here. Return your context (any\n \
         * non-NULL pointer), or NULL to refuse the run (the stub exits with an error). */\n\
         void *oils_fsw_init(const oils_fsw_config *config);\n\
         \n/* Called once per cycle with Telemetry(k): fill cmd->thrust_cmd_n, cmd->engine_on\n \
         * (0/1), and cmd->torque_cmd_body_nm (attitude_mode 0) or cmd->thruster_on_time_ns\n \
         * (attitude_mode 1) (cmd arrives zeroed; the stub stamps the header\n \
         * and stub_compute_ns). Must not block, allocate or read the wall clock: simulated\n \
         * time is tlm->header.t_ns. Return OILS_FSW_STATUS_OK, or any other value to stop\n \
         * the run with that error code. */\n\
         int32_t oils_fsw_step(void *ctx, const oils_telemetry *tlm, oils_command *cmd);\n\
         \n/* Called once after the last step (also after a failed step): free the context. */\n\
         void oils_fsw_fini(void *ctx);\n\
         \n/* Optional (ABI v2): called before oils_fsw_step once per frame that telemetry\n \
         * announces (tlm->sensors.frames), with the frame's pixels in shared memory: len ==\n \
         * ann->bytes bytes, read-only, valid until this call returns (copy what you keep).\n \
         * Must not block or allocate. Return OILS_FSW_STATUS_OK, or any other value to stop\n \
         * the run. A library that does not export it never sees frames. */\n\
         int32_t oils_fsw_frame(void *ctx, const oils_frame_announcement *ann,\n\
         \x20                      const uint8_t *pixels, size_t len);\n"
    );
    let _ = writeln!(
        w,
        "#ifdef __cplusplus\n}} /* extern \"C\" */\n#endif\n\n#endif /* OILS_H */"
    );
    h
}

/// Sizes and offsets of every struct the schemas list, as JSON (for mirrors in other
/// languages to test against): `{"protocol_version":1,"schema":"...","schema_hash":"0x...",
/// "structs":{"PacketHeader":{"size":40,"fields":{"flags":{"offset":4,"type":"u32"},...}}}}`.
pub fn layout_json() -> String {
    let mut j = String::new();
    let _ = write!(
        j,
        "{{\"protocol_version\":{PROTOCOL_VERSION},\"schema\":\"{SCHEMA}\",\"schema_hash\":\"{SCHEMA_HASH:#018x}\",\
         \"fsw_abi_version\":{FSW_ABI_VERSION},\"fsw_layout_hash\":\"{FSW_LAYOUT_HASH:#018x}\",\"structs\":{{"
    );
    for (i, entry) in entries(SCHEMA).chain(entries(FSW_ABI_SCHEMA)).enumerate() {
        let (name, fields, size) = parse_entry(entry);
        if i > 0 {
            j.push(',');
        }
        let _ = write!(j, "\"{name}\":{{\"size\":{size},\"fields\":{{");
        for (k, f) in fields.iter().enumerate() {
            if k > 0 {
                j.push(',');
            }
            let ty = match f.len {
                Some(n) => format!("[{};{n}]", f.ty),
                None => f.ty.to_string(),
            };
            let _ = write!(
                j,
                "\"{}\":{{\"offset\":{},\"type\":\"{ty}\"}}",
                f.name, f.offset
            );
        }
        j.push_str("}}");
    }
    j.push_str("}}");
    j
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schema_hash_of;
    use core::mem::{offset_of, size_of};

    #[test]
    fn layout_hash_covers_both_schemas() {
        let both = format!("{SCHEMA}{FSW_ABI_SCHEMA}");
        assert_eq!(FSW_LAYOUT_HASH, schema_hash_of(&both));
        assert_ne!(FSW_LAYOUT_HASH, SCHEMA_HASH);
    }

    /// The header is generated from the schema strings, so their offsets must be the Rust
    /// offsets: every field of every struct, by name.
    #[test]
    fn schema_offsets_are_the_rust_offsets() {
        use crate::*;
        macro_rules! rust_offsets {
            ($($t:ident { $($f:ident),* }),*) => {
                vec![$($((stringify!($t), stringify!($f), offset_of!($t, $f)),)*)*]
            };
        }
        let rust: Vec<(&str, &str, usize)> = rust_offsets!(
            PacketHeader {
                protocol_version,
                flags,
                schema_hash,
                run_id,
                step,
                t_ns
            },
            NavState {
                pos_mci_m,
                vel_mci_m_s,
                q_mci_from_body,
                rate_body_rad_s
            },
            EngineReading {
                thrust_n,
                chamber_pressure_pa,
                valve_open,
                flags
            },
            PropulsionReadings {
                gas_pressure_pa,
                fuel_tank_pressure_pa,
                ox_tank_pressure_pa,
                engines
            },
            ImuSample {
                t_ns,
                delta_v_body_m_s,
                delta_theta_body_rad,
                valid,
                flags
            },
            StarTrackerSample {
                t_ns,
                q_mci_from_body,
                valid,
                flags
            },
            AltimeterSample {
                t_ns,
                range_m,
                valid,
                flags
            },
            VelocimeterSample {
                t_ns,
                los_velocity_m_s,
                range_m,
                valid,
                flags
            },
            FrameAnnouncement {
                device,
                format,
                width,
                height,
                seq,
                t_ns,
                exposure_ns,
                bytes,
                flags,
                hash
            },
            SensorFrame {
                imu_count,
                star_tracker_count,
                laser_altimeter_count,
                rf_altimeter_count,
                velocimeter_count,
                frame_count,
                imu,
                star_tracker,
                laser_altimeter,
                rf_altimeter,
                velocimeter,
                frames
            },
            Telemetry {
                header,
                nav,
                accel_body_m_s2,
                altitude_m,
                mass_estimate_kg,
                propulsion,
                sensors
            },
            FswReport {
                nav_pos_mci_m,
                nav_vel_mci_m_s,
                nav_pos_sigma_m,
                nav_vel_sigma_m_s,
                nav_altitude_m,
                nav_altitude_sigma_m,
                group_compute_ns,
                nav_flags,
                phase,
                boot_count,
                cycle_slips
            },
            Command {
                header,
                thrust_cmd_n,
                engine_on,
                torque_cmd_body_nm,
                stub_compute_ns,
                thruster_on_time_ns,
                attitude_mode,
                reserved,
                fsw
            },
            FswConfig {
                abi_version,
                protocol_version,
                schema_hash,
                run_id,
                params,
                params_len
            }
        );
        let mut schema = Vec::new();
        for entry in entries(SCHEMA).chain(entries(FSW_ABI_SCHEMA)) {
            let (name, fields, _) = parse_entry(entry);
            for f in fields {
                schema.push((name, f.name, f.offset.parse::<usize>().unwrap()));
            }
        }
        assert_eq!(
            schema, rust,
            "SCHEMA/FSW_ABI_SCHEMA and the Rust structs disagree"
        );
    }

    #[test]
    fn fsw_config_matches_its_schema() {
        assert_eq!(size_of::<FswConfig>(), 40);
        assert_eq!(offset_of!(FswConfig, abi_version), 0);
        assert_eq!(offset_of!(FswConfig, protocol_version), 4);
        assert_eq!(offset_of!(FswConfig, schema_hash), 8);
        assert_eq!(offset_of!(FswConfig, run_id), 16);
        assert_eq!(offset_of!(FswConfig, params), 24);
        assert_eq!(offset_of!(FswConfig, params_len), 32);
        assert!(FSW_ABI_SCHEMA.ends_with("}=40|"));
    }

    #[test]
    fn names_and_entries_parse() {
        assert_eq!(c_name("PacketHeader"), "oils_packet_header");
        assert_eq!(c_name("Telemetry"), "oils_telemetry");
        let (name, fields, size) = parse_entry(
            "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72}=120",
        );
        assert_eq!((name, size, fields.len()), ("Command", "120", 3));
        assert_eq!(fields[1].name, "thrust_cmd_n");
        assert_eq!((fields[1].ty, fields[1].len), ("f64", Some("4")));
        assert_eq!(fields[2].offset, "72");
    }
}
