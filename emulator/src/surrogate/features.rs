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

use crate::propulsion::hifi::engine::{Tfcv, TfcvDynamics};
use oils_shared::ENGINE_COUNT;

pub use super::stroke_map::{StrokeMap, StrokeSlope};
use serde::{Deserialize, Serialize};

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
    #[serde(default)]
    pub start_steps: usize,
    /// Beyond the paper, per-engine layout only: stop-phase indicators `stop0..stop{K-1}`
    /// ("this engine switched off k steps ago") for the tail-off (dome dribble). 0 = none.
    #[serde(default)]
    pub stop_steps: usize,
    /// Highest degree of library terms with a phase indicator (0: the library degree).
    #[serde(default)]
    pub phase_degree: usize,
    /// Beyond the paper, per-engine layout only: the sum of the four engines' commands
    /// over the step, `T_rsum[t]` (off engines count 0). The engines share feed lines and
    /// manifolds, so how fast one engine's dome fills at a start depends on what the
    /// others draw; a per-engine model cannot see that otherwise.
    #[serde(default)]
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

/// A throttle valve actuator in newtons: the valve position, expressed as the thrust it
/// stands for, follows `max(command, park_n)` through a first-order lag whose rate is
/// limited, then through backlash. It is computed from the commands alone (the runtime
/// has nothing else), the same way in training and in the loop. Parameters are the
/// actuator's data-sheet figures (`emulator/config/train.toml`), not fitted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValveFilter {
    /// Lag time constant, s.
    pub time_constant_s: f64,
    /// Rate limit, N/s of equivalent thrust (full stroke over the stroke time).
    pub rate_n_per_s: f64,
    /// Backlash width, N of equivalent thrust.
    pub backlash_n: f64,
    /// Where the valve parks with the engine off, and the least it is driven to when on
    /// (the minimum throttle), N.
    pub park_n: f64,
    /// Beyond the valve: when the dome the valve feeds is primed and the engine ignites
    /// ([`IgnitionClock`]). `None`: no ignition features.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ignition: Option<IgnitionClock>,
    /// The valve's calibration, commanded thrust to stroke ([`StrokeMap`]): with it the
    /// rate limit and backlash act in stroke, as hifi's TFCV's do (`rate_n_per_s` and
    /// `backlash_n` are then per position newton and scaled by the newtons per stroke
    /// where the valve moves). The ignition clock keeps integrating a second filter
    /// with them constant, the path its constants were fitted on (docs/surrogate.md,
    /// "The rate limit in stroke"). `None`: constant in newtons (absent from files
    /// before version 7).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stroke: Option<StrokeMap>,
}

/// An estimate of when each engine ignites, driven by its valve-filtered command.
///
/// Why: at a start hifi's thrust stays 0 while the dome between valve and injector
/// fills, then rises by some 460 N within 20 ms. When that edge comes depends on how far
/// the valve is open while the dome fills (60-120 ms) and on what is left in the dome
/// from the last burn. A per-step lookup ("switched on k steps ago") cannot place an edge
/// that moves by milliseconds with the command; a clock that says how long ago the
/// engine ignited can, and the thrust is then a function of that time
/// (hat functions of it, [`IgnitionClock::hat`]).
///
/// The dome model, relative to the fill at which the engine ignites: while the engine is
/// on it fills at a rate proportional to the valve position (the flow into an empty dome
/// is set by the valve's area), `d(fill)/dt = T_v / fill_n_s`, up to `full`; while off
/// it drains by Torricelli's law, `sqrt(fill)` falling linearly to 0 in `drain_time_s`
/// from full. The time of ignition is where the fill crosses 1, interpolated within the
/// step; up to `lead_s` before it, the clock reads minus the time still to go at the
/// current valve position, so that hats before the estimate can take up its scatter.
/// The engines share the feed: while others draw, the manifold sags and a dome fills
/// more slowly, so `fill_n_s` is scaled by `1 + sag_per_n * (valve positions of the
/// other engines that are on)` (hifi: relative to the clock without sag, a four-engine
/// cold start ignites some 8 ms later than a single engine's at the same command).
/// Parameters: `drain_time_s` and `full` are hifi's dome figures, `fill_n_s` and
/// `sag_per_n` are fitted to hifi's ignition times (`cargo run --release -p
/// oils-emulator --example ignition_times`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IgnitionClock {
    /// Integral of the valve-filtered command that fills a dry dome to ignition, N s.
    pub fill_n_s: f64,
    /// Time for a full dome to drain, s.
    pub drain_time_s: f64,
    /// A full dome relative to the fill at ignition (>= 1).
    pub full: f64,
    /// How long before the estimated ignition the clock starts, s.
    pub lead_s: f64,
    /// Spacing of the hat functions' knots, s.
    pub knot_spacing_s: f64,
    /// Number of hat functions, at `-lead_s`, `-lead_s + spacing`, ... from ignition.
    pub knots: usize,
    /// Slower filling per newton of the other engines' valve positions, 1/N (0: none;
    /// absent from files before version 5).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub sag_per_n: f64,
}

