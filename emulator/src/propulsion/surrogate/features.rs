//! History features of the seed paper, Section V, built from a window of past inputs and
//! states. One code path serves training (over a recorded trajectory) and the runtime
//! (over a ring buffer), so the model sees in the loop exactly what it was fitted on.
//!
//! Causal reading (the paper is loose here; see `docs/surrogate.md`): the model predicts
//! the state at the end of step `t` from the command held over step `t` and what is known
//! at its start. So commands and switches appear at `t` and earlier, while every state
//! variable (thrust, gas pressure, ejected masses, lambda) appears at `t-1` and earlier.
//! The paper's "current" gas pressure `P` is therefore `P[t-1]` and its history `P_h` is
//! `P[t-2] .. P[t-n-1]`, which keeps the dimension at the paper's `11n+10`.

use oils_shared::ENGINE_COUNT;

use super::valve::{valve_sum_of, IgnitionClock, ValveFilter, ValveState};
use serde::{Deserialize, Serialize};
use wide::{f64x4, CmpEq};

/// Inputs per step: four thrust commands (N), then four on/off switches (0 or 1).
pub const INPUT_DIM: usize = 2 * ENGINE_COUNT;
/// States per step: four thrusts (N), gas pressure (Pa), ejected fuel and oxidiser (kg).
pub const STATE_DIM: usize = ENGINE_COUNT + 3;
/// Index of the gas pressure in a state vector.
pub const STATE_P: usize = ENGINE_COUNT;
/// Index of the ejected fuel mass in a state vector.
pub const STATE_MF: usize = ENGINE_COUNT + 1;
/// Index of the ejected oxidiser mass in a state vector.
pub const STATE_MO: usize = ENGINE_COUNT + 2;

/// One step's inputs, see [`INPUT_DIM`].
pub type InputVec = [f64; INPUT_DIM];
/// One step's state, see [`STATE_DIM`].
pub type StateVec = [f64; STATE_DIM];

/// Names of the state entries, as used in term names and dataset columns.
pub const STATE_NAMES: [&str; STATE_DIM] = ["T_o1", "T_o2", "T_o3", "T_o4", "P", "m_f", "m_o"];

/// Ejected mass below which lambda = 1/(m_f+m_o) is held constant, kg: at the start
/// nothing has been ejected and the paper's lambda would be infinite.
pub const LAMBDA_MASS_FLOOR_KG: f64 = 1.0;

/// The paper's lambda, guarded near zero ejected mass.
pub fn lambda_of(ejected_fuel_kg: f64, ejected_ox_kg: f64) -> f64 {
    1.0 / (ejected_fuel_kg + ejected_ox_kg).max(LAMBDA_MASS_FLOOR_KG)
}

/// How features are laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Layout {
    /// The paper's MIMO vector: all four engines in one feature vector of `11n+10`.
    Mimo,
    /// One engine's view: its own command, switch and thrust history plus the shared gas
    /// pressure (and masses); one model with shared coefficients serves all four engines.
    PerEngine,
}

/// Which features, for which history length.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeatureSpec {
    /// Layout of the vector.
    pub layout: Layout,
    /// History length `n` (>= 1).
    pub history: usize,
    /// Include the ejected-mass histories and lambda (the paper does).
    pub mass_features: bool,
    /// Beyond the paper, per-engine layout only: start-phase indicators `start0..start{K-1}`
    /// ("this engine switched on k steps ago"), so the delayed, dome-filling cold start is
    /// a learned lookup rather than something a polynomial of 10 ms histories must
    /// reproduce. 0 = none (the paper's features).
    pub start_steps: usize,
    /// Beyond the paper, per-engine layout only: stop-phase indicators `stop0..stop{K-1}`
    /// ("this engine switched off k steps ago") for the tail-off (dome dribble). 0 = none.
    pub stop_steps: usize,
    /// Highest degree of library terms with a phase indicator (0: the library degree).
    pub phase_degree: usize,
    /// Beyond the paper, per-engine layout only: the sum of the four engines' commands
    /// over the step, `T_rsum[t]` (off engines count 0). The engines share feed lines and
    /// manifolds, so how fast one engine's dome fills at a start depends on what the
    /// others draw; a per-engine model cannot see that otherwise.
    pub command_sum: bool,
    /// Beyond the paper, per-engine layout only: the command passed through a model of
    /// the throttle valve's actuator (lag, rate limit, backlash; [`ValveFilter`]),
    /// `T_v[t]` and its history `T_v[t-1..t-n]`. hifi's thrust follows its valve, not
    /// the command: small slow changes with the 15 ms lag, large steps at the rate limit,
    /// reversals only once the backlash is taken up, and a polynomial of command
    /// histories cannot be both at once. `None`: no such features (the paper's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valve: Option<ValveFilter>,
    /// Beyond the paper, per-engine layout with a valve filter only: how much more the
    /// engines that are on draw than a step before, `dT_vsum[t]`, and the same for the
    /// last `n` steps, `dT_vsum[t-1..t-n]` ([`valve_sum_change_of`]). The four engines
    /// draw through one feed, so an engine's thrust dips while the others open and
    /// recovers as the feed settles. `T_rsum[t]` gives the level of the total draw but
    /// no history, so it cannot carry that recovery. Changes, not levels: they are 0 in
    /// steady running, so these features move the transients and cannot shift a hold
    /// (levels, tried first, moved the descent's steady thrust and doubled its mass
    /// error). Over the `sine-700` validation case, hifi's thrust less a least-squares
    /// fit of a cubic in its own valve and two lags leaves 6.5 N max; adding the total
    /// draw and its last two steps leaves 2.4 N (measured before any training).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub valve_sum: bool,
}

