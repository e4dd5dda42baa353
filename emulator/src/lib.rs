//! The run core of the oils bench: everything that runs in the loop. A deterministic
//! simulation of a lunar lander (rigid body plus propulsion) stepped against flight
//! software over a link, from a [`run_config::RunConfig`] to a [`report::RunReport`].
//!
//! Modules by responsibility: [`run_config`] (a run as a plain value), [`config`]
//! (scenario numbers), [`plant`] (rigid body, gravity, contact), [`propulsion`] (models
//! behind one trait, the learned surrogate's runtime among them), [`sanitize`] (the
//! link's guard), [`link`] (the exchange: iceoryx2, in-process, replay), [`clock`]
//! (lockstep, realtime, replay pacing), [`faults`], [`schedule`] (rate groups on one
//! base tick), [`scheduler`] (the one step loop), [`sensors`] (device models: IMU, star
//! tracker, altimeters, velocimeter),
//! [`timing`], [`digest`], [`recorder`], [`report`], [`session`] (one run, with the
//! flight software handed in as a value), and [`exact_json`] (what the bench writes,
//! read back bit for bit), [`fixed_len`] (arrays read at exactly their length), and
//! [`world`] (the terrain about the landing site).
//!
//! The lab (`oils-lab`: training, validation, campaigns, plots, MCAP) builds on this
//! crate; nothing here depends on it, on a command line or on plotting.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod clock;
pub mod config;
pub mod devices;
pub mod digest;
pub mod exact_json;
pub mod failure_scenarios;
pub mod faults;
pub mod fixed_len;
pub mod frame_png;
pub mod fsw_monitor;
pub mod link;
pub mod log_fields;
pub mod log_layout;
pub mod plant;
pub mod propulsion;
pub mod recorder;
pub mod report;
pub mod run_config;
pub mod sanitize;
pub mod schedule;
pub mod scheduler;
pub mod sensors;
pub mod session;
pub mod timing;
pub mod world;