/// `since_ignition_s` of an engine that has not ignited.
pub const NOT_IGNITED: f64 = f64::NEG_INFINITY;

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl IgnitionClock {
    /// Describes the first invalid parameter.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        if !pos(self.fill_n_s) || !pos(self.drain_time_s) || !pos(self.knot_spacing_s) {
            return Err(
                "ignition fill_n_s, drain_time_s and knot_spacing_s must be positive".into(),
            );
        }
        if !(self.lead_s.is_finite() && self.lead_s >= 0.0) {
            return Err("ignition lead_s must be finite and not negative".into());
        }
        if !(self.full.is_finite() && self.full >= 1.0) {
            return Err("ignition full must be finite and at least 1".into());
        }
        if !(self.sag_per_n.is_finite() && self.sag_per_n >= 0.0) {
            return Err("ignition sag_per_n must be finite and not negative".into());
        }
        if !(1..=64).contains(&self.knots) {
            return Err("ignition knots must be 1..=64".into());
        }
        Ok(())
    }

    /// Hat function `j` of the time since ignition: 1 at its knot, `j` spacings after
    /// `-lead_s`, falling linearly to 0 one spacing either side; 0 before the clock runs.
    #[inline(always)]
    pub fn hat(&self, since_ignition_s: f64, j: usize) -> f64 {
        let at = (since_ignition_s + self.lead_s) / self.knot_spacing_s;
        (1.0 - (at - j as f64).abs()).max(0.0)
    }

    /// The priming indicator: the engine is on and the clock has not started.
    #[inline(always)]
    pub fn priming(on: bool, since_ignition_s: f64) -> f64 {
        f64::from(u8::from(on && since_ignition_s == NOT_IGNITED))
    }

    /// Time after ignition beyond which every hat is 0, s.
    pub fn window_s(&self) -> f64 {
        self.knots as f64 * self.knot_spacing_s - self.lead_s
    }

    /// How far the square root of the fill falls in a step of `dt_s` while draining
    /// (see [`IgnitionClock::advance`]).
    fn drain_root_per_step(&self, dt_s: f64) -> f64 {
        self.full.sqrt() * dt_s / self.drain_time_s
    }

    /// Advances one engine's dome by a step of `dt_s` with the switch `on`, the valve
    /// moving from `valve0_n` to `valve1_n` and the other engines that are on at
    /// `others_n` (their valve positions' sum): `fill` and the time since ignition at
    /// the end of the step. `drain_root` is [`IgnitionClock::drain_root_per_step`] of
    /// `dt_s`, computed once rather than per step.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn advance(
        &self,
        on: bool,
        valve0_n: f64,
        valve1_n: f64,
        others_n: f64,
        dt_s: f64,
        drain_root: f64,
        fill: &mut f64,
        since_s: &mut f64,
    ) {
        if on {
            let f0 = *fill;
            // Without sag the factor is exactly 1 and the bits are those of the
            // unscaled constant.
            let fill_n_s = self.fill_n_s * (1.0 + self.sag_per_n * others_n);
            if f0 >= 1.0 && *since_s != NOT_IGNITED {
                *since_s += dt_s;
                // Running with a full dome (the common case) costs no division: the
                // fill would only be clamped back to `full`.
                if f0 < self.full {
                    let f1 = f0 + dt_s * 0.5 * (valve0_n + valve1_n) / fill_n_s;
                    *fill = f1.min(self.full);
                }
                return;
            }
            let f1 = f0 + dt_s * 0.5 * (valve0_n + valve1_n) / fill_n_s;
            if f1 >= 1.0 {
                // Ignition within the step (at its start when the dome was primed).
                let at = ((1.0 - f0) / (f1 - f0)).max(0.0);
                *since_s = (1.0 - at) * dt_s;
            } else {
                // Still filling: within the lead, minus the time to go at this valve.
                let to_go_s = (1.0 - f1) * fill_n_s / valve1_n;
                *since_s = if to_go_s <= self.lead_s {
                    -to_go_s
                } else {
                    NOT_IGNITED
                };
            }
            *fill = f1.min(self.full);
        } else {
            *since_s = NOT_IGNITED;
            let root = fill.sqrt() - drain_root;
            *fill = if root > 0.0 { root * root } else { 0.0 };
        }
    }
}

