//! Judging traces against the seed paper's bounds (and the halved goal), and the JSON
//! report `oils validate --report` writes.

use super::cases::{CaseKind, WindowKind};
use super::compare::{Trace, GAS, MASS, OUTPUTS, OUTPUT_NAMES};
use super::stats::{ErrorAccumulator, ErrorStats};
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Error bounds on |surrogate - hifi|.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// Thrust over a sine sweep, newtons.
    pub sine_n: f64,
    /// Thrust in a transient window after a step, newtons.
    pub transient_n: f64,
    /// Thrust in steady state, newtons.
    pub steady_n: f64,
    /// Thrust over a full descent profile, newtons.
    pub descent_n: f64,
    /// Total module mass, kilograms.
    pub mass_kg: f64,
}

impl Bounds {
    /// The seed paper's bounds (Section VI): sine +-2 N, step transient +-20 N, steady
    /// +-2 N, descent +-15 N, module mass +-1.5 kg.
    pub const PAPER: Bounds = Bounds {
        sine_n: 2.0,
        transient_n: 20.0,
        steady_n: 2.0,
        descent_n: 15.0,
        mass_kg: 1.5,
    };

    /// Every bound times `factor`.
    pub fn scaled(&self, factor: f64) -> Bounds {
        Bounds {
            sine_n: self.sine_n * factor,
            transient_n: self.transient_n * factor,
            steady_n: self.steady_n * factor,
            descent_n: self.descent_n * factor,
            mass_kg: self.mass_kg * factor,
        }
    }

    /// The thrust bound of a window kind.
    pub fn thrust_n(&self, kind: WindowKind) -> f64 {
        match kind {
            WindowKind::Transient => self.transient_n,
            WindowKind::Steady => self.steady_n,
            WindowKind::Sine => self.sine_n,
            WindowKind::Descent => self.descent_n,
        }
    }
}

/// The project's accuracy goal: half the paper's bounds.
pub const GOAL_FACTOR: f64 = 0.5;

/// One bound checked.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// What is checked (e.g. `thrust in steady windows`).
    pub what: String,
    /// Largest |error| found.
    pub max_abs_error: f64,
    /// The paper's bound.
    pub bound: f64,
    /// The goal (half the bound).
    pub goal: f64,
    /// `max_abs_error <= bound`.
    pub pass: bool,
    /// `max_abs_error <= goal`.
    pub pass_goal: bool,
}

/// Errors over all windows of one kind in a case.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowReport {
    /// Window kind.
    pub kind: WindowKind,
    /// Number of windows of this kind.
    pub windows: usize,
    /// Largest |thrust error| over the four engines, newtons.
    pub thrust_max_abs_error_n: f64,
    /// RMS thrust error over the four engines, newtons.
    pub thrust_rms_error_n: f64,
    /// Per output.
    pub outputs: BTreeMap<String, ErrorStats>,
}

/// One case's result. The first keys are the interface scripts rely on.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CaseReport {
    /// Case name.
    pub name: String,
    /// Case kind.
    pub kind: CaseKind,
    /// Largest |thrust error| over the four engines and the whole case, newtons.
    pub thrust_max_abs_error_n: f64,
    /// RMS thrust error over the four engines and the whole case, newtons.
    pub thrust_rms_error_n: f64,
    /// Largest |total module mass error|, kilograms.
    pub mass_max_abs_error_kg: f64,
    /// Largest |gas pressure error|, pascals.
    pub gas_pressure_max_abs_error_pa: f64,
    /// Within the paper's bounds.
    pub pass: bool,
    /// Within half the paper's bounds.
    pub pass_goal: bool,
    /// Simulated duration, seconds.
    pub duration_s: f64,
    /// Bench steps compared.
    pub steps: u64,
    /// Steps on which the surrogate left its training envelope (inputs clamped).
    pub out_of_envelope_steps: Option<u64>,
    /// Bounds checked.
    pub checks: Vec<Check>,
    /// Per window kind (transient / steady split for steps).
    pub windows: Vec<WindowReport>,
    /// Per output over the whole case.
    pub outputs: BTreeMap<String, ErrorStats>,
}

