//! One submodel compiled for the step: the features its active terms use, gathered
//! from the history window, and its rows' terms evaluated per engine lane.

use super::aligned::LaneSlots;
#[cfg(target_arch = "x86_64")]
use super::aligned::{four_lanes, four_lanes_mut};
use super::dense::{Dense, DENSE_ROWS};
#[cfg(target_arch = "x86_64")]
use super::gather::gather_lanes_avx2;
use super::gather::{Clock, ClockGather, FeatureScaling, Gather, PhaseGather, Phases};
use super::ring::{Ring, REC_LAMBDA, REC_STATE, REC_SUM, REC_VALVE, REC_VALVE_SUM_CHANGE};
use super::terms::CompiledRow;
use crate::surrogate::runtime::features::{Layout, Source, StateVec, STATE_MF, STATE_MO};
use crate::surrogate::runtime::model::{Submodel, Target};
use crate::surrogate::runtime::valve::IgnitionClock;

/// A submodel compiled for `LANES` evaluations per step: 1 for a MIMO submodel, 4 (one
/// per engine, evaluated together and vectorised, the same arithmetic per lane as for
/// one) for a per-engine submodel.
#[derive(Debug, Clone)]
pub(super) struct CompiledSub<const LANES: usize> {
    pub(super) target: Target,
    pub(super) outputs: Vec<usize>,
    /// Features the active terms use, and only those (a model of 60 active terms reads
    /// some 20-40 of its ~100 features): read once per step, into slots `0..shared.len()`
    /// ...
    pub(super) shared: Vec<Gather>,
    /// ... read per engine (per-engine submodels only), into the next slots ...
    pub(super) lanes: Vec<Gather>,
    /// ... and the phase indicators (per engine) ...
    pub(super) phases: Vec<PhaseGather>,
    /// ... and the ignition features (per engine), computed from the clock.
    pub(super) clock: Vec<ClockGather>,
    /// The ignition clock the features read.
    pub(super) ignition: Option<IgnitionClock>,
    /// The ignition features are exactly 0 outside an engine's window, so their terms
    /// are kept apart and they are gathered only while some engine is in it.
    pub(super) clock_grouped: bool,
    /// Phase group of "switched on k steps ago" (`[0][k]`) and "off" (`[1][k]`), for
    /// the indicators whose terms are kept apart (see [`CompiledRow`]).
    pub(super) phase_group: [Vec<Option<usize>>; 2],
    /// Gathered scaled features followed by the constant 1.0, one value per lane.
    pub(super) x: LaneSlots<LANES>,
    /// Linear terms only, their coefficients scaled: the features are gathered clamped
    /// but unscaled.
    pub(super) folded: bool,
    /// A folded submodel of up to [`DENSE_ROWS`] rows as dense coefficients, four
    /// features at a time: a chunk of four features then costs one vector multiply-add
    /// per row instead of one scalar multiply-add per term.
    pub(super) dense: Option<Dense>,
    /// The rows' terms, compiled (empty when `dense` evaluates the submodel).
    pub(super) rows: Vec<CompiledRow>,
}