/// An actuator and the valve it drives through backlash, for each engine, N.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ValvePath {
    /// Actuator position.
    pub actuator: [f64; ENGINE_COUNT],
    /// Valve position.
    pub valve: [f64; ENGINE_COUNT],
}

impl ValvePath {
    /// Both at `at`.
    const fn at(at: f64) -> Self {
        Self {
            actuator: [at; ENGINE_COUNT],
            valve: [at; ENGINE_COUNT],
        }
    }

    /// Advances both one step towards `target` ([`step_valve`]).
    #[inline(always)]
    fn advance(
        &mut self,
        target: &[f64; ENGINE_COUNT],
        scale: &[f64; ENGINE_COUNT],
        d: &TfcvDynamics,
        dt_s: f64,
        decay: f64,
    ) {
        step_valve(
            &mut self.actuator,
            &mut self.valve,
            target,
            scale,
            d,
            dt_s,
            decay,
        );
    }
}

/// Advances an actuator and its valve, for each engine, one step towards `target`. The
/// actuator solution is exact for a held target: the same element as hifi's TFCV
/// ([`Tfcv::advance`]), without quantisation.
///
/// Written engine-parallel for the step path: an actuator within the lag's band of its
/// target (steady running) takes the exponential step, computed for the four engines
/// at once; one outside it (a large command step) takes [`Tfcv::advance`]. Each engine
/// sees the same operations as in [`Tfcv::advance`], so the bits are the same (tested
/// against it).
///
/// `d` gives the lag, rate and backlash; `scale` multiplies each engine's rate and
/// backlash (all 1 for the ignition clock's filter beside a stroke map: multiplying by
/// 1 is exact, so that is the plain filter's bits, tested).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn step_valve(
    actuator_n: &mut [f64; ENGINE_COUNT],
    valve_n: &mut [f64; ENGINE_COUNT],
    target: &[f64; ENGINE_COUNT],
    scale: &[f64; ENGINE_COUNT],
    d: &TfcvDynamics,
    dt_s: f64,
    decay: f64,
) {
    let rate_per_s: [f64; ENGINE_COUNT] = std::array::from_fn(|e| d.rate_per_s * scale[e]);
    let half_backlash: [f64; ENGINE_COUNT] = std::array::from_fn(|e| d.half_backlash * scale[e]);
    let mut actuator = [0.0; ENGINE_COUNT];
    let mut lagging = 0u8;
    for e in 0..ENGINE_COUNT {
        let err = target[e] - actuator_n[e];
        lagging |= u8::from(err.abs() > rate_per_s[e] * d.tau_s) << e;
        actuator[e] = target[e] - err * decay;
    }
    if lagging != 0 {
        for e in (0..ENGINE_COUNT).filter(|e| lagging & (1 << e) != 0) {
            let mut v = Tfcv {
                target: target[e],
                actuator: actuator_n[e],
                valve: valve_n[e],
            };
            let engine = TfcvDynamics {
                rate_per_s: rate_per_s[e],
                half_backlash: half_backlash[e],
                ..*d
            };
            v.advance(dt_s, &engine, decay);
            actuator[e] = v.actuator;
        }
    }
    for e in 0..ENGINE_COUNT {
        // `f64::clamp`'s two comparisons, without its check that lo <= hi (always
        // true here: the half backlash is not negative).
        let (lo, hi) = (
            actuator[e] - half_backlash[e],
            actuator[e] + half_backlash[e],
        );
        let v = valve_n[e];
        let v = if v < lo { lo } else { v };
        valve_n[e] = if v > hi { hi } else { v };
    }
    *actuator_n = actuator;
}

impl ValveState {
    /// Every valve parked at `park_n`, nothing in the domes.
    fn parked(park_n: f64) -> Self {
        ValveState {
            actuator_n: [park_n; ENGINE_COUNT],
            valve_n: [park_n; ENGINE_COUNT],
            fill: [0.0; ENGINE_COUNT],
            since_ignition_s: [NOT_IGNITED; ENGINE_COUNT],
            clock: ValvePath::at(park_n),
        }
    }
}

