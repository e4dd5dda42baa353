//! A propulsion model of the bench as a Functional Mock-up Unit (FMI 2.0 and 3.0
//! co-simulation): the learned surrogate of a model file, or hifi (for the round trip
//! of `--truth fmu:`). One binary serves every packed model: it reads the model from the
//! FMU's `resources/` ([`Resource`]) at instantiation. `oils export-fmu` writes the
//! model description from [`VARIABLES`] and packs this library as the FMU's binary.
//!
//! The C entry points are in [`fmi2`] and [`fmi3`]; the model behind them is
//! [`instance::Instance`], plain safe Rust over the bench's own `Propulsion` models, so
//! an FMU steps bit for bit as the bench does.
#![warn(missing_docs)]
#![deny(unsafe_op_in_unsafe_fn)]

pub mod fmi2;
pub mod fmi3;
pub mod instance;
pub mod variables;

pub use instance::{Resource, RESOURCE_FILE, RESOURCE_FORMAT, RESOURCE_VERSION};
pub use variables::{Causality, VarType, Variable, VARIABLES};

/// The model identifier: the binary's file name in the FMU (`oils_propulsion.so`) and
/// the `modelIdentifier` of the model description.
pub const MODEL_IDENTIFIER: &str = "oils_propulsion";
