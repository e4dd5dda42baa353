//! The free-running predictor of a fitted [`Model`]: what the runtime steps and what
//! cross-validation scores, so a model is chosen on exactly the behaviour it has in the
//! loop. A step reads like the model's definition: the step's commands join a history
//! ring, each submodel's features are filled from that ring by [`FeatureSpec::fill`]
//! (the function training builds its rows with), clamped to the training envelope and
//! scaled, the active terms are summed, and the physical guards are applied.
//!
//! [`FeatureSpec::fill`]: super::features::FeatureSpec::fill

use super::features::{History, InputVec, Layout, StateVec, INPUT_DIM, STATE_MF, STATE_MO};
use super::model::{eval_term, ActiveTerm, Model, OutputRow, Submodel, Term};
use super::valve::{ValveState, ValveTrack};
use oils_shared::ENGINE_COUNT;

/// The last steps' inputs (as the model saw them), valve states and states; slot `head`
/// is the latest step. Allocated once, overwritten in place.
#[derive(Debug, Clone)]
struct Ring {
    inputs: Vec<InputVec>,
    valves: Vec<ValveState>,
    states: Vec<StateVec>,
    head: usize,
}

impl Ring {
    fn new(depth: usize) -> Self {
        Self {
            inputs: vec![[0.0; INPUT_DIM]; depth],
            valves: vec![ValveState::default(); depth],
            states: vec![[0.0; super::features::STATE_DIM]; depth],
            head: 0,
        }
    }

    fn depth(&self) -> usize {
        self.inputs.len()
    }

    /// The slot holding step `t - lag` (`t` the latest step). Every feature read comes
    /// through here, so no division: an integer division per read is slow enough to
    /// show in a whole descent.
    fn slot(&self, lag: usize) -> usize {
        debug_assert!(lag < self.depth(), "lag {lag} beyond the ring");
        if lag <= self.head {
            self.head - lag
        } else {
            self.head + self.depth() - lag
        }
    }

    /// Makes room for a new latest step (the oldest is overwritten).
    fn advance(&mut self) {
        self.head = if self.head + 1 == self.depth() {
            0
        } else {
            self.head + 1
        };
    }
}

impl History for Ring {
    fn input(&self, lag: usize) -> &InputVec {
        &self.inputs[self.slot(lag)]
    }
    fn state(&self, lag: usize) -> &StateVec {
        &self.states[self.slot(lag)]
    }
    fn valve(&self, lag: usize) -> &ValveState {
        &self.valves[self.slot(lag)]
    }
}

/// Free-running evaluation of a [`Model`]: its own predictions become its history.
/// Every buffer is sized in [`Predictor::new`]; [`Predictor::step`] does not allocate.
#[derive(Debug, Clone)]
pub struct Predictor {
    model: Model,
    /// What the step needs of each submodel beyond the model file, in the same order.
    subs: Vec<SubmodelUse>,
    ring: Ring,
    /// The valve filter (and ignition clock) the features read, if any.
    valve: Option<ValveTrack>,
    /// One submodel's scaled features, then the constant 1.0 that pads lower-degree
    /// terms ([`eval_term`]).
    x: Vec<f64>,
    /// The same for the four engines of a per-engine submodel, side by side.
    lanes: Vec<Lanes>,
    out_of_envelope_steps: u64,
    guards: crate::propulsion::diagnostics::SurrogateGuards,
    /// Per state output, the largest value a prediction may take ([`Limits`]).
    upper: StateVec,
}

/// The largest thrust and gas pressure a prediction may take: beyond them it is not
/// physical, and is clamped to the bound and counted
/// ([`SurrogateGuards::bounded_predictions`]). Ejected masses have none (they may
/// only grow, and the plant stops at the propellant load).
///
/// [`SurrogateGuards::bounded_predictions`]: crate::propulsion::diagnostics::SurrogateGuards::bounded_predictions
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Thrust of one engine, newtons.
    pub thrust_n: f64,
    /// Helium bottle pressure, pascals.
    pub gas_pressure_pa: f64,
}

impl Limits {
    /// No bound (training: a candidate is scored on what it predicts).
    pub const NONE: Self = Self {
        thrust_n: f64::INFINITY,
        gas_pressure_pa: f64::INFINITY,
    };