/// Sum of the four commands of one step (off engines are commanded 0), in engine order.
#[inline(always)]
pub fn command_sum_of(input: &InputVec) -> f64 {
    input[0] + input[1] + input[2] + input[3]
}

/// How much more the engines draw after step `t - lag` than after the step before
/// ([`valve_sum_of`], [`FeatureSpec::valve_sum`]).
#[inline]
pub fn valve_sum_change_of<H: History + ?Sized>(h: &H, lag: usize) -> f64 {
    h.valve_sum(lag) - h.valve_sum(lag + 1)
}

/// The features a phase indicator is multiplied with in the library: the command, the
/// latest thrust and the latest gas pressure. A start or stop transient is then a lookup
/// of per-step gains on these (`start3[t]*T_r[t]`, ...) rather than products with every
/// history feature, which would triple the library for terms that carry no physics.
pub const PHASE_PARTNERS: [&str; 4] = ["T_r[t]", "T_o[t-1]", "P[t-1]", "T_rsum[t]"];

/// How a feature may enter the library's products.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Role {
    /// 0: continuous. Otherwise the feature takes only 0 and 1, and two binary features
    /// of the same group never multiply to anything new (the per-engine switch and phase
    /// indicators: a start indicator implies the switch, start and stop indicators
    /// exclude each other), so such products and powers are left out.
    pub group: u8,
    /// A phase indicator: its products are only with [`PHASE_PARTNERS`].
    pub phase: bool,
    /// One of [`PHASE_PARTNERS`].
    pub phase_partner: bool,
}

/// Where one feature is read from: the runtime gathers only the features its active terms
/// use, and a test checks that reading every source equals [`FeatureSpec::fill`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Source {
    /// Input component at a lag; for a per-engine feature the engine index is added.
    Input {
        /// Steps back (0: the step being predicted).
        lag: usize,
        /// Component (engine 0's for per-engine features).
        comp: usize,
        /// Add the engine index to `comp`.
        per_engine: bool,
    },
    /// State component at a lag (>= 1); see `Input`.
    State {
        /// Steps back.
        lag: usize,
        /// Component (engine 0's for per-engine features).
        comp: usize,
        /// Add the engine index to `comp`.
        per_engine: bool,
    },
    /// The valve-filtered command of the engine after step `t - lag` ([`ValveFilter`]).
    Valve {
        /// Steps back (0: after the step being predicted).
        lag: usize,
    },
    /// The guarded lambda at `t-1`.
    Lambda,
    /// The sum of the four commands at `t` ([`command_sum_of`]).
    CommandSum,
    /// The change of what the engines that are on draw, after step `t - lag`
    /// ([`valve_sum_change_of`]).
    ValveSum {
        /// Steps back (0: after the step being predicted).
        lag: usize,
    },
    /// 1 when the engine switched on exactly `k` steps before `t` (see [`phase_age`]).
    Start(usize),
    /// 1 when the engine switched off exactly `k` steps before `t`.
    Stop(usize),
    /// 1 when the engine is on and has not ignited by the end of step `t`
    /// ([`IgnitionClock`]).
    Priming,
    /// Hat function `j` of the engine's time since ignition at the end of step `t`.
    Ignition(usize, IgnitionClock),
}

impl Source {
    /// Whether the value depends on the engine (per-engine layouts).
    pub fn per_engine(&self) -> bool {
        match *self {
            Source::Input { per_engine, .. } | Source::State { per_engine, .. } => per_engine,
            Source::Lambda | Source::CommandSum | Source::ValveSum { .. } => false,
            Source::Start(_)
            | Source::Stop(_)
            | Source::Valve { .. }
            | Source::Priming
            | Source::Ignition(..) => true,
        }
    }

    /// Reads the raw value from a history (phases by scanning it).
    pub fn read<H: History + ?Sized>(&self, h: &H, engine: usize) -> f64 {
        let off = |p: bool| if p { engine } else { 0 };
        match *self {
            Source::Input {
                lag,
                comp,
                per_engine,
            } => h.input(lag)[comp + off(per_engine)],
            Source::State {
                lag,
                comp,
                per_engine,
            } => h.state(lag)[comp + off(per_engine)],
            Source::Lambda => {
                let s = h.state(1);
                lambda_of(s[STATE_MF], s[STATE_MO])
            }
            Source::CommandSum => command_sum_of(h.input(0)),
            Source::ValveSum { lag } => valve_sum_change_of(h, lag),
            Source::Valve { lag } => h.valve(lag).valve_n[engine],
            Source::Start(k) => indicator(phase_age(h, engine, true, k + 1) == Some(k)),
            Source::Stop(k) => indicator(phase_age(h, engine, false, k + 1) == Some(k)),
            Source::Priming => priming(h, engine),
            Source::Ignition(j, clock) => clock.hat(h.valve(0).since_ignition_s[engine], j),
        }
    }
}

