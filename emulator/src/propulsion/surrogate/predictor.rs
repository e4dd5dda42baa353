//! The free-running predictor of a fitted [`Model`]: what the runtime steps and what
//! cross-validation scores, so a model is chosen on exactly the behaviour it has in the
//! loop. A step reads like the model's definition: the step's commands join a history
//! ring, each submodel's features are filled from that ring by [`FeatureSpec::fill`]
//! (the function training builds its rows with), clamped to the training envelope and
//! scaled, the active terms are summed, and the physical guards are applied.
//!
//! The four engines of a per-engine submodel share one row of coefficients: they are
//! evaluated as the four lanes of one vector (`f64x4` of the `wide` crate, safe SIMD on
//! stable Rust), every lane doing exactly the operations, in the order, that evaluating
//! its engine alone does (no fused multiply-add, nothing reassociated), so the result
//! is that evaluation's bit for bit. The tests hold the engine-by-engine evaluation as
//! the reference and compare bits (`lanes_equal_engine_by_engine_*`).
//!
//! [`FeatureSpec::fill`]: super::features::FeatureSpec::fill

use super::features::{
    EngineLanes, History, InputVec, Layout, Source, StateVec, INPUT_DIM, STATE_DIM, STATE_MF,
    STATE_MO,
};
use super::model::{ActiveTerm, Model, OutputRow, Submodel, Term, MAX_FEATURES};
use super::valve::{valve_sum_of, ValveState, ValveTrack};
use oils_shared::ENGINE_COUNT;
use wide::{f64x4, CmpEq, CmpGt, CmpLt, CmpNe};

/// The last steps' inputs (as the model saw them), valve states and states. Allocated
/// once, overwritten in place. Each step is kept twice, at slots `s` and `s + depth`,
/// so that step `t - lag` (`t` the latest) is always at `head + depth - lag`: a read is
/// one subtraction, with no wrap around to test, and the reads of one lag across the
/// steps are a fixed offset from `head` ([`MimoUse`]).
#[derive(Debug, Clone)]
struct Ring {
    /// Steps kept (the deepest lag read, plus one).
    depth: usize,
    /// The latest step's lower slot, `0..depth`.
    head: usize,
    inputs: Vec<InputVec>,
    valves: Vec<ValveState>,
    /// [`valve_sum_of`] of each slot's input and valve state, worked out as the slot is
    /// written ([`Ring::set_valve`]): the `dT_vsum` features read each twice.
    valve_sums: Vec<f64>,
    states: Vec<StateVec>,
}

impl Ring {
    fn new(depth: usize) -> Self {
        let slots = 2 * depth;
        Self {
            depth,
            head: 0,
            inputs: vec![[0.0; INPUT_DIM]; slots],
            valves: vec![ValveState::default(); slots],
            valve_sums: vec![0.0; slots],
            states: vec![[0.0; super::features::STATE_DIM]; slots],
        }
    }

    fn depth(&self) -> usize {
        self.depth
    }

    /// The slot read for step `t - lag`.
    #[inline(always)]
    fn slot(&self, lag: usize) -> usize {
        debug_assert!(lag < self.depth, "lag {lag} beyond the ring");
        self.head + self.depth - lag
    }

    /// Both slots of step `t - lag`.
    fn copies(&self, lag: usize) -> [usize; 2] {
        let s = self.slot(lag);
        let low = if s >= self.depth { s - self.depth } else { s };
        [low, low + self.depth]
    }

    fn set_input(&mut self, lag: usize, input: InputVec) {
        for i in self.copies(lag) {
            self.inputs[i] = input;
        }
    }

    fn set_state(&mut self, lag: usize, state: StateVec) {
        for i in self.copies(lag) {
            self.states[i] = state;
        }
    }

    /// Sets step `t - lag`'s valve state (its input already set) and the sum it draws.
    fn set_valve(&mut self, lag: usize, valve: ValveState) {
        let [low, _] = self.copies(lag);
        let sum = valve_sum_of(&self.inputs[low], &valve.valve_n);
        for i in self.copies(lag) {
            self.valves[i] = valve;
            self.valve_sums[i] = sum;
        }
    }

