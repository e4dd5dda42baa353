//! SIGINT and SIGTERM as a flag the step loops poll (one relaxed atomic load per step).
//!
//! Installed before tick 0 in both processes, so a termination request is seen even
//! before any iceoryx2 wait (iceoryx2's own handling is switched off: see
//! [`crate::link::create_node`]), and every exit path flushes the log.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Registers SIGINT and SIGTERM to raise the returned flag.
pub fn termination_flag() -> std::io::Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flag))?;
    signal_hook::flag::register(signal_hook::consts::SIGTERM, Arc::clone(&flag))?;
    Ok(flag)
}