/// Per-engine state of the [`ValveFilter`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ValveState {
    /// Actuator position, N.
    pub actuator_n: [f64; ENGINE_COUNT],
    /// Valve position (what the thrust follows and the features read), N.
    pub valve_n: [f64; ENGINE_COUNT],
    /// Dome fill relative to the fill at ignition ([`IgnitionClock`]; 0 without one).
    pub fill: [f64; ENGINE_COUNT],
    /// Time from the estimated ignition to the end of the step, s; [`NOT_IGNITED`]
    /// while the engine is off or its dome is filling.
    pub since_ignition_s: [f64; ENGINE_COUNT],
    /// With a stroke map, the same actuator with its rate and backlash constant in
    /// newtons, which the ignition clock integrates; without one it stays at rest (the
    /// clock reads `valve_n`). Last, so that the plain filter's state keeps its layout.
    pub clock: ValvePath,
}

impl ValveFilter {
    /// Describes the first invalid parameter.
    pub fn validate(&self) -> Result<(), String> {
        let ok = |v: f64, zero_ok: bool| v.is_finite() && (v > 0.0 || (zero_ok && v == 0.0));
        if !ok(self.time_constant_s, false) || !ok(self.rate_n_per_s, false) {
            return Err("valve time_constant_s and rate_n_per_s must be positive".into());
        }
        if !ok(self.backlash_n, true) || !ok(self.park_n, true) {
            return Err("valve backlash_n and park_n must be finite and not negative".into());
        }
        if let Some(m) = &self.stroke {
            if !(m.first_n()..=m.last_n()).contains(&self.park_n) {
                return Err(format!(
                    "valve park_n {} is outside the stroke map's {}..={} N",
                    self.park_n,
                    m.first_n(),
                    m.last_n()
                ));
            }
        }
        self.ignition
            .as_ref()
            .map_or(Ok(()), IgnitionClock::validate)
    }

    /// At rest: every valve parked (how the reference model starts).
    pub fn rest(&self) -> ValveState {
        ValveState::parked(self.park_n)
    }

    /// The state after every step of `inputs`, from rest.
    pub fn track(&self, inputs: &[InputVec], dt_s: f64) -> Vec<ValveState> {
        let mut v = ValveTrack::new(*self, dt_s);
        inputs.iter().map(|u| *v.advance(u)).collect()
    }
}

/// A [`ValveFilter`] stepping at a fixed sample time, and its state: what training's
/// [`ValveFilter::track`] and the runtime's step both advance, so the two compute the
/// same bits. The lag's decay is computed once, not per step.
#[derive(Debug, Clone, Copy)]
pub struct ValveTrack {
    park_n: f64,
    ignition: Option<IgnitionClock>,
    /// The stroke map's slope, if the filter has one (not the whole map: the track is
    /// read every step and kept small).
    stroke: Option<StrokeSlope>,
    dynamics: TfcvDynamics,
    dt_s: f64,
    decay: f64,
    /// [`IgnitionClock::drain_root_per_step`] of `dt_s` (0 without a clock).
    drain_root: f64,
    /// With a stroke map, how far the actuator goes in a rate-limited step at the
    /// slope of the middle of the map's range, N (0 without one).
    reach_n: f64,
    /// State after the latest step.
    pub state: ValveState,
}

impl ValveTrack {
    /// At rest, stepping by `dt_s`.
    pub fn new(filter: ValveFilter, dt_s: f64) -> Self {
        Self {
            park_n: filter.park_n,
            ignition: filter.ignition,
            stroke: filter.stroke.map(|m| m.slope()),
            dynamics: TfcvDynamics {
                tau_s: filter.time_constant_s,
                rate_per_s: filter.rate_n_per_s,
                half_backlash: 0.5 * filter.backlash_n,
                quantum: 0.0,
            },
            dt_s,
            decay: (-dt_s / filter.time_constant_s).exp(),
            drain_root: filter.ignition.map_or(0.0, |c| c.drain_root_per_step(dt_s)),
            reach_n: filter.stroke.map_or(0.0, |m| {
                filter.rate_n_per_s * m.slope_at(0.5 * (m.first_n() + m.last_n())) * dt_s
            }),
            state: filter.rest(),
        }
    }

    /// The ignition clock the filter runs, if any.
    pub fn ignition(&self) -> Option<IgnitionClock> {
        self.ignition
    }

    /// Back to rest.
    pub fn reset(&mut self) {
        self.state = ValveState::parked(self.park_n);
    }