/// The priming indicator of `engine` at step `t` (see [`Source::Priming`]).
fn priming<H: History + ?Sized>(h: &H, engine: usize) -> f64 {
    let on = h.input(0)[ENGINE_COUNT + engine] > 0.5;
    IgnitionClock::priming(on, h.valve(0).since_ignition_s[engine])
}

fn indicator(b: bool) -> f64 {
    f64::from(u8::from(b))
}

/// Steps since engine `engine` entered its current on/off state `on`, as seen at step
/// `t`: `Some(k)` when the switch was `on` over steps `t-k..=t` and not at `t-k-1`, for
/// `k < cap`; `None` when the switch is not `on` at `t` or has been for `cap` steps or
/// more. Before the first step the engines were off (as the history pads), so an engine
/// never switched on has no stop phase.
pub fn phase_age<H: History + ?Sized>(h: &H, engine: usize, on: bool, cap: usize) -> Option<usize> {
    let is = |lag: usize| (h.input(lag)[ENGINE_COUNT + engine] > 0.5) == on;
    if !is(0) {
        return None;
    }
    (0..cap).find(|&k| !is(k + 1))
}

/// Past inputs and states as seen from step `t`.
pub trait History {
    /// Inputs of step `t - lag` (lag 0: the command held over the step being predicted).
    fn input(&self, lag: usize) -> &InputVec;
    /// State at the end of step `t - lag` (lag >= 1).
    fn state(&self, lag: usize) -> &StateVec;
    /// Valve filter state after step `t - lag` (lag 0: after the step being predicted,
    /// a function of the commands only). Only read by specs with [`FeatureSpec::valve`].
    fn valve(&self, lag: usize) -> &ValveState;
    /// [`valve_sum_of`] after step `t - lag`. A history that keeps it (the runtime's
    /// ring works it out once, as the step is written, where each of the `dT_vsum`
    /// features would read it twice) returns the same number.
    #[inline(always)]
    fn valve_sum(&self, lag: usize) -> f64 {
        valve_sum_of(self.input(lag), &self.valve(lag).valve_n)
    }
}

impl FeatureSpec {
    /// The paper's Section V vector of `11n + 10` features for history `n`: all four
    /// engines in one MIMO vector, with the ejected-mass histories and lambda, and none
    /// of the physics features beyond it.
    pub fn paper(history: usize) -> Self {
        Self {
            layout: Layout::Mimo,
            history,
            mass_features: true,
            start_steps: 0,
            stop_steps: 0,
            phase_degree: 0,
            command_sum: false,
            valve: None,
            valve_sum: false,
        }
    }

    /// The per-engine layout for history `n` without any feature beyond the paper's
    /// (tests state only how theirs differ, with struct update syntax).
    #[cfg(test)]
    pub(crate) fn per_engine(history: usize) -> Self {
        Self {
            layout: Layout::PerEngine,
            mass_features: false,
            ..Self::paper(history)
        }
    }

    /// Deepest state lag read (`n+1`, for the gas pressure history).
    pub fn max_state_lag(&self) -> usize {
        self.history + 1
    }

    /// Deepest lag read of anything (the phase indicators scan the switch history).
    pub fn max_lag(&self) -> usize {
        self.max_state_lag()
            .max(self.start_steps)
            .max(self.stop_steps)
    }

    /// Number of phase indicators.
    pub fn phase_features(&self) -> usize {
        self.start_steps + self.stop_steps
    }

    /// Number of per-engine physics features (valve, command sum, phase indicators,
    /// ignition clock).
    fn physics_features(&self) -> usize {
        self.valve_features()
            + self.valve_sum_features()
            + usize::from(self.command_sum)
            + self.phase_features()
            + self.ignition_features()
    }

    /// The ignition clock the features read (per-engine layout with a valve filter that
    /// has one).
    pub fn ignition(&self) -> Option<IgnitionClock> {
        match self.layout {
            Layout::PerEngine => self.valve.and_then(|v| v.ignition),
            Layout::Mimo => None,
        }
    }

    /// Number of ignition features: the priming indicator and the hats.
    pub fn ignition_features(&self) -> usize {
        self.ignition().map_or(0, |c| c.knots + 1)
    }

    /// Number of valve features (`T_v[t]` and its history), 0 without a valve filter.
    pub fn valve_features(&self) -> usize {
        if self.valve.is_some() && self.layout == Layout::PerEngine {
            self.history + 1
        } else {
            0
        }
    }

    /// Number of valve-sum features (`dT_vsum[t]` and its history), 0 without them.
    pub fn valve_sum_features(&self) -> usize {
        if self.valve_sum {
            self.valve_features()
        } else {
            0
        }
    }

    /// Number of features.
    pub fn dim(&self) -> usize {
        let n = self.history;
        let m = usize::from(self.mass_features);
        match self.layout {
            // T_r 4, T_r-h 4n, T_o-h 4n, P 1, P_h n, m_f-h n, m_o-h n, S_e 4, lambda 1.
            Layout::Mimo => 4 + 4 * n + 4 * n + 1 + n + m * 2 * n + 4 + m,
            // T_r 1, T_r-h n, T_o-h n, P 1, P_h n, m_f-h n, m_o-h n, S_e 1, lambda 1.
            // ... then start and stop indicators.
            Layout::PerEngine => 1 + n + n + 1 + n + m * 2 * n + 1 + m + self.physics_features(),
        }
    }

