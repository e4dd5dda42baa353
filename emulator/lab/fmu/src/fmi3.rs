//! The FMI 3.0 co-simulation entry points (`fmi3Functions.h`). Every function the
//! standard names is exported (FMPy, like other importers, resolves them all when it
//! loads a binary); those of Model Exchange, Scheduled Execution, clocks, states and
//! derivatives answer `fmi3Error`.
//!
//! SAFETY (all functions): the importer passes an instance this library returned from
//! `fmi3InstantiateCoSimulation` and not yet freed, and arrays of the lengths it gives,
//! as the standard requires; every pointer is checked for null before use.
#![allow(non_snake_case)]

use crate::instance::Instance;
use std::ffi::{c_char, c_void, CStr, CString};

/// `fmi3Status`.
pub type Status = i32;
/// `fmi3OK`.
pub const OK: Status = 0;
/// `fmi3Error`.
pub const ERROR: Status = 3;

/// `fmi3LogMessageCallback`.
pub type LogMessage = Option<
    unsafe extern "C" fn(
        env: *mut c_void,
        status: Status,
        category: *const c_char,
        message: *const c_char,
    ),
>;

/// One instance with what the importer handed in for logging.
pub struct Fmu3 {
    inst: Instance,
    env: *mut c_void,
    log: LogMessage,
}

impl Fmu3 {
    fn log_error(&self, message: &str) {
        let Some(log) = self.log else { return };
        let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
        // SAFETY: the callback and its environment are the importer's, as given at
        // instantiation; both strings are NUL-terminated and live across the call.
        unsafe { log(self.env, ERROR, c"logStatusError".as_ptr(), text.as_ptr()) };
    }

    fn status(&self, r: Result<(), String>) -> Status {
        match r {
            Ok(()) => OK,
            Err(m) => {
                self.log_error(&m);
                ERROR
            }
        }
    }
}

/// The instance behind a handle, or `None` for null.
///
/// # Safety
/// `instance` is null or a live handle from [`fmi3InstantiateCoSimulation`].
unsafe fn fmu<'a>(instance: *mut c_void) -> Option<&'a mut Fmu3> {
    // SAFETY: per the function's contract.
    unsafe { (instance as *mut Fmu3).as_mut() }
}

/// A slice from an importer's array, empty for null or length 0.
///
/// # Safety
/// `ptr` is null or points to `n` valid `T`.
unsafe fn slice<'a, T>(ptr: *const T, n: usize) -> &'a [T] {
    if ptr.is_null() || n == 0 {
        &[]
    } else {
        // SAFETY: per the function's contract.
        unsafe { std::slice::from_raw_parts(ptr, n) }
    }
}

/// As [`slice`], mutable.
///
/// # Safety
/// `ptr` is null or points to `n` valid, writable `T`.
unsafe fn slice_mut<'a, T>(ptr: *mut T, n: usize) -> &'a mut [T] {
    if ptr.is_null() || n == 0 {
        &mut []
    } else {
        // SAFETY: per the function's contract.
        unsafe { std::slice::from_raw_parts_mut(ptr, n) }
    }
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

/// The FMI version this binary implements.
#[no_mangle]
pub extern "C" fn fmi3GetVersion() -> *const c_char {
    c"3.0".as_ptr()
}

/// Debug categories: none; logging is of errors only, always on.
#[no_mangle]
pub extern "C" fn fmi3SetDebugLogging(
    _instance: *mut c_void,
    _logging_on: bool,
    _n: usize,
    _categories: *const *const c_char,
) -> Status {
    OK
}

/// Instantiates the model in `resourcePath` (a directory path, FMI 3.0).
///
/// # Safety
/// Strings are null or NUL-terminated; see the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3InstantiateCoSimulation(
    _instance_name: *const c_char,
    token: *const c_char,
    resource_path: *const c_char,
    _visible: bool,
    _logging_on: bool,
    _event_mode_used: bool,
    _early_return_allowed: bool,
    _required_intermediate: *const u32,
    _n_required_intermediate: usize,
    env: *mut c_void,
    log: LogMessage,
    _intermediate_update: *mut c_void,
) -> *mut c_void {
    // SAFETY: strings per the contract.
    let (token, dir) = unsafe { (string(token), string(resource_path)) };
    match Instance::new(std::path::Path::new(&dir), &token) {
        Ok(inst) => Box::into_raw(Box::new(Fmu3 { inst, env, log })) as *mut c_void,
        Err(m) => {
            if let Some(log) = log {
                let text = CString::new(m.replace('\0', " ")).unwrap_or_default();
                // SAFETY: the importer's callback, as given; strings live across the call.
                unsafe { log(env, ERROR, c"logStatusError".as_ptr(), text.as_ptr()) };
            }
            std::ptr::null_mut()
        }
    }
}

