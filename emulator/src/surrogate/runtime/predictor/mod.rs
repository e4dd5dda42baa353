//! The free-running predictor of a fitted [`Model`]: what cross-validation scores and
//! what the runtime steps, so a model is chosen on exactly the behaviour it has in the
//! loop. [`Predictor::new`] compiles the model once (only the features and terms it
//! uses, laid out for the step); [`Predictor::step`] allocates nothing.
//!
//! - `aligned`: storage from 32-byte boundaries (the ring's buffer, the gathered features);
//! - `ring`: the history window the features are read from;
//! - `gather`: feature reads, envelope clamp and scaling, phase and ignition features;
//! - `terms`: a row's terms, factored and summed in partial sums;
//! - `dense`: the linear pressure/mass rows as dense coefficients;
//! - `compiled`: one submodel compiled from these parts.

mod aligned;
mod compiled;
mod dense;
mod gather;
mod ring;
mod terms;

use super::features::{History, InputVec, Layout, StateVec, INPUT_DIM};
use super::model::Model;
use super::valve::{valve_sum_of, ValveState, ValveTrack};
use compiled::CompiledSub;
use gather::{Clock, Phases};
use oils_shared::ENGINE_COUNT;
use ring::Ring;

#[cfg(target_arch = "x86_64")]
fn avx2_detected() -> bool {
    std::is_x86_feature_detected!("avx2")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_detected() -> bool {
    false
}

/// Free-running evaluation of a [`Model`]: its own predictions become its history.
/// Every buffer is sized in [`Predictor::new`]; [`Predictor::step`] does not allocate.
#[derive(Debug, Clone)]
pub struct Predictor {
    on_command_range_n: [f64; 2],
    mimo: Vec<CompiledSub<1>>,
    per_engine: Vec<CompiledSub<ENGINE_COUNT>>,
    ring: Ring,
    phases: Phases,
    /// The valve filter some submodel reads, and its state after the latest step.
    valve: Option<ValveTrack>,
    /// The ignition clocks after the step (idle without one).
    clock: Clock,
    out_of_envelope_steps: u64,
    /// Step with the AVX2 build of the same code (x86-64 CPUs that have it).
    avx2: bool,
}

impl Predictor {
    /// Compiles a model (assumed checked) and starts it from its initial state.
    pub fn new(model: &Model) -> Self {
        // The phase indicators are kept incrementally, so the ring only has to hold the
        // lags the features read directly.
        let depth = model
            .submodels
            .iter()
            .map(|s| s.features.max_state_lag())
            .max()
            .unwrap_or(1)
            .saturating_add(1);
        let cap = model
            .submodels
            .iter()
            .map(|s| s.features.start_steps.max(s.features.stop_steps))
            .max()
            .unwrap_or(0);
        let of_layout = |l: Layout| {
            model
                .submodels
                .iter()
                .filter(move |s| s.features.layout == l)
        };
        let mut p = Self {
            on_command_range_n: model.on_command_range_n,
            mimo: of_layout(Layout::Mimo)
                .map(|s| CompiledSub::compile(s, depth))
                .collect(),
            per_engine: of_layout(Layout::PerEngine)
                .map(|s| CompiledSub::compile(s, depth))
                .collect(),
            ring: Ring::new(depth),
            phases: Phases {
                on: [false; ENGINE_COUNT],
                run: [cap + 1; ENGINE_COUNT],
                cap,
            },
            valve: model
                .submodels
                .iter()
                .filter(|s| s.features.valve_features() > 0)
                .find_map(|s| s.features.valve)
                .map(|f| ValveTrack::new(f, model.sample_time_ns as f64 * 1e-9)),
            clock: Clock::IDLE,
            out_of_envelope_steps: 0,
            avx2: cfg!(target_arch = "x86_64") && avx2_detected(),
        };
        p.reset_to(&model.initial_state);
        p
    }

    /// Restarts from a state at rest: engines off for all of the history, every past
    /// state equal to `state` (how the reference model is started).
    pub fn reset_to(&mut self, state: &StateVec) {
        let rest = self.valve.as_mut().map_or(ValveState::default(), |v| {
            v.reset();
            v.state
        });
        for i in 0..self.ring.depth {
            self.ring.set_input(i, &[0.0; INPUT_DIM]);
            // At rest nothing draws, before or after.
            self.ring
                .set_valve(i, &rest.valve_n, &[0.0; INPUT_DIM], 0.0);
            self.ring.set_state(i, state);
        }
        self.ring.head = 0;
        self.phases.on = [false; ENGINE_COUNT];
        self.phases.run = [self.phases.cap + 1; ENGINE_COUNT];
        self.clock = Clock::IDLE;
        self.out_of_envelope_steps = 0;
    }

    /// Loads a true history (oldest first; the last state is the latest known) so that a
    /// free run can start mid-trajectory, as cross-validation does on a test block.
    pub fn seed_history<H: History>(&mut self, h: &H) {
        // Slot `head` is the step about to be predicted; lags 1..depth-1 are the past.
        self.ring.head = 0;
        for lag in 1..self.ring.depth {
            let i = self.ring.index(lag);
            self.ring.set_input(i, h.input(lag));
            if self.valve.is_some() {
                let before = valve_sum_of(h.input(lag + 1), &h.valve(lag + 1).valve_n);
                self.ring
                    .set_valve(i, &h.valve(lag).valve_n, h.input(lag), before);
            }
            self.ring.set_state(i, h.state(lag));
        }
        if let Some(v) = &mut self.valve {
            v.state = *h.valve(1);
        }
        // One slot back, so the next step() advances onto slot 0.
        self.ring.head = self.ring.depth - 1;
        // The switch phase at the latest known step, read from the history (which may
        // reach further back than the ring).
        let cap = self.phases.cap;
        for e in 0..ENGINE_COUNT {
            let sw = |lag: usize| h.input(lag)[ENGINE_COUNT + e] > 0.5;
            let on = sw(1);
            self.phases.on[e] = on;
            self.phases.run[e] = (1..=cap).find(|&k| sw(k + 1) != on).unwrap_or(cap + 1);
        }
    }

    /// Number of steps on which some used feature was outside the training envelope.
    pub fn out_of_envelope_steps(&self) -> u64 {
        self.out_of_envelope_steps
    }

    /// The latest state.
    pub fn state(&self) -> StateVec {
        self.ring.state()
    }

    /// The state before the latest step (the latest state, before any step).
    pub fn previous_state(&self) -> StateVec {
        self.ring.state_at(1)
    }

    /// Predicts the state at the end of a step with `input` held, and makes it history.
    #[inline]
    pub fn step(&mut self, input: &InputVec) -> StateVec {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: the CPU has AVX2 (checked in `new`).
            return unsafe { self.step_avx2(input) };
        }
        self.step_in::<false>(input)
    }

    /// [`Predictor::step`] compiled for AVX2: the four engines' lanes in one vector
    /// instead of two. Bit for bit the same results: each lane is the same IEEE operation
    /// in the same order, and without fused multiply-add (which would round differently,
    /// and so is not enabled) nothing else changes. Tested against the portable path.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn step_avx2(&mut self, input: &InputVec) -> StateVec {
        self.step_in::<true>(input)
    }

    /// The step; `AVX2` only in [`Predictor::step_avx2`]. A constant rather than a flag
    /// read at run time, so that each build holds only its own paths: with the flag,
    /// the AVX2 build carried the portable fallbacks too, between its hot parts.
    #[inline(always)]
    fn step_in<const AVX2: bool>(&mut self, input: &InputVec) -> StateVec {
        let prev = self.ring.state();
        let head = self.ring.advance();
        let [lo, hi] = self.on_command_range_n;
        // The input is read value by value, not copied whole: the caller has just
        // written it value by value, and one wide read of it waited for those writes
        // (a store-forwarding stall; `perf` on the probe's no-term step put it among
        // the hottest instructions, and this took that step from about 95 to 83 ns).
        let u: InputVec = std::array::from_fn(|i| {
            let raw = input[i % ENGINE_COUNT];
            let on = input[ENGINE_COUNT + i % ENGINE_COUNT] > 0.5;
            if i < ENGINE_COUNT && on {
                raw.clamp(lo, hi)
            } else {
                input[i]
            }
        });
        let mut outside = false;
        for e in 0..ENGINE_COUNT {
            let on = u[ENGINE_COUNT + e] > 0.5;
            outside |= on && u[e] != input[e];
            let ph = &mut self.phases;
            ph.run[e] = if on == ph.on[e] {
                (ph.run[e] + 1).min(ph.cap + 1)
            } else {
                1
            };
            ph.on[e] = on;
        }
        // The model sees the commands after the on-range clamp above. The record's state
        // is still an old one; it is never read (state lags start at 1).
        self.ring.set_input(head, &u);
        if let Some(v) = &mut self.valve {
            let ignition = v.ignition();
            let s = v.advance(&u);
            let before = self.ring.valve_sum(1);
            self.ring.set_valve(head, &s.valve_n, &u, before);
            if let Some(c) = ignition {
                // The switches are the phases' (already updated for this step).
                let window_s = c.window_s();
                let k = &mut self.clock;
                k.any = false;
                for e in 0..ENGINE_COUNT {
                    let since = s.since_ignition_s[e];
                    k.since_ignition_s[e] = since;
                    k.active[e] = self.phases.on[e] && since < window_s;
                    k.any |= k.active[e];
                }
            }
        }
        let mut next = prev;
        let window = self.ring.window();
        for sub in &mut self.per_engine {
            outside |= sub.eval::<AVX2>(window, &self.phases, &self.clock, &prev, &mut next);
        }
        for sub in &mut self.mimo {
            outside |= sub.eval::<AVX2>(window, &self.phases, &self.clock, &prev, &mut next);
        }
        // The physical guards are applied as each output is written (`compiled::guarded`;
        // every output is written by exactly one submodel, `Model::check`).
        self.out_of_envelope_steps += u64::from(outside);
        self.ring.set_state(head, &next);
        next
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::surrogate::runtime::features::{
        FeatureSpec, TrajectoryHistory, STATE_DIM, STATE_MF, STATE_MO, STATE_P,
    };
    use crate::surrogate::runtime::model::{ActiveTerm, OutputRow, Submodel, Target};
    use crate::surrogate::runtime::valve::{IgnitionClock, ValveFilter};
    use crate::surrogate::training::library::Library;

    /// A valve filter for the test models (hifi's TFCV figures in newtons).
    pub(crate) const TEST_VALVE: ValveFilter = ValveFilter {
        time_constant_s: 0.015,
        rate_n_per_s: 6000.0,
        backlash_n: 4.7,
        park_n: 320.0,
        ignition: Some(TEST_IGNITION),
        stroke: None,
    };

    /// An ignition clock for the test models (with both sags, so the engines' clocks
    /// depend on each other).
    pub(crate) const TEST_IGNITION: IgnitionClock = IgnitionClock {
        fill_n_s: 20.0,
        drain_time_s: 0.6,
        full: 1.1,
        lead_s: 0.01,
        knot_spacing_s: 0.005,
        knots: 6,
        sag_per_n: 6e-5,
        priming_sag_per_n: 8e-5,
    };

    /// The valve track of `inputs` for `model` (empty when no submodel reads it).
    fn valves_of(model: &Model, inputs: &[InputVec]) -> (Vec<ValveState>, ValveState) {
        let dt_s = model.sample_time_ns as f64 * 1e-9;
        match model.submodels.iter().find_map(|s| s.features.valve) {
            Some(f) => (f.track(inputs, dt_s), f.rest()),
            None => (Vec::new(), ValveState::default()),
        }
    }

    /// A model with every library term active (pseudo-random coefficients), so every
    /// feature, phase indicator and term degree is exercised. With `mimo_degree` 1 the
    /// MIMO submodel is linear, and compiled with its scaling folded.
    fn dense_model(mimo_degree: usize) -> Model {
        let mut seed = 12345u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let specs = [
            (
                FeatureSpec {
                    mass_features: true,
                    start_steps: 5,
                    stop_steps: 3,
                    command_sum: true,
                    valve: Some(TEST_VALVE),
                    valve_sum: true,
                    ..FeatureSpec::per_engine(2)
                },
                3,
                (0..ENGINE_COUNT).collect::<Vec<_>>(),
            ),
            (
                FeatureSpec::paper(1),
                mimo_degree,
                (ENGINE_COUNT..STATE_DIM).collect(),
            ),
        ];
        let submodels = specs
            .into_iter()
            .map(|(features, degree, outputs)| {
                let dim = features.dim();
                let names = features.names();
                let lib = Library::new(dim, degree, &features.roles(), features.phase_degree);
                let rows = match features.layout {
                    Layout::PerEngine => 1,
                    Layout::Mimo => outputs.len(),
                };
                Submodel {
                    features,
                    degree,
                    library_size: lib.len(),
                    target: Target::Increment,
                    feature_names: names.clone(),
                    // Start indicators uncentred, as training leaves them (their terms are
                    // then evaluated only in their phase); the others centred, which the
                    // predictor must handle too.
                    feature_mean: names
                        .iter()
                        .map(|n| if n.starts_with("start") { 0.0 } else { rnd() })
                        .collect(),
                    feature_std: (0..dim).map(|_| 1.0 + rnd()).collect(),
                    envelope_lo: vec![-1e9; dim],
                    envelope_hi: vec![1e9; dim],
                    rows: (0..rows)
                        .map(|o| OutputRow {
                            output: format!("y{o}"),
                            intercept: rnd(),
                            terms: lib
                                .terms
                                .iter()
                                .map(|t| ActiveTerm {
                                    name: lib.term_name(t, &names),
                                    factors: *t,
                                    coef: 1e-16 * rnd(),
                                })
                                .collect(),
                        })
                        .collect(),
                    outputs,
                }
            })
            .collect();
        Model {
            sample_time_ns: 10_000_000,
            initial_state: [0.0, 0.0, 0.0, 0.0, 2.8e7, 0.0, 0.0],
            on_command_range_n: [320.0, 800.0],
            submodels,
        }
    }

    /// The straightforward evaluation: every feature by `fill`, every term in library
    /// order. The compiled predictor must agree to rounding (it sums the phase terms of
    /// an engine in a phase after the others).
    #[test]
    fn compiled_step_equals_full_evaluation() {
        for mimo_degree in [1, 2] {
            compiled_step_equals_full_evaluation_of(&dense_model(mimo_degree));
        }
    }

    /// A term with two phase or ignition features would be evaluated in one's window
    /// with the other's in-phase constant: refused.
    #[test]
    fn a_term_with_two_phase_features_is_refused() {
        let mut m = dense_model(1);
        m.check().unwrap();
        let s = &mut m.submodels[0];
        let names = s.features.names();
        let at = |n: &str| names.iter().position(|x| x == n).unwrap() as u16;
        let one = s.features.dim() as u16;
        s.rows[0].terms.push(ActiveTerm {
            name: "priming[t]*stop0[t]".into(),
            factors: [at("priming[t]"), at("stop0[t]"), one],
            coef: 1.0,
        });
        let e = m.check().unwrap_err();
        assert!(e.contains("more than one phase or ignition feature"), "{e}");
    }

    /// The committed default model.
    fn committed_model() -> Model {
        crate::surrogate::runtime::model_file::ModelFile::parse(
            crate::surrogate::runtime::DEFAULT_MODEL_JSON,
        )
        .expect("the committed model parses")
        .model
    }

    /// The guards, applied as each output is written: a command that is not a number
    /// makes predictions that are not finite; those outputs keep their previous values,
    /// nothing goes negative or backwards, and the step is counted.
    #[test]
    fn a_prediction_that_is_not_finite_keeps_the_previous_value_and_is_counted() {
        let mut p = Predictor::new(&committed_model());
        let good = [600.0, 650.0, 700.0, 550.0, 1.0, 1.0, 1.0, 1.0];
        for _ in 0..200 {
            p.step(&good);
        }
        assert_eq!(p.out_of_envelope_steps(), 0);
        let before = p.state();
        // Engine 2 switched off with a command that is not a number: no on-range clamp
        // sees it, so only the guards can count the step.
        let mut bad = good;
        bad[1] = f64::NAN;
        bad[ENGINE_COUNT + 1] = 0.0;
        let after = p.step(&bad);
        assert_eq!(p.out_of_envelope_steps(), 1);
        assert!(after.iter().all(|v| v.is_finite()), "{after:?}");
        // Engine 2's own features are not numbers: its thrust is held.
        assert_eq!(after[1], before[1]);
        assert!(after[..ENGINE_COUNT].iter().all(|&t| t >= 0.0));
        assert!(after[STATE_P] >= 0.0);
        assert!(after[STATE_MF] >= before[STATE_MF] && after[STATE_MO] >= before[STATE_MO]);
        assert_eq!(p.state(), after, "the ring holds the guarded state");
        // And the model carries on from there.
        let next = p.step(&good);
        assert!(next.iter().all(|v| v.is_finite()));
    }

    /// The AVX2 build of the step gives the same bits as the portable one (on a CPU
    /// without AVX2 both runs take the portable path).
    #[test]
    fn avx2_and_portable_steps_agree_bit_for_bit() {
        let committed = committed_model();
        let (cmds, _) =
            crate::surrogate::runtime::features::source_tests::switching_trajectory(400);
        // The same switching at 2.5 times the thrust: commands beyond the on-range,
        // clamped and counted.
        let wild: Vec<InputVec> = cmds
            .iter()
            .map(|u| std::array::from_fn(|k| if k < ENGINE_COUNT { 2.5 * u[k] } else { u[k] }))
            .collect();
        // The committed model with every envelope narrowed to its middle third: the
        // features are clamped from both sides in every path.
        let mut narrowed = committed.clone();
        for s in &mut narrowed.submodels {
            for (lo, hi) in s.envelope_lo.iter_mut().zip(&mut s.envelope_hi) {
                let third = (*hi - *lo) / 3.0;
                (*lo, *hi) = (*lo + third, *hi - third);
            }
        }
        for model in [dense_model(1), dense_model(2), committed, narrowed] {
            for cmds in [&cmds, &wild] {
                let mut fast = Predictor::new(&model);
                let mut portable = Predictor::new(&model);
                portable.avx2 = false;
                for (t, cmd) in cmds.iter().enumerate() {
                    let (a, b) = (fast.step(cmd), portable.step(cmd));
                    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "step {t}");
                }
                assert_eq!(
                    fast.out_of_envelope_steps(),
                    portable.out_of_envelope_steps()
                );
            }
        }
    }

    /// The straightforward prediction of step `t` from the true history: `inputs` up to
    /// and including step `t` (as the model sees them), `states` up to step `t - 1`.
    fn full_step(model: &Model, inputs: &[InputVec], states: &[StateVec], t: usize) -> StateVec {
        let prev = states[..t].last().copied().unwrap_or(model.initial_state);
        let (valves, valve_rest) = valves_of(model, &inputs[..=t]);
        let mut want = prev;
        for s in &model.submodels {
            let dim = s.features.dim();
            let mut x = vec![1.0; dim + 1];
            for (e, &o) in s.outputs.iter().enumerate() {
                let h = TrajectoryHistory {
                    inputs,
                    states,
                    initial: &model.initial_state,
                    valves: &valves,
                    valve_rest,
                    t,
                };
                s.features.fill(&h, e, &mut x[..dim]);
                for j in 0..dim {
                    let v = x[j].max(s.envelope_lo[j]).min(s.envelope_hi[j]);
                    x[j] = (v - s.feature_mean[j]) * (1.0 / s.feature_std[j]);
                }
                let row = &s.rows[if s.rows.len() == 1 { 0 } else { e }];
                let mut y = row.intercept;
                for term in &row.terms {
                    let f = term.factors.map(|f| x[f as usize]);
                    y += term.coef * (f[0] * f[1] * f[2]);
                }
                want[o] = prev[o] + y;
            }
        }
        for v in want.iter_mut().take(ENGINE_COUNT) {
            *v = v.max(0.0);
        }
        want[STATE_P] = want[STATE_P].max(0.0);
        want[STATE_MF] = want[STATE_MF].max(prev[STATE_MF]);
        want[STATE_MO] = want[STATE_MO].max(prev[STATE_MO]);
        want
    }

    /// One step at a time from a true history, so that coefficients of ordinary size
    /// stay bounded (a free run of an all-active model needs tiny ones, which would hide
    /// a wrong intercept or scale in the folded linear submodel).
    #[test]
    fn one_step_from_history_equals_full_evaluation() {
        for mimo_degree in [1, 2] {
            let mut model = dense_model(mimo_degree);
            for r in &mut model.submodels[1].rows {
                for t in &mut r.terms {
                    t.coef *= 1e16;
                }
            }
            let (inputs, states) =
                crate::surrogate::runtime::features::source_tests::switching_trajectory(60);
            let (valves, valve_rest) = valves_of(&model, &inputs);
            let mut p = Predictor::new(&model);
            for t in 4..inputs.len() {
                p.seed_history(&TrajectoryHistory {
                    inputs: &inputs,
                    states: &states,
                    initial: &model.initial_state,
                    valves: &valves,
                    valve_rest,
                    t,
                });
                let got = p.step(&inputs[t]);
                let want = full_step(&model, &inputs, &states, t);
                for o in 0..STATE_DIM {
                    let tol = 1e-12 * (1.0 + want[o].abs());
                    assert!(
                        (got[o] - want[o]).abs() <= tol,
                        "degree {mimo_degree} step {t} output {o}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    fn compiled_step_equals_full_evaluation_of(model: &Model) {
        model.check().unwrap();
        let mut p = Predictor::new(model);
        let (cmds, _) =
            crate::surrogate::runtime::features::source_tests::switching_trajectory(150);
        let mut inputs: Vec<InputVec> = Vec::new();
        let mut states: Vec<StateVec> = Vec::new();
        let mut clocked_steps = 0;
        for (t, cmd) in cmds.iter().enumerate() {
            let got = p.step(cmd);
            clocked_steps += usize::from(p.clock.any);
            let mut u = *cmd;
            for e in 0..ENGINE_COUNT {
                if u[ENGINE_COUNT + e] > 0.5 {
                    u[e] = u[e].clamp(320.0, 800.0);
                }
            }
            inputs.push(u);
            let want = full_step(model, &inputs, &states, t);
            for o in 0..STATE_DIM {
                let tol = 1e-12 * (1.0 + want[o].abs());
                assert!(
                    (got[o] - want[o]).abs() <= tol,
                    "step {t} output {o}: {got:?} vs {want:?}"
                );
            }
            states.push(got);
        }
        // The run does go through ignition windows (their terms are evaluated apart).
        let clocked = model
            .submodels
            .iter()
            .any(|s| s.features.ignition().is_some());
        assert!(
            !clocked || clocked_steps > 20,
            "{clocked_steps} steps in a window"
        );
        // Seeding from the recorded history mid-run continues identically.
        let mut q = Predictor::new(model);
        let t0 = 77;
        let (valves, valve_rest) = valves_of(model, &inputs);
        q.seed_history(&TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &model.initial_state,
            valves: &valves,
            valve_rest,
            t: t0,
        });
        for t in t0..cmds.len() {
            assert_eq!(q.step(&cmds[t]), states[t], "seeded step {t}");
        }
    }
}