    /// The bounds of an engine rated `max_thrust_n`:
    /// [`MAX_THRUST_OVER_RATING`](super::model::MAX_THRUST_OVER_RATING) times it and
    /// [`MAX_GAS_PRESSURE_PA`](super::model::MAX_GAS_PRESSURE_PA).
    pub fn of_rating(max_thrust_n: f64) -> Self {
        Self {
            thrust_n: super::model::MAX_THRUST_OVER_RATING * max_thrust_n,
            gas_pressure_pa: super::model::MAX_GAS_PRESSURE_PA,
        }
    }

    fn upper(&self) -> StateVec {
        let mut u = [f64::INFINITY; super::features::STATE_DIM];
        u[..ENGINE_COUNT].fill(self.thrust_n);
        u[super::features::STATE_P] = self.gas_pressure_pa;
        u
    }
}

impl Predictor {
    /// A predictor of a model (assumed checked), started from its initial state.
    pub fn new(model: &Model) -> Self {
        let subs = &model.submodels;
        // The deepest lag any feature reads, and the step being predicted.
        let depth = subs.iter().map(|s| s.features.max_lag()).max().unwrap_or(1) + 1;
        let uses = subs.iter().map(SubmodelUse::of).collect();
        let max_dim = subs.iter().map(|s| s.features.dim()).max().unwrap_or(0);
        let dt_s = model.sample_time_ns as f64 * 1e-9;
        let mut p = Self {
            model: model.clone(),
            subs: uses,
            ring: Ring::new(depth),
            valve: subs
                .iter()
                .filter(|s| s.features.valve_features() > 0)
                .find_map(|s| s.features.valve)
                .map(|f| ValveTrack::new(f, dt_s)),
            x: vec![0.0; max_dim + 1],
            lanes: vec![[0.0; ENGINE_COUNT]; max_dim + 1],
            out_of_envelope_steps: 0,
            guards: Default::default(),
            upper: Limits::NONE.upper(),
        };
        p.reset_to(&model.initial_state);
        p
    }

    /// Bounds what a prediction may be (none until set).
    pub fn set_limits(&mut self, limits: Limits) {
        self.upper = limits.upper();
    }

    /// Restarts from a state at rest: engines off for all of the history, every past
    /// state equal to `state` (how the reference model is started).
    pub fn reset_to(&mut self, state: &StateVec) {
        let rest = self.valve.as_mut().map_or(ValveState::default(), |v| {
            v.reset();
            v.state
        });
        self.ring.inputs.fill([0.0; INPUT_DIM]);
        self.ring.valves.fill(rest);
        self.ring.states.fill(*state);
        self.ring.head = 0;
        self.out_of_envelope_steps = 0;
        self.guards = Default::default();
    }

    /// Loads a true history (the last state is the latest known) so that a free run can
    /// start mid-trajectory, as cross-validation does on a test block: the next
    /// [`Predictor::step`] predicts the step `h` is seen from.
    pub fn seed_history<H: History>(&mut self, h: &H) {
        // After the next step's advance, the ring's lag j + 1 is the history's lag j + 1.
        self.ring.head = 0;
        for j in 0..self.ring.depth() {
            let i = self.ring.slot(j);
            self.ring.inputs[i] = *h.input(j + 1);
            self.ring.states[i] = *h.state(j + 1);
            if self.valve.is_some() {
                self.ring.valves[i] = *h.valve(j + 1);
            }
        }
        if let Some(v) = &mut self.valve {
            v.state = *h.valve(1);
        }
    }

    /// Number of steps on which some used feature was outside the training envelope, a
    /// command outside the on-range, or a prediction not finite.
    pub fn out_of_envelope_steps(&self) -> u64 {
        self.out_of_envelope_steps
    }

    /// How often the guards acted (clamped commands, non-finite and clamped predictions).
    pub fn guards(&self) -> crate::propulsion::diagnostics::SurrogateGuards {
        self.guards
    }

    /// The latest state.
    pub fn state(&self) -> StateVec {
        *self.ring.state(0)
    }

    /// The state before the latest step (the latest state, before any step).
    pub fn previous_state(&self) -> StateVec {
        *self.ring.state(1)
    }

