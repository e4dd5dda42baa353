//! One instance of an FMU's co-simulation interface, from instantiation to free.

use crate::ffi::{self, Api, CallbackFunctions2, Status};
use crate::{file_uri, FmiError, Fmu};
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::sync::{Arc, Mutex};

/// Most log messages kept per instance (the latest; an error names them).
const LOG_KEEP: usize = 16;

/// Where an instance's log messages go: handed to the FMU as its environment pointer,
/// boxed so its address is stable for the instance's life.
#[derive(Default)]
struct LogSink {
    messages: Mutex<Vec<String>>,
}

impl LogSink {
    fn push(&self, status: Status, category: &str, text: String) {
        if let Ok(mut m) = self.messages.lock() {
            if m.len() == LOG_KEEP {
                m.remove(0);
            }
            m.push(format!("[{} {category}] {text}", ffi::status_name(status)));
        }
    }

    fn take(&self) -> Vec<String> {
        self.messages
            .lock()
            .map(|mut m| std::mem::take(&mut *m))
            .unwrap_or_default()
    }
}

/// # Safety
/// `s` is null or NUL-terminated.
unsafe fn text(s: *const c_char) -> String {
    if s.is_null() {
        String::new()
    } else {
        // SAFETY: per the contract.
        unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
    }
}

/// The FMI 2.0 logger. The message is a printf format with variadic arguments, which
/// stable Rust cannot read as such: the first argument is declared as a sixth pointer
/// (the x86-64 and AArch64 Linux conventions pass a variadic pointer where a fixed one
/// would be), and it is read only when the format's first conversion is `%s`, so it is
/// a string by the printf contract. Other formats are kept as written.
unsafe extern "C" fn log2(
    env: *mut c_void,
    _instance_name: *const c_char,
    status: Status,
    category: *const c_char,
    message: *const c_char,
    arg0: *const c_char,
) {
    // SAFETY: `env` is the `LogSink` this crate handed in, alive while the instance is.
    let Some(sink) = (unsafe { (env as *const LogSink).as_ref() }) else {
        return;
    };
    // SAFETY: C strings from the FMU, per the standard.
    let (category, format) = unsafe { (text(category), text(message)) };
    let first = format.match_indices('%').find(|(i, _)| {
        format[..*i].chars().rev().take_while(|c| *c == '%').count() % 2 == 0
            && !format[i + 1..].starts_with('%')
    });
    let message = match first {
        None => format.replace("%%", "%"),
        Some((i, _)) if format[i + 1..].starts_with('s') && !arg0.is_null() => {
            // SAFETY: the format's first conversion is %s, so the FMU passed a string.
            let arg = unsafe { text(arg0) };
            format!("{}{arg}{}", &format[..i], &format[i + 2..])
        }
        Some(_) => format,
    };
    sink.push(status, &category, message);
}

/// The FMI 3.0 logger.
unsafe extern "C" fn log3(
    env: *mut c_void,
    status: Status,
    category: *const c_char,
    message: *const c_char,
) {
    // SAFETY: as in `log2`.
    let Some(sink) = (unsafe { (env as *const LogSink).as_ref() }) else {
        return;
    };
    // SAFETY: C strings from the FMU, per the standard.
    let (category, message) = unsafe { (text(category), text(message)) };
    sink.push(status, &category, message);
}

unsafe extern "C" fn calloc(n: usize, size: usize) -> *mut c_void {
    // SAFETY: the C allocator.
    unsafe { libc::calloc(n, size) }
}

unsafe extern "C" fn free(p: *mut c_void) {
    // SAFETY: a pointer from `calloc` above (the FMU's own), or null.
    unsafe { libc::free(p) }
}

/// One co-simulation instance, in step mode once [`Instance::new`] returns. Terminated
/// and freed on drop (not after a fatal status, when the standard allows no call).
pub struct Instance {
    fmu: Arc<Fmu>,
    handle: *mut c_void,
    sink: Box<LogSink>,
    _callbacks: Box<CallbackFunctions2>,
    start_s: f64,
    elapsed_ns: u64,
    /// FMI 2.0 Booleans are `int`: converted here (no allocation once sized).
    bools2: Vec<c_int>,
    fatal: bool,
}

// SAFETY: an instance is used by one thread at a time (`&mut self` for every call), as
// the standard requires; nothing in it is tied to the thread that made it.
unsafe impl Send for Instance {}

