//! Validation of the learned surrogate against the hifi model (seed paper, Section VI):
//! both run free on the same thrust-command profiles (4-sphere sine sweeps, a rise and a
//! fall step stair, a full powered-descent profile, any user profile); the errors of
//! every output are summarised per case and per window (transient / steady for steps)
//! and judged against the paper's bounds and against the project's goal (half of them).
//! The statistics are also written as model uncertainty for a Monte Carlo. See
//! `docs/validation.md`.

pub mod cases;
pub mod compare;
pub mod plots;
pub mod recorded;
pub mod report;
pub mod stats;
pub mod uncertainty;

use cases::Case;
use compare::{run_case, NonFinite, Trace};
use oils_emulator::propulsion::{BuildError, Propulsion};
use report::{evaluate, Bounds, CaseReport, GOAL_FACTOR};

/// A validation run failed (not: the model failed validation).
#[derive(Debug, thiserror::Error)]
pub enum ValidationError {
    /// A model could not be built.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// A model produced NaN or infinity.
    #[error(transparent)]
    NonFinite(#[from] NonFinite),
}

/// Builds a fresh model for a case.
pub type Factory<'a> = &'a dyn Fn() -> Result<Box<dyn Propulsion>, BuildError>;

/// Runs every case with fresh models from `truth` and `model`; returns the per-case
/// reports (judged against `bounds` and `bounds * GOAL_FACTOR`) and the traces.
pub fn run_cases(
    cases: &[Case],
    truth: Factory<'_>,
    model: Factory<'_>,
    dt_ns: u64,
    initial_mass_kg: f64,
    bounds: &Bounds,
    mut progress: impl FnMut(&CaseReport),
) -> Result<(Vec<CaseReport>, Vec<Trace>), ValidationError> {
    let goal = bounds.scaled(GOAL_FACTOR);
    let mut reports = Vec::new();
    let mut traces = Vec::new();
    for case in cases {
        let (mut t, mut m) = (truth()?, model()?);
        let trace = run_case(case, t.as_mut(), m.as_mut(), dt_ns, initial_mass_kg)?;
        let r = evaluate(&trace, bounds, &goal);
        progress(&r);
        reports.push(r);
        traces.push(trace);
    }
    Ok((reports, traces))
}
