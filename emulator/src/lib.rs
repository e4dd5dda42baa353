//! The emulator process of the oils bench: a deterministic fixed-step simulation of a
//! lunar lander (rigid body plus propulsion) that exchanges telemetry and commands with
//! an onboard computer over iceoryx2.
//!
//! Modules by responsibility: [`run_config`] (a run as a plain value), [`config`]
//! (scenario numbers), [`plant`] (rigid body, gravity, contact), [`propulsion`] (models
//! behind one trait), [`surrogate`] (the learned model: runtime and training),
//! [`sanitize`] (the link's guard), [`link`] (the exchange: iceoryx2, in-process,
//! replay), [`clock`] (lockstep, realtime, replay pacing), [`scheduler`] (the one step
//! loop), [`timing`], [`digest`], [`recorder`], [`report`], and [`session`] (one run,
//! from a `RunConfig` to a report).
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod campaign;
pub mod clock;
pub mod config;
pub mod digest;
pub mod faults;
pub mod link;
pub mod mcap_log;
pub mod plant;
pub mod plot;
pub mod propulsion;
pub mod recorder;
pub mod report;
pub mod run_config;
pub mod run_plots;
pub mod sanitize;
pub mod scheduler;
pub mod session;
pub mod surrogate;
pub mod timing;
pub mod validation;
