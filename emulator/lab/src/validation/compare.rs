//! Runs the truth model and the surrogate, each free, on the same commands and keeps the
//! outputs the comparison needs at every bench step.

use super::cases::Case;
use oils_emulator::propulsion::{EngineCommand, Propulsion, PropulsionOutput};
use oils_shared::ENGINE_COUNT;

/// Outputs compared, in this order: thrust 1-4 (N), gas pressure (Pa), ejected fuel and
/// oxidiser (kg), total module mass (kg, as initial mass minus ejected).
pub const OUTPUT_NAMES: [&str; OUTPUTS] = [
    "thrust1_n",
    "thrust2_n",
    "thrust3_n",
    "thrust4_n",
    "gas_pressure_pa",
    "ejected_fuel_kg",
    "ejected_ox_kg",
    "total_mass_kg",
];
/// Number of compared outputs.
pub const OUTPUTS: usize = ENGINE_COUNT + 4;
/// Index of the gas pressure in [`OUTPUT_NAMES`].
pub const GAS: usize = ENGINE_COUNT;
/// Index of the total mass in [`OUTPUT_NAMES`].
pub const MASS: usize = ENGINE_COUNT + 3;

/// The compared outputs of one model at one instant.
pub type Outputs = [f64; OUTPUTS];

fn outputs_of(o: &PropulsionOutput, initial_mass_kg: f64) -> Outputs {
    [
        o.thrust_n[0],
        o.thrust_n[1],
        o.thrust_n[2],
        o.thrust_n[3],
        o.gas_pressure_pa,
        o.ejected_fuel_kg,
        o.ejected_ox_kg,
        initial_mass_kg - o.ejected_kg(),
    ]
}

/// One bench step: the command held over it and both models' outputs at its end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Time at the end of the step, nanoseconds.
    pub t_ns: i64,
    /// Command held over the step.
    pub cmd: EngineCommand,
    /// Truth (hifi).
    pub truth: Outputs,
    /// Surrogate.
    pub model: Outputs,
}

/// Both models over one case.
#[derive(Debug, Clone)]
pub struct Trace {
    /// The case.
    pub case: Case,
    /// Every step; the first is the initial state at t = 0 (no command yet).
    pub samples: Vec<Sample>,
    /// Steps on which the surrogate left its training envelope, if it has one.
    pub out_of_envelope_steps: Option<u64>,
}

/// A model produced a non-finite output.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("case {case}: the {which} model produced a non-finite output at t = {t_s} s")]
pub struct NonFinite {
    /// Case name.
    pub case: String,
    /// `truth` or `model`.
    pub which: &'static str,
    /// Time, seconds.
    pub t_s: f64,
}

/// The command in force over the step starting at `t_ns` (engines off before the first
/// row; a switched-off engine's command reads 0).
pub fn command_at(case: &Case, t_ns: i64) -> EngineCommand {
    case.profile
        .at(t_ns)
        .map(|r| EngineCommand {
            thrust_cmd_n: std::array::from_fn(|e| if r.on[e] { r.thrust_cmd_n[e] } else { 0.0 }),
            on: r.on,
        })
        .unwrap_or_default()
}

/// Runs both models, fresh, over `case` in steps of `dt_ns`. `initial_mass_kg` is the
/// module's mass at t = 0 (for the total-mass output).
pub fn run_case(
    case: &Case,
    truth: &mut dyn Propulsion,
    model: &mut dyn Propulsion,
    dt_ns: u64,
    initial_mass_kg: f64,
) -> Result<Trace, NonFinite> {
    let steps = (case.duration_ns.max(0) as u64).div_ceil(dt_ns.max(1));
    let mut samples = Vec::with_capacity(steps as usize + 1);
    samples.push(Sample {
        t_ns: 0,
        cmd: EngineCommand::default(),
        truth: outputs_of(&truth.output(), initial_mass_kg),
        model: outputs_of(&model.output(), initial_mass_kg),
    });
    let mut t_ns = 0i64;
    for _ in 0..steps {
        let cmd = command_at(case, t_ns);
        let a = outputs_of(&truth.step(&cmd, dt_ns), initial_mass_kg);
        let b = outputs_of(&model.step(&cmd, dt_ns), initial_mass_kg);
        t_ns += dt_ns as i64;
        for (which, o) in [("truth", &a), ("model", &b)] {
            if o.iter().any(|v| !v.is_finite()) {
                return Err(NonFinite {
                    case: case.name.clone(),
                    which,
                    t_s: t_ns as f64 * 1e-9,
                });
            }
        }
        samples.push(Sample {
            t_ns,
            cmd,
            truth: a,
            model: b,
        });
    }
    Ok(Trace {
        case: case.clone(),
        samples,
        out_of_envelope_steps: model.diagnostics().and_then(|d| d.out_of_envelope_steps),
    })
}
