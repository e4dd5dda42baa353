//! The lab of the oils bench: offline work built on the run core (`oils-emulator`).
//! Nothing here runs in the loop, so it may use anything: rayon, plotters, mcap.
//!
//! - [`training`]: the surrogate's training pipeline (seed paper): excitation, data,
//!   library, Lasso, cross-validation, the model file the core's runtime reads.
//! - [`validation`]: the surrogate against the hifi model on the paper's cases.
//! - [`campaign`]: Monte Carlo campaigns (local on all cores, or a Slurm job array).
//! - [`mcap_log`]: MCAP logs (Foxglove), written in the loop through the core's
//!   `RecordSink` and read back for export, plots and replay.
//! - [`fmu`]: the user's propulsion model as an FMU (in) and bench models as FMUs (out).
//! - [`onboard`]: the flight software a configuration names, flown in process.
//! - [`plot`], [`run_plots`], [`timing_plots`], [`hifi_figures`]: figures.
//! - [`report_page`]: the self-contained HTML page of a campaign or a run.
#![warn(missing_docs)]
#![forbid(unsafe_code)]

pub mod campaign;
pub mod fmu;
pub mod hifi_figures;
pub mod json_schema;
pub mod log_json;
pub mod mcap_frames;
pub mod mcap_log;
pub mod onboard;
pub mod plot;
pub mod report_page;
pub mod run_plots;
pub mod timing_plots;
pub mod training;
pub mod validation;