impl<const LANES: usize> CompiledSub<LANES> {
    /// `depth`: the ring's depth (every lag the submodel reads is below it).
    pub(super) fn compile(s: &Submodel, depth: usize) -> Self {
        let dim = s.features.dim();
        let sources = s.features.sources();
        let per_engine = s.features.layout == Layout::PerEngine;
        assert_eq!(
            LANES,
            s.evaluations(),
            "compiled with the submodel's lane count"
        );
        let mut used = vec![false; dim + 1];
        for r in &s.rows {
            for t in &r.terms {
                for &f in &t.factors {
                    // A checked model never has a factor above dim; clamping makes the
                    // unchecked reads in `eval` sound for any model.
                    used[(f as usize).min(dim)] = true;
                }
            }
        }
        let scaling = |j: usize| FeatureScaling {
            lo: s.envelope_lo[j],
            hi: s.envelope_hi[j].max(s.envelope_lo[j]),
            mean: s.feature_mean[j],
            inv_std: 1.0 / s.feature_std[j],
        };
        let read = |j: usize, lag: usize, comp: usize| {
            assert!(lag < depth, "the ring holds every lag read");
            Gather {
                offset: Ring::offset(depth, lag, comp),
                scaling: scaling(j),
            }
        };
        // Sort the used features into shared reads, lane reads and phase indicators,
        // remembering which feature each read is.
        let (mut shared, mut lanes) = (Vec::new(), Vec::new());
        let mut phase_js = Vec::new();
        let mut clock_js = Vec::new();
        for j in (0..dim).filter(|&j| used[j]) {
            let lane = |p: bool| per_engine && p;
            match sources[j] {
                Source::Input {
                    lag,
                    comp,
                    per_engine: p,
                } => (if lane(p) { &mut lanes } else { &mut shared }).push((j, read(j, lag, comp))),
                Source::State {
                    lag,
                    comp,
                    per_engine: p,
                } => (if lane(p) { &mut lanes } else { &mut shared })
                    .push((j, read(j, lag, REC_STATE + comp))),
                Source::Lambda => shared.push((j, read(j, 1, REC_LAMBDA))),
                Source::CommandSum => shared.push((j, read(j, 0, REC_SUM))),
                Source::Valve { lag } => lanes.push((j, read(j, lag, REC_VALVE))),
                Source::ValveSum { lag } => shared.push((j, read(j, lag, REC_VALVE_SUM_CHANGE))),
                Source::Start(_) | Source::Stop(_) => phase_js.push(j),
                Source::Priming | Source::Ignition(..) => clock_js.push(j),
            }
        }
        // `slot[j]`: feature j's place in `x`, in the order gathered; `dim` maps to the
        // 1.0 slot.
        let mut slot = vec![0u16; dim + 1];
        let mut count = 0;
        for &j in shared
            .iter()
            .chain(&lanes)
            .map(|(j, _)| j)
            .chain(&phase_js)
            .chain(&clock_js)
        {
            slot[j] = count as u16;
            count += 1;
        }
        slot[dim] = count as u16;
        let mut phases: Vec<PhaseGather> = phase_js
            .iter()
            .map(|&j| PhaseGather {
                slot: slot[j] as usize,
                on: matches!(sources[j], Source::Start(_)),
                run: match sources[j] {
                    Source::Start(k) | Source::Stop(k) => k + 1,
                    _ => unreachable!("only phase indicators are listed"),
                },
                scaling: scaling(j),
            })
            .collect();
        // Phase indicators that are exactly 0 outside their phase get a term group.
        let mut group = vec![None; count + 1];
        let mut phase_group = [Vec::new(), Vec::new()];
        let mut groups = 0;
        let mut constant = Vec::new();
        phases.retain(|g| {
            let sc = g.scaling;
            // 0 scales to exactly 0 and neither 0 nor 1 is ever clamped: then every term
            // with the indicator is 0 outside the phase (not evaluated) and sees the
            // indicator's in-phase value inside it, a constant set here once.
            let skippable = sc.mean == 0.0 && sc.lo <= 0.0 && sc.hi >= 1.0;
            if skippable {
                group[g.slot] = Some(groups);
                let table = &mut phase_group[usize::from(!g.on)];
                if table.len() < g.run {
                    table.resize(g.run, None);
                }
                table[g.run - 1] = Some(groups);
                groups += 1;
                constant.push((g.slot, sc.apply(1.0).0));
            }
            !skippable
        });
        let clock: Vec<ClockGather> = clock_js
            .iter()
            .map(|&j| ClockGather {
                slot: slot[j] as usize,
                hat: match sources[j] {
                    Source::Ignition(k, _) => Some(k),
                    _ => None,
                },
                scaling: scaling(j),
            })
            .collect();
        // As for the phase indicators: 0 must scale to exactly 0, unclamped.
        let clock_grouped = clock
            .iter()
            .all(|g| g.scaling.mean == 0.0 && g.scaling.lo <= 0.0 && g.scaling.hi >= 0.0);
        let mut clocked = vec![false; count + 1];
        if clock_grouped {
            for g in &clock {
                clocked[g.slot] = true;
            }
        }
        let mut x = vec![[1.0; LANES]; count + 1];
        for (slot, v) in constant {
            x[slot] = [v; LANES];
        }
        // A submodel of linear terms only (the pressure and mass rows) has the scaling
        // folded into its coefficients: `c * (v - mean) / std` is `(c / std) * v` plus a
        // constant, so a feature costs a clamp rather than a clamp, a subtraction and a
        // multiplication. The sum moves by rounding only.
        let folded = phase_js.is_empty()
            && clock_js.is_empty()
            && s.rows.iter().all(|r| {
                r.terms
                    .iter()
                    .all(|t| t.factors.iter().filter(|&&f| f as usize != dim).count() <= 1)
            });
        let rows: Vec<CompiledRow> = s
            .rows
            .iter()
            .map(|r| {
                if !folded {
                    return CompiledRow::new(r, &slot, dim, &group, groups, &clocked);
                }
                let mut r = r.clone();
                for t in &mut r.terms {
                    if let Some(&j) = t.factors.iter().find(|&&f| (f as usize) < dim) {
                        let j = j as usize;
                        t.coef /= s.feature_std[j];
                        r.intercept -= t.coef * s.feature_mean[j];
                    }
                }
                CompiledRow::new(&r, &slot, dim, &group, groups, &clocked)
            })
            .collect();
        let unscaled = |(_, g): (usize, Gather)| {
            if folded {
                Gather {
                    scaling: FeatureScaling {
                        mean: 0.0,
                        inv_std: 1.0,
                        ..g.scaling
                    },
                    ..g
                }
            } else {
                g
            }
        };
        let shared: Vec<Gather> = shared.into_iter().map(unscaled).collect();
        let dense = (folded && LANES == 1 && rows.len() <= DENSE_ROWS).then(|| {
            let mut intercept = [0.0; DENSE_ROWS];
            let mut coef = vec![[0.0; DENSE_ROWS]; count];
            for (r, row) in rows.iter().enumerate() {
                intercept[r] = row.intercept;
                // Folded rows are linear: every term is a single factor (checked here,
                // once, so that no term could be dropped silently).
                assert!(
                    row.terms.groups.is_empty(),
                    "a folded row has only linear terms"
                );
                for &([a], c) in &row.terms.single {
                    coef[a as usize][r] += c;
                }
            }
            // A dense submodel reads shared features only: its slots are `shared`'s.
            assert_eq!(
                count,
                shared.len(),
                "a dense submodel has shared reads only"
            );
            Dense::new(intercept, &shared, &coef)
        });
        // The dense coefficients replace the rows.
        let rows = if dense.is_some() { Vec::new() } else { rows };
        Self {
            dense,
            phase_group,
            target: s.target,
            outputs: s.outputs.clone(),
            x: LaneSlots::new(&x),
            folded,
            shared,
            lanes: lanes.into_iter().map(unscaled).collect(),
            phases,
            clock,
            ignition: s.features.ignition(),
            clock_grouped,
            rows,
        }
    }

