//! The FMI 2.0 co-simulation entry points (`fmi2Functions.h`). Every function of the
//! standard's co-simulation interface is exported; state, derivative and status
//! queries answer `fmi2Error`.
//!
//! SAFETY (all functions): as for [`crate::fmi3`]: the importer passes a component this
//! library returned from `fmi2Instantiate` and not yet freed, and arrays of the lengths
//! it gives; every pointer is checked for null before use.
#![allow(non_snake_case)]

use crate::instance::Instance;
use std::ffi::{c_char, c_int, c_void, CStr, CString};

/// `fmi2Status`.
pub type Status = c_int;
/// `fmi2OK`.
pub const OK: Status = 0;
/// `fmi2Error`.
pub const ERROR: Status = 3;
/// `fmi2CoSimulation`.
pub const CO_SIMULATION: c_int = 1;

/// `fmi2CallbackLogger` (C-variadic: the message is a printf format).
pub type Logger = Option<
    unsafe extern "C" fn(
        env: *mut c_void,
        instance_name: *const c_char,
        status: Status,
        category: *const c_char,
        message: *const c_char,
        ...
    ),
>;

/// `fmi2CallbackFunctions`.
#[repr(C)]
pub struct CallbackFunctions {
    /// Logger.
    pub logger: Logger,
    /// `calloc`-like allocator (unused: this FMU allocates with Rust's).
    pub allocate_memory: *mut c_void,
    /// `free`-like (unused).
    pub free_memory: *mut c_void,
    /// Asynchronous step end (unused).
    pub step_finished: *mut c_void,
    /// Passed back to the logger.
    pub component_environment: *mut c_void,
}

/// One component with what the importer handed in for logging.
pub struct Fmu2 {
    inst: Instance,
    name: CString,
    env: *mut c_void,
    logger: Logger,
}

fn log(logger: Logger, env: *mut c_void, name: &CStr, message: &str) {
    let Some(log) = logger else { return };
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    // SAFETY: the importer's callback and environment; the message goes through "%s",
    // so no `%` in it is read as a format; all strings live across the call.
    unsafe {
        log(
            env,
            name.as_ptr(),
            ERROR,
            c"logStatusError".as_ptr(),
            c"%s".as_ptr(),
            text.as_ptr(),
        )
    };
}

impl Fmu2 {
    fn status(&self, r: Result<(), String>) -> Status {
        match r {
            Ok(()) => OK,
            Err(m) => {
                log(self.logger, self.env, &self.name, &m);
                ERROR
            }
        }
    }
}

/// # Safety
/// `c` is null or a live component.
unsafe fn fmu<'a>(c: *mut c_void) -> Option<&'a mut Fmu2> {
    // SAFETY: per the function's contract.
    unsafe { (c as *mut Fmu2).as_mut() }
}

/// # Safety
/// `s` is null or a NUL-terminated string.
unsafe fn string(s: *const c_char) -> String {
    if s.is_null() {
        String::new()
    } else {
        // SAFETY: per the function's contract.
        unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
    }
}

/// The directory a `file:` URI names (`file:///a/b`, `file:/a/b`), percent-decoded.
pub fn path_of_uri(uri: &str) -> Option<std::path::PathBuf> {
    let rest = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))?;
    // `file://host/path`: only an empty host or localhost is local.
    let rest = if let Some(p) = rest.strip_prefix("localhost/") {
        format!("/{p}")
    } else if rest.starts_with('/') {
        rest.to_string()
    } else {
        return None;
    };
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    Some(std::path::PathBuf::from(String::from_utf8(out).ok()?))
}

/// The standard platform types.
#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

/// The FMI version this binary implements.
#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

/// Debug categories: none; logging is of errors only, always on.
#[no_mangle]
pub extern "C" fn fmi2SetDebugLogging(
    _c: *mut c_void,
    _logging_on: c_int,
    _n: usize,
    _categories: *const *const c_char,
) -> Status {
    OK
}

/// Instantiates the model in `resource_location` (a `file:` URI, FMI 2.0).
///
/// # Safety
/// Strings are null or NUL-terminated, `functions` null or valid; see the module.
#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: *const c_char,
    fmu_type: c_int,
    guid: *const c_char,
    resource_location: *const c_char,
    functions: *const CallbackFunctions,
    _visible: c_int,
    _logging_on: c_int,
) -> *mut c_void {
    // SAFETY: strings and callbacks per the contract.
    let (name, guid, uri) = unsafe {
        (
            string(instance_name),
            string(guid),
            string(resource_location),
        )
    };
    // SAFETY: per the contract.
    let (logger, env) = match unsafe { functions.as_ref() } {
        Some(f) => (f.logger, f.component_environment),
        None => (None, std::ptr::null_mut()),
    };
    let name = CString::new(name.replace('\0', " ")).unwrap_or_default();
    let made = if fmu_type != CO_SIMULATION {
        Err("this FMU offers co-simulation only".to_string())
    } else {
        match path_of_uri(&uri) {
            Some(dir) => Instance::new(&dir, &guid),
            None => Err(format!("resource location {uri} is not a local file: URI")),
        }
    };
    match made {
        Ok(inst) => Box::into_raw(Box::new(Fmu2 {
            inst,
            name,
            env,
            logger,
        })) as *mut c_void,
        Err(m) => {
            log(logger, env, &name, &m);
            std::ptr::null_mut()
        }
    }
}

