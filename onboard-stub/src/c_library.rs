//! Flight software from a shared library with the C ABI of `shared/include/oils.h`
//! (`--fsw c:PATH`): hashed (BLAKE3, for the run report), loaded with libloading,
//! checked (ABI version and layout hash) before anything else is called, and wrapped as
//! a [`FlightSoftware`]. The optional `oils_fsw_frame` (ABI v2) gets the frames the
//! telemetry announces, in place.

use crate::fsw::{FlightSoftware, FswFailure};
use libloading::Library;
use oils_shared::c_abi::{FswConfig, FSW_ABI_VERSION, FSW_LAYOUT_HASH, FSW_STATUS_OK};
use oils_shared::{Command, FrameAnnouncement, Telemetry, PROTOCOL_VERSION, SCHEMA_HASH};
use std::ffi::{c_void, CString};
use std::path::{Path, PathBuf};

type AbiVersionFn = unsafe extern "C" fn() -> u32;
type LayoutHashFn = unsafe extern "C" fn() -> u64;
type InitFn = unsafe extern "C" fn(*const FswConfig) -> *mut c_void;
type StepFn = unsafe extern "C" fn(*mut c_void, *const Telemetry, *mut Command) -> i32;
type FiniFn = unsafe extern "C" fn(*mut c_void);
type FrameFn = unsafe extern "C" fn(*mut c_void, *const FrameAnnouncement, *const u8, usize) -> i32;

/// Why a C flight software could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum CLibraryError {
    /// The dynamic loader refused the file.
    #[error("c:{path}: cannot load: {detail}")]
    Load {
        /// The library.
        path: PathBuf,
        /// The loader's message.
        detail: String,
    },
    /// A required `oils_fsw_*` function is not exported.
    #[error(
        "c:{path}: does not export `{symbol}` (see shared/include/oils.h for the five functions)"
    )]
    MissingSymbol {
        /// The library.
        path: PathBuf,
        /// The missing symbol.
        symbol: &'static str,
    },
    /// Built against another `oils.h`.
    #[error(
        "c:{path}: built against oils C ABI v{lib_version} (layout hash {lib_hash:#018x}), \
         this stub speaks v{ours_version} (layout hash {ours_hash:#018x}); \
         rebuild the library against this bench's shared/include/oils.h"
    )]
    AbiMismatch {
        /// The library.
        path: PathBuf,
        /// What the library reports.
        lib_version: u32,
        /// What the library reports.
        lib_hash: u64,
        /// [`FSW_ABI_VERSION`].
        ours_version: u32,
        /// [`FSW_LAYOUT_HASH`].
        ours_hash: u64,
    },
    /// The parameters text holds a NUL byte.
    #[error("c:{path}: the flight-software parameters contain a NUL byte")]
    ParamsNul {
        /// The library.
        path: PathBuf,
    },
    /// `oils_fsw_init` returned NULL.
    #[error("c:{path}: oils_fsw_init refused the run (returned NULL)")]
    InitRefused {
        /// The library.
        path: PathBuf,
    },
    /// The file is not the one the run expects (it changed since it was hashed).
    #[error("c:{path}: the file changed: its BLAKE3 is {found}, the run expects {expected}")]
    Changed {
        /// The library.
        path: PathBuf,
        /// The hash the run expects.
        expected: String,
        /// The file's hash now.
        found: String,
    },
}

