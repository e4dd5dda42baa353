//! The C functions of the FMI 2.0 and 3.0 co-simulation interfaces the importer calls,
//! declared from `fmi2Functions.h` / `fmi3Functions.h`, and the binary they are loaded
//! from (kept loaded as long as any instance lives: [`Binary`] owns the library).

use crate::{FmiError, FmiVersion};
use std::ffi::{c_char, c_int, c_void};
use std::path::Path;

/// `fmi2Status` / `fmi3Status`: both enumerate OK, Warning, Discard, Error, Fatal,
/// (2.0:) Pending.
pub type Status = c_int;

/// The status's name.
pub fn status_name(s: Status) -> &'static str {
    match s {
        0 => "OK",
        1 => "Warning",
        2 => "Discard",
        3 => "Error",
        4 => "Fatal",
        5 => "Pending",
        _ => "an unknown status",
    }
}

/// `fmi2CallbackLogger`. C-variadic in the header; declared here with the first
/// variadic argument as a sixth pointer parameter, which the x86-64 and AArch64 Linux
/// calling conventions pass where a fixed one would be (see `instance::log2`).
pub type Logger2 = unsafe extern "C" fn(
    env: *mut c_void,
    instance_name: *const c_char,
    status: Status,
    category: *const c_char,
    message: *const c_char,
    arg0: *const c_char,
);

/// `fmi2CallbackFunctions`.
#[repr(C)]
pub struct CallbackFunctions2 {
    pub logger: Option<Logger2>,
    pub allocate_memory: Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>,
    pub free_memory: Option<unsafe extern "C" fn(*mut c_void)>,
    pub step_finished: Option<unsafe extern "C" fn(*mut c_void, Status)>,
    pub component_environment: *mut c_void,
}

/// `fmi3LogMessageCallback`.
pub type Logger3 = unsafe extern "C" fn(
    env: *mut c_void,
    status: Status,
    category: *const c_char,
    message: *const c_char,
);

pub type Instantiate2 = unsafe extern "C" fn(
    *const c_char,
    c_int,
    *const c_char,
    *const c_char,
    *const CallbackFunctions2,
    c_int,
    c_int,
) -> *mut c_void;
pub type SetupExperiment2 =
    unsafe extern "C" fn(*mut c_void, c_int, f64, f64, c_int, f64) -> Status;
pub type Component = unsafe extern "C" fn(*mut c_void) -> Status;
pub type FreeInstance = unsafe extern "C" fn(*mut c_void);
pub type SetReal2 = unsafe extern "C" fn(*mut c_void, *const u32, usize, *const f64) -> Status;
pub type GetReal2 = unsafe extern "C" fn(*mut c_void, *const u32, usize, *mut f64) -> Status;
pub type SetBoolean2 = unsafe extern "C" fn(*mut c_void, *const u32, usize, *const c_int) -> Status;
pub type DoStep2 = unsafe extern "C" fn(*mut c_void, f64, f64, c_int) -> Status;

pub type Instantiate3 = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    bool,
    bool,
    *const u32,
    usize,
    *mut c_void,
    Option<Logger3>,
    *mut c_void,
) -> *mut c_void;
pub type EnterInit3 = unsafe extern "C" fn(*mut c_void, bool, f64, f64, bool, f64) -> Status;
pub type SetFloat64 =
    unsafe extern "C" fn(*mut c_void, *const u32, usize, *const f64, usize) -> Status;
pub type GetFloat64 =
    unsafe extern "C" fn(*mut c_void, *const u32, usize, *mut f64, usize) -> Status;
pub type SetBoolean3 =
    unsafe extern "C" fn(*mut c_void, *const u32, usize, *const bool, usize) -> Status;
pub type DoStep3 = unsafe extern "C" fn(
    *mut c_void,
    f64,
    f64,
    bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut f64,
) -> Status;