    /// Feature names in order, e.g. `T_r2[t-1]`, `P[t-1]`, `lambda[t-1]`.
    pub fn names(&self) -> Vec<String> {
        let mut v = Vec::with_capacity(self.dim());
        let n = self.history;
        let engines: Vec<String> = match self.layout {
            Layout::Mimo => (1..=ENGINE_COUNT).map(|e| e.to_string()).collect(),
            Layout::PerEngine => vec![String::new()],
        };
        let lag = |k: usize| {
            if k == 0 {
                "[t]".to_string()
            } else {
                format!("[t-{k}]")
            }
        };
        for e in &engines {
            v.push(format!("T_r{e}{}", lag(0)));
        }
        for k in 1..=n {
            for e in &engines {
                v.push(format!("T_r{e}{}", lag(k)));
            }
        }
        for k in 1..=n {
            for e in &engines {
                v.push(format!("T_o{e}{}", lag(k)));
            }
        }
        for k in 1..=n + 1 {
            v.push(format!("P{}", lag(k)));
        }
        if self.mass_features {
            for k in 1..=n {
                v.push(format!("m_f{}", lag(k)));
            }
            for k in 1..=n {
                v.push(format!("m_o{}", lag(k)));
            }
        }
        for e in &engines {
            v.push(format!("S_e{e}{}", lag(0)));
        }
        if self.mass_features {
            v.push(format!("lambda{}", lag(1)));
        }
        if self.layout == Layout::PerEngine {
            for k in 0..self.valve_features() {
                v.push(format!("T_v{}", lag(k)));
            }
            for k in 0..self.valve_sum_features() {
                v.push(format!("dT_vsum{}", lag(k)));
            }
            if self.command_sum {
                v.push(format!("T_rsum{}", lag(0)));
            }
            for k in 0..self.start_steps {
                v.push(format!("start{k}{}", lag(0)));
            }
            for k in 0..self.stop_steps {
                v.push(format!("stop{k}{}", lag(0)));
            }
            if let Some(c) = self.ignition() {
                v.push(format!("priming{}", lag(0)));
                for j in 0..c.knots {
                    v.push(format!("ign{j}{}", lag(0)));
                }
            }
        }
        debug_assert_eq!(v.len(), self.dim());
        v
    }

    /// Where every feature is read from, in order (see [`Source`]).
    pub fn sources(&self) -> Vec<Source> {
        let n = self.history;
        let per = self.layout == Layout::PerEngine;
        let engines = if per { 1 } else { ENGINE_COUNT };
        let input = |lag, comp| Source::Input {
            lag,
            comp,
            per_engine: per,
        };
        let state = |lag, comp, per_engine| Source::State {
            lag,
            comp,
            per_engine,
        };
        let mut v = Vec::with_capacity(self.dim());
        for e in 0..engines {
            v.push(input(0, e));
        }
        for k in 1..=n {
            for e in 0..engines {
                v.push(input(k, e));
            }
        }
        for k in 1..=n {
            for e in 0..engines {
                v.push(state(k, e, per));
            }
        }
        for k in 1..=n + 1 {
            v.push(state(k, STATE_P, false));
        }
        if self.mass_features {
            for k in 1..=n {
                v.push(state(k, STATE_MF, false));
            }
            for k in 1..=n {
                v.push(state(k, STATE_MO, false));
            }
        }
        for e in 0..engines {
            v.push(input(0, ENGINE_COUNT + e));
        }
        if self.mass_features {
            v.push(Source::Lambda);
        }
        if per {
            v.extend((0..self.valve_features()).map(|lag| Source::Valve { lag }));
            v.extend((0..self.valve_sum_features()).map(|lag| Source::ValveSum { lag }));
            if self.command_sum {
                v.push(Source::CommandSum);
            }
            v.extend((0..self.start_steps).map(Source::Start));
            v.extend((0..self.stop_steps).map(Source::Stop));
            if let Some(c) = self.ignition() {
                v.push(Source::Priming);
                v.extend((0..c.knots).map(|j| Source::Ignition(j, c)));
            }
        }
        debug_assert_eq!(v.len(), self.dim());
        v
    }

    /// How each feature may enter library products (see [`Role`]).
    pub fn roles(&self) -> Vec<Role> {
        self.names()
            .iter()
            .map(|s| {
                // The ignition features are 0 outside a start like the phase
                // indicators, and enter products the same way.
                let phase = ["start", "stop", "priming", "ign"]
                    .iter()
                    .any(|p| s.starts_with(p));
                let group = if let Some(rest) = s.strip_prefix("S_e") {
                    // MIMO: each engine's switch its own group; per-engine: group 1.
                    rest.chars()
                        .next()
                        .and_then(|c| c.to_digit(10))
                        .map_or(1, |d| d as u8)
                } else if phase {
                    1
                } else {
                    0
                };
                Role {
                    group,
                    phase,
                    phase_partner: PHASE_PARTNERS.contains(&s.as_str()),
                }
            })
            .collect()
    }