/// BLAKE3 of the file at `path`, 64 lowercase hex digits: what a run report records of
/// the C library it flew.
pub fn file_blake3(path: &Path) -> Result<String, CLibraryError> {
    let bytes = std::fs::read(path).map_err(|e| CLibraryError::Load {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    Ok(blake3::hash(&bytes).to_hex().to_string())
}

/// A loaded C flight software with its context.
pub struct CLibraryFsw {
    ctx: *mut c_void,
    step_fn: StepFn,
    fini_fn: FiniFn,
    /// `oils_fsw_frame`, if the library exports it.
    frame_fn: Option<FrameFn>,
    /// A nonzero status `oils_fsw_frame` returned: the step it came before fails.
    frame_status: Option<i32>,
    failure: Option<FswFailure>,
    blake3: String,
    // Last field: dropped after `Drop::drop` has called `oils_fsw_fini`.
    _library: Library,
}

impl std::fmt::Debug for CLibraryFsw {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CLibraryFsw")
            .field("ctx", &self.ctx)
            .field("failure", &self.failure)
            .finish_non_exhaustive()
    }
}

impl CLibraryFsw {
    /// Loads `path`, checks its ABI version and layout hash, and calls `oils_fsw_init`
    /// with the run id and `params` (the flight software's own parameter text).
    pub fn load(path: &Path, run_id: u64, params: &str) -> Result<Self, CLibraryError> {
        Self::load_expecting(path, run_id, params, None)
    }

    /// [`CLibraryFsw::load`], refusing the file ([`CLibraryError::Changed`]) unless its
    /// BLAKE3 is `expected_blake3` (when given): the stub flies the very file the
    /// emulator hashed into the report.
    pub fn load_expecting(
        path: &Path,
        run_id: u64,
        params: &str,
        expected_blake3: Option<&str>,
    ) -> Result<Self, CLibraryError> {
        let owned = || path.to_path_buf();
        let blake3 = file_blake3(path)?;
        if let Some(expected) = expected_blake3.filter(|e| !e.eq_ignore_ascii_case(&blake3)) {
            return Err(CLibraryError::Changed {
                path: owned(),
                expected: expected.to_string(),
                found: blake3,
            });
        }
        // SAFETY: loading a library runs its initialisers; the user named this file as
        // the flight software to fly, which is the trust we extend to any fsw.
        let library = unsafe { Library::new(path) }.map_err(|e| CLibraryError::Load {
            path: owned(),
            detail: e.to_string(),
        })?;
        // SAFETY (all five lookups): the types are those `oils.h` declares; the version
        // and layout checks below refuse a library built against another header before
        // init, step or fini is called.
        let abi_version: AbiVersionFn = unsafe { symbol(&library, path, "oils_fsw_abi_version")? };
        let layout_hash: LayoutHashFn = unsafe { symbol(&library, path, "oils_fsw_layout_hash")? };
        // SAFETY: plain functions without arguments.
        let (lib_version, lib_hash) = unsafe { (abi_version(), layout_hash()) };
        if lib_version != FSW_ABI_VERSION || lib_hash != FSW_LAYOUT_HASH {
            return Err(CLibraryError::AbiMismatch {
                path: owned(),
                lib_version,
                lib_hash,
                ours_version: FSW_ABI_VERSION,
                ours_hash: FSW_LAYOUT_HASH,
            });
        }
        let init_fn: InitFn = unsafe { symbol(&library, path, "oils_fsw_init")? };
        let step_fn: StepFn = unsafe { symbol(&library, path, "oils_fsw_step")? };
        let fini_fn: FiniFn = unsafe { symbol(&library, path, "oils_fsw_fini")? };
        // SAFETY: the type `oils.h` declares for the optional `oils_fsw_frame`.
        let frame_fn: Option<FrameFn> = unsafe { symbol(&library, path, "oils_fsw_frame") }.ok();
        let params =
            CString::new(params).map_err(|_| CLibraryError::ParamsNul { path: owned() })?;
        let config = FswConfig {
            abi_version: FSW_ABI_VERSION,
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
            run_id,
            params: params.as_ptr(),
            params_len: params.as_bytes().len() as u64,
        };
        // SAFETY: `config` and the text it points to outlive the call (the ABI says the
        // library copies what it keeps).
        let ctx = unsafe { init_fn(&config) };
        if ctx.is_null() {
            return Err(CLibraryError::InitRefused { path: owned() });
        }
        Ok(Self {
            ctx,
            step_fn,
            fini_fn,
            frame_fn,
            frame_status: None,
            failure: None,
            blake3,
            _library: library,
        })
    }

    /// BLAKE3 of the file as it was loaded ([`file_blake3`]).
    pub fn blake3(&self) -> &str {
        &self.blake3
    }
}

/// Looks up one function of the ABI.
///
/// # Safety
/// `T` must be the function type `oils.h` declares for `name`.
unsafe fn symbol<T: Copy>(
    library: &Library,
    path: &Path,
    name: &'static str,
) -> Result<T, CLibraryError> {
    // SAFETY: forwarded to the caller.
    unsafe { library.get::<T>(name.as_bytes()) }
        .map(|s| *s)
        .map_err(|_| CLibraryError::MissingSymbol {
            path: path.to_path_buf(),
            symbol: name,
        })
}

impl FlightSoftware for CLibraryFsw {
    fn name(&self) -> &'static str {
        "c"
    }

    fn step(&mut self, tlm: &Telemetry) -> Command {
        let mut cmd = Command::default();
        if self.failure.is_some() {
            return cmd;
        }
        if let Some(status) = self.frame_status.take() {
            self.failure = Some(FswFailure {
                step: tlm.header.step,
                status,
            });
            return cmd;
        }
        // SAFETY: `ctx` came from this library's init and is not yet finalised; both
        // packets are valid for the call.
        let status = unsafe { (self.step_fn)(self.ctx, tlm, &mut cmd) };
        if status != FSW_STATUS_OK {
            self.failure = Some(FswFailure {
                step: tlm.header.step,
                status,
            });
            return Command::default();
        }
        cmd
    }

    fn failure(&self) -> Option<FswFailure> {
        self.failure
    }

    fn frame(&mut self, ann: &FrameAnnouncement, pixels: &[u8]) {
        let Some(frame_fn) = self.frame_fn else {
            return;
        };
        if self.failure.is_some() || self.frame_status.is_some() {
            return;
        }
        // SAFETY: `ctx` is live; `ann` and `pixels` are valid for the call, which is all
        // the ABI promises the library.
        let status = unsafe { frame_fn(self.ctx, ann, pixels.as_ptr(), pixels.len()) };
        if status != FSW_STATUS_OK {
            self.frame_status = Some(status);
        }
    }
}

impl Drop for CLibraryFsw {
    fn drop(&mut self) {
        // SAFETY: `ctx` came from init and is finalised exactly once, before the library
        // is unloaded (the `_library` field drops after this).
        unsafe { (self.fini_fn)(self.ctx) };
    }
}
