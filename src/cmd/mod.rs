//! Subcommands of the `oils` binary.

pub mod hifi;
pub mod run;
pub mod train;
pub mod validate;
