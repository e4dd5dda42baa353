//! The reference descent GNC ([`ReferenceGnc`]) behind the C ABI of
//! `shared/include/oils.h`, built as `liboils_cabi_gnc.so`:
//!
//! ```text
//! cargo build --release -p oils-cabi-gnc
//! oils run --fsw c:target/release/liboils_cabi_gnc.so
//! ```
//!
//! It proves the ABI carries a whole GNC: through it the default descent gives the same
//! digest as the native `--fsw gnc` (tested in `tests/fsw_c_abi.rs` at the workspace root).
//! Without parameters it flies [`GncConfig::default`] (the default scenario's site, the
//! bench's navigation, the ideal torque), like `--fsw gnc`. `--fsw-params FILE` takes a
//! TOML file with the choices `oils run --gnc-nav/--gnc-attitude` make for the native GNC,
//! and the site:
//!
//! ```toml
//! navigation = "sensors"      # or "bench"; sensors needs `--telemetry sensors`
//! attitude = "thrusters"      # or "torque"
//! site_deg = [-69.373, 32.319] # latitude, east longitude; default: the default scenario's
//! map = "pinpoint.oilsmap"    # terrain navigation data (`oils map`): navigates by the camera
//! ```
//!
//! With a map it also exports `oils_fsw_frame`: the camera's frames reach the GNC's
//! terrain-relative navigation in place, as they reach the native one.
//!
//! Anything else in the file, or a value it cannot read, fails `oils_fsw_init` with the
//! reason on standard error.
#![warn(missing_docs)]

use oils_onboard_stub::fsw::FlightSoftware;
use oils_onboard_stub::gnc::{ReferenceGnc, SiteTarget};
use oils_shared::c_abi::{FswConfig, FSW_ABI_VERSION, FSW_LAYOUT_HASH, FSW_STATUS_OK};
use oils_shared::fsw::{GncAttitude, GncNavigation, GncOptions};
use oils_shared::{Command, FrameAnnouncement, Telemetry};
use std::ffi::c_void;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// `oils_fsw_step` status: the GNC panicked (a bug; the run stops).
pub const STATUS_PANIC: i32 = 2;
/// `oils_fsw_step` status: a NULL context or packet.
pub const STATUS_NULL: i32 = 3;

/// [`FSW_ABI_VERSION`] this library was built with.
#[no_mangle]
pub extern "C" fn oils_fsw_abi_version() -> u32 {
    FSW_ABI_VERSION
}

/// [`FSW_LAYOUT_HASH`] this library was built with.
#[no_mangle]
pub extern "C" fn oils_fsw_layout_hash() -> u64 {
    FSW_LAYOUT_HASH
}

/// The parameters `--fsw-params` may give (see the crate documentation).
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Params {
    navigation: Option<GncNavigation>,
    attitude: Option<GncAttitude>,
    site_deg: Option<[f64; 2]>,
    /// Terrain navigation data (`oils map`), read when the library is initialised.
    map: Option<std::path::PathBuf>,
    /// Hazard detection and avoidance at the hover.
    hazard_avoidance: Option<bool>,
}

/// The GNC the parameters text asks for.
fn build(params: &str) -> Result<ReferenceGnc, String> {
    let p: Params = toml::from_str(params).map_err(|e| format!("--fsw-params: {e}"))?;
    let options = GncOptions {
        navigation: p.navigation.unwrap_or_default(),
        attitude: p.attitude.unwrap_or_default(),
        map: p.map,
        hazard_avoidance: p.hazard_avoidance.unwrap_or(false),
    };
    let site = p.site_deg.map(|[latitude_deg, longitude_deg]| SiteTarget {
        latitude_deg,
        longitude_deg,
    });
    let cfg = oils_onboard_stub::build::gnc_config(site, &options)
        .map_err(|e| format!("--fsw-params: {e}"))?;
    ReferenceGnc::new(cfg).map_err(|e| format!("--fsw-params: {e}"))
}