    /// Writes the feature vector of step `t` into `out` (length `dim()`). `engine` picks
    /// the engine for [`Layout::PerEngine`] and is ignored for [`Layout::Mimo`].
    /// No allocation: this runs in the surrogate's step.
    #[inline]
    pub fn fill<H: History + ?Sized>(&self, h: &H, engine: usize, out: &mut [f64]) {
        let out = &mut out[..self.dim()];
        let mut i = 0;
        self.fill_with(h, engine, |x| {
            out[i] = x;
            i += 1;
        });
        debug_assert_eq!(i, self.dim());
    }

    /// [`FeatureSpec::fill`], handing the features to `put` in order instead (the
    /// predictor writes each engine's straight into its lane).
    #[inline]
    pub fn fill_with<H: History + ?Sized>(&self, h: &H, engine: usize, mut put: impl FnMut(f64)) {
        let n = self.history;
        let (e0, e1) = match self.layout {
            Layout::Mimo => (0, ENGINE_COUNT),
            Layout::PerEngine => (engine, engine + 1),
        };
        for e in e0..e1 {
            put(h.input(0)[e]);
        }
        for k in 1..=n {
            for e in e0..e1 {
                put(h.input(k)[e]);
            }
        }
        for k in 1..=n {
            for e in e0..e1 {
                put(h.state(k)[e]);
            }
        }
        for k in 1..=n + 1 {
            put(h.state(k)[STATE_P]);
        }
        if self.mass_features {
            for k in 1..=n {
                put(h.state(k)[STATE_MF]);
            }
            for k in 1..=n {
                put(h.state(k)[STATE_MO]);
            }
        }
        for e in e0..e1 {
            put(h.input(0)[ENGINE_COUNT + e]);
        }
        if self.mass_features {
            let s = h.state(1);
            put(lambda_of(s[STATE_MF], s[STATE_MO]));
        }
        for k in 0..self.valve_features() {
            put(h.valve(k).valve_n[engine]);
        }
        for k in 0..self.valve_sum_features() {
            put(valve_sum_change_of(h, k));
        }
        if self.layout == Layout::PerEngine && self.command_sum {
            put(command_sum_of(h.input(0)));
        }
        if self.layout == Layout::PerEngine && self.phase_features() > 0 {
            let start = phase_age(h, engine, true, self.start_steps);
            let stop = phase_age(h, engine, false, self.stop_steps);
            for k in 0..self.start_steps {
                put(indicator(start == Some(k)));
            }
            for k in 0..self.stop_steps {
                put(indicator(stop == Some(k)));
            }
        }
        if let Some(c) = self.ignition() {
            put(priming(h, engine));
            let since = h.valve(0).since_ignition_s[engine];
            for j in 0..c.knots {
                put(c.hat(since, j));
            }
        }
    }
}

impl FeatureSpec {
    /// [`FeatureSpec::fill_with`] for the four engines of a per-engine layout at once:
    /// each feature as one vector whose lane `e` is what `fill_with(h, e, ..)` gives for
    /// engine `e`, by the same operations in the same order on each lane, so the same
    /// bits (`fill_engines_equals_fill_engine_by_engine`). A feature the engines share
    /// (gas pressure, masses, lambda, the sums) is computed once and put in every lane;
    /// an engine's own one is read as the four engines' values side by side, which is
    /// how the ring holds them. A run of features that are 0 in every lane (a phase no
    /// engine is in, hats of clocks that all read outside their knots: most steps) is
    /// handed over as a count ([`EngineLanes::put_zeros`]), not computed.
    #[inline]
    pub fn fill_engines<H: History + ?Sized>(&self, h: &H, out: &mut impl EngineLanes) {
        debug_assert_eq!(self.layout, Layout::PerEngine);
        let n = self.history;
        // Entries `at..at + 4` of an input or state: the four engines' values.
        let engines = |v: &[f64], at: usize| f64x4::new([v[at], v[at + 1], v[at + 2], v[at + 3]]);
        let shared = f64x4::splat;
        out.put(engines(h.input(0), 0));
        for k in 1..=n {
            out.put(engines(h.input(k), 0));
        }
        for k in 1..=n {
            out.put(engines(h.state(k), 0));
        }
        for k in 1..=n + 1 {
            out.put(shared(h.state(k)[STATE_P]));
        }
        if self.mass_features {
            for k in 1..=n {
                out.put(shared(h.state(k)[STATE_MF]));
            }
            for k in 1..=n {
                out.put(shared(h.state(k)[STATE_MO]));
            }
        }
        out.put(engines(h.input(0), ENGINE_COUNT));
        if self.mass_features {
            let s = h.state(1);
            out.put(shared(lambda_of(s[STATE_MF], s[STATE_MO])));
        }
        for k in 0..self.valve_features() {
            out.put(f64x4::new(h.valve(k).valve_n));
        }
        for k in 0..self.valve_sum_features() {
            out.put(shared(valve_sum_change_of(h, k)));
        }
        if self.command_sum {
            out.put(shared(command_sum_of(h.input(0))));
        }
        if self.phase_features() > 0 {
            // Each engine's phase age as a lane, NaN for none (NaN equals no k).
            let age = |on: bool, cap: usize| {
                f64x4::new(std::array::from_fn(|e| {
                    phase_age(h, e, on, cap).map_or(f64::NAN, |k| k as f64)
                }))
            };
            // An age that is NaN in every lane: no engine in the phase, every
            // indicator 0.0 in every lane.
            for (ages, steps) in [
                (age(true, self.start_steps), self.start_steps),
                (age(false, self.stop_steps), self.stop_steps),
            ] {
                if ages.is_nan().all() {
                    out.put_zeros(steps);
                } else {
                    for k in 0..steps {
                        out.put(indicator_lanes(ages.cmp_eq(shared(k as f64))));
                    }
                }
            }
        }
        if let Some(c) = self.ignition() {
            let since = f64x4::new(h.valve(0).since_ignition_s);
            out.put(IgnitionClock::priming_lanes(
                engines(h.input(0), ENGINE_COUNT),
                since,
            ));
            let at = c.clock_lanes(since);
            if c.hats_all_zero(at) {
                out.put_zeros(c.knots);
            } else {
                for j in 0..c.knots {
                    out.put(IgnitionClock::hat_lanes(at, j));
                }
            }
        }
    }
}