    /// Makes room for a new latest step (the oldest is overwritten).
    fn advance(&mut self) {
        self.head = if self.head + 1 == self.depth {
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
    fn valve_sum(&self, lag: usize) -> f64 {
        self.valve_sums[self.slot(lag)]
    }
}

/// Slots of the feature buffers: every feature index, and the 1.0 pad after the
/// features, is below it (`Model::check` holds a submodel to [`MAX_FEATURES`]). A
/// factor's index masked with `SLOTS - 1` is then the index itself, and the compiler,
/// seeing the mask keep it inside the array, drops the bounds check of each factor
/// read: in the sums' inner loops, two reads a term, those checks were a fifth of the
/// instructions. Safe code throughout; the buffers are allocated once.
const SLOTS: usize = MAX_FEATURES + 1;
const _: () = assert!(SLOTS.is_power_of_two());

/// A factor's slot ([`SLOTS`]).
#[inline(always)]
fn slot(f: u16) -> usize {
    debug_assert!(usize::from(f) < SLOTS);
    usize::from(f) & (SLOTS - 1)
}

/// A MIMO submodel's scaled features, then the 1.0 pad ([`eval_term`](super::model::eval_term)).
type Features = [f64; SLOTS];
/// The same for the four engines of a per-engine submodel, as lanes, with the
/// features that were handed over as zeros and the groups a step sums.
#[derive(Debug, Clone)]
struct FeatureLanes {
    x: [f64x4; SLOTS],
    /// The features handed over as zeros by the latest gather; their lanes hold what a
    /// zero scales to, which the next gather then need not write again.
    zeros: ZeroRuns,
    /// The submodel ([`EngineUse::id`]) whose features `x` holds.
    filled_for: Option<usize>,
    /// The row's groups the latest gather left to sum ([`EngineUse::turned_off_below`]).
    active: GroupSet,
}

/// The features a gather was handed as zeros ([`EngineLanes::put_zeros`]): a phase no
/// engine is in, an ignition clock no engine is inside. A group gated by such a feature
/// is off in every lane, known without reading its lanes ([`sum_engines`]). A bit a
/// feature slot, so that the check is a load and a bit test.
#[derive(Debug, Clone, Copy)]
struct ZeroRuns {
    bits: [u64; SLOTS / 64],
}

impl ZeroRuns {
    const NONE: Self = Self {
        bits: [0; SLOTS / 64],
    };

    /// Features `start..start + n` were zeros (those beyond the slots are not noted:
    /// no feature is there).
    fn note(&mut self, start: usize, n: usize) {
        Self::words_of(start, n, |word, ones| self.bits[word] |= ones);
    }

    /// Whether every feature of `start..start + n` was handed over as zeros.
    fn covers_all(&self, start: usize, n: usize) -> bool {
        let mut all = true;
        Self::words_of(start, n, |word, ones| all &= self.bits[word] & ones == ones);
        all
    }

    /// The bits of `start..start + n` (within the slots), a word at a time.
    #[inline(always)]
    fn words_of(start: usize, n: usize, mut each: impl FnMut(usize, u64)) {
        let end = (start + n).min(SLOTS);
        let mut f = start;
        while f < end {
            let word = f / 64;
            let (lo, hi) = (f % 64, (end - word * 64).min(64));
            let ones = u64::MAX >> (64 - (hi - lo));
            each(word % (SLOTS / 64), ones << lo);
            f = word * 64 + hi;
        }
    }

    /// Whether feature `f` was handed over as zeros.
    #[cfg(test)]
    fn covers(&self, f: usize) -> bool {
        self.bits[(f / 64) % (SLOTS / 64)] & (1 << (f % 64)) != 0
    }
}

/// Words of a [`GroupSet`]: a row has at most one group per feature, and one more.
const GROUP_WORDS: usize = SLOTS / 64;

/// Some of a per-engine row's groups ([`EngineUse::groups`]), a bit each in the
/// groups' order, so that the sum visits the groups it needs in that order without a
/// test for each of the others.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GroupSet {
    bits: [u64; GROUP_WORDS],
}

impl GroupSet {
    const NONE: Self = Self {
        bits: [0; GROUP_WORDS],
    };

    /// Groups `0..n`.
    fn first(n: usize) -> Self {
        let mut s = Self::NONE;
        for g in 0..n.min(GROUP_WORDS * 64) {
            s.insert(g);
        }
        s
    }

    fn insert(&mut self, g: usize) {
        self.bits[(g / 64) % GROUP_WORDS] |= 1 << (g % 64);
    }

    /// Takes out the groups in one of `a` and `b` but not both (a run of zeros between
    /// two features, [`EngineUse::turned_off_below`]), looking at the first `words`
    /// words (the others hold no group).
    #[inline(always)]
    fn remove_between(&mut self, a: &Self, b: &Self, words: usize) {
        for w in 0..words.min(GROUP_WORDS) {
            self.bits[w] &= !(a.bits[w] ^ b.bits[w]);
        }
    }