    /// Predicts the state at the end of a step with `input` held, and makes it history.
    pub fn step(&mut self, input: &InputVec) -> StateVec {
        let prev = self.state();
        // The commands of engines that are on, clamped to the range seen on-and-running.
        let [lo, hi] = self.model.on_command_range_n;
        let mut u = *input;
        let mut outside = false;
        for e in 0..ENGINE_COUNT {
            if input[ENGINE_COUNT + e] > 0.5 {
                u[e] = input[e].clamp(lo, hi);
                outside |= u[e] != input[e];
            }
        }
        self.guards.clamped_commands += u64::from(outside);
        let mut guard = Guard::default();
        self.ring.advance();
        let head = self.ring.head;
        self.ring.inputs[head] = u;
        if let Some(v) = &mut self.valve {
            self.ring.valves[head] = *v.advance(&u);
        }
        // Not read (state lags start at 1) until the prediction replaces it.
        self.ring.states[head] = prev;
        let mut next = prev;
        for (s, u) in self.model.submodels.iter().zip(&self.subs) {
            match s.features.layout {
                // The four engines share one row, each with its own features.
                Layout::PerEngine => {
                    outside |= gather_engines(s, u, &self.ring, &mut self.lanes);
                    let y = sum_engines(&s.rows[0], &u.groups[0], &self.lanes);
                    for (engine, &o) in s.outputs.iter().enumerate() {
                        let v = s.target.apply(prev[o], y[engine]);
                        next[o] = guarded(o, v, prev[o], self.upper[o], &mut guard);
                    }
                }
                // One feature vector, one row per output.
                Layout::Mimo => {
                    outside |= gather(s, u, &self.ring, 0, &mut self.x);
                    for (r, &o) in s.outputs.iter().enumerate() {
                        let y = sum(&s.rows[r], &u.groups[r], &self.x);
                        let v = s.target.apply(prev[o], y);
                        next[o] = guarded(o, v, prev[o], self.upper[o], &mut guard);
                    }
                }
            }
        }
        outside |= guard.non_finite;
        self.guards.non_finite_predictions += u64::from(guard.non_finite);
        self.guards.clamped_predictions += u64::from(guard.clamped);
        self.guards.bounded_predictions += u64::from(guard.bounded);
        self.out_of_envelope_steps += u64::from(outside);
        self.ring.states[head] = next;
        next
    }
}

/// One feature's training envelope and scaling, as the model file gives them.
#[derive(Debug, Clone, Copy)]
struct Scaling {
    lo: f64,
    hi: f64,
    mean: f64,
    /// `1 / std`.
    inv_std: f64,
    /// Whether some active term reads the feature. Only those count as leaving the
    /// envelope: a feature no term reads cannot move a prediction.
    used: bool,
}

impl Scaling {
    /// A raw feature clamped to the envelope and scaled; sets `outside` when a used
    /// feature was clamped. A value that is not a number stays one.
    #[inline(always)]
    fn scale(&self, raw: f64, outside: &mut bool) -> f64 {
        *outside |= self.used & ((raw < self.lo) | (raw > self.hi));
        let clamped = if raw < self.lo {
            self.lo
        } else if raw > self.hi {
            self.hi
        } else {
            raw
        };
        (clamped - self.mean) * self.inv_std
    }
}

/// What the step reads of a submodel besides its coefficients, worked out once.
#[derive(Debug, Clone)]
struct SubmodelUse {
    /// Per feature, its envelope and scaling.
    scaling: Vec<Scaling>,
    /// Per row, its terms in groups: first those summed every step, then one group per
    /// phase or ignition feature (a term has at most one, `Model::check`) with the terms
    /// that have it. Such a feature is 0 outside its phase, most steps, and then so are
    /// its terms: the group is skipped. Most of a thrust row's terms are gated (260 of
    /// the committed model's 430), so this skips most of the step's work; grouped, the
    /// check is once per feature, where a check per term in file order would mispredict
    /// its branch.
    groups: Vec<Vec<TermGroup>>,
}