/// Where [`FeatureSpec::fill_engines`] hands the features over, in order.
pub trait EngineLanes {
    /// The next feature, the four engines' values as lanes.
    fn put(&mut self, lanes: f64x4);
    /// The next `n` features, each 0.0 in every lane (a consumer may know what that
    /// gives without the values).
    fn put_zeros(&mut self, n: usize) {
        for _ in 0..n {
            self.put(f64x4::ZERO);
        }
    }
}

/// Features as lane vectors in a `Vec`, in order (tests).
impl EngineLanes for Vec<f64x4> {
    fn put(&mut self, lanes: f64x4) {
        self.push(lanes);
    }
}

/// [`indicator`] of each lane of a comparison's mask: 1.0 where it holds, 0.0 elsewhere.
#[inline(always)]
pub fn indicator_lanes(mask: f64x4) -> f64x4 {
    mask & f64x4::ONE
}

/// A recorded trajectory seen from one step, for training. Before the first step the
/// engines were off and the state was the initial one (as the runtime starts).
pub struct TrajectoryHistory<'a> {
    /// Inputs of every step.
    pub inputs: &'a [InputVec],
    /// State at the end of every step.
    pub states: &'a [StateVec],
    /// State before the first step.
    pub initial: &'a StateVec,
    /// Valve filter state after every step (empty when no feature reads it).
    pub valves: &'a [ValveState],
    /// Valve filter state before the first step.
    pub valve_rest: ValveState,
    /// The step being predicted.
    pub t: usize,
}

const OFF: InputVec = [0.0; INPUT_DIM];

impl History for TrajectoryHistory<'_> {
    fn input(&self, lag: usize) -> &InputVec {
        self.t.checked_sub(lag).map_or(&OFF, |k| &self.inputs[k])
    }
    fn state(&self, lag: usize) -> &StateVec {
        self.t
            .checked_sub(lag)
            .map_or(self.initial, |k| &self.states[k])
    }
    fn valve(&self, lag: usize) -> &ValveState {
        self.t
            .checked_sub(lag)
            .map_or(&self.valve_rest, |k| &self.valves[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_dimension_is_11n_plus_10() {
        for n in 1..=10 {
            let s = FeatureSpec::paper(n);
            assert_eq!(s.dim(), 11 * n + 10);
            assert_eq!(s.names().len(), 11 * n + 10);
        }
    }

    #[test]
    fn fill_is_causal_and_matches_names() {
        // Inputs and states encode their own step index, so each feature says where it
        // was read from.
        let inputs: Vec<InputVec> = (0..10).map(|k| [k as f64; INPUT_DIM]).collect();
        let states: Vec<StateVec> = (0..10).map(|k| [100.0 + k as f64; STATE_DIM]).collect();
        let initial = [-1.0; STATE_DIM];
        let spec = FeatureSpec::paper(2);
        let mut out = vec![0.0; spec.dim()];
        let h = TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &initial,
            valves: &[],
            valve_rest: ValveState::default(),
            t: 5,
        };
        spec.fill(&h, 0, &mut out);
        let names = spec.names();
        let pos = |name: &str| names.iter().position(|s| s == name).unwrap();
        let at = |out: &[f64], name: &str| out[pos(name)];
        assert_eq!(at(&out, "T_r3[t]"), 5.0);
        assert_eq!(at(&out, "T_r1[t-2]"), 3.0);
        assert_eq!(at(&out, "T_o4[t-1]"), 104.0);
        assert_eq!(at(&out, "P[t-1]"), 104.0);
        assert_eq!(at(&out, "P[t-3]"), 102.0);
        assert_eq!(at(&out, "m_o[t-2]"), 103.0);
        assert_eq!(at(&out, "S_e2[t]"), 5.0);
        assert_eq!(at(&out, "lambda[t-1]"), 1.0 / 208.0);
        // Before the start: engines off, initial state.
        let h0 = TrajectoryHistory { t: 0, ..h };
        spec.fill(&h0, 0, &mut out);
        assert_eq!(at(&out, "T_r1[t-1]"), 0.0);
        assert_eq!(at(&out, "P[t-1]"), -1.0);
        assert_eq!(at(&out, "lambda[t-1]"), 1.0 / LAMBDA_MASS_FLOOR_KG);
    }

    #[test]
    fn per_engine_reads_its_own_engine() {
        let inputs: Vec<InputVec> = (0..4)
            .map(|_| [10.0, 20.0, 30.0, 40.0, 1.0, 0.0, 1.0, 0.0])
            .collect();
        let states: Vec<StateVec> = (0..4)
            .map(|_| [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0])
            .collect();
        let spec = FeatureSpec::per_engine(1);
        let mut out = vec![0.0; spec.dim()];
        let h = TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &[0.0; STATE_DIM],
            valves: &[],
            valve_rest: ValveState::default(),
            t: 3,
        };
        spec.fill(&h, 2, &mut out);
        assert_eq!(
            spec.names(),
            ["T_r[t]", "T_r[t-1]", "T_o[t-1]", "P[t-1]", "P[t-2]", "S_e[t]"]
        );
        assert_eq!(out, [30.0, 30.0, 3.0, 5.0, 5.0, 1.0]);
    }
}