impl std::fmt::Debug for Instance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Instance")
            .field("fmu", &self.fmu)
            .field("time_s", &self.time_s())
            .finish()
    }
}

impl Instance {
    /// Instantiates `fmu` as `name`, sets up the experiment from `start_s`, sets the
    /// initial inputs in initialization mode and leaves it: the instance is ready to step.
    pub fn new(
        fmu: Arc<Fmu>,
        name: &str,
        start_s: f64,
        reals: (&[u32], &[f64]),
        bools: (&[u32], &[bool]),
    ) -> Result<Self, FmiError> {
        let cstr = |s: &str| CString::new(s.replace('\0', " ")).unwrap_or_default();
        let name_c = cstr(name);
        let token = cstr(&fmu.description.token);
        let resources = fmu.resources();
        let sink = Box::<LogSink>::default();
        let env = &*sink as *const LogSink as *mut c_void;
        let callbacks = Box::new(CallbackFunctions2 {
            logger: Some(log2),
            allocate_memory: Some(calloc),
            free_memory: Some(free),
            step_finished: None,
            component_environment: env,
        });
        let handle = match &fmu.binary.api {
            Api::V2(api) => {
                let uri = cstr(&file_uri(&resources));
                // SAFETY: the standard's signature; every string and the callbacks live
                // across the call (the callbacks for the instance's life).
                unsafe {
                    (api.instantiate)(
                        name_c.as_ptr(),
                        1, // fmi2CoSimulation
                        token.as_ptr(),
                        uri.as_ptr(),
                        &*callbacks,
                        0,
                        0,
                    )
                }
            }
            Api::V3(api) => {
                // FMI 3.0 wants a path that ends with a separator.
                let mut dir = resources.to_string_lossy().into_owned();
                dir.push(std::path::MAIN_SEPARATOR);
                let dir = cstr(&dir);
                // SAFETY: as above; `sink` is the environment the logger receives.
                unsafe {
                    (api.instantiate)(
                        name_c.as_ptr(),
                        token.as_ptr(),
                        dir.as_ptr(),
                        false,
                        false,
                        false,
                        false,
                        std::ptr::null(),
                        0,
                        env,
                        Some(log3),
                        std::ptr::null_mut(),
                    )
                }
            }
        };
        if handle.is_null() {
            return Err(FmiError::Instantiate {
                function: match fmu.description.version {
                    crate::FmiVersion::V2 => "fmi2Instantiate",
                    crate::FmiVersion::V3 => "fmi3InstantiateCoSimulation",
                },
                log: sink.take(),
            });
        }
        let mut inst = Self {
            fmu,
            handle,
            sink,
            _callbacks: callbacks,
            start_s,
            elapsed_ns: 0,
            bools2: Vec::new(),
            fatal: false,
        };
        let (h, fmu) = (inst.handle, inst.fmu.clone());
        match &fmu.binary.api {
            Api::V2(api) => {
                // SAFETY: a live component of this binary.
                let s = unsafe { (api.setup_experiment)(h, 0, 0.0, start_s, 0, 0.0) };
                inst.check("fmi2SetupExperiment", s)?;
                // SAFETY: as above.
                let s = unsafe { (api.enter_initialization_mode)(h) };
                inst.check("fmi2EnterInitializationMode", s)?;
            }
            Api::V3(api) => {
                // SAFETY: a live instance of this binary.
                let s =
                    unsafe { (api.enter_initialization_mode)(h, false, 0.0, start_s, false, 0.0) };
                inst.check("fmi3EnterInitializationMode", s)?;
            }
        }
        inst.set_reals(reals.0, reals.1)?;
        inst.set_bools(bools.0, bools.1)?;
        let (function, s) = match &fmu.binary.api {
            // SAFETY: a live instance in initialization mode.
            Api::V2(api) => ("fmi2ExitInitializationMode", unsafe {
                (api.exit_initialization_mode)(h)
            }),
            // SAFETY: as above.
            Api::V3(api) => ("fmi3ExitInitializationMode", unsafe {
                (api.exit_initialization_mode)(h)
            }),
        };
        inst.check(function, s)?;
        Ok(inst)
    }

    fn check(&mut self, function: &'static str, status: Status) -> Result<(), FmiError> {
        match status {
            0 | 1 => Ok(()),
            s => {
                self.fatal |= s == 4;
                Err(FmiError::Call {
                    function,
                    status: ffi::status_name(s),
                    log: self.sink.take(),
                })
            }
        }
    }