    /// Gathers, clamps and scales the used features of the history `window` into `x`;
    /// true when one was outside its envelope. `AVX2`: as in [`CompiledSub::eval`].
    #[inline(always)]
    pub(super) fn gather<const AVX2: bool>(
        &mut self,
        window: &[f64],
        phases: &Phases,
        clock: &Clock,
    ) -> bool {
        let mut outside = 0;
        // SAFETY: `compile` places every read (and the engines after it) inside a window
        // of the ring's depth, which is the length of `window`.
        let at = |i: usize| unsafe { *window.get_unchecked(i) };
        debug_assert!(self.lanes.iter().all(|g| g.offset + LANES <= window.len()));
        debug_assert!(self.shared.iter().all(|g| g.offset < window.len()));
        let (x_shared, x_rest) = self.x.slots_mut().split_at_mut(self.shared.len());
        if self.folded {
            for (g, x) in self.shared.iter().zip(x_shared) {
                let (v, out) = g.scaling.clamp(at(g.offset));
                *x = [v; LANES];
                outside |= out;
            }
        } else {
            for (g, x) in self.shared.iter().zip(x_shared) {
                let (v, out) = g.scaling.apply(at(g.offset));
                *x = [v; LANES];
                outside |= out;
            }
        }
        #[cfg(target_arch = "x86_64")]
        let lanes_done = match four_lanes_mut(x_rest) {
            Some(x4) if AVX2 => {
                // SAFETY: the CPU has AVX2 (the caller checked); reads as above.
                outside |= unsafe { gather_lanes_avx2(&self.lanes, window, x4) };
                true
            }
            _ => false,
        };
        #[cfg(not(target_arch = "x86_64"))]
        let lanes_done = false;
        if !lanes_done {
            for (g, x) in self.lanes.iter().zip(x_rest) {
                for (e, x) in x.iter_mut().enumerate() {
                    let (v, out) = g.scaling.apply(at(g.offset + e));
                    *x = v;
                    outside |= out;
                }
            }
        }
        for g in &self.phases {
            let x = &mut self.x.slots_mut()[g.slot];
            for (e, x) in x.iter_mut().enumerate() {
                let hit = phases.on[e] == g.on && phases.run[e] == g.run;
                let (v, out) = g.scaling.apply(f64::from(u8::from(hit)));
                *x = v;
                outside |= out;
            }
        }
        if self.ignition.is_some() && (clock.any || !self.clock_grouped) {
            outside |= self.gather_clock(phases, clock);
        }
        outside != 0
    }