#[cfg(test)]
pub(crate) mod source_tests {
    use super::*;

    /// A trajectory with engines switching on and off at different times.
    pub(crate) fn switching_trajectory(steps: usize) -> (Vec<InputVec>, Vec<StateVec>) {
        let mut inputs = Vec::new();
        let mut states = Vec::new();
        for t in 0..steps {
            let mut u = [0.0; INPUT_DIM];
            let mut x = [0.0; STATE_DIM];
            for e in 0..ENGINE_COUNT {
                let on = ((t + 3 * e) / (5 + e)) % 3 != 0;
                u[ENGINE_COUNT + e] = f64::from(u8::from(on));
                u[e] = if on {
                    320.0 + ((t * 37 + e * 11) % 480) as f64
                } else {
                    0.0
                };
                x[e] = (t * 13 + e) as f64 % 800.0;
            }
            x[STATE_P] = 2.8e7 - 1e3 * t as f64;
            x[STATE_MF] = 0.1 * t as f64;
            x[STATE_MO] = 0.17 * t as f64;
            inputs.push(u);
            states.push(x);
        }
        (inputs, states)
    }

    #[test]
    fn reading_every_source_equals_fill() {
        let (inputs, states) = switching_trajectory(120);
        let initial = [1.0, 2.0, 3.0, 4.0, 2.8e7, 0.0, 0.0];
        for spec in [
            FeatureSpec::paper(3),
            FeatureSpec {
                mass_features: true,
                start_steps: 7,
                stop_steps: 4,
                command_sum: true,
                valve: Some(crate::propulsion::surrogate::predictor::tests::TEST_VALVE),
                valve_sum: true,
                ..FeatureSpec::per_engine(2)
            },
        ] {
            let valve_rest = spec.valve.map_or_else(ValveState::default, |f| f.rest());
            let valves = spec.valve.map_or_else(Vec::new, |f| f.track(&inputs, 0.01));
            let sources = spec.sources();
            assert_eq!(sources.len(), spec.dim());
            let mut out = vec![0.0; spec.dim()];
            let mut starts = 0.0;
            let mut ignitions = 0.0;
            for t in 0..inputs.len() {
                let h = TrajectoryHistory {
                    inputs: &inputs,
                    states: &states,
                    initial: &initial,
                    valves: &valves,
                    valve_rest,
                    t,
                };
                for e in 0..ENGINE_COUNT {
                    spec.fill(&h, e, &mut out);
                    for (j, s) in sources.iter().enumerate() {
                        assert_eq!(s.read(&h, e), out[j], "t {t} engine {e} {s:?}");
                    }
                    let clock_at = spec.dim() - spec.ignition_features();
                    starts += out[clock_at - spec.phase_features()..clock_at]
                        .iter()
                        .sum::<f64>();
                    ignitions += out[clock_at..].iter().skip(1).sum::<f64>();
                }
            }
            // The trajectory does exercise the phase indicators and the hats.
            assert!(spec.phase_features() == 0 || starts > 20.0);
            assert!(spec.ignition_features() == 0 || ignitions > 20.0);
        }
    }

    /// The four engines' features as lanes are each engine's `fill`, bit for bit, for
    /// a spec with every per-engine feature (phases, valve, sums, ignition clock) over a
    /// trajectory that switches engines and fires their ignition clocks.
    #[test]
    fn fill_engines_equals_fill_engine_by_engine() {
        let (inputs, states) = switching_trajectory(300);
        let initial = [1.0, 2.0, 3.0, 4.0, 2.8e7, 0.0, 0.0];
        let spec = FeatureSpec {
            mass_features: true,
            start_steps: 7,
            stop_steps: 4,
            command_sum: true,
            valve: Some(crate::propulsion::surrogate::predictor::tests::TEST_VALVE),
            valve_sum: true,
            ..FeatureSpec::per_engine(3)
        };
        let valves = spec.valve.map(|f| f.track(&inputs, 0.01)).unwrap();
        let valve_rest = spec.valve.unwrap().rest();
        let mut one = vec![0.0; spec.dim()];
        let mut nonzero_hats = 0;
        for t in 0..inputs.len() {
            let h = TrajectoryHistory {
                inputs: &inputs,
                states: &states,
                initial: &initial,
                valves: &valves,
                valve_rest,
                t,
            };
            let mut lanes: Vec<f64x4> = Vec::new();
            spec.fill_engines(&h, &mut lanes);
            let lanes: Vec<[f64; 4]> = lanes.iter().map(|l| l.to_array()).collect();
            assert_eq!(lanes.len(), spec.dim());
            for e in 0..ENGINE_COUNT {
                spec.fill(&h, e, &mut one);
                for (j, l) in lanes.iter().enumerate() {
                    assert_eq!(
                        l[e].to_bits(),
                        one[j].to_bits(),
                        "t {t} engine {e} feature {j}"
                    );
                }
                let hats = &one[spec.dim() - spec.ignition_features() + 1..];
                nonzero_hats += hats.iter().filter(|&&v| v != 0.0).count();
            }
        }
        assert!(nonzero_hats > 50, "{nonzero_hats}");
    }