/// The FMI 2.0 functions.
pub struct Api2 {
    pub instantiate: Instantiate2,
    pub setup_experiment: SetupExperiment2,
    pub enter_initialization_mode: Component,
    pub exit_initialization_mode: Component,
    pub set_real: SetReal2,
    pub get_real: GetReal2,
    pub set_boolean: SetBoolean2,
    pub do_step: DoStep2,
    pub terminate: Component,
    pub free_instance: FreeInstance,
}

/// The FMI 3.0 functions.
pub struct Api3 {
    pub instantiate: Instantiate3,
    pub enter_initialization_mode: EnterInit3,
    pub exit_initialization_mode: Component,
    pub set_float64: SetFloat64,
    pub get_float64: GetFloat64,
    pub set_boolean: SetBoolean3,
    pub do_step: DoStep3,
    pub terminate: Component,
    pub free_instance: FreeInstance,
}

/// The functions of one version.
pub enum Api {
    V2(Api2),
    V3(Api3),
}

/// A loaded FMU binary: the library (unloaded on drop, after every instance) and its
/// functions.
pub struct Binary {
    pub api: Api,
    _lib: libloading::Library,
}

/// Resolves `name` in `lib` as a function of type `T`.
///
/// # Safety
/// `T` must be the function's real C signature.
unsafe fn sym<T: Copy>(lib: &libloading::Library, name: &'static str) -> Result<T, FmiError> {
    // SAFETY: per the function's contract; the pointer is used only while `lib` lives
    // (`Binary` keeps both).
    unsafe {
        lib.get::<T>(name.as_bytes())
            .map(|s| *s)
            .map_err(|source| FmiError::Symbol { name, source })
    }
}

impl Binary {
    /// Loads `path` and resolves the functions of `version`.
    pub fn load(path: &Path, version: FmiVersion) -> Result<Self, FmiError> {
        // SAFETY: loading a library runs its initialisers: the FMU's binary is trusted
        // as the user's own model, as any FMI importer trusts it.
        let lib = unsafe { libloading::Library::new(path) }.map_err(|source| FmiError::Load {
            path: path.to_path_buf(),
            source,
        })?;
        // SAFETY (every `sym` below): the types are the standard's signatures.
        let api = unsafe {
            match version {
                FmiVersion::V2 => Api::V2(Api2 {
                    instantiate: sym(&lib, "fmi2Instantiate")?,
                    setup_experiment: sym(&lib, "fmi2SetupExperiment")?,
                    enter_initialization_mode: sym(&lib, "fmi2EnterInitializationMode")?,
                    exit_initialization_mode: sym(&lib, "fmi2ExitInitializationMode")?,
                    set_real: sym(&lib, "fmi2SetReal")?,
                    get_real: sym(&lib, "fmi2GetReal")?,
                    set_boolean: sym(&lib, "fmi2SetBoolean")?,
                    do_step: sym(&lib, "fmi2DoStep")?,
                    terminate: sym(&lib, "fmi2Terminate")?,
                    free_instance: sym(&lib, "fmi2FreeInstance")?,
                }),
                FmiVersion::V3 => Api::V3(Api3 {
                    instantiate: sym(&lib, "fmi3InstantiateCoSimulation")?,
                    enter_initialization_mode: sym(&lib, "fmi3EnterInitializationMode")?,
                    exit_initialization_mode: sym(&lib, "fmi3ExitInitializationMode")?,
                    set_float64: sym(&lib, "fmi3SetFloat64")?,
                    get_float64: sym(&lib, "fmi3GetFloat64")?,
                    set_boolean: sym(&lib, "fmi3SetBoolean")?,
                    do_step: sym(&lib, "fmi3DoStep")?,
                    terminate: sym(&lib, "fmi3Terminate")?,
                    free_instance: sym(&lib, "fmi3FreeInstance")?,
                }),
            }
        };
        Ok(Self { api, _lib: lib })
    }
}
