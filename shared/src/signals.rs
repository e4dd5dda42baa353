//! SIGINT, SIGTERM and SIGHUP as a flag the step loops poll (one relaxed atomic load per step).
//!
//! Installed before tick 0 in both processes, so a termination request is seen even
//! before any iceoryx2 wait (iceoryx2's own handling is switched off: see
//! [`crate::link::create_node`]), and every exit path flushes the log.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Registers SIGINT, SIGTERM and SIGHUP (a closed terminal) to raise the returned
/// flag: each ends a run the same way, with its summary, report and a complete log.
pub fn termination_flag() -> std::io::Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ] {
        signal_hook::flag::register(signal, Arc::clone(&flag))?;
    }
    Ok(flag)
}
