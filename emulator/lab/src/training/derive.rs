//! What training derives from the reference model itself rather than from numbers in
//! `train.toml`: the throttle valve's stroke table (hifi's own calibration) and the
//! ignition clock's constants (fitted to hifi's ignition times). A retrain against
//! changed hifi parameters (a dispersed regulator, another dome) is then consistent with
//! them; copied by hand, they went stale silently.
//!
//! `train.toml` gives only what is not hifi's to say: the actuator's data-sheet figures,
//! the stroke table's grid, and the hat functions' placement ([`ValveSpec`]).

use oils_emulator::config::PropulsionConfig;
use oils_emulator::propulsion::hifi::{HifiParams, HifiPropulsion};
use oils_emulator::propulsion::surrogate::features::{InputVec, INPUT_DIM};
use oils_emulator::propulsion::surrogate::stroke_map::{StrokeMap, StrokeMapSpec};
use oils_emulator::propulsion::surrogate::valve::{
    IgnitionClock, ValveFilter, ValveTrack, NOT_IGNITED,
};
use oils_emulator::propulsion::{EngineCommand, Propulsion};
use oils_shared::ENGINE_COUNT;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The valve filter as `train.toml` gives it: the actuator's figures, and what to
/// derive from the reference.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValveSpec {
    /// Lag time constant, s (data sheet).
    pub time_constant_s: f64,
    /// Rate limit, N/s of equivalent thrust (data sheet).
    pub rate_n_per_s: f64,
    /// Backlash width, N of equivalent thrust (data sheet).
    pub backlash_n: f64,
    /// Where the valve parks with the engine off, N.
    pub park_n: f64,
    /// The stroke table's grid; the strokes are hifi's calibration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stroke: Option<StrokeGrid>,
    /// The hat functions of the ignition clock; its constants are fitted to hifi.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ignition: Option<ClockHats>,
}

/// Where the stroke table has knots: every `step_n` over the throttle range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrokeGrid {
    /// Commanded thrust between knots, N (must divide the throttle range).
    pub step_n: f64,
    /// The thrust a full stroke stands for, N: the unit of the rate and backlash.
    pub full_stroke_n: f64,
}

/// The ignition clock's hat functions (their placement is the model's choice; the
/// clock's dome constants are hifi's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClockHats {
    /// How long before the estimated ignition the clock starts, s.
    pub lead_s: f64,
    /// Spacing of the knots, s.
    pub knot_spacing_s: f64,
    /// Number of hat functions.
    pub knots: usize,
}

/// How well a fitted clock places hifi's ignitions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockFit {
    /// The clock.
    pub clock: IgnitionClock,
    /// Starts measured (that ignited).
    pub starts: usize,
    /// Mean of hifi's ignition time less the clock's, s (absorbed by the hats).
    pub offset_s: f64,
    /// RMS of that difference about its mean, s.
    pub rms_s: f64,
    /// Largest such deviation, s.
    pub max_s: f64,
}

impl std::fmt::Display for ClockFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.clock;
        write!(
            f,
            "ignition clock fill_n_s {:.1}, sag_per_n {:.1e}, priming_sag_per_n {:.1e}, \
             drain_time_s {}, full {:.4}: over {} hifi starts, hifi ignites {:.2} ms after \
             the clock on average, spread RMS {:.2} ms, max {:.2} ms",
            c.fill_n_s,
            c.sag_per_n,
            c.priming_sag_per_n,
            c.drain_time_s,
            c.full,
            self.starts,
            self.offset_s * 1e3,
            self.rms_s * 1e3,
            self.max_s * 1e3
        )
    }
}

impl ValveSpec {
    /// Checks the figures (the derived parts are checked once derived).
    pub fn validate(&self) -> Result<(), String> {
        self.filter(None, None).validate()?;
        if let Some(g) = &self.stroke {
            if !(g.step_n > 0.0 && g.full_stroke_n > 0.0) {
                return Err("stroke.step_n and stroke.full_stroke_n must be positive".into());
            }
        }
        if let Some(h) = &self.ignition {
            if !(h.lead_s >= 0.0 && h.knot_spacing_s > 0.0 && (1..=64).contains(&h.knots)) {
                return Err(
                    "ignition: lead_s >= 0, knot_spacing_s > 0 and knots 1..=64 needed".into(),
                );
            }
        }
        Ok(())
    }

