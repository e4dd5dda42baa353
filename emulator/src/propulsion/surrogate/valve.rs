//! The throttle valve as the model sees it, computed from the commands alone: the
//! actuator filter ([`ValveFilter`], rate-limited in stroke through a [`StrokeMap`] when
//! the model has one) and the ignition clock ([`IgnitionClock`]) that estimates when each
//! engine's dome fills. [`ValveTrack`] runs both step by step, the same way in training
//! (over a recorded trajectory) and in the loop, and [`super::features`] reads them.

use super::features::InputVec;
use super::stroke_map::{StrokeMap, StrokeSlope};
use crate::propulsion::hifi::engine::{Tfcv, TfcvDynamics};
use oils_shared::ENGINE_COUNT;
use serde::{Deserialize, Serialize};
use wide::{f64x4, CmpEq, CmpGt, CmpLt};

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
    /// with them constant, the path its constants were fitted on (docs/journal/surrogate-history.md,
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
/// cold start ignites some 8 ms later than a single engine's at the same command), plus
/// `priming_sag_per_n * (valve positions of the other engines still priming)`: a branch
/// whose dome is still filling meets no injector and draws far more than a running one.
/// Parameters: `drain_time_s` and `full` are hifi's dome figures, `fill_n_s`, `sag_per_n`
/// and `priming_sag_per_n` are fitted to hifi's ignition times by `oils train`
/// (`surrogate::training::derive`).
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
    /// Slower filling per newton of the valve positions of the other engines that are
    /// still priming (on, dome short of ignition), on top of `sag_per_n`, 1/N (0: none).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub priming_sag_per_n: f64,
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
        if !(self.priming_sag_per_n.is_finite() && self.priming_sag_per_n >= 0.0) {
            return Err("ignition priming_sag_per_n must be finite and not negative".into());
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

    /// [`IgnitionClock::priming`] of four engines as lanes, from their switches
    /// (on above 0.5, as the features read them) and times since ignition.
    #[inline(always)]
    pub fn priming_lanes(switch: f64x4, since_ignition_s: f64x4) -> f64x4 {
        let on = switch.cmp_gt(f64x4::splat(0.5));
        super::features::indicator_lanes(on & since_ignition_s.cmp_eq(f64x4::splat(NOT_IGNITED)))
    }

    /// Where four engines' times since ignition fall among the knots (the `at` of
    /// [`IgnitionClock::hat`], the same operations), once for all the hats.
    #[inline(always)]
    pub fn clock_lanes(&self, since_ignition_s: f64x4) -> f64x4 {
        (since_ignition_s + f64x4::splat(self.lead_s)) / f64x4::splat(self.knot_spacing_s)
    }

    /// Whether every hat of [`IgnitionClock::clock_lanes`] `at` is 0.0 in every lane:
    /// no lane strictly between -1 and `knots` (a clock not running, -inf, or past its
    /// last knot). Exact: `at - j` rounds no higher than `at <= -1` nor lower than
    /// `knots - j >= 1`, so `1 - |at - j| <= 0` and the hat is `max(.., 0)` = +0.0;
    /// a lane that is not a number gives +0.0 too.
    #[inline(always)]
    pub fn hats_all_zero(&self, at: f64x4) -> bool {
        (at.cmp_gt(f64x4::splat(-1.0)) & at.cmp_lt(f64x4::splat(self.knots as f64))).none()
    }

    /// [`IgnitionClock::hat`] `j` of four engines at once from [`IgnitionClock::clock_lanes`].
    /// `max` with 0.0 returns 0.0 for a lane that is not a number, as `f64::max` does;
    /// `1 - |a|` is never -0.0, the one value where the two could differ.
    #[inline(always)]
    pub fn hat_lanes(at: f64x4, j: usize) -> f64x4 {
        (f64x4::ONE - (at - f64x4::splat(j as f64)).abs()).max(f64x4::ZERO)
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

    /// The part of [`IgnitionClock::advance`] for an engine that is on and has not yet
    /// ignited: the dome fills, ignition is placed within the step or the time still to
    /// go is read against the lead. Out of line and cold: it runs only in the first tens
    /// of milliseconds of a start.
    #[allow(clippy::too_many_arguments)]
    #[cold]
    #[inline(never)]
    fn filling(
        &self,
        f0: f64,
        valve0_n: f64,
        valve1_n: f64,
        fill_n_s: f64,
        dt_s: f64,
        fill: &mut f64,
        since_s: &mut f64,
    ) {
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
        priming_others_n: f64,
        dt_s: f64,
        drain_root: f64,
        fill: &mut f64,
        since_s: &mut f64,
    ) {
        if on {
            let f0 = *fill;
            // Without sag the factor is exactly 1 and the bits are those of the
            // unscaled constant.
            let fill_n_s = self.fill_n_s
                * (1.0 + self.sag_per_n * others_n + self.priming_sag_per_n * priming_others_n);
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
            self.filling(f0, valve0_n, valve1_n, fill_n_s, dt_s, fill, since_s);
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
        actuator = rate_limited(
            lagging,
            actuator,
            *actuator_n,
            *valve_n,
            *target,
            rate_per_s,
            half_backlash,
            d,
            dt_s,
            decay,
        );
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

/// The actuators of `step_valve` that are outside the lag's band of their target (bit e
/// of `lagging`): [`Tfcv::advance`], rate limit included, in `actuator`. Out of line
/// and cold: only a large command step gets here, and inline it put some hundreds of
/// instructions between the step's hot parts. Arrays by value: a reference to a local
/// array would keep it in memory for the whole step, not only on this path.
#[allow(clippy::too_many_arguments)]
#[cold]
#[inline(never)]
fn rate_limited(
    lagging: u8,
    mut actuator: [f64; ENGINE_COUNT],
    actuator_n: [f64; ENGINE_COUNT],
    valve_n: [f64; ENGINE_COUNT],
    target: [f64; ENGINE_COUNT],
    rate_per_s: [f64; ENGINE_COUNT],
    half_backlash: [f64; ENGINE_COUNT],
    d: &TfcvDynamics,
    dt_s: f64,
    decay: f64,
) -> [f64; ENGINE_COUNT] {
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
    actuator
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
                // factors of 1: the same operations and bits, without multiplying by
                // factors that are 1 on every step.
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
                    actuator = rate_limited(
                        lagging,
                        actuator,
                        s.actuator_n,
                        s.valve_n,
                        target_n,
                        [d.rate_per_s; ENGINE_COUNT],
                        [d.half_backlash; ENGINE_COUNT],
                        d,
                        dt_s,
                        decay,
                    );
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
                // operations.
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
            let priming: [f64; ENGINE_COUNT] = std::array::from_fn(|e| {
                if on[e] && s.fill[e] < 1.0 {
                    clock_n[e]
                } else {
                    0.0
                }
            });
            let priming_total = (priming[0] + priming[1]) + (priming[2] + priming[3]);
            for e in 0..ENGINE_COUNT {
                let drawing = if on[e] { clock_n[e] } else { 0.0 };
                c.advance(
                    on[e],
                    clock_before_n[e],
                    clock_n[e],
                    total - drawing,
                    priming_total - priming[e],
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

/// A valve filter for test models (hifi's TFCV figures in newtons); the core's and
/// the lab's tests share it.
#[doc(hidden)]
pub const TEST_VALVE: ValveFilter = ValveFilter {
    time_constant_s: 0.015,
    rate_n_per_s: 6000.0,
    backlash_n: 4.7,
    park_n: 320.0,
    ignition: Some(TEST_IGNITION),
    stroke: None,
};

/// An ignition clock for the test models (with both sags, so the engines' clocks
/// depend on each other).
#[doc(hidden)]
pub const TEST_IGNITION: IgnitionClock = IgnitionClock {
    fill_n_s: 20.0,
    drain_time_s: 0.6,
    full: 1.1,
    lead_s: 0.01,
    knot_spacing_s: 0.005,
    knots: 6,
    sag_per_n: 6e-5,
    priming_sag_per_n: 8e-5,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::propulsion::surrogate::features::INPUT_DIM;

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
            priming_sag_per_n: 0.0,
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
        // Engine 0's time since ignition after each of `steps` steps of `u`.
        let engine0 = |track: &mut ValveTrack, u: InputVec, steps: usize| -> Vec<f64> {
            (0..steps)
                .map(|_| track.advance(&u).since_ignition_s[0])
                .collect()
        };
        // Ignition 7.5 ms before the end of the 7th step (62.5 ms), not before.
        let slowed = |since: &[f64]| {
            assert_eq!(since[..6], [NOT_IGNITED; 6], "{since:?}");
            assert!((since[6] - 0.0075).abs() < 1e-12, "{since:?}");
        };
        slowed(&engine0(
            &mut ValveTrack::new(sag_filter, 0.01),
            all(true, true),
            7,
        ));
        let since = engine0(&mut ValveTrack::new(sag_filter, 0.01), all(true, false), 5);
        assert!(since[4].abs() < 1e-12, "{since:?}");
        // Priming sag: the same 1/6000 per N, for the other engines whose domes are still
        // filling only. Four engines started together all prime: 62.5 ms, as above ...
        let priming = ValveFilter {
            ignition: Some(IgnitionClock {
                priming_sag_per_n: 1.0 / 6000.0,
                ..clock
            }),
            stroke: None,
            ..f
        };
        let mut together = ValveTrack::new(priming, 0.01);
        slowed(&engine0(&mut together, all(true, true), 7));
        // ... but an engine restarted (after a full drain) beside three running engines is
        // not slowed: 50 ms, the end of the 5th step.
        let restart = |on: bool| {
            let mut u = all(true, true);
            u[ENGINE_COUNT] = f64::from(u8::from(on));
            u[0] = if on { 500.0 } else { 0.0 };
            u
        };
        for _ in 0..61 {
            together.advance(&restart(false));
        }
        assert_eq!(together.state.fill[0], 0.0);
        assert!(together.state.fill[1..].iter().all(|&f| f >= 1.0));
        let since = engine0(&mut together, restart(true), 5);
        assert_eq!(since[..4], [NOT_IGNITED; 4], "{since:?}");
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
        names(
            IgnitionClock {
                priming_sag_per_n: f64::NAN,
                ..clock
            },
            "priming_sag_per_n",
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
}