    /// The draw changes: what the engines that are on draw after a step, less what they
    /// drew after the step before; an engine that is off draws nothing, however its
    /// valve is parked, and before the first step nothing was drawn.
    #[test]
    fn draw_changes_count_only_engines_that_are_on() {
        let spec = FeatureSpec {
            valve: Some(crate::propulsion::surrogate::predictor::tests::TEST_VALVE),
            valve_sum: true,
            ..FeatureSpec::per_engine(2)
        };
        let names = spec.names();
        let first = names.iter().position(|s| s == "dT_vsum[t]").unwrap();
        assert_eq!(
            names[first..first + 3],
            ["dT_vsum[t]", "dT_vsum[t-1]", "dT_vsum[t-2]"]
        );
        // Hand-made valve states: each valve at 100 * (engine + 1) + step; engines 0 and
        // 2 on from step 0, engine 1 on from step 2, engine 3 never.
        let on = |t: usize, e: usize| e == 0 || e == 2 || (e == 1 && t >= 2);
        let inputs: Vec<InputVec> = (0..4)
            .map(|t| {
                let mut u = [0.0; INPUT_DIM];
                for e in 0..ENGINE_COUNT {
                    u[ENGINE_COUNT + e] = f64::from(u8::from(on(t, e)));
                }
                u
            })
            .collect();
        let valves: Vec<ValveState> = (0..4)
            .map(|t| ValveState {
                valve_n: std::array::from_fn(|e| 100.0 * (e + 1) as f64 + t as f64),
                ..ValveState::default()
            })
            .collect();
        let drawn = |t: usize| -> f64 {
            (0..ENGINE_COUNT)
                .filter(|&e| on(t, e))
                .map(|e| valves[t].valve_n[e])
                .sum()
        };
        let states = vec![[0.0; STATE_DIM]; 4];
        let mut out = vec![0.0; spec.dim()];
        for t in 0..4 {
            let h = TrajectoryHistory {
                inputs: &inputs,
                states: &states,
                initial: &[0.0; STATE_DIM],
                valves: &valves,
                // Parked valves of engines that are off: not drawn.
                valve_rest: ValveState {
                    valve_n: [320.0; ENGINE_COUNT],
                    ..ValveState::default()
                },
                t,
            };
            for engine in 0..ENGINE_COUNT {
                spec.fill(&h, engine, &mut out);
                for lag in 0..3 {
                    let drawn_at = |k: isize| if k < 0 { 0.0 } else { drawn(k as usize) };
                    let k = t as isize - lag as isize;
                    let want = drawn_at(k) - drawn_at(k - 1);
                    assert_eq!(out[first + lag], want, "t {t} lag {lag} engine {engine}");
                }
            }
        }
        // Step 2: engine 1 switches on (+ its 202 N) and the other two open by 1 N each.
        let h = TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &[0.0; STATE_DIM],
            valves: &valves,
            valve_rest: ValveState::default(),
            t: 2,
        };
        assert_eq!(valve_sum_change_of(&h, 0), 204.0);
        // Step 0: engines 0 and 2 start drawing 100 + 300 N.
        assert_eq!(valve_sum_change_of(&h, 2), 400.0);
    }

    #[test]
    fn phase_age_counts_steps_since_the_switch() {
        // Engine 0: off for 2 steps, on for 5, off again.
        let inputs: Vec<InputVec> = (0..9)
            .map(|t| {
                let mut u = [0.0; INPUT_DIM];
                u[ENGINE_COUNT] = f64::from(u8::from((2..7).contains(&t)));
                u
            })
            .collect();
        let states = vec![[0.0; STATE_DIM]; 9];
        let h = |t| TrajectoryHistory {
            inputs: &inputs,
            states: &states,
            initial: &[0.0; STATE_DIM],
            valves: &[],
            valve_rest: ValveState::default(),
            t,
        };
        assert_eq!(phase_age(&h(2), 0, true, 10), Some(0));
        assert_eq!(phase_age(&h(4), 0, true, 10), Some(2));
        assert_eq!(phase_age(&h(4), 0, true, 2), None);
        assert_eq!(phase_age(&h(4), 0, false, 10), None);
        assert_eq!(phase_age(&h(8), 0, false, 10), Some(1));
        // Never switched on: no stop phase at the start.
        assert_eq!(phase_age(&h(1), 0, false, 10), None);
    }
}