    fn filter(&self, stroke: Option<StrokeMap>, ignition: Option<IgnitionClock>) -> ValveFilter {
        ValveFilter {
            time_constant_s: self.time_constant_s,
            rate_n_per_s: self.rate_n_per_s,
            backlash_n: self.backlash_n,
            park_n: self.park_n,
            ignition,
            stroke,
        }
    }

    /// The filter without anything to derive; an error if the spec asks for a stroke
    /// table or a clock (those need hifi, [`ValveSpec::derive`]).
    pub fn plain(&self) -> Result<ValveFilter, String> {
        if self.stroke.is_some() || self.ignition.is_some() {
            return Err(
                "a stroke table or an ignition clock is derived from the hifi reference".into(),
            );
        }
        Ok(self.filter(None, None))
    }

    /// The filter with its stroke table and clock derived from hifi with `params`.
    pub fn derive(
        &self,
        params: &HifiParams,
        propulsion: &PropulsionConfig,
        dt_s: f64,
    ) -> Result<(ValveFilter, Option<ClockFit>), String> {
        let stroke = match &self.stroke {
            Some(g) => Some(stroke_table(g, params, propulsion)?),
            None => None,
        };
        let filter = self.filter(stroke, None);
        let fit = match &self.ignition {
            Some(h) => Some(fit_ignition_clock(&filter, h, params, propulsion, dt_s)?),
            None => None,
        };
        let filter = self.filter(stroke, fit.map(|f| f.clock));
        filter.validate()?;
        Ok((filter, fit))
    }
}

/// The stroke table: the mean of hifi's fuel and oxidiser valve positions at every knot
/// of the grid over the throttle range (hifi's acceptance-test calibration).
pub fn stroke_table(
    grid: &StrokeGrid,
    params: &HifiParams,
    propulsion: &PropulsionConfig,
) -> Result<StrokeMap, String> {
    let hifi = HifiPropulsion::new(params, propulsion).map_err(|e| e.to_string())?;
    let first_n = propulsion.throttle_min_frac * propulsion.max_thrust_n;
    let intervals = (propulsion.max_thrust_n - first_n) / grid.step_n;
    if (intervals - intervals.round()).abs() > 1e-9 || intervals.round() < 1.0 {
        return Err(format!(
            "stroke.step_n {} does not divide the throttle range {first_n}..={} N",
            grid.step_n, propulsion.max_thrust_n
        ));
    }
    let stroke = (0..=intervals.round() as usize)
        .map(|k| {
            let [fuel, ox] = hifi
                .throttle_table()
                .positions(first_n + grid.step_n * k as f64);
            0.5 * (fuel + ox)
        })
        .collect();
    StrokeMap::try_from(StrokeMapSpec {
        first_n,
        step_n: grid.step_n,
        full_stroke_n: grid.full_stroke_n,
        stroke,
    })
    .map_err(|e| format!("stroke map from hifi's calibration: {e}"))
}

/// Thrust that marks ignition, N.
const IGNITION_THRUST_N: f64 = 100.0;
/// hifi's steps per model step while its ignitions are timed.
const FINE_STEPS: u64 = 100;
/// Model steps of the ignition schedule (240 s at 10 ms).
const SCHEDULE_STEPS: usize = 24_000;
/// Model steps of one group-start cycle (off half the time).
const GROUP_CYCLE_STEPS: usize = 300;

/// A small deterministic generator (xorshift64) for the start schedule.
struct Xorshift(u64);