/// # Safety
/// See the module's contract; the handle is not used again.
#[no_mangle]
pub unsafe extern "C" fn fmi3FreeInstance(instance: *mut c_void) {
    if !instance.is_null() {
        // SAFETY: a handle from Box::into_raw, freed once.
        drop(unsafe { Box::from_raw(instance as *mut Fmu3) });
    }
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3EnterInitializationMode(
    instance: *mut c_void,
    _tolerance_defined: bool,
    _tolerance: f64,
    start_time: f64,
    _stop_time_defined: bool,
    _stop_time: f64,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    f.inst.set_start(start_time);
    OK
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3ExitInitializationMode(instance: *mut c_void) -> Status {
    if instance.is_null() {
        ERROR
    } else {
        OK
    }
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3EnterStepMode(instance: *mut c_void) -> Status {
    if instance.is_null() {
        ERROR
    } else {
        OK
    }
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3Terminate(instance: *mut c_void) -> Status {
    if instance.is_null() {
        ERROR
    } else {
        OK
    }
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3GetFloat64(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *mut f64,
    n_values: usize,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    // SAFETY: arrays of the given lengths, per the contract.
    let (vrs, values) = unsafe { (slice(vrs, n_vrs), slice_mut(values, n_values)) };
    if vrs.len() != values.len() {
        return f.status(Err("nValues differs from nValueReferences".into()));
    }
    let r = vrs.iter().zip(values.iter_mut()).try_for_each(|(&vr, v)| {
        *v = f.inst.float(vr)?;
        Ok(())
    });
    f.status(r)
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3SetFloat64(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *const f64,
    n_values: usize,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    // SAFETY: arrays of the given lengths, per the contract.
    let (vrs, values) = unsafe { (slice(vrs, n_vrs), slice(values, n_values)) };
    if vrs.len() != values.len() {
        return f.status(Err("nValues differs from nValueReferences".into()));
    }
    let r = vrs
        .iter()
        .zip(values)
        .try_for_each(|(&vr, &v)| f.inst.set_float(vr, v));
    f.status(r)
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3GetBoolean(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *mut bool,
    n_values: usize,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    // SAFETY: arrays of the given lengths, per the contract.
    let (vrs, values) = unsafe { (slice(vrs, n_vrs), slice_mut(values, n_values)) };
    if vrs.len() != values.len() {
        return f.status(Err("nValues differs from nValueReferences".into()));
    }
    let r = vrs.iter().zip(values.iter_mut()).try_for_each(|(&vr, v)| {
        *v = f.inst.bool(vr)?;
        Ok(())
    });
    f.status(r)
}

/// # Safety
/// See the module's contract.
#[no_mangle]
pub unsafe extern "C" fn fmi3SetBoolean(
    instance: *mut c_void,
    vrs: *const u32,
    n_vrs: usize,
    values: *const bool,
    n_values: usize,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    // SAFETY: arrays of the given lengths, per the contract.
    let (vrs, values) = unsafe { (slice(vrs, n_vrs), slice(values, n_values)) };
    if vrs.len() != values.len() {
        return f.status(Err("nValues differs from nValueReferences".into()));
    }
    let r = vrs
        .iter()
        .zip(values)
        .try_for_each(|(&vr, &v)| f.inst.set_bool(vr, v));
    f.status(r)
}

/// # Safety
/// See the module's contract; the out-pointers are null or writable.
#[no_mangle]
pub unsafe extern "C" fn fmi3DoStep(
    instance: *mut c_void,
    _current: f64,
    step: f64,
    _no_set_prior: bool,
    event_handling_needed: *mut bool,
    terminate_simulation: *mut bool,
    early_return: *mut bool,
    last_successful_time: *mut f64,
) -> Status {
    // SAFETY: per the contract.
    let Some(f) = (unsafe { fmu(instance) }) else {
        return ERROR;
    };
    let r = f.inst.do_step(step);
    // SAFETY: each out-pointer is null or writable, per the contract.
    unsafe {
        for p in [event_handling_needed, terminate_simulation, early_return] {
            if let Some(p) = p.as_mut() {
                *p = false;
            }
        }
        if let Some(p) = last_successful_time.as_mut() {
            *p = f.inst.time_s();
        }
    }
    f.status(r)
}

/// Functions of the standard this FMU does not support: each answers `fmi3Error` (or a
/// null instance) without reading its arguments.
///
/// SAFETY: declared without parameters. Under the C calling conventions of the
/// platforms an FMU is packed for (x86-64 and AArch64 System V), the caller passes
/// arguments in registers and on its own stack frame and cleans up itself, so a callee
/// that reads none is called soundly with any argument list.
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
    fmi3EnterEventMode,
    fmi3Reset,
    fmi3GetFloat32,
    fmi3GetInt8,
    fmi3GetUInt8,
    fmi3GetInt16,
    fmi3GetUInt16,
    fmi3GetInt32,
    fmi3GetUInt32,
    fmi3GetInt64,
    fmi3GetUInt64,
    fmi3GetString,
    fmi3GetBinary,
    fmi3GetClock,
    fmi3SetFloat32,
    fmi3SetInt8,
    fmi3SetUInt8,
    fmi3SetInt16,
    fmi3SetUInt16,
    fmi3SetInt32,
    fmi3SetUInt32,
    fmi3SetInt64,
    fmi3SetUInt64,
    fmi3SetString,
    fmi3SetBinary,
    fmi3SetClock,
    fmi3GetNumberOfVariableDependencies,
    fmi3GetVariableDependencies,
    fmi3GetFMUState,
    fmi3SetFMUState,
    fmi3FreeFMUState,
    fmi3SerializedFMUStateSize,
    fmi3SerializeFMUState,
    fmi3DeserializeFMUState,
    fmi3GetDirectionalDerivative,
    fmi3GetAdjointDerivative,
    fmi3EnterConfigurationMode,
    fmi3ExitConfigurationMode,
    fmi3GetIntervalDecimal,
    fmi3GetIntervalFraction,
    fmi3GetShiftDecimal,
    fmi3GetShiftFraction,
    fmi3SetIntervalDecimal,
    fmi3SetIntervalFraction,
    fmi3SetShiftDecimal,
    fmi3SetShiftFraction,
    fmi3EvaluateDiscreteStates,
    fmi3UpdateDiscreteStates,
    fmi3EnterContinuousTimeMode,
    fmi3CompletedIntegratorStep,
    fmi3SetTime,
    fmi3SetContinuousStates,
    fmi3GetContinuousStateDerivatives,
    fmi3GetEventIndicators,
    fmi3GetContinuousStates,
    fmi3GetNominalsOfContinuousStates,
    fmi3GetNumberOfEventIndicators,
    fmi3GetNumberOfContinuousStates,
    fmi3GetOutputDerivatives,
    fmi3ActivateModelPartition,
);

/// Model Exchange and Scheduled Execution are not offered: no instance.
#[no_mangle]
pub extern "C" fn fmi3InstantiateModelExchange() -> *mut c_void {
    std::ptr::null_mut()
}

/// See [`fmi3InstantiateModelExchange`].
#[no_mangle]
pub extern "C" fn fmi3InstantiateScheduledExecution() -> *mut c_void {
    std::ptr::null_mut()
}