/// # Safety
/// See the module's contract; the component is not used again.
#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: *mut c_void) {
    if !c.is_null() {
        // SAFETY: a handle from Box::into_raw, freed once.
        drop(unsafe { Box::from_raw(c as *mut Fmu2) });
    }
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: *mut c_void,
    _tolerance_defined: c_int,
    _tolerance: f64,
    start_time: f64,
    _stop_time_defined: c_int,
    _stop_time: f64,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    f.inst.set_start(start_time);
    OK
}

macro_rules! ok_if_live {
    ($($name:ident),* $(,)?) => {$(
        /// Nothing to do for this model: `fmi2OK` for a live component.
        ///
        /// # Safety
        /// See the module's contract.
        #[no_mangle]
        pub unsafe extern "C" fn $name(c: *mut c_void) -> Status {
            if c.is_null() { ERROR } else { OK }
        }
    )*};
}

ok_if_live!(
    fmi2EnterInitializationMode,
    fmi2ExitInitializationMode,
    fmi2Terminate
);

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetReal(
    c: *mut c_void,
    vrs: *const u32,
    n: usize,
    values: *mut f64,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    if n > 0 && (vrs.is_null() || values.is_null()) {
        return ERROR;
    }
    for i in 0..n {
        // SAFETY: arrays of n elements, per the contract.
        let vr = unsafe { *vrs.add(i) };
        match f.inst.float(vr) {
            // SAFETY: as above.
            Ok(v) => unsafe { *values.add(i) = v },
            Err(m) => return f.status(Err(m)),
        }
    }
    OK
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(
    c: *mut c_void,
    vrs: *const u32,
    n: usize,
    values: *const f64,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    if n > 0 && (vrs.is_null() || values.is_null()) {
        return ERROR;
    }
    for i in 0..n {
        // SAFETY: arrays of n elements, per the contract.
        let (vr, v) = unsafe { (*vrs.add(i), *values.add(i)) };
        if let Err(m) = f.inst.set_float(vr, v) {
            return f.status(Err(m));
        }
    }
    OK
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2GetBoolean(
    c: *mut c_void,
    vrs: *const u32,
    n: usize,
    values: *mut c_int,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    if n > 0 && (vrs.is_null() || values.is_null()) {
        return ERROR;
    }
    for i in 0..n {
        // SAFETY: arrays of n elements, per the contract.
        let vr = unsafe { *vrs.add(i) };
        match f.inst.bool(vr) {
            // SAFETY: as above.
            Ok(v) => unsafe { *values.add(i) = c_int::from(v) },
            Err(m) => return f.status(Err(m)),
        }
    }
    OK
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2SetBoolean(
    c: *mut c_void,
    vrs: *const u32,
    n: usize,
    values: *const c_int,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    if n > 0 && (vrs.is_null() || values.is_null()) {
        return ERROR;
    }
    for i in 0..n {
        // SAFETY: arrays of n elements, per the contract.
        let (vr, v) = unsafe { (*vrs.add(i), *values.add(i)) };
        if let Err(m) = f.inst.set_bool(vr, v != 0) {
            return f.status(Err(m));
        }
    }
    OK
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi2DoStep(
    c: *mut c_void,
    _current: f64,
    step: f64,
    _no_set_prior: c_int,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(c) }) else {
        return ERROR;
    };
    let r = f.inst.do_step(step);
    f.status(r)
}

/// Functions of the standard this FMU does not support: each answers `fmi2Error`
/// without reading its arguments (see `crate::fmi3`'s `unsupported!` for why a
/// parameterless definition is sound on the packed platforms).
macro_rules! unsupported {
    ($($name:ident),* $(,)?) => {$(
        /// Not supported: answers the error status.
        #[no_mangle]
        pub extern "C" fn $name() -> Status {
            ERROR
        }
    )*};
}

unsupported!(
    fmi2Reset,
    fmi2GetInteger,
    fmi2GetString,
    fmi2SetInteger,
    fmi2SetString,
    fmi2GetFMUstate,
    fmi2SetFMUstate,
    fmi2FreeFMUstate,
    fmi2SerializedFMUstateSize,
    fmi2SerializeFMUstate,
    fmi2DeSerializeFMUstate,
    fmi2GetDirectionalDerivative,
    fmi2SetRealInputDerivatives,
    fmi2GetRealOutputDerivatives,
    fmi2CancelStep,
    fmi2GetStatus,
    fmi2GetRealStatus,
    fmi2GetIntegerStatus,
    fmi2GetBooleanStatus,
    fmi2GetStringStatus,
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resource_uris_become_paths() {
        let p = |s| path_of_uri(s).map(|p| p.display().to_string());
        assert_eq!(
            p("file:///tmp/a%20b/resources"),
            Some("/tmp/a b/resources".into())
        );
        assert_eq!(p("file:/tmp/x"), Some("/tmp/x".into()));
        assert_eq!(p("file://localhost/tmp/x"), Some("/tmp/x".into()));
        assert_eq!(p("file://host/tmp/x"), None);
        assert_eq!(p("http://x/y"), None);
        assert_eq!(p("file:///bad%zz"), None);
    }
}