impl Xorshift {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// One start: engine, the model step it switched on at, and hifi's ignition time after
/// the switch, s.
#[derive(Debug, Clone, Copy)]
struct Start {
    engine: usize,
    step: usize,
    ignition_s: f64,
}

/// hifi's ignitions over a schedule of starts: the first half random and independent
/// (each engine off 0.1-2.6 s, then on 0.5-2 s at a random command in the throttle
/// range), the second half group starts (every 3 s two to four engines switch on
/// together), where the engines draw on the shared feed at once. An off engine is
/// commanded 0 N, as everywhere else, so its valve parks. Ignition is where the thrust
/// crosses 100 N, interpolated in hifi's 0.1 ms steps.
fn hifi_ignitions(
    params: &HifiParams,
    propulsion: &PropulsionConfig,
    dt_s: f64,
) -> Result<(Vec<InputVec>, Vec<Start>), String> {
    let mut hifi = HifiPropulsion::new(params, propulsion).map_err(|e| e.to_string())?;
    let (lo, hi) = (
        propulsion.throttle_min_frac * propulsion.max_thrust_n,
        propulsion.max_thrust_n,
    );
    let step_ns = (dt_s * 1e9).round() as u64;
    let mut rng = Xorshift(0x9e37_79b9_7f4a_7c15);
    let mut cmd = EngineCommand::default();
    let mut next: [usize; ENGINE_COUNT] =
        std::array::from_fn(|_| 10 + (rng.uniform() * 100.0) as usize);
    let mut inputs = Vec::with_capacity(SCHEDULE_STEPS);
    let mut starts: Vec<(usize, usize, Option<f64>)> = Vec::new();
    let mut prev_thrust = [0.0; ENGINE_COUNT];
    for k in 0..SCHEDULE_STEPS {
        let mut switch_on = |e: usize, cmd: &mut EngineCommand, rng: &mut Xorshift| {
            cmd.on[e] = true;
            cmd.thrust_cmd_n[e] = lo + rng.uniform() * (hi - lo);
            starts.push((e, k, None));
        };
        if k < SCHEDULE_STEPS / 2 {
            for (e, due) in next.iter_mut().enumerate() {
                if k != *due {
                    continue;
                }
                if cmd.on[e] {
                    cmd.on[e] = false;
                    cmd.thrust_cmd_n[e] = 0.0;
                    *due = k + 10 + (rng.uniform() * 250.0) as usize;
                } else {
                    switch_on(e, &mut cmd, &mut rng);
                    *due = k + 50 + (rng.uniform() * 150.0) as usize;
                }
            }
        } else {
            let phase = (k - SCHEDULE_STEPS / 2) % GROUP_CYCLE_STEPS;
            if phase == 0 {
                cmd = EngineCommand::default();
            } else if phase == GROUP_CYCLE_STEPS / 2 {
                let n = 2 + (rng.uniform() * 3.0) as usize;
                for e in 0..n.min(ENGINE_COUNT) {
                    switch_on(e, &mut cmd, &mut rng);
                }
            }
        }
        let mut u = [0.0; INPUT_DIM];
        for e in 0..ENGINE_COUNT {
            u[e] = if cmd.on[e] { cmd.thrust_cmd_n[e] } else { 0.0 };
            u[ENGINE_COUNT + e] = f64::from(u8::from(cmd.on[e]));
        }
        inputs.push(u);
        let fine_s = dt_s / FINE_STEPS as f64;
        for fine in 0..FINE_STEPS {
            let out = hifi.step(&cmd, step_ns / FINE_STEPS);
            let t_s = (k as f64 + (fine + 1) as f64 / FINE_STEPS as f64) * dt_s;
            for s in starts.iter_mut().filter(|s| s.2.is_none()) {
                let (a, b) = (prev_thrust[s.0], out.thrust_n[s.0]);
                if b >= IGNITION_THRUST_N {
                    let within = (IGNITION_THRUST_N - a) / (b - a);
                    s.2 = Some(t_s - fine_s * (1.0 - within) - s.1 as f64 * dt_s);
                }
            }
            prev_thrust = out.thrust_n;
        }
    }
    // A start whose thrust had not yet fallen below the mark is not an ignition.
    let starts = starts
        .into_iter()
        .filter_map(|(engine, step, t)| {
            t.filter(|&t| t > 0.005).map(|ignition_s| Start {
                engine,
                step,
                ignition_s,
            })
        })
        .collect();
    Ok((inputs, starts))
}

/// The clock's ignition time after each start's switch, s (`None` if one never ignites).
fn clock_ignitions(
    filter: &ValveFilter,
    clock: IgnitionClock,
    inputs: &[InputVec],
    starts: &[Start],
    dt_s: f64,
) -> Option<Vec<f64>> {
    let mut track = ValveTrack::new(
        ValveFilter {
            ignition: Some(clock),
            ..*filter
        },
        dt_s,
    );
    let mut ignited_at: Vec<Vec<(usize, f64)>> = vec![Vec::new(); ENGINE_COUNT];
    let mut before = [NOT_IGNITED; ENGINE_COUNT];
    for (k, u) in inputs.iter().enumerate() {
        let s = track.advance(u);
        for e in 0..ENGINE_COUNT {
            let since = s.since_ignition_s[e];
            if since != NOT_IGNITED && before[e] == NOT_IGNITED {
                ignited_at[e].push((k, (k + 1) as f64 * dt_s - since));
            }
            before[e] = since;
        }
    }
    starts
        .iter()
        .map(|s| {
            ignited_at[s.engine]
                .iter()
                .find(|&&(k, _)| k >= s.step)
                .map(|&(_, t)| t - s.step as f64 * dt_s)
        })
        .collect()
}

/// Mean, RMS about the mean and largest deviation of hifi's ignition times less the
/// clock's.
fn spread(starts: &[Start], clock_s: &[f64]) -> (f64, f64, f64) {
    let d: Vec<f64> = starts
        .iter()
        .zip(clock_s)
        .map(|(s, c)| s.ignition_s - c)
        .collect();
    let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
    let rms = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len().max(1) as f64).sqrt();
    let max = d.iter().fold(0.0, |m: f64, x| m.max((x - mean).abs()));
    (mean, rms, max)
}