/// A boxed [`ReferenceGnc`] configured by the parameters; NULL when `config` is NULL,
/// from another ABI version, or its parameters are refused (the reason on stderr).
///
/// # Safety
/// `config` is NULL or points to a valid [`FswConfig`] whose `params` holds `params_len`
/// readable bytes.
#[no_mangle]
pub unsafe extern "C" fn oils_fsw_init(config: *const FswConfig) -> *mut c_void {
    // SAFETY: the caller passes NULL or a valid config.
    let Some(config) = (unsafe { config.as_ref() }) else {
        return std::ptr::null_mut();
    };
    if config.abi_version != FSW_ABI_VERSION {
        return std::ptr::null_mut();
    }
    let params = if config.params.is_null() || config.params_len == 0 {
        ""
    } else {
        // SAFETY: the loader passes `params_len` readable bytes at `params`.
        let bytes = unsafe {
            std::slice::from_raw_parts(config.params.cast::<u8>(), config.params_len as usize)
        };
        match std::str::from_utf8(bytes) {
            Ok(t) => t,
            Err(_) => {
                eprintln!("liboils_cabi_gnc: --fsw-params is not UTF-8 text");
                return std::ptr::null_mut();
            }
        }
    };
    match catch_unwind(|| build(params)) {
        Ok(Ok(gnc)) => Box::into_raw(Box::new(gnc)).cast(),
        Ok(Err(why)) => {
            eprintln!("liboils_cabi_gnc: {why}");
            std::ptr::null_mut()
        }
        Err(_) => std::ptr::null_mut(),
    }
}

/// One GNC step: Telemetry(k) in, Command(k) out.
///
/// # Safety
/// `ctx` comes from [`oils_fsw_init`] and is not yet finalised; `tlm` and `cmd` are NULL
/// or valid packets.
#[no_mangle]
pub unsafe extern "C" fn oils_fsw_step(
    ctx: *mut c_void,
    tlm: *const Telemetry,
    cmd: *mut Command,
) -> i32 {
    // SAFETY: the caller's contract.
    let (gnc, tlm, cmd) = unsafe {
        (
            ctx.cast::<ReferenceGnc>().as_mut(),
            tlm.as_ref(),
            cmd.as_mut(),
        )
    };
    let (Some(gnc), Some(tlm), Some(cmd)) = (gnc, tlm, cmd) else {
        return STATUS_NULL;
    };
    // A panic must not unwind into C.
    match catch_unwind(AssertUnwindSafe(|| gnc.step(tlm))) {
        Ok(c) => {
            *cmd = c;
            FSW_STATUS_OK
        }
        Err(_) => STATUS_PANIC,
    }
}

/// A frame the coming telemetry announces, its pixels in place (valid during the call).
///
/// # Safety
/// `ctx` comes from [`oils_fsw_init`]; `ann` is NULL or a valid announcement; `pixels`
/// is NULL or points to `len` readable bytes.
#[no_mangle]
pub unsafe extern "C" fn oils_fsw_frame(
    ctx: *mut c_void,
    ann: *const FrameAnnouncement,
    pixels: *const u8,
    len: usize,
) -> i32 {
    // SAFETY: the caller's contract.
    let (gnc, ann) = unsafe { (ctx.cast::<ReferenceGnc>().as_mut(), ann.as_ref()) };
    let (Some(gnc), Some(ann)) = (gnc, ann) else {
        return STATUS_NULL;
    };
    if pixels.is_null() {
        return STATUS_NULL;
    }
    // SAFETY: `len` readable bytes at `pixels`, for the call.
    let pixels = unsafe { std::slice::from_raw_parts(pixels, len) };
    match catch_unwind(AssertUnwindSafe(|| gnc.frame(ann, pixels))) {
        Ok(()) => FSW_STATUS_OK,
        Err(_) => STATUS_PANIC,
    }
}

/// Frees the GNC.
///
/// # Safety
/// `ctx` is NULL or comes from [`oils_fsw_init`] and is finalised only once.
#[no_mangle]
pub unsafe extern "C" fn oils_fsw_fini(ctx: *mut c_void) {
    if !ctx.is_null() {
        // SAFETY: made by Box::into_raw in init, freed once.
        drop(unsafe { Box::from_raw(ctx.cast::<ReferenceGnc>()) });
    }
}
