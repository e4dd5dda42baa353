//! Subcommands of the `oils` binary.

pub mod excitation;
pub mod export_fmu;
pub mod hifi;
pub mod mc;
pub mod plot;
pub mod run;
pub mod stub;
pub mod stub_process;
pub mod train;
pub mod validate;