/// Fits the clock's fill constant and sags to hifi's ignition times: the spread of hifi
/// less the clock (a constant offset is absorbed by the hats) is minimised over sags in
/// steps of 5e-6 / N (0-6e-5), priming sags in steps of 5e-6 / N (0-1.2e-4) and fill
/// constants in 25-55 N s (by 1 N s, then by 0.2 N s around the best). The dome's drain
/// time and fill at ignition are hifi's parameters.
pub fn fit_ignition_clock(
    filter: &ValveFilter,
    hats: &ClockHats,
    params: &HifiParams,
    propulsion: &PropulsionConfig,
    dt_s: f64,
) -> Result<ClockFit, String> {
    let (inputs, starts) = hifi_ignitions(params, propulsion, dt_s)?;
    if starts.len() < 50 {
        return Err(format!(
            "only {} of hifi's starts ignited: no ignition clock to fit",
            starts.len()
        ));
    }
    let clock = |fill_n_s: f64, sag_per_n: f64, priming_sag_per_n: f64| IgnitionClock {
        fill_n_s,
        sag_per_n,
        priming_sag_per_n,
        drain_time_s: params.engine.dome_drain_time_s,
        full: 1.0 / params.engine.dome_fill_knee_frac,
        lead_s: hats.lead_s,
        knot_spacing_s: hats.knot_spacing_s,
        knots: hats.knots,
    };
    let score = |c: IgnitionClock| {
        clock_ignitions(filter, c, &inputs, &starts, dt_s).map(|t| spread(&starts, &t))
    };
    // The best fill constant for one pair of sags, and its spread.
    let best_fill = |sag: f64, priming: f64| {
        let best = |fills: &mut dyn Iterator<Item = f64>| {
            fills
                .filter_map(|f| score(clock(f, sag, priming)).map(|s| (f, s)))
                .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
        };
        let (coarse, _) = best(&mut (25..=55).map(f64::from))?;
        best(&mut (-5..=5).map(|i| coarse + 0.2 * f64::from(i)))
    };
    let pairs: Vec<(f64, f64)> = (0..=12)
        .flat_map(|i| (0..=24).map(move |j| (f64::from(i) * 5e-6, f64::from(j) * 5e-6)))
        .collect();
    let ((sag, priming), (fill, (offset_s, rms_s, max_s))) = pairs
        .par_iter()
        .filter_map(|&(s, p)| best_fill(s, p).map(|b| ((s, p), b)))
        .min_by(|a, b| {
            a.1 .1
                 .1
                .total_cmp(&b.1 .1 .1)
                .then(a.0 .0.total_cmp(&b.0 .0))
        })
        .ok_or("no fill constant in 25-55 N s ignites every start")?;
    Ok(ClockFit {
        clock: clock(fill, sag, priming),
        starts: starts.len(),
        offset_s,
        rms_s,
        max_s,
    })
}

/// How well a given clock places the ignitions of hifi with `params` (the same
/// schedule as [`fit_ignition_clock`]): offset, spread RMS and largest deviation, s.
pub fn clock_spread(
    filter: &ValveFilter,
    clock: IgnitionClock,
    params: &HifiParams,
    propulsion: &PropulsionConfig,
    dt_s: f64,
) -> Result<(f64, f64, f64), String> {
    let (inputs, starts) = hifi_ignitions(params, propulsion, dt_s)?;
    let t = clock_ignitions(filter, clock, &inputs, &starts, dt_s)
        .ok_or("some start never ignites on this clock")?;
    Ok(spread(&starts, &t))
}