    /// The groups in one but not both.
    fn symmetric_difference(&self, other: &Self) -> Self {
        Self {
            bits: std::array::from_fn(|w| self.bits[w] ^ other.bits[w]),
        }
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
    /// A MIMO submodel's scaled features, then the constant 1.0 that pads lower-degree
    /// terms ([`eval_term`](super::model::eval_term)).
    x: Box<Features>,
    /// The same for the four engines of a per-engine submodel, as lanes.
    lanes: Box<FeatureLanes>,
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
        let uses = subs
            .iter()
            .enumerate()
            .map(|(id, s)| SubmodelUse::of(s, id, depth))
            .collect();
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
            x: Box::new([0.0; SLOTS]),
            lanes: Box::new(FeatureLanes {
                x: [f64x4::ZERO; SLOTS],
                zeros: ZeroRuns::NONE,
                filled_for: None,
                active: GroupSet::NONE,
            }),
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
        self.ring
            .valve_sums
            .fill(valve_sum_of(&[0.0; INPUT_DIM], &rest.valve_n));
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
            self.ring.set_input(j, *h.input(j + 1));
            self.ring.set_state(j, *h.state(j + 1));
            if self.valve.is_some() {
                self.ring.set_valve(j, *h.valve(j + 1));
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
        self.step_by(input, predict_engines)
    }

    /// [`Predictor::step`] with the four engines of a per-engine submodel predicted by
    /// `engines` (their increments or values, and whether a used feature was clamped):
    /// [`predict_engines`] in the loop, the engine-by-engine reference in the tests.
    #[inline(always)]
    fn step_by(&mut self, input: &InputVec, mut engines: impl EnginePrediction) -> StateVec {
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
        self.ring.set_input(0, u);
        if let Some(v) = &mut self.valve {
            self.ring.set_valve(0, *v.advance(&u));
        }
        // The latest state's slots still hold the oldest step's: state lags start at 1,
        // and the prediction replaces it.
        let mut next = prev;
        for (s, u) in self.model.submodels.iter().zip(&self.subs) {
            match u {
                // The four engines share one row, each with its own features.
                SubmodelUse::PerEngine(u) => {
                    let (y, out) = engines(s, u, &self.ring, &mut self.lanes);
                    outside |= out;
                    for (engine, &o) in s.outputs.iter().enumerate() {
                        let v = s.target.apply(prev[o], y[engine]);
                        next[o] = guarded(o, v, prev[o], self.upper[o], &mut guard);
                    }
                }
                // One feature vector, one row per output.
                SubmodelUse::Mimo(u) => {
                    outside |= gather(s, u, &self.ring, &mut self.x);
                    for (r, &o) in s.outputs.iter().enumerate() {
                        let y = sum_split(&s.rows[r], &u.rows[r], &self.x);
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
        self.ring.set_state(0, next);
        next
    }
}

/// What predicts a per-engine submodel's four engines in [`Predictor::step_by`].
trait EnginePrediction:
    FnMut(&Submodel, &EngineUse, &Ring, &mut FeatureLanes) -> ([f64; ENGINE_COUNT], bool)
{
}
impl<F: FnMut(&Submodel, &EngineUse, &Ring, &mut FeatureLanes) -> ([f64; ENGINE_COUNT], bool)>
    EnginePrediction for F
{
}

/// The four engines of a per-engine submodel as lanes: their features gathered and
/// scaled ([`gather_engines`]) and the shared row summed ([`sum_engines`]).
#[inline(always)]
fn predict_engines(
    s: &Submodel,
    u: &EngineUse,
    h: &Ring,
    lanes: &mut FeatureLanes,
) -> ([f64; ENGINE_COUNT], bool) {
    let outside = gather_engines(s, u, h, lanes);
    (
        sum_engines(&s.rows[0], &u.groups, &lanes.x, &lanes.active).to_array(),
        outside,
    )
}

/// One feature's training envelope and scaling, as the model file gives them, with
/// `T` = `f64` for one value or `f64x4` for four engines' (each number in every lane).
#[derive(Debug, Clone, Copy)]
struct Scaling<T> {
    lo: T,
    hi: T,
    mean: T,
    /// `1 / std`.
    inv_std: T,
    /// Whether some active term reads the feature. Only those count as leaving the
    /// envelope: a feature no term reads cannot move a prediction.
    used: bool,
}

impl Scaling<f64> {
    fn of(s: &Submodel, j: usize, used: bool) -> Self {
        Scaling {
            lo: s.envelope_lo[j],
            hi: s.envelope_hi[j],
            mean: s.feature_mean[j],
            inv_std: 1.0 / s.feature_std[j],
            used,
        }
    }

    /// A raw feature clamped to the envelope and scaled; sets `outside` when a used
    /// feature was clamped. A value that is not a number stays one.
    #[inline(always)]
    fn scale(&self, raw: f64, outside: &mut bool) -> f64 {
        let clamped = if raw < self.lo {
            *outside |= self.used;
            self.lo
        } else if raw > self.hi {
            *outside |= self.used;
            self.hi
        } else {
            raw
        };
        (clamped - self.mean) * self.inv_std
    }

    /// The same numbers in four lanes, with what a 0.0 gives. A feature no term reads
    /// gets no envelope: its value is never read and its leaving the envelope never
    /// counts, so it need not send the step down the clamping path.
    fn lanes(&self) -> LaneScaling {
        let (lo, hi) = if self.used {
            (self.lo, self.hi)
        } else {
            (f64::NEG_INFINITY, f64::INFINITY)
        };
        let mut zero_outside = false;
        let zero = self.scale(0.0, &mut zero_outside);
        LaneScaling {
            scaling: Scaling {
                lo: f64x4::splat(lo),
                hi: f64x4::splat(hi),
                mean: f64x4::splat(self.mean),
                inv_std: f64x4::splat(self.inv_std),
                used: self.used,
            },
            zero: f64x4::splat(zero),
            zero_outside,
        }
    }
}

/// A per-engine feature's scaling in four lanes, and what a 0.0 in every lane gives.
#[derive(Debug, Clone, Copy)]
struct LaneScaling {
    scaling: Scaling<f64x4>,
    /// [`Scaling::scale`] of 0.0 (clamped if 0.0 is outside the envelope), each lane.
    zero: f64x4,
    /// 0.0 is outside the envelope of a used feature.
    zero_outside: bool,
}

impl Scaling<f64x4> {
    /// [`Scaling::scale`] of four engines' values: per lane the same comparisons pick
    /// the same value (the bound below, else the bound above, else the value), then the
    /// same two operations. Inside the envelope (nearly every step) the selection is
    /// skipped: it would pick the value itself.
    #[inline(always)]
    fn scale(&self, raw: f64x4, outside: &mut bool) -> f64x4 {
        let below = raw.cmp_lt(self.lo);
        let above = raw.cmp_gt(self.hi);
        let clamped = if (below | above).any() {
            *outside |= self.used;
            below.blend(self.lo, above.blend(self.hi, raw))
        } else {
            raw
        };
        (clamped - self.mean) * self.inv_std
    }
}

/// What the step reads of a submodel besides its coefficients, worked out once.
#[derive(Debug, Clone)]
enum SubmodelUse {
    Mimo(MimoUse),
    PerEngine(EngineUse),
}

/// A MIMO submodel: the features its terms read, and its rows.
///
/// Only the features some active term reads are gathered (the committed model's MIMO
/// terms read 28 of its 65). Nearly all are an input or a state at a lag: those are
/// read straight from the ring's numbers, at a fixed offset from the latest step's
/// ([`Ring`] keeps every step at `head + depth - lag`), the others through
/// [`Source::read`].
#[derive(Debug, Clone)]
struct MimoUse {
    input_reads: Vec<RingRead>,
    state_reads: Vec<RingRead>,
    other_reads: Vec<Read>,
    /// Per row, its terms in groups, split by degree ([`SplitGroup`]).
    rows: Vec<Vec<SplitGroup<f64>>>,
}

/// One feature a MIMO submodel gathers: its index, where it is read from, its scaling.
#[derive(Debug, Clone, Copy)]
struct Read {
    feature: usize,
    source: Source,
    scaling: Scaling<f64>,
}

/// A MIMO feature that is an input or a state component at a lag: its offset among
/// the ring's inputs (or states), as numbers, from the start of the slot `head`
/// (`(depth - lag) * width + component`), its index, its scaling.
#[derive(Debug, Clone, Copy)]
struct RingRead {
    at: usize,
    feature: u16,
    scaling: Scaling<f64>,
}

impl MimoUse {
    fn of(s: &Submodel, used: &[bool], depth: usize) -> Self {
        let mut u = MimoUse {
            input_reads: Vec::new(),
            state_reads: Vec::new(),
            other_reads: Vec::new(),
            rows: s
                .rows
                .iter()
                .map(|r| {
                    let split = |g: TermGroup| g.split(s.features.dim(), |c| c, |f| f);
                    groups_of(s, r).into_iter().map(split).collect()
                })
                .collect(),
        };
        let sources = s.features.sources();
        for (j, source) in sources.into_iter().enumerate().filter(|&(j, _)| used[j]) {
            let scaling = Scaling::of(s, j, true);
            let ring = |lag: usize, comp: usize, width: usize| RingRead {
                at: (depth - lag) * width + comp,
                feature: j as u16,
                scaling,
            };
            // A MIMO read is engine 0's: a component gets no engine offset.
            match source {
                Source::Input { lag, comp, .. } if lag < depth && comp < INPUT_DIM => {
                    u.input_reads.push(ring(lag, comp, INPUT_DIM));
                }
                Source::State { lag, comp, .. } if lag < depth && comp < STATE_DIM => {
                    u.state_reads.push(ring(lag, comp, STATE_DIM));
                }
                source => u.other_reads.push(Read {
                    feature: j,
                    source,
                    scaling,
                }),
            }
        }
        u
    }
}

/// A per-engine submodel: every feature's scaling and the shared row's terms in groups,
/// all with their numbers in four lanes.
#[derive(Debug, Clone)]
struct EngineUse {
    scaling: Vec<LaneScaling>,
    /// Terms in groups: first those summed every step, then one group per phase or
    /// ignition feature (a term has at most one, `Model::check`) with the terms that
    /// have it. Such a feature is 0 outside its phase, most steps, and then so are its
    /// terms: the group is skipped. Most of a thrust row's terms are gated (260 of the
    /// committed model's 430), so this skips most of the step's work; grouped, the
    /// check is once per feature, where a check per term in file order would
    /// mispredict its branch.
    groups: Vec<LaneGroup>,
    /// The submodel's index in the model.
    id: usize,
    /// All of `groups`.
    all_groups: GroupSet,
    /// The words of a [`GroupSet`] that hold `groups`.
    group_words: usize,
    /// Per feature `f` (and the pad's index, `dim`), the groups a zero at a feature
    /// below `f` turns off, as an exclusive or: a group has one gate, so a run of zeros
    /// `a..b` turns off `turned_off_below[b] ^ turned_off_below[a]`. A group is turned
    /// off by its gate's zero when that zero scales to 0.0 (an indicator, not centred,
    /// with 0.0 in its envelope): every lane of the gate is then 0.0.
    turned_off_below: Vec<GroupSet>,
    /// Per feature `f` (and `dim`), how many features below `f` are used and have 0.0
    /// outside their envelope: a run of zeros `a..b` leaves the envelope when the
    /// counts at `a` and `b` differ.
    zero_outside_below: Vec<u16>,
}

/// Per feature of a submodel, whether some active term reads it.
fn used_features(s: &Submodel) -> Vec<bool> {
    let mut used = vec![false; s.features.dim()];
    for t in s.rows.iter().flat_map(|r| &r.terms) {
        for &f in &t.factors {
            if let Some(u) = used.get_mut(f as usize) {
                *u = true;
            }
        }
    }
    used
}

/// A row's terms in groups ([`TermGroup`]): the every-step group first, then one per
/// phase or ignition feature, each in file order.
fn groups_of(s: &Submodel, r: &OutputRow) -> Vec<TermGroup> {
    let dim = s.features.dim();
    let roles = s.features.roles();
    let gate_of = |t: &ActiveTerm| {
        t.factors
            .iter()
            .map(|&f| f as usize)
            .find(|&f| f < dim && roles[f].phase)
    };
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
    }
    groups
}

impl SubmodelUse {
    /// What the step reads of `s`, submodel `id` of its model, in a ring of `depth`
    /// steps.
    fn of(s: &Submodel, id: usize, depth: usize) -> Self {
        let used = used_features(s);
        match s.features.layout {
            Layout::Mimo => Self::Mimo(MimoUse::of(s, &used, depth)),
            Layout::PerEngine => Self::PerEngine(EngineUse::of(s, id, &used)),
        }
    }
}

impl EngineUse {
    fn of(s: &Submodel, id: usize, used: &[bool]) -> Self {
        let dim = s.features.dim();
        let scaling: Vec<_> = (0..dim)
            .map(|j| Scaling::of(s, j, used[j]).lanes())
            .collect();
        let groups: Vec<_> = groups_of(s, &s.rows[0])
            .into_iter()
            .map(|g| g.lanes(dim))
            .collect();
        // The groups each feature's zero turns off.
        let mut turned_off_by = vec![GroupSet::NONE; dim];
        for (k, g) in groups.iter().enumerate() {
            let gate = g.gate.and_then(|f| Some((f, scaling.get(f)?)));
            if let Some((f, gate)) = gate {
                if gate.zero.cmp_eq(f64x4::ZERO).all() {
                    turned_off_by[f].insert(k);
                }
            }
        }
        let mut turned_off_below = vec![GroupSet::NONE];
        let mut zero_outside_below = vec![0u16];
        for (off, f) in turned_off_by.iter().zip(&scaling) {
            let below = turned_off_below[turned_off_below.len() - 1];
            turned_off_below.push(below.symmetric_difference(off));
            let count = zero_outside_below[zero_outside_below.len() - 1];
            zero_outside_below.push(count + u16::from(f.zero_outside));
        }
        EngineUse {
            scaling,
            all_groups: GroupSet::first(groups.len()),
            group_words: groups.len().div_ceil(64),
            groups,
            id,
            turned_off_below,
            zero_outside_below,
        }
    }
}

/// Fills `x` with the scaled features of a MIMO submodel that its terms read (the
/// others are never read) and the constant 1.0 after them; true when one was outside
/// the envelope and clamped. A feature that is not a number stays one: the prediction
/// is then not finite and [`guarded`] keeps the previous value.
fn gather(s: &Submodel, u: &MimoUse, h: &Ring, x: &mut Features) -> bool {
    let mut outside = false;
    let mut from_ring = |numbers: &[f64], width: usize, reads: &[RingRead]| {
        let head = h.head * width;
        for r in reads {
            let raw = numbers.get(head + r.at).copied().unwrap_or(f64::NAN);
            x[slot(r.feature)] = r.scaling.scale(raw, &mut outside);
        }
    };
    from_ring(bytemuck::cast_slice(&h.inputs), INPUT_DIM, &u.input_reads);
    from_ring(bytemuck::cast_slice(&h.states), STATE_DIM, &u.state_reads);
    for r in &u.other_reads {
        x[r.feature] = r.scaling.scale(r.source.read(h, 0), &mut outside);
    }
    x[s.features.dim()] = 1.0;
    outside
}

/// The features of the four engines of a per-engine submodel, as lanes: each feature
/// is read for the four engines at once ([`FeatureSpec::fill_engines`]) and scaled in
/// its four lanes together, into `lanes`, with the constant 1.0 after them; true when a
/// used feature was outside the envelope.
///
/// Nearly every step every feature is inside its envelope, where clamping picks the
/// value itself: the features are scaled without it ([`Unclamped`]) while the lanes
/// that leave the envelope are noted, and only when some did is the step gathered
/// again with the clamping ([`Clamped`]), which is then what the lanes hold.
///
/// [`FeatureSpec::fill_engines`]: super::features::FeatureSpec::fill_engines
fn gather_engines(s: &Submodel, u: &EngineUse, h: &Ring, lanes: &mut FeatureLanes) -> bool {
    let dim = s.features.dim();
    // The runs of zeros the latest gather of this submodel left in place.
    let kept = match lanes.filled_for {
        Some(id) if id == u.id => lanes.zeros,
        _ => ZeroRuns::NONE,
    };
    lanes.filled_for = Some(u.id);
    lanes.zeros = ZeroRuns::NONE;
    lanes.active = u.all_groups;
    let mut fast = Unclamped {
        lanes: &mut lanes.x,
        zeros: &mut lanes.zeros,
        kept,
        active: &mut lanes.active,
        u,
        i: 0,
        leaving: f64x4::ZERO,
        zero_outside: false,
    };
    s.features.fill_engines(h, &mut fast);
    debug_assert_eq!(fast.i, dim);
    let mut outside = fast.zero_outside;
    if fast.leaving.any() {
        let mut clamped = Clamped {
            lanes: fast.lanes,
            scaling: &u.scaling,
            i: 0,
            outside: false,
        };
        s.features.fill_engines(h, &mut clamped);
        outside |= clamped.outside;
    }
    lanes.x[dim] = f64x4::ONE;
    outside
}

/// Scales features into their lanes without clamping, noting which lanes were outside
/// the envelope, for [`gather_engines`].
struct Unclamped<'a> {
    lanes: &'a mut [f64x4; SLOTS],
    zeros: &'a mut ZeroRuns,
    /// The runs of zeros already in `lanes`.
    kept: ZeroRuns,
    active: &'a mut GroupSet,
    u: &'a EngineUse,
    /// The next feature.
    i: usize,
    /// Lanes that may have left the envelope: held to it, the value changed (or it is
    /// not a number, which some instruction sets flag). Only a step with one is
    /// gathered again, with the clamping, which decides; a lane not flagged is inside,
    /// where the clamping would have given the value itself.
    leaving: f64x4,
    /// A run of zeros was outside the envelope of a used feature (its lanes hold the
    /// clamped value).
    zero_outside: bool,
}

impl EngineLanes for Unclamped<'_> {
    #[inline(always)]
    fn put(&mut self, raw: f64x4) {
        let f = &self.u.scaling[self.i].scaling;
        // One compare where a test below and a test above took two.
        self.leaving |= raw.fast_max(f.lo).fast_min(f.hi).cmp_ne(raw);
        self.lanes[self.i] = (raw - f.mean) * f.inv_std;
        self.i += 1;
    }

    /// A run of zeros: its lanes get what a zero scales to, unless the latest gather
    /// left them so (most steps: a phase no engine is in stays so), and the groups
    /// they turn off are taken out of the step's sum.
    #[inline(always)]
    fn put_zeros(&mut self, n: usize) {
        let (start, end) = (self.i, self.i + n);
        if !self.kept.covers_all(start, n) {
            for (l, f) in self.lanes[start..end]
                .iter_mut()
                .zip(&self.u.scaling[start..end])
            {
                *l = f.zero;
            }
        }
        self.zeros.note(start, n);
        let below = &self.u.turned_off_below;
        self.active
            .remove_between(&below[start], &below[end], self.u.group_words);
        let outside = &self.u.zero_outside_below;
        self.zero_outside |= outside[end] != outside[start];
        self.i = end;
    }
}

/// Clamps and scales features into their lanes ([`Scaling::scale`]), for
/// [`gather_engines`] when some lane left the envelope.
struct Clamped<'a> {
    lanes: &'a mut [f64x4; SLOTS],
    scaling: &'a [LaneScaling],
    i: usize,
    outside: bool,
}

impl EngineLanes for Clamped<'_> {
    fn put(&mut self, raw: f64x4) {
        self.lanes[self.i] = self.scaling[self.i].scaling.scale(raw, &mut self.outside);
        self.i += 1;
    }
}

/// Some of a row's terms (coefficients and factors, in file order), and the phase or
/// ignition feature they all have, if any.
#[derive(Debug, Clone, Default)]
struct TermGroup {
    gate: Option<usize>,
    coefs: Vec<f64>,
    factors: Vec<Term>,
}

impl TermGroup {
    /// The group with its terms by degree ([`SplitGroup`]): coefficients as `coef`
    /// makes them, factors as `at` places them; `dim` is the pad's index.
    fn split<C>(
        self,
        dim: usize,
        coef: impl Fn(f64) -> C,
        at: impl Fn(u16) -> u16,
    ) -> SplitGroup<C> {
        let pad = dim as u16;
        // 1, 2 or 3: the factors before the trailing pads.
        let degree = |t: &Term| match t {
            [_, j, k] if *j == pad && *k == pad => 1,
            [_, _, k] if *k == pad => 2,
            _ => 3,
        };
        let mut g = SplitGroup {
            gate: self.gate,
            linear: Vec::new(),
            quadratic: Vec::new(),
            cubic: Vec::new(),
        };
        let in_degree_order = self
            .factors
            .windows(2)
            .all(|w| degree(&w[0]) <= degree(&w[1]));
        for (&c, t) in self.coefs.iter().zip(&self.factors) {
            let (c, d, t) = (coef(c), degree(t), t.map(&at));
            match (in_degree_order, d) {
                (true, 1) => g.linear.push((c, t[0])),
                (true, 2) => g.quadratic.push((c, [t[0], t[1]])),
                _ => g.cubic.push((c, t)),
            }
        }
        g
    }

