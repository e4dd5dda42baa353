//! The onboard-computer side of the oils bench: the [`fsw::FlightSoftware`] trait, the
//! reference descent GNC ([`gnc::ReferenceGnc`]), open-loop profile playback
//! ([`playback::ProfilePlayback`]), flight software from a C shared library
//! ([`c_library::CLibraryFsw`]), and the loop that serves them over the iceoryx2 link
//! ([`runner`], [`cli`]).
#![warn(missing_docs)]

pub mod c_library;
pub mod cli;
pub mod fsw;
pub mod gnc;
pub mod playback;
pub mod runner;
