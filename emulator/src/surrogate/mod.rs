//! The learned sparse surrogate of the propulsion system (seed paper, Sections III-V):
//! excitation, data, history features, polynomial library, Lasso, cross-validation on
//! free-run error, the model file, and the runtime that stands in for `hifi` in the loop.

pub mod features;
pub mod lasso;
pub mod library;