    /// The FMU.
    pub fn fmu(&self) -> &Arc<Fmu> {
        &self.fmu
    }

    /// The current communication point, seconds.
    pub fn time_s(&self) -> f64 {
        self.start_s + self.elapsed_ns as f64 / 1e9
    }

    /// Sets real (`Float64`) variables.
    pub fn set_reals(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmiError> {
        if vrs.is_empty() {
            return Ok(());
        }
        let n = vrs.len().min(values.len());
        let (function, s) = match &self.fmu.binary.api {
            // SAFETY: a live instance; arrays of n elements.
            Api::V2(api) => ("fmi2SetReal", unsafe {
                (api.set_real)(self.handle, vrs.as_ptr(), n, values.as_ptr())
            }),
            // SAFETY: as above.
            Api::V3(api) => ("fmi3SetFloat64", unsafe {
                (api.set_float64)(self.handle, vrs.as_ptr(), n, values.as_ptr(), n)
            }),
        };
        self.check(function, s)
    }

    /// Sets Boolean variables.
    pub fn set_bools(&mut self, vrs: &[u32], values: &[bool]) -> Result<(), FmiError> {
        if vrs.is_empty() {
            return Ok(());
        }
        let n = vrs.len().min(values.len());
        let fmu = self.fmu.clone();
        let (function, s) = match &fmu.binary.api {
            Api::V2(api) => {
                self.bools2.clear();
                self.bools2
                    .extend(values[..n].iter().map(|&b| c_int::from(b)));
                // SAFETY: a live instance; arrays of n elements.
                ("fmi2SetBoolean", unsafe {
                    (api.set_boolean)(self.handle, vrs.as_ptr(), n, self.bools2.as_ptr())
                })
            }
            // SAFETY: as above.
            Api::V3(api) => ("fmi3SetBoolean", unsafe {
                (api.set_boolean)(self.handle, vrs.as_ptr(), n, values.as_ptr(), n)
            }),
        };
        self.check(function, s)
    }

    /// Reads real (`Float64`) variables into `values`.
    pub fn get_reals(&mut self, vrs: &[u32], values: &mut [f64]) -> Result<(), FmiError> {
        if vrs.is_empty() {
            return Ok(());
        }
        let n = vrs.len().min(values.len());
        let (function, s) = match &self.fmu.binary.api {
            // SAFETY: a live instance; arrays of n elements.
            Api::V2(api) => ("fmi2GetReal", unsafe {
                (api.get_real)(self.handle, vrs.as_ptr(), n, values.as_mut_ptr())
            }),
            // SAFETY: as above.
            Api::V3(api) => ("fmi3GetFloat64", unsafe {
                (api.get_float64)(self.handle, vrs.as_ptr(), n, values.as_mut_ptr(), n)
            }),
        };
        self.check(function, s)
    }

    /// One communication step of `h_ns` nanoseconds from the current point.
    pub fn do_step(&mut self, h_ns: u64) -> Result<(), FmiError> {
        let t = self.time_s();
        let h = h_ns as f64 / 1e9;
        let (function, s) = match &self.fmu.binary.api {
            // SAFETY: a live instance.
            Api::V2(api) => ("fmi2DoStep", unsafe { (api.do_step)(self.handle, t, h, 1) }),
            Api::V3(api) => {
                let (mut event, mut terminate, mut early) = (false, false, false);
                let mut last = 0.0;
                // SAFETY: a live instance; the out-pointers are to locals.
                let s = unsafe {
                    (api.do_step)(
                        self.handle,
                        t,
                        h,
                        true,
                        &mut event,
                        &mut terminate,
                        &mut early,
                        &mut last,
                    )
                };
                ("fmi3DoStep", s)
            }
        };
        self.check(function, s)?;
        self.elapsed_ns += h_ns;
        Ok(())
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        if self.fatal {
            return;
        }
        match &self.fmu.binary.api {
            // SAFETY: a live instance, terminated then freed once; its status after
            // an error is not needed.
            Api::V2(api) => unsafe {
                (api.terminate)(self.handle);
                (api.free_instance)(self.handle);
            },
            // SAFETY: as above.
            Api::V3(api) => unsafe {
                (api.terminate)(self.handle);
                (api.free_instance)(self.handle);
            },
        }
    }
}
