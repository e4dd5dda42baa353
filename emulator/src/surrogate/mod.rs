//! The learned sparse surrogate of the propulsion system (seed paper, Sections III-V), in
//! two parts:
//!
//! - [`runtime`]: what runs in the loop. The model file, the fitted model, the features,
//!   the valve filter and ignition clock, the predictor, and `SurrogatePropulsion`.
//! - [`training`]: what makes a model file (`oils train`). Excitation, data, library,
//!   Lasso, fits, cross-validation, held-out runs, reports and figures.
//!
//! Training uses the runtime (a model is chosen on exactly the behaviour it has in the
//! loop); the runtime never uses training. `docs/surrogate.md` is the reference.

pub mod runtime;
pub mod training;

// The path the propulsion module names the model file's errors by.
pub use runtime::model_file;