    /// The group for four lanes ([`LaneGroup`]).
    fn lanes(self, dim: usize) -> LaneGroup {
        self.split(dim, f64x4::splat, lane_offset)
    }
}

/// Where feature `f`'s four lanes start in the feature lanes read as one run of
/// numbers ([`sum_engines`]).
fn lane_offset(f: u16) -> u16 {
    debug_assert!(usize::from(f) < SLOTS);
    f.wrapping_mul(4)
}

/// A [`TermGroup`] with its terms by degree, each coefficient (`C`: `f64`, or
/// `f64x4` for a per-engine row, the coefficient in every lane) beside its factors.
/// The 1.0 pad makes `a * 1.0` = `a` and `a * b * 1.0` = `a * b` bit for bit, so a term
/// of one or two factors skips its pads; kept in file order, since the library lists
/// terms by degree (a group whose terms are not in that order keeps them all, pads and
/// all, in `cubic`).
#[derive(Debug, Clone)]
struct SplitGroup<C> {
    gate: Option<usize>,
    linear: Vec<(C, u16)>,
    quadratic: Vec<(C, [u16; 2])>,
    cubic: Vec<(C, Term)>,
}

/// A per-engine row's group for four lanes, its factors as [`lane_offset`]s.
type LaneGroup = SplitGroup<f64x4>;

/// [`sum`] of a MIMO row with its groups split by degree: the same operations on the
/// same numbers, less the products with the 1.0 pad.
fn sum_split(row: &OutputRow, groups: &[SplitGroup<f64>], x: &Features) -> f64 {
    let at = |f: u16| x[slot(f)];
    let mut y = row.intercept;
    for g in groups {
        if g.gate.is_some_and(|f| x[f] == 0.0) {
            continue;
        }
        for &(c, i) in &g.linear {
            y += c * at(i);
        }
        for &(c, [i, j]) in &g.quadratic {
            y += c * (at(i) * at(j));
        }
        for &(c, [i, j, k]) in &g.cubic {
            y += c * (at(i) * at(j) * at(k));
        }
    }
    y
}

/// A row's intercept plus its active terms, group by group (see [`EngineUse`]),
/// skipping a group whose phase or ignition feature is 0: the model's definition, which
/// the tests hold [`sum_engines`] to, engine by engine, bit for bit.
#[cfg(test)]
fn sum(row: &OutputRow, groups: &[TermGroup], x: &Features) -> f64 {
    use super::model::eval_term;
    let mut y = row.intercept;
    for g in groups {
        if g.gate.is_some_and(|f| x[f] == 0.0) {
            continue;
        }
        for (c, t) in g.coefs.iter().zip(&g.factors) {
            y += c * eval_term(t, x);
        }
    }
    y
}

/// [`sum`] for the four engines of a per-engine row at once, each engine a lane: the
/// same operations in the same order as [`sum`] of that engine alone. It visits the
/// `active` groups, in order: the others were turned off by a run of zeros, their
/// feature 0 in every lane ([`EngineUse::turned_off_below`]). A group is skipped when
/// its feature is 0 for every engine; when it is 0 for some, those lanes get back the
/// sum from before the group, as [`sum`] skipping it leaves it (adding its terms would
/// add zeros, or not a number for a feature that is not one).
///
/// Not in line: inside the whole step the compiler ran out of registers and reloaded
/// the lanes' address from the stack for every term.
#[inline(never)]
fn sum_engines(
    row: &OutputRow,
    groups: &[LaneGroup],
    x: &[f64x4; SLOTS],
    active: &GroupSet,
) -> f64x4 {
    // The lanes as one run of numbers, read at a factor's lane offset (four times its
    // index, [`lane_offset`]): an x86 address scales an index by at most 8, so an
    // index of 32-byte lanes costs a shift a read, an offset in 8-byte numbers none.
    // Masked to the buffer (the offsets are multiples of 4 below it), the compiler
    // sees the four reads inside and checks no bound.
    let flat: &[f64; 4 * SLOTS] = bytemuck::cast_ref(x);
    let at = |p: u16| {
        let p = usize::from(p) & (4 * SLOTS - 4);
        f64x4::new([flat[p], flat[p + 1], flat[p + 2], flat[p + 3]])
    };
    let mut y = f64x4::splat(row.intercept);
    let words = groups.len().div_ceil(64).min(GROUP_WORDS);
    for (w, &word) in active.bits[..words].iter().enumerate() {
        // The word's groups, lowest first.
        let mut left = word;
        while left != 0 {
            let Some(g) = groups.get(w * 64 + left.trailing_zeros() as usize) else {
                break;
            };
            left &= left - 1;
            let off = match g.gate {
                Some(f) => x[f].cmp_eq(f64x4::ZERO),
                None => f64x4::ZERO,
            };
            if off.all() {
                continue;
            }
            let before = y;
            for &(c, i) in &g.linear {
                y += c * at(i);
            }
            // Four terms a turn (the same additions in the same order): the loop's own
            // count, compare and branch are then a quarter of a term's, of some 13.5
            // instructions.
            let mut fours = g.quadratic.chunks_exact(4);
            for four in &mut fours {
                for &(c, [i, j]) in four {
                    y += c * (at(i) * at(j));
                }
            }
            for &(c, [i, j]) in fours.remainder() {
                y += c * (at(i) * at(j));
            }
            for &(c, [i, j, k]) in &g.cubic {
                y += c * (at(i) * at(j) * at(k));
            }
            if off.any() {
                y = off.blend(before, y);
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

    /// The reference for the lanes: each engine of a per-engine submodel on its own, in
    /// scalar code, as the predictor evaluated them before they were lanes: its features
    /// by `fill`, clamped and scaled one by one ([`Scaling::scale`]), its row summed by
    /// [`sum`] from the model's own terms.
    fn engine_by_engine(
        s: &Submodel,
        _: &EngineUse,
        h: &Ring,
        _: &mut FeatureLanes,
    ) -> ([f64; ENGINE_COUNT], bool) {
        let dim = s.features.dim();
        let used = used_features(s);
        let scaling: Vec<_> = (0..dim).map(|j| Scaling::of(s, j, used[j])).collect();
        let groups = groups_of(s, &s.rows[0]);
        let mut x = Box::new([0.0; SLOTS]);
        let mut outside = false;
        let y = std::array::from_fn(|engine| {
            s.features.fill(h, engine, &mut x[..dim]);
            for (v, f) in x[..dim].iter_mut().zip(&scaling) {
                *v = f.scale(*v, &mut outside);
            }
            x[dim] = 1.0;
            sum(&s.rows[0], &groups, &x)
        });
        (y, outside)
    }

    /// Steps the lanes and the reference side by side through `cmds` and compares every
    /// state bit for bit, and the guards' counts.
    fn assert_lanes_equal_engine_by_engine(model: &Model, limits: Limits, cmds: &[InputVec]) {
        let mut lanes = Predictor::new(model);
        lanes.set_limits(limits);
        let mut reference = lanes.clone();
        for (t, cmd) in cmds.iter().enumerate() {
            let got = lanes.step(cmd);
            let want = reference.step_by(cmd, engine_by_engine);
            assert_eq!(
                got.map(f64::to_bits),
                want.map(f64::to_bits),
                "step {t} command {cmd:?}: {got:?} vs {want:?}"
            );
            // The ring's valve sums are the ones the features would work out.
            for lag in 0..lanes.ring.depth() {
                let r = &lanes.ring;
                let want = valve_sum_of(r.input(lag), &r.valve(lag).valve_n);
                assert_eq!(r.valve_sum(lag).to_bits(), want.to_bits(), "lag {lag}");
            }
        }
        assert_eq!(
            lanes.out_of_envelope_steps(),
            reference.out_of_envelope_steps()
        );
        assert_eq!(
            format!("{:?}", lanes.guards()),
            format!("{:?}", reference.guards())
        );
    }

    /// The models the lanes are checked on: the committed one, the same with a narrow
    /// envelope (features clamped in some lanes and not others), and dense ones with
    /// every library term (three-factor terms, every gate).
    fn lane_models() -> Vec<Model> {
        let mut narrow = committed_model();
        for s in &mut narrow.submodels {
            for (lo, hi) in s.envelope_lo.iter_mut().zip(&mut s.envelope_hi) {
                let mid = 0.5 * (*lo + *hi);
                let half = 0.3 * (*hi - *lo);
                (*lo, *hi) = (mid - half, mid + half);
            }
        }
        // Phase features whose envelope leaves out 0.0: every step outside a phase
        // (handed over as a run of zeros) is outside the envelope, and nothing else is.
        let mut phases_above_zero = committed_model();
        for s in &mut phases_above_zero.submodels {
            for (j, role) in s.features.roles().iter().enumerate() {
                if role.phase {
                    s.envelope_lo[j] = 0.5;
                }
            }
        }
        vec![
            committed_model(),
            narrow,
            phases_above_zero,
            dense_model(3, 1),
            dense_model(2, 2),
        ]
    }

    /// A command of one engine: mostly within the range, sometimes outside it, now and
    /// then not a number or infinite.
    fn command_n() -> impl proptest::strategy::Strategy<Value = f64> {
        use proptest::prelude::*;
        prop_oneof![
            20 => 300.0..820.0f64,
            2 => -100.0..2000.0f64,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(0.0),
        ]
    }

    /// Random commands, engines switching on and off at random (each step keeps the
    /// previous switch with some odds, so phases last a while).
    fn command_sequences() -> impl proptest::strategy::Strategy<Value = Vec<InputVec>> {
        use proptest::prelude::*;
        let step = (
            proptest::array::uniform4(command_n()),
            proptest::array::uniform4(0u8..8),
        );
        proptest::collection::vec(step, 20..250).prop_map(|steps| {
            let mut on = [true; ENGINE_COUNT];
            steps
                .into_iter()
                .map(|(cmd, flip)| {
                    let mut u = [0.0; INPUT_DIM];
                    for e in 0..ENGINE_COUNT {
                        on[e] ^= flip[e] == 0;
                        u[e] = if on[e] { cmd[e] } else { 0.0 };
                        u[ENGINE_COUNT + e] = f64::from(u8::from(on[e]));
                    }
                    u
                })
                .collect()
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config::with_cases(24))]
        /// The lanes give the engine-by-engine reference's bits on random commands,
        /// including ones outside the envelope, not numbers and infinite.
        #[test]
        fn lanes_equal_engine_by_engine_on_random_commands(cmds in command_sequences()) {
            for model in lane_models() {
                assert_lanes_equal_engine_by_engine(&model, Limits::of_rating(800.0), &cmds);
            }
        }
    }

    /// An engine whose phase feature is 0 skips the phase's terms even when another
    /// engine's is not, as it does on its own: its lane keeps the sum from before the
    /// group, even where the group's terms would not add zero (a feature that is not a
    /// number, read only by the phase's terms).
    #[test]
    fn an_engine_out_of_a_phase_skips_its_terms_while_another_is_in_it() {
        // Features: 0 a phase indicator, 1 a partner; 2 the 1.0 pad.
        let row = OutputRow {
            output: "T_o".into(),
            intercept: 1.5,
            terms: vec![ActiveTerm {
                name: "stop0[t]*T_r[t]".into(),
                factors: [0, 1, 2],
                coef: 0.25,
            }],
        };
        let scalar = vec![
            TermGroup::default(),
            TermGroup {
                gate: Some(0),
                coefs: vec![0.25],
                factors: vec![[0, 1, 2]],
            },
        ];
        let lanes: Vec<_> = scalar.iter().cloned().map(|g| g.lanes(2)).collect();
        let gate = [0.0, 1.0, 1.0, 0.0];
        let partner = [f64::NAN, 2.0, f64::NAN, 4.0];
        let mut x = Box::new([f64x4::ZERO; SLOTS]);
        x[..3].copy_from_slice(&[f64x4::new(gate), f64x4::new(partner), f64x4::ONE]);
        let got = sum_engines(&row, &lanes, &x, &GroupSet::first(lanes.len())).to_array();
        for e in 0..ENGINE_COUNT {
            let mut x = Box::new([0.0; SLOTS]);
            x[..3].copy_from_slice(&[gate[e], partner[e], 1.0]);
            let want = sum(&row, &scalar, &x);
            assert_eq!(got[e].to_bits(), want.to_bits(), "engine {e}: {got:?}");
        }
        assert_eq!(got[0], 1.5);
        assert!(got[2].is_nan());
    }

    /// A run of zeros marks exactly its features, across word boundaries too.
    #[test]
    fn zero_runs_cover_exactly_their_features() {
        for (start, n) in [
            (0, 1),
            (3, 10),
            (60, 10),
            (63, 1),
            (64, 64),
            (100, 200),
            (1000, 23),
            (1020, 10),
        ] {
            let mut z = ZeroRuns::NONE;
            z.note(start, n);
            z.note(2, 0);
            for f in 0..SLOTS {
                assert_eq!(
                    z.covers(f),
                    (start..start + n).contains(&f),
                    "{start}+{n}: {f}"
                );
            }
            let end = (start + n).min(SLOTS);
            assert!(z.covers_all(start, n) && z.covers_all(start + 1, n - 1));
            assert!(z.covers_all(SLOTS, 5), "nothing to cover past the slots");
            if start > 0 {
                assert!(!z.covers_all(start - 1, n));
            }
            if end < SLOTS {
                assert!(!z.covers_all(start, n + 1));
            }
        }
    }

    /// A run of zeros turns off exactly the groups gated by one of its features whose
    /// zero scales to 0.0, and counts a zero outside an envelope exactly when one of its
    /// features has it.
    #[test]
    fn a_run_of_zeros_turns_off_the_groups_its_features_gate() {
        for model in lane_models() {
            let (id, s) = model
                .submodels
                .iter()
                .enumerate()
                .find(|(_, s)| s.features.layout == Layout::PerEngine)
                .unwrap();
            let u = EngineUse::of(s, id, &used_features(s));
            let dim = s.features.dim();
            let runs = [
                (0, 1),
                (0, dim),
                (dim / 2, dim - dim / 2),
                (3, 7),
                (dim - 1, 1),
            ];
            for (a, n) in runs {
                let b = a + n;
                let mut active = u.all_groups;
                active.remove_between(
                    &u.turned_off_below[a],
                    &u.turned_off_below[b],
                    u.group_words,
                );
                for (k, g) in u.groups.iter().enumerate() {
                    let off = g.gate.is_some_and(|f| {
                        (a..b).contains(&f) && u.scaling[f].zero.cmp_eq(f64x4::ZERO).all()
                    });
                    let on = active.bits[k / 64] & (1 << (k % 64)) != 0;
                    assert_eq!(on, !off, "group {k} gated by {:?}, run {a}..{b}", g.gate);
                }
                let outside = (a..b).any(|f| u.scaling[f].zero_outside);
                assert_eq!(u.zero_outside_below[b] != u.zero_outside_below[a], outside);
            }
        }
    }

    /// The same over the switching trajectory and a long steady run (the ignition
    /// window, the stop phases and the running engine are all passed through).
    /// The feature buffers' fixed slots ([`SLOTS`]) hold the largest feature vector the
    /// model checks allow (every option on, every length at its limit), with room for
    /// the 1.0 pad: raising a limit past them fails here (`Model::check` refuses a wider
    /// submodel, a backstop the limits keep out of reach).
    #[test]
    fn largest_feature_vectors_fit_the_buffers() {
        use crate::propulsion::surrogate::valve::TEST_IGNITION;
        let valve = super::super::valve::ValveFilter {
            ignition: Some(super::super::valve::IgnitionClock {
                knots: 64,
                ..TEST_IGNITION
            }),
            ..TEST_VALVE
        };
        let widest = [
            FeatureSpec {
                mass_features: true,
                start_steps: 64,
                stop_steps: 64,
                command_sum: true,
                valve: Some(valve),
                valve_sum: true,
                ..FeatureSpec::per_engine(64)
            },
            FeatureSpec::paper(64),
        ];
        for spec in widest {
            assert!(
                spec.dim() <= MAX_FEATURES,
                "{:?}: {} features",
                spec.layout,
                spec.dim()
            );
        }
    }

    #[test]
    fn lanes_equal_engine_by_engine_on_switching_and_steady_runs() {
        let (mut cmds, _) =
            crate::propulsion::surrogate::features::source_tests::switching_trajectory(400);
        cmds.extend((0..600).map(|k| {
            let c = 400.0 + (k % 300) as f64;
            [c, c + 10.0, 800.0 - c * 0.5, 600.0, 1.0, 1.0, 1.0, 1.0]
        }));
        for model in lane_models() {
            assert_lanes_equal_engine_by_engine(&model, Limits::NONE, &cmds);
            assert_lanes_equal_engine_by_engine(&model, Limits::of_rating(800.0), &cmds);
        }
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
