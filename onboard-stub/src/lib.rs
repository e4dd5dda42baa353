//! The onboard-computer side of the oils bench: the [`fsw::FlightSoftware`] trait, the
//! reference descent GNC ([`gnc::ReferenceGnc`]) and open-loop profile playback
//! ([`playback::ProfilePlayback`]).
#![warn(missing_docs)]

pub mod fsw;
pub mod gnc;
pub mod playback;
