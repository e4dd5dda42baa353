//! The onboard-computer stub of the oils bench: flight software behind the
//! [`fsw::FlightSoftware`] trait (the reference GNC, profile playback, or yours), and the
//! loop that serves it over the iceoryx2 link.
#![warn(missing_docs)]

pub mod cli;
pub mod fsw;
pub mod gnc;
pub mod playback;
pub mod runner;