/// Everything `oils validate` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ValidationReport {
    /// Which surrogate model (file path or `committed default`).
    pub model: String,
    /// What the model was trained on (`provenance.reference` of the file).
    pub model_reference: String,
    /// The model's variant.
    pub model_variant: String,
    /// The truth model.
    pub truth: String,
    /// Hifi parameters (file path or `defaults`).
    pub hifi_params: String,
    /// Bench step, milliseconds.
    pub dt_ms: f64,
    /// Transient window after each step, seconds.
    pub transient_window_s: f64,
    /// The paper's bounds.
    pub bounds: Bounds,
    /// The goal's bounds (the paper's times [`GOAL_FACTOR`]).
    pub goal: Bounds,
    /// Per case.
    pub cases: Vec<CaseReport>,
    /// Every case within the paper's bounds.
    pub pass: bool,
    /// Every case within the goal.
    pub pass_goal: bool,
}

/// Per-output accumulators of one stretch.
#[derive(Debug, Clone, Copy, Default)]
pub struct OutputAccumulators {
    /// One per output of [`OUTPUT_NAMES`].
    pub outputs: [ErrorAccumulator; OUTPUTS],
    /// All four thrusts pooled.
    pub thrust: ErrorAccumulator,
}

impl OutputAccumulators {
    fn add(&mut self, d: &[f64; OUTPUTS]) {
        for (a, v) in self.outputs.iter_mut().zip(d) {
            a.add(*v);
        }
        for v in &d[..ENGINE_COUNT] {
            self.thrust.add(*v);
        }
    }

    fn by_name(&self) -> BTreeMap<String, ErrorStats> {
        OUTPUT_NAMES
            .iter()
            .zip(&self.outputs)
            .map(|(n, a)| (n.to_string(), a.stats()))
            .collect()
    }
}

/// Accumulates `model - truth` of a trace: over the whole case and per window kind
/// (`WindowKind` order). The initial sample (t = 0, before any command) is left out.
pub fn accumulate(trace: &Trace) -> (OutputAccumulators, BTreeMap<WindowKind, OutputAccumulators>) {
    let mut all = OutputAccumulators::default();
    let mut by_kind: BTreeMap<WindowKind, OutputAccumulators> = BTreeMap::new();
    let windows = &trace.case.windows;
    let mut w = 0usize;
    for s in trace.samples.iter().skip(1) {
        let d: [f64; OUTPUTS] = std::array::from_fn(|i| s.model[i] - s.truth[i]);
        all.add(&d);
        while w < windows.len() && s.t_ns > windows[w].end_ns {
            w += 1;
        }
        if let Some(win) = windows.get(w).filter(|x| s.t_ns > x.start_ns) {
            by_kind.entry(win.kind).or_default().add(&d);
        }
    }
    (all, by_kind)
}

fn check(what: String, max_abs_error: f64, bound: f64, goal: f64) -> Check {
    Check {
        what,
        max_abs_error,
        bound,
        goal,
        pass: max_abs_error <= bound,
        pass_goal: max_abs_error <= goal,
    }
}