    /// Advances one step with `input` held: the filter ([`step_valve`]) towards
    /// `max(command, park_n)`, through the stroke map if there is one; then the
    /// ignition clock, if any, which follows the valve in newtons.
    #[inline]
    pub fn advance(&mut self, input: &InputVec) -> &ValveState {
        let (d, dt_s, decay) = (&self.dynamics, self.dt_s, self.decay);
        let s = &mut self.state;
        let target_n: [f64; ENGINE_COUNT] = std::array::from_fn(|e| input[e].max(self.park_n));
        // The path the clock integrates: the filter itself without a map, the filter in
        // newtons beside it with one.
        let clock_before_n = match &self.stroke {
            None => {
                // The plain filter, written out rather than through `step_valve` with
                // factors of 1 (the same operations and bits): through `step_valve` the
                // bench step read 196-207 ns, written out 193 ns (interleaved runs).
                let before = s.valve_n;
                let band = d.rate_per_s * d.tau_s;
                let mut actuator = [0.0; ENGINE_COUNT];
                let mut lagging = 0u8;
                for e in 0..ENGINE_COUNT {
                    let err = target_n[e] - s.actuator_n[e];
                    lagging |= u8::from(err.abs() > band) << e;
                    actuator[e] = target_n[e] - err * decay;
                }
                if lagging != 0 {
                    for e in (0..ENGINE_COUNT).filter(|e| lagging & (1 << e) != 0) {
                        let mut v = Tfcv {
                            target: target_n[e],
                            actuator: s.actuator_n[e],
                            valve: s.valve_n[e],
                        };
                        v.advance(dt_s, d, decay);
                        actuator[e] = v.actuator;
                    }
                }
                for e in 0..ENGINE_COUNT {
                    let (lo, hi) = (actuator[e] - d.half_backlash, actuator[e] + d.half_backlash);
                    let v = s.valve_n[e];
                    let v = if v < lo { lo } else { v };
                    s.valve_n[e] = if v > hi { hi } else { v };
                }
                s.actuator_n = actuator;
                before
            }
            Some(map) => {
                let before = s.clock.valve;
                s.clock
                    .advance(&target_n, &[1.0; ENGINE_COUNT], d, dt_s, decay);
                // Newtons per position newton over this step's move: at the middle of
                // the way the actuator can go in one step towards the target. How far
                // that is depends on the slope itself; the slope at the middle of the
                // range sets it, which is close enough to place the middle and keeps
                // one slope evaluation, not two, in the step's chain of dependent
                // operations (measured: 8-11 ns a step less in the probe).
                let slope: [f64; ENGINE_COUNT] = std::array::from_fn(|e| {
                    let at = s.actuator_n[e];
                    let moved = (target_n[e] - at).max(-self.reach_n).min(self.reach_n);
                    map.at(at + 0.5 * moved)
                });
                step_valve(
                    &mut s.actuator_n,
                    &mut s.valve_n,
                    &target_n,
                    &slope,
                    d,
                    dt_s,
                    decay,
                );
                before
            }
        };
        if let Some(c) = &self.ignition {
            let clock_n = if self.stroke.is_some() {
                s.clock.valve
            } else {
                s.valve_n
            };
            let on: [bool; ENGINE_COUNT] = std::array::from_fn(|e| input[ENGINE_COUNT + e] > 0.5);
            let total = valve_sum_of(input, &clock_n);
            for e in 0..ENGINE_COUNT {
                let drawing = if on[e] { clock_n[e] } else { 0.0 };
                c.advance(
                    on[e],
                    clock_before_n[e],
                    clock_n[e],
                    total - drawing,
                    dt_s,
                    self.drain_root,
                    &mut s.fill[e],
                    &mut s.since_ignition_s[e],
                );
            }
        }
        s
    }
}

/// Sum of the four commands of one step (off engines are commanded 0), in engine order.
#[inline(always)]
pub fn command_sum_of(input: &InputVec) -> f64 {
    input[0] + input[1] + input[2] + input[3]
}

/// Sum of the valve positions `valve_n` of the engines that are on in `input`, in engine
/// order: what the engines draw through their shared feed. A parked valve of an engine
/// that is off draws nothing.
#[inline(always)]
pub fn valve_sum_of(input: &InputVec, valve_n: &[f64; ENGINE_COUNT]) -> f64 {
    let drawing = |e: usize| {
        if input[ENGINE_COUNT + e] > 0.5 {
            valve_n[e]
        } else {
            0.0
        }
    };
    drawing(0) + drawing(1) + drawing(2) + drawing(3)
}

