//! The emulator process of the oils bench: a deterministic fixed-step simulation of a
//! lunar lander (rigid body plus propulsion) that exchanges telemetry and commands with
//! an onboard computer over iceoryx2.
#![warn(missing_docs)]

pub mod config;
pub mod plot;
pub mod propulsion;
