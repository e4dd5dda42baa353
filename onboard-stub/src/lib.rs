//! The onboard-computer side of the oils bench: the reference descent GNC
//! ([`gnc::ReferenceGnc`]), open-loop profile playback ([`playback::ProfilePlayback`]),
//! flight software from a C shared library ([`c_library::CLibraryFsw`]), the flight
//! software a run names built as a value ([`build`]), and the loop that serves it over
//! the iceoryx2 link ([`runner`], [`join`]). The [`fsw::FlightSoftware`] trait itself
//! lives in `oils-shared`, where the emulator's in-process link reaches it too.
#![warn(missing_docs)]

pub mod build;
pub mod c_library;
pub mod gnc;
pub mod join;
pub mod playback;
pub mod runner;

pub use oils_shared::fsw;