/// How much more the engines draw after step `t - lag` than after the step before
/// ([`valve_sum_of`], [`FeatureSpec::valve_sum`]).
#[inline]
pub fn valve_sum_change_of<H: History + ?Sized>(h: &H, lag: usize) -> f64 {
    valve_sum_of(h.input(lag), &h.valve(lag).valve_n)
        - valve_sum_of(h.input(lag + 1), &h.valve(lag + 1).valve_n)
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
        let n = self.history;
        let (e0, e1) = match self.layout {
            Layout::Mimo => (0, ENGINE_COUNT),
            Layout::PerEngine => (engine, engine + 1),
        };
        let out = &mut out[..self.dim()];
        let mut i = 0;
        let mut put = |x: f64| {
            out[i] = x;
            i += 1;
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
        debug_assert_eq!(i, self.dim());
    }
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
                valve: Some(crate::surrogate::predictor::tests::TEST_VALVE),
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

    /// The draw changes: what the engines that are on draw after a step, less what they
    /// drew after the step before; an engine that is off draws nothing, however its
    /// valve is parked, and before the first step nothing was drawn.
    #[test]
    fn draw_changes_count_only_engines_that_are_on() {
        let spec = FeatureSpec {
            valve: Some(crate::surrogate::predictor::tests::TEST_VALVE),
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

    /// The valve filter: parked when off, a large step at the rate limit, a small one
    /// with the lag, a reversal only after the backlash.
    #[test]
    fn valve_filter_rate_limit_lag_and_backlash() {
        let f = ValveFilter {
            time_constant_s: 0.015,
            rate_n_per_s: 6000.0,
            backlash_n: 4.0,
            park_n: 320.0,
            ignition: None,
            stroke: None,
        };
        let cmd = |c: f64, on: bool| {
            let mut u = [0.0; INPUT_DIM];
            u[0] = c;
            u[ENGINE_COUNT] = f64::from(u8::from(on));
            u
        };
        let mut v = ValveTrack::new(f, 0.01);
        let s = *v.advance(&cmd(0.0, false));
        assert_eq!(s.valve_n[0], 320.0, "off: parked at the minimum");
        // 320 -> 800 N: 480 N at 6000 N/s is rate-limited for the first 10 ms step.
        let s = *v.advance(&cmd(800.0, true));
        assert!((s.actuator_n[0] - 380.0).abs() < 1e-9, "{s:?}");
        assert!(
            (s.valve_n[0] - 378.0).abs() < 1e-9,
            "the valve trails by half the backlash"
        );
        for _ in 0..40 {
            v.advance(&cmd(800.0, true));
        }
        assert!((v.state.actuator_n[0] - 800.0).abs() < 1e-6);
        // A small step (10 N, inside rate x lag = 90 N): first order, 1 - e^(-10/15).
        let a0 = v.state.actuator_n[0];
        let s = *v.advance(&cmd(790.0, true));
        let want = 790.0 + (a0 - 790.0) * (-0.01f64 / 0.015).exp();
        assert!((s.actuator_n[0] - want).abs() < 1e-9);
        // Moving up, the valve trails the actuator by half the backlash; a reversal by
        // less than the backlash moves the actuator, not the valve.
        v.state = ValveState {
            actuator_n: [600.0; 4],
            valve_n: [598.0; 4],
            ..v.state
        };
        let r = *v.advance(&cmd(597.0, true));
        assert!(r.actuator_n[0] > 597.0 && r.actuator_n[0] < 599.0);
        assert_eq!(r.valve_n[0], 598.0);
        // Continuing up instead pushes the valve along.
        v.state = ValveState {
            actuator_n: [600.0; 4],
            valve_n: [598.0; 4],
            ..v.state
        };
        let r = *v.advance(&cmd(603.0, true));
        assert!((r.valve_n[0] - (r.actuator_n[0] - 2.0)).abs() < 1e-12);
        // Commands below the park value are raised to it.
        v.reset();
        assert_eq!(v.advance(&cmd(100.0, true)).actuator_n[0], 320.0);
        // Engine-parallel stepping is hifi's element, bit for bit: a random walk of
        // commands with large steps (rate-limited, then exponential) and small ones
        // (within the band), engines switching on and off.
        let dyn_ = TfcvDynamics {
            tau_s: f.time_constant_s,
            rate_per_s: f.rate_n_per_s,
            half_backlash: 0.5 * f.backlash_n,
            quantum: 0.0,
        };
        let decay = (-0.01f64 / f.time_constant_s).exp();
        let mut w = ValveTrack::new(f, 0.01);
        let mut hifi = [Tfcv {
            target: 0.0,
            actuator: 320.0,
            valve: 320.0,
        }; ENGINE_COUNT];
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut lagging_steps = 0;
        for k in 0..2000 {
            let mut u = [0.0; INPUT_DIM];
            for (e, h) in hifi.iter_mut().enumerate() {
                let r: f64 = rng.gen();
                let on = (k / 37 + e) % 5 != 0;
                u[e] = if on { 300.0 + 500.0 * r * r } else { 0.0 };
                u[ENGINE_COUNT + e] = f64::from(u8::from(on));
                h.target = u[e].max(f.park_n);
                lagging_steps += usize::from((h.target - h.actuator).abs() > 90.0);
                h.advance(0.01, &dyn_, decay);
            }
            let s = w.advance(&u);
            for (e, h) in hifi.iter().enumerate() {
                assert_eq!(s.actuator_n[e].to_bits(), h.actuator.to_bits(), "step {k}");
                assert_eq!(s.valve_n[e].to_bits(), h.valve.to_bits(), "step {k}");
            }
        }
        assert!(
            lagging_steps > 500,
            "{lagging_steps} rate-limited engine steps"
        );
        // Training's track is the same stepping.
        let inputs = [cmd(0.0, false), cmd(800.0, true), cmd(790.0, true)];
        let mut w = ValveTrack::new(f, 0.01);
        let stepped: Vec<ValveState> = inputs.iter().map(|u| *w.advance(u)).collect();
        assert_eq!(f.track(&inputs, 0.01), stepped);
        assert!(f.validate().is_ok());
        assert!(ValveFilter {
            time_constant_s: 0.0,
            ..f
        }
        .validate()
        .is_err());
        assert!(ValveFilter {
            backlash_n: f64::NAN,
            ..f
        }
        .validate()
        .is_err());
    }

    /// The ignition clock: a dry dome fills in `fill_n_s / valve`, the crossing is
    /// interpolated within the step, a full dome drains in `drain_time_s`, and a part-full
    /// one refills sooner.
    #[test]
    fn ignition_clock_fills_interpolates_and_drains() {
        let clock = IgnitionClock {
            fill_n_s: 25.0,
            drain_time_s: 0.6,
            full: 1.25,
            lead_s: 0.0,
            knot_spacing_s: 0.005,
            knots: 4,
            sag_per_n: 0.0,
        };
        let f = ValveFilter {
            time_constant_s: 0.015,
            rate_n_per_s: 6000.0,
            backlash_n: 0.0,
            park_n: 500.0,
            ignition: Some(clock),
            stroke: None,
        };
        let cmd = |on: bool| {
            let mut u = [0.0; INPUT_DIM];
            u[0] = 500.0;
            u[ENGINE_COUNT] = f64::from(u8::from(on));
            u
        };
        let mut v = ValveTrack::new(f, 0.01);
        // Off: nothing fills. On at a steady 500 N valve: 25 N s fill in 50 ms, so the
        // dome reaches the ignition fill at the end of the 5th step, exactly.
        assert_eq!(v.advance(&cmd(false)).since_ignition_s[0], NOT_IGNITED);
        for k in 1..=4 {
            let s = *v.advance(&cmd(true));
            assert!((s.fill[0] - 0.2 * k as f64).abs() < 1e-12);
            assert_eq!(s.since_ignition_s[0], NOT_IGNITED);
        }
        let s = *v.advance(&cmd(true));
        assert!(s.since_ignition_s[0].abs() < 1e-12, "{s:?}");
        // Then the clock runs, and the dome stops at full.
        for _ in 0..3 {
            v.advance(&cmd(true));
        }
        assert!((v.state.since_ignition_s[0] - 0.03).abs() < 1e-12);
        assert_eq!(v.state.fill[0], 1.25);
        // Hats: 1 at their knot, linear between, 0 before ignition and past the window.
        assert_eq!(clock.hat(0.0, 0), 1.0);
        assert!((clock.hat(0.0075, 1) - 0.5).abs() < 1e-12);
        assert!((clock.hat(0.0075, 2) - 0.5).abs() < 1e-12);
        assert_eq!(clock.hat(0.0075, 0), 0.0);
        assert_eq!(clock.hat(NOT_IGNITED, 0), 0.0);
        assert_eq!(clock.hat(clock.window_s(), clock.knots - 1), 0.0);
        // Off for 0.3 s: sqrt(fill) falls by half of sqrt(full), so a quarter is left.
        for _ in 0..30 {
            v.advance(&cmd(false));
        }
        assert!((v.state.fill[0] - 1.25 / 4.0).abs() < 1e-9, "{:?}", v.state);
        assert_eq!(v.state.since_ignition_s[0], NOT_IGNITED);
        // ... so it refills to ignition in 0.6875 of a dry fill: 34.4 ms, crossing
        // within the 4th step, 5.6 ms before its end.
        for _ in 0..3 {
            assert_eq!(v.advance(&cmd(true)).since_ignition_s[0], NOT_IGNITED);
        }
        let s = *v.advance(&cmd(true));
        assert!((s.since_ignition_s[0] - 0.005_625).abs() < 1e-9, "{s:?}");
        // A full drain empties it: 0.6 s.
        for _ in 0..60 {
            v.advance(&cmd(false));
        }
        assert_eq!(v.state.fill[0], 0.0);
        // With a lead of 20 ms the clock starts 20 ms before the estimate, counting the
        // time to go at the current valve; the hats move with it.
        let led = IgnitionClock {
            lead_s: 0.02,
            ..clock
        };
        let mut w = ValveTrack::new(
            ValveFilter {
                ignition: Some(led),
                stroke: None,
                ..f
            },
            0.01,
        );
        let since: Vec<f64> = (0..7)
            .map(|_| w.advance(&cmd(true)).since_ignition_s[0])
            .collect();
        assert_eq!(since[..2], [NOT_IGNITED; 2]);
        for (k, want) in [(2, -0.02), (3, -0.01), (4, 0.0), (5, 0.01), (6, 0.02)] {
            assert!((since[k] - want).abs() < 1e-12, "{since:?}");
        }
        assert_eq!(led.hat(-0.02, 0), 1.0);
        assert!((led.window_s() - 0.0).abs() < 1e-15);
        // Sag: with three other engines on at 500 N each and 1/6000 per N, the dome
        // fills at 1 / (1 + 0.25) of the rate, so ignition takes 62.5 ms instead of
        // 50 ms: within the 7th step, 7.5 ms before its end. An engine alone is not
        // slowed, nor by engines that are off.
        let sagging = IgnitionClock {
            sag_per_n: 1.0 / 6000.0,
            ..clock
        };
        let all = |on: bool, others_on: bool| {
            let mut u = [500.0; INPUT_DIM];
            u[ENGINE_COUNT] = f64::from(u8::from(on));
            for e in 1..ENGINE_COUNT {
                u[ENGINE_COUNT + e] = f64::from(u8::from(others_on));
                u[e] = if others_on { 500.0 } else { 0.0 };
            }
            u
        };
        let sag_filter = ValveFilter {
            ignition: Some(sagging),
            stroke: None,
            ..f
        };
        let mut w = ValveTrack::new(sag_filter, 0.01);
        let since: Vec<f64> = (0..7)
            .map(|_| w.advance(&all(true, true)).since_ignition_s)
            .map(|s| s[0])
            .collect();
        assert_eq!(since[..6], [NOT_IGNITED; 6], "{since:?}");
        assert!((since[6] - 0.0075).abs() < 1e-12, "{since:?}");
        let mut alone = ValveTrack::new(sag_filter, 0.01);
        let since: Vec<f64> = (0..5)
            .map(|_| alone.advance(&all(true, false)).since_ignition_s[0])
            .collect();
        assert!(since[4].abs() < 1e-12, "{since:?}");
        // Validation names the bad parameter.
        let names = |c: IgnitionClock, name: &str| {
            let err = c.validate().unwrap_err();
            assert!(err.contains(name), "{err:?} does not name {name}");
        };
        names(
            IgnitionClock {
                sag_per_n: -1.0,
                ..clock
            },
            "sag_per_n",
        );
        names(IgnitionClock { full: 0.9, ..clock }, "full");
        names(IgnitionClock { knots: 0, ..clock }, "knots");
        let err = ValveFilter {
            ignition: Some(IgnitionClock {
                fill_n_s: -1.0,
                ..clock
            }),
            ..f
        }
        .validate()
        .unwrap_err();
        assert!(err.contains("fill_n_s"), "{err:?}");
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
