//! Subcommands of the `oils` binary.

pub mod hifi;
pub mod train;
pub mod validate;