impl SubmodelUse {
    fn of(s: &Submodel) -> Self {
        let dim = s.features.dim();
        let mut used = vec![false; dim];
        for t in s.rows.iter().flat_map(|r| &r.terms) {
            for &f in &t.factors {
                if let Some(u) = used.get_mut(f as usize) {
                    *u = true;
                }
            }
        }
        let roles = s.features.roles();
        let gate_of = |t: &ActiveTerm| {
            t.factors
                .iter()
                .map(|&f| f as usize)
                .find(|&f| f < dim && roles[f].phase)
        };
        let groups_of = |r: &OutputRow| {
            let mut groups = vec![TermGroup::default()];
            for t in &r.terms {
                let gate = gate_of(t);
                let g = match groups.iter().position(|g| g.gate == gate) {
                    Some(g) => g,
                    None => {
                        groups.push(TermGroup {
                            gate,
                            ..TermGroup::default()
                        });
                        groups.len() - 1
                    }
                };
                groups[g].coefs.push(t.coef);
                groups[g].factors.push(t.factors);
                groups[g].cubic |= t.factors[2] as usize != dim;
            }
            groups
        };
        let scaling = (0..dim)
            .map(|j| Scaling {
                lo: s.envelope_lo[j],
                hi: s.envelope_hi[j],
                mean: s.feature_mean[j],
                inv_std: 1.0 / s.feature_std[j],
                used: used[j],
            })
            .collect();
        Self {
            scaling,
            groups: s.rows.iter().map(groups_of).collect(),
        }
    }
}

/// Fills `x` with the scaled features of `engine` (every engine's, for a MIMO submodel)
/// and the constant 1.0 after them; true when a used feature was outside the envelope
/// and clamped. A feature that is not a number stays one: the prediction is then not
/// finite and [`guarded`] keeps the previous value.
fn gather(s: &Submodel, u: &SubmodelUse, h: &Ring, engine: usize, x: &mut [f64]) -> bool {
    let dim = s.features.dim();
    s.features.fill(h, engine, &mut x[..dim]);
    let mut outside = false;
    for (v, f) in x[..dim].iter_mut().zip(&u.scaling) {
        *v = f.scale(*v, &mut outside);
    }
    x[dim] = 1.0;
    outside
}

/// [`gather`] for the four engines of a per-engine submodel at once, into lanes: each
/// engine's features go straight into its lane, then each feature is clamped and scaled
/// in its four lanes together (the same operations on each value as [`gather`], so the
/// same bits; one engine at a time and then transposed, the step took longer).
fn gather_engines(s: &Submodel, u: &SubmodelUse, h: &Ring, lanes: &mut [Lanes]) -> bool {
    let dim = s.features.dim();
    for engine in 0..ENGINE_COUNT {
        let mut i = 0;
        s.features.fill_with(h, engine, |v| {
            lanes[i][engine] = v;
            i += 1;
        });
    }
    // Feature by feature, the four lanes clamped and scaled together, each operation
    // over the whole lane (the same operations on each value as `Scaling::scale`), so
    // they compile to vector instructions; value by value they compiled to branches.
    let mut outside = false;
    for (l, f) in lanes[..dim].iter_mut().zip(&u.scaling) {
        let raw = *l;
        let moved = raw.map(|r| (r < f.lo) | (r > f.hi));
        outside |= f.used & moved.iter().any(|&m| m);
        let above_lo = raw.map(|r| if r < f.lo { f.lo } else { r });
        let clamped = above_lo.map(|r| if r > f.hi { f.hi } else { r });
        *l = clamped.map(|c| (c - f.mean) * f.inv_std);
    }
    lanes[dim] = [1.0; ENGINE_COUNT];
    outside
}

/// Some of a row's terms (coefficients and factors, in file order), and the phase or
/// ignition feature they all have, if any.
#[derive(Debug, Clone, Default)]
struct TermGroup {
    gate: Option<usize>,
    coefs: Vec<f64>,
    factors: Vec<Term>,
    /// Some term has a third factor that is a feature, not the 1.0 pad. Otherwise the
    /// group's products skip the pad: `a * b * 1.0` is `a * b` bit for bit, and a
    /// degree-2 model (the committed one) then does a third fewer loads and products.
    cubic: bool,
}