/// Judges one trace.
pub fn evaluate(trace: &Trace, bounds: &Bounds, goal: &Bounds) -> CaseReport {
    let (all, by_kind) = accumulate(trace);
    let mut checks = Vec::new();
    let mut windows = Vec::new();
    for (kind, acc) in &by_kind {
        let t = acc.thrust.stats();
        checks.push(check(
            format!("thrust in {} windows [N]", kind.as_str()),
            t.max_abs,
            bounds.thrust_n(*kind),
            goal.thrust_n(*kind),
        ));
        windows.push(WindowReport {
            kind: *kind,
            windows: trace
                .case
                .windows
                .iter()
                .filter(|w| w.kind == *kind)
                .count(),
            thrust_max_abs_error_n: t.max_abs,
            thrust_rms_error_n: t.rms,
            outputs: acc.by_name(),
        });
    }
    let mass = all.outputs[MASS].stats();
    checks.push(check(
        "total module mass [kg]".into(),
        mass.max_abs,
        bounds.mass_kg,
        goal.mass_kg,
    ));
    let thrust = all.thrust.stats();
    CaseReport {
        name: trace.case.name.clone(),
        kind: trace.case.kind,
        thrust_max_abs_error_n: thrust.max_abs,
        thrust_rms_error_n: thrust.rms,
        mass_max_abs_error_kg: mass.max_abs,
        gas_pressure_max_abs_error_pa: all.outputs[GAS].stats().max_abs,
        pass: checks.iter().all(|c| c.pass),
        pass_goal: checks.iter().all(|c| c.pass_goal),
        duration_s: trace.case.duration_ns as f64 * 1e-9,
        steps: trace.samples.len().saturating_sub(1) as u64,
        out_of_envelope_steps: trace.out_of_envelope_steps,
        checks,
        windows,
        outputs: all.by_name(),
    }
}

impl ValidationReport {
    /// A report of `cases` judged against `bounds` by `hifi`: the goal is the bounds
    /// times [`GOAL_FACTOR`], and the overall verdicts are every case's.
    pub fn new(
        model: String,
        model_reference: String,
        model_variant: String,
        hifi_params: String,
        dt_ms: f64,
        bounds: Bounds,
        cases: Vec<CaseReport>,
    ) -> Self {
        Self {
            model,
            model_reference,
            model_variant,
            truth: "hifi".into(),
            hifi_params,
            dt_ms,
            transient_window_s: super::cases::TRANSIENT_WINDOW_S,
            bounds,
            goal: bounds.scaled(GOAL_FACTOR),
            pass: cases.iter().all(|r| r.pass),
            pass_goal: cases.iter().all(|r| r.pass_goal),
            cases,
        }
    }

    /// Pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }

    /// A table for the terminal: per case and check, error against bound and goal.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "oils validate: surrogate `{}` (trained on {}, {}) against {} ({}), dt {} ms, transient window {} s",
            self.model, self.model_reference, self.model_variant, self.truth, self.hifi_params,
            self.dt_ms, self.transient_window_s
        );
        let _ = writeln!(
            out,
            "{:<10} {:<28} {:>12} {:>9} {:>9}  {:<6} {:<6} {:>10}",
            "case", "check", "max|err|", "bound", "goal", "paper", "goal", "rms thr N"
        );
        let verdict = |b: bool| if b { "ok" } else { "MISS" };
        for c in &self.cases {
            for (i, k) in c.checks.iter().enumerate() {
                let rms = match c.windows.get(i) {
                    Some(w) => format!("{:.3}", w.thrust_rms_error_n),
                    None => String::new(),
                };
                let _ = writeln!(
                    out,
                    "{:<10} {:<28} {:>12.3} {:>9.2} {:>9.2}  {:<6} {:<6} {:>10}",
                    if i == 0 { c.name.as_str() } else { "" },
                    k.what,
                    k.max_abs_error,
                    k.bound,
                    k.goal,
                    verdict(k.pass),
                    verdict(k.pass_goal),
                    rms
                );
            }
            let _ = writeln!(
                out,
                "{:<10} gas pressure max|err| {:.3} bar; out-of-envelope steps {}",
                "",
                c.gas_pressure_max_abs_error_pa * 1e-5,
                c.out_of_envelope_steps
                    .map_or_else(|| "-".to_string(), |n| n.to_string())
            );
        }
        let _ = writeln!(
            out,
            "verdict: paper bounds {}, goal (half the bounds) {}",
            if self.pass { "PASS" } else { "FAIL" },
            if self.pass_goal { "PASS" } else { "FAIL" }
        );
        out
    }
}
