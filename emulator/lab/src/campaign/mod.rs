//! Monte Carlo campaigns: many runs of one base configuration with dispersions, the
//! surrogate's validated error injected as model uncertainty, and random faults.
//!
//! - [`spec`]: the campaign file (TOML) and the committed default.
//! - [`streams`]: case `i`'s random numbers from (master seed, i, dispersion name).
//! - [`case`]: a case's configuration, its in-process run and its result.
//! - [`store`]: the campaign directory, one atomically written file per case.
//! - [`local`]: the local backend (rayon over all cores, shards, resume, budgets).
//! - [`summary`]: merging into `cases.csv` and `summary.json`.
//! - [`compare`]: the same cases under two propulsion models (KS statistics).
//! - [`drivers`]: which applied values drive the failures (rank correlations).
//! - [`plots`]: footprint, histograms, CDFs, drivers, traces, model overlays.
//!
//! - [`slurm`]: the Slurm backend, a job array of `oils mc run --shard I/K` tasks and a
//!   merge job: a shard runs the same code as a local campaign, so its results are the
//!   same files.

pub mod case;
pub mod compare;
pub mod drivers;
pub mod local;
pub mod plots;
pub mod slurm;
pub mod spec;
pub mod store;
pub mod streams;
pub mod summary;

pub use case::{case_setup, CaseResult, CaseSetup};
pub use local::{run_cases, RunOptions, Shard};
pub use spec::CampaignSpec;
pub use store::Store;
pub use summary::{Merged, Summary};

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// A campaign could not be set up, run or merged.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// The spec is invalid.
    #[error("campaign spec: {0}")]
    Spec(String),
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The campaign directory is not usable as asked.
    #[error("{0}")]
    Store(String),
    /// A stop request ended the work before it was done.
    #[error("interrupted by a stop request; run the same command again to resume")]
    Interrupted,
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// Slurm refused or could not take a submission.
    #[error("Slurm: {0}")]
    Slurm(String),
}

/// Merges the campaign in `store`: runs the nominal case if needed, writes
/// `cases.csv`, `summary.json` and (with `plots`) `plots/*.png`.
pub fn merge(
    spec: &CampaignSpec,
    store: &Store,
    partial: bool,
    plots: bool,
    stop: &AtomicBool,
) -> Result<Merged, CampaignError> {
    let nominal = local::nominal(spec, store, stop)?;
    let merged = summary::collect(spec, store, nominal, partial)?;
    summary::write(store, &merged)?;
    if plots {
        plots::write_all(spec, &merged, &store.dir().join("plots"))?;
    }
    Ok(merged)
}
