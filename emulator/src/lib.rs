//! The emulator process of the oils bench: a deterministic fixed-step simulation of a
//! lunar lander (rigid body plus propulsion) that exchanges telemetry and commands with
//! an onboard computer over iceoryx2.
//!
//! Modules by responsibility: [`config`] (scenario numbers), [`plant`] (rigid body,
//! gravity, contact), [`propulsion`] (models behind one trait), [`sanitize`] (the link's
//! guard), [`scheduler`] (the step loop), [`timing`], [`digest`], [`recorder`],
//! [`report`], and [`session`] (one run, from arguments to report).
#![warn(missing_docs)]

pub mod config;
pub mod digest;
pub mod plant;
pub mod plot;
pub mod propulsion;
pub mod recorder;
pub mod report;
pub mod sanitize;
pub mod scheduler;
pub mod session;
pub mod surrogate;
pub mod timing;
pub mod validation;