/// A row's intercept plus its active terms, group by group (see [`SubmodelUse`]),
/// skipping a group whose phase or ignition feature is 0.
fn sum(row: &OutputRow, groups: &[TermGroup], x: &[f64]) -> f64 {
    let mut y = row.intercept;
    for g in groups {
        if g.gate.is_some_and(|f| x[f] == 0.0) {
            continue;
        }
        if g.cubic {
            for (c, t) in g.coefs.iter().zip(&g.factors) {
                y += c * eval_term(t, x);
            }
        } else {
            for (c, &[i, j, _]) in g.coefs.iter().zip(&g.factors) {
                y += c * (x[i as usize] * x[j as usize]);
            }
        }
    }
    y
}

/// Four engines' values of one feature, side by side.
type Lanes = [f64; ENGINE_COUNT];

/// [`sum`] for the four engines at once (a per-engine row, shared by the engines): the
/// same operations in the same order for each engine, side by side, so the compiler
/// turns them into vector instructions; one engine at a time, the step took about twice
/// as long. A group is skipped when its feature is 0 for every engine (for the others
/// its terms add exact zeros).
fn sum_engines(row: &OutputRow, groups: &[TermGroup], x: &[Lanes]) -> Lanes {
    let mut y = [row.intercept; ENGINE_COUNT];
    for g in groups {
        if g.gate.is_some_and(|f| x[f] == [0.0; ENGINE_COUNT]) {
            continue;
        }
        if g.cubic {
            for (c, t) in g.coefs.iter().zip(&g.factors) {
                let [a, b, d] = t.map(|f| &x[f as usize]);
                for e in 0..ENGINE_COUNT {
                    y[e] += c * (a[e] * b[e] * d[e]);
                }
            }
        } else {
            for (c, &[i, j, _]) in g.coefs.iter().zip(&g.factors) {
                let (a, b) = (&x[i as usize], &x[j as usize]);
                for e in 0..ENGINE_COUNT {
                    y[e] += c * (a[e] * b[e]);
                }
            }
        }
    }
    y
}

/// What the guards did on one step.
#[derive(Debug, Clone, Copy, Default)]
struct Guard {
    non_finite: bool,
    clamped: bool,
    bounded: bool,
}