    /// The ignition features, per engine (non-zero: one was outside its envelope). Out of
    /// line and cold: they are read only while an engine is in its ignition window.
    #[cold]
    #[inline(never)]
    fn gather_clock(&mut self, phases: &Phases, clock: &Clock) -> u64 {
        let Some(c) = &self.ignition else {
            return 0;
        };
        let mut outside = 0;
        for g in &self.clock {
            let x = &mut self.x.slots_mut()[g.slot];
            for (e, x) in x.iter_mut().enumerate() {
                let since = clock.since_ignition_s[e];
                let raw = match g.hat {
                    None => IgnitionClock::priming(phases.on[e], since),
                    Some(j) => c.hat(since, j),
                };
                let (v, out) = g.scaling.apply(raw);
                *x = v;
                outside |= out;
            }
        }
        outside
    }

    /// Predicts this submodel's outputs into `next`, guarded ([`guarded`]); true when a
    /// feature was outside its envelope or a prediction was not finite. `AVX2`: the step
    /// runs in its AVX2 build (see [`super::Predictor::step`]), and the lanes, term sums
    /// and dense rows take their AVX2 intrinsics.
    #[inline(always)]
    pub(super) fn eval<const AVX2: bool>(
        &mut self,
        window: &[f64],
        phases: &Phases,
        clock: &Clock,
        prev: &StateVec,
        next: &mut StateVec,
    ) -> bool {
        let mut nonfinite = false;
        if let Some(d) = &self.dense {
            debug_assert!(self.lanes.is_empty() && self.phases.is_empty() && self.clock.is_empty());
            let (y, outside) = d.eval::<AVX2>(window);
            for (&o, y) in self.outputs.iter().zip(y) {
                next[o] = guarded(o, self.target.apply(prev[o], y), prev[o], &mut nonfinite);
            }
            return outside | nonfinite;
        }
        let outside = self.gather::<AVX2>(window, phases, clock);
        if LANES == 1 {
            for (row, &o) in self.rows.iter().zip(&self.outputs) {
                let mut y = [row.intercept; LANES];
                row.terms.add(self.x.slots(), &mut y);
                next[o] = guarded(o, self.target.apply(prev[o], y[0]), prev[o], &mut nonfinite);
            }
        } else {
            // One shared row for the engines, plus each engine's phase terms.
            let row = &self.rows[0];
            let mut y = [row.intercept; LANES];
            #[cfg(target_arch = "x86_64")]
            let added = match (
                four_lanes(self.x.slots()),
                <&mut [f64; 4]>::try_from(&mut y[..]),
            ) {
                (Some(x4), Ok(y4)) if AVX2 => {
                    // SAFETY: the CPU has AVX2 (the caller checked); `compile` maps every
                    // factor to a slot of `x`.
                    unsafe { row.terms.add_avx2(x4, y4) };
                    true
                }
                _ => false,
            };
            #[cfg(not(target_arch = "x86_64"))]
            let added = false;
            if !added {
                row.terms.add(self.x.slots(), &mut y);
            }
            for (e, y) in y.iter_mut().enumerate() {
                let table = &self.phase_group[usize::from(!phases.on[e])];
                if let Some(&Some(g)) = table.get(phases.run[e] - 1) {
                    row.phase[g].add_lane(self.x.slots(), e, y);
                }
                if self.clock_grouped && clock.active[e] {
                    row.clock.add_lane(self.x.slots(), e, y);
                }
            }
            for (&o, y) in self.outputs.iter().zip(y) {
                next[o] = guarded(o, self.target.apply(prev[o], y), prev[o], &mut nonfinite);
            }
        }
        outside | nonfinite
    }
}

/// The physical guards on output `o`: thrust and pressure not negative, ejected mass
/// never falling; a prediction that is not finite keeps the previous value (and sets
/// `nonfinite`, so the step is counted). Applied as each output is written, not over the
/// assembled state afterwards: that pass read the state back as vectors just after it
/// was written value by value, a store-forwarding stall.
#[inline(always)]
fn guarded(o: usize, v: f64, prev: f64, nonfinite: &mut bool) -> f64 {
    let v = if v.is_finite() {
        v
    } else {
        *nonfinite = true;
        prev
    };
    if o == STATE_MF || o == STATE_MO {
        v.max(prev)
    } else {
        // The thrusts and the gas pressure.
        v.max(0.0)
    }
}