/// The physical guards: thrust and gas pressure never negative, ejected masses never
/// falling, nothing above `upper` ([`Limits`]); a prediction that is not finite keeps
/// the previous value and sets `non_finite`, so the step is counted.
fn guarded(o: usize, v: f64, prev: f64, upper: f64, guard: &mut Guard) -> f64 {
    let v = if v.is_finite() {
        v
    } else {
        guard.non_finite = true;
        prev
    };
    let g = if o == STATE_MF || o == STATE_MO {
        v.max(prev)
    } else {
        v.max(0.0)
    };
    guard.clamped |= g != v;
    // `min` with an infinite bound is the value itself, bit for bit.
    let b = g.min(upper);
    guard.bounded |= b != g;
    b
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::propulsion::surrogate::features::{
        FeatureSpec, TrajectoryHistory, STATE_DIM, STATE_MF, STATE_MO, STATE_P,
    };
    use crate::propulsion::surrogate::library::Library;
    use crate::propulsion::surrogate::model::{ActiveTerm, OutputRow, Submodel, Target};

    pub(crate) use crate::propulsion::surrogate::valve::TEST_VALVE;

    /// Whether some engine of `p` is on and within its ignition window after its latest
    /// step (where the ignition features are not all zero).
    fn in_ignition_window(p: &Predictor) -> bool {
        let Some(v) = &p.valve else { return false };
        let Some(c) = v.ignition() else { return false };
        let on = p.ring.input(0);
        (0..ENGINE_COUNT)
            .any(|e| on[ENGINE_COUNT + e] > 0.5 && v.state.since_ignition_s[e] < c.window_s())
    }

    /// The valve track of `inputs` for `model` (empty when no submodel reads it).
    fn valves_of(model: &Model, inputs: &[InputVec]) -> (Vec<ValveState>, ValveState) {
        let dt_s = model.sample_time_ns as f64 * 1e-9;
        match model.submodels.iter().find_map(|s| s.features.valve) {
            Some(f) => (f.track(inputs, dt_s), f.rest()),
            None => (Vec::new(), ValveState::default()),
        }
    }

    /// A model with every library term active (pseudo-random coefficients), so every
    /// feature, phase indicator and term degree is exercised. `engine_degree` is the
    /// per-engine submodel's (3 exercises three-factor terms, 2 the two-factor sums the
    /// committed model takes). With `mimo_degree` 1 the MIMO submodel is linear.
    fn dense_model(engine_degree: usize, mimo_degree: usize) -> Model {
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
                engine_degree,
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

    /// Equal to rounding: the predictor sums a row's terms group by group (every-step
    /// terms, then each phase feature's), the oracle in file order.
    fn assert_close(got: &StateVec, want: &StateVec, what: &str) {
        for o in 0..STATE_DIM {
            let tol = 1e-12 * (1.0 + want[o].abs());
            assert!(
                (got[o] - want[o]).abs() <= tol,
                "{what} output {o}: {got:?} vs {want:?}"
            );
        }
    }

    /// The straightforward evaluation from a recorded trajectory: every feature by `fill`,
    /// every term in file order. The predictor, free-running on its own ring, agrees to
    /// rounding.
    #[test]
    fn free_run_equals_full_evaluation() {
        for (engine_degree, mimo_degree) in [(3, 1), (3, 2), (2, 1)] {
            free_run_equals_full_evaluation_of(&dense_model(engine_degree, mimo_degree));
        }
    }

    /// A term with two phase or ignition features would be evaluated in one's window
    /// with the other's in-phase constant: refused.
    #[test]
    fn a_term_with_two_phase_features_is_refused() {
        let mut m = dense_model(3, 1);
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
        crate::propulsion::surrogate::model_file::ModelFile::parse(
            crate::propulsion::surrogate::DEFAULT_MODEL_JSON,
        )
        .expect("the committed model parses")
        .model
    }

    /// A per-engine feature outside its training envelope is clamped and the step
    /// counted, whichever engine's lane it is in.
    #[test]
    fn a_per_engine_feature_outside_its_envelope_is_counted() {
        let mut model = committed_model();
        let s = &mut model.submodels[0];
        assert_eq!(s.features.layout, Layout::PerEngine);
        let t_r = s.feature_names.iter().position(|n| n == "T_r[t]").unwrap();
        s.envelope_hi[t_r] = 650.0;
        let mut p = Predictor::new(&model);
        let mut cmd = [600.0, 600.0, 600.0, 600.0, 1.0, 1.0, 1.0, 1.0];
        for _ in 0..50 {
            p.step(&cmd);
        }
        assert_eq!(p.out_of_envelope_steps(), 0);
        for engine in 0..ENGINE_COUNT {
            cmd[engine] = 700.0;
            p.step(&cmd);
            assert_eq!(
                p.out_of_envelope_steps(),
                engine as u64 + 1,
                "engine {engine}"
            );
            cmd[engine] = 600.0;
            p.step(&cmd);
        }
        assert_eq!(p.out_of_envelope_steps(), ENGINE_COUNT as u64);
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
    /// a wrong intercept or scale).
    #[test]
    fn one_step_from_history_equals_full_evaluation() {
        for mimo_degree in [1, 2] {
            let mut model = dense_model(3, mimo_degree);
            for r in &mut model.submodels[1].rows {
                for t in &mut r.terms {
                    t.coef *= 1e16;
                }
            }
            let (inputs, states) =
                crate::propulsion::surrogate::features::source_tests::switching_trajectory(60);
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
                assert_close(&got, &want, &format!("degree {mimo_degree} step {t}"));
            }
        }
    }

    fn free_run_equals_full_evaluation_of(model: &Model) {
        model.check().unwrap();
        let mut p = Predictor::new(model);
        let (cmds, _) =
            crate::propulsion::surrogate::features::source_tests::switching_trajectory(150);
        let mut inputs: Vec<InputVec> = Vec::new();
        let mut states: Vec<StateVec> = Vec::new();
        let mut clocked_steps = 0;
        for (t, cmd) in cmds.iter().enumerate() {
            let got = p.step(cmd);
            clocked_steps += usize::from(in_ignition_window(&p));
            let mut u = *cmd;
            for e in 0..ENGINE_COUNT {
                if u[ENGINE_COUNT + e] > 0.5 {
                    u[e] = u[e].clamp(320.0, 800.0);
                }
            }
            inputs.push(u);
            let want = full_step(model, &inputs, &states, t);
            assert_close(&got, &want, &format!("step {t}"));
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
