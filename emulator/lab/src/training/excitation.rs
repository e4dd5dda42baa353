//! Input excitation (seed paper, eq. 1-4): the four-engine signal on the 4-sphere, scaled
//! and biased over M thrust levels, plus step stairs, ramps and engine on/off switching.
//! Deterministic from a seed; clamped to the valid thrust range when an engine is on.

use oils_emulator::propulsion::surrogate::features::{InputVec, INPUT_DIM};
use oils_shared::profile::{ProfileError, ProfileRow, ThrustProfile};
use oils_shared::ENGINE_COUNT;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Shape of the excitation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExcitationConfig {
    /// Seed of the random stream (step levels, ramp ends, which engines switch).
    pub seed: u64,
    /// Lowest thrust command of an engine that is on, newtons (40 % of 800 N).
    pub thrust_min_n: f64,
    /// Highest thrust command, newtons.
    pub thrust_max_n: f64,
    /// M: number of bias levels E_k = E_min + k/M (E_max - E_min), k = 0..M-1.
    pub levels: usize,
    /// A_amp: amplitude of the sphere signal, newtons.
    pub amplitude_n: f64,
    /// How long each bias level is excited with the sphere signal, seconds.
    pub sphere_duration_s: f64,
    /// Time scale of the sphere signal: it is evaluated at `time_scale * t`.
    pub time_scale: f64,
    /// Number of step-stair holds per cycle.
    pub steps: usize,
    /// Hold time of one stair, seconds.
    pub step_hold_s: f64,
    /// Number of ramps per cycle.
    pub ramps: usize,
    /// Duration of one ramp, seconds.
    pub ramp_duration_s: f64,
    /// Number of on/off switching events per cycle.
    pub switches: usize,
    /// Hold time between switching events, seconds.
    pub switch_hold_s: f64,
    /// Per cycle, a long burn (rough-braking-like) at a random level in the upper
    /// `burn_band_n` of the range, all engines on, seconds: it ejects the propellant a
    /// whole descent ejects, so bottle pressure and ejected mass cover a descent's range.
    pub burn_s: f64,
    /// Width of the burn's level band below `thrust_max_n`, newtons.
    pub burn_band_n: f64,
    /// Beyond the paper: per cycle, this many cold starts after the burn: all engines off
    /// for `start_off_s` (longer than the dome drain, so the start is cold), then all on
    /// for `start_on_s` at a common level or, with probability 1/2, a level per engine.
    /// The switching events restart only a few engines, so without these a start
    /// transient is learned from a few dozen events; the held-out cases and a descent
    /// begin with all four engines starting at once.
    pub starts: usize,
    /// Off time before each cold start, seconds.
    pub start_off_s: f64,
    /// On time after each cold start, seconds.
    pub start_on_s: f64,
    /// The whole sequence (sphere levels, stairs, ramps, switching) is played this many
    /// times, each with fresh random draws and a time-shifted sphere signal.
    pub cycles: usize,
}

impl Default for ExcitationConfig {
    fn default() -> Self {
        Self {
            seed: 7,
            thrust_min_n: 320.0,
            thrust_max_n: 800.0,
            levels: 5,
            amplitude_n: 200.0,
            sphere_duration_s: 2.4,
            time_scale: 1.0,
            steps: 3,
            step_hold_s: 1.5,
            ramps: 2,
            ramp_duration_s: 2.0,
            switches: 4,
            switch_hold_s: 1.5,
            burn_s: 0.0,
            burn_band_n: 80.0,
            starts: 0,
            start_off_s: 1.0,
            start_on_s: 1.0,
            cycles: 5,
        }
    }
}

/// What kind of segment a sample belongs to (for plots and reports).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Segment {
    /// The 4-sphere signal at one bias level.
    Sphere,
    /// Step stair.
    Steps,
    /// Ramps.
    Ramps,
    /// On/off switching.
    Switching,
    /// Long burn near full throttle.
    Burn,
    /// Cold starts of all engines.
    Starts,
    /// Recorded data (`oils train --data`): whatever the recording's commands were.
    Recorded,
}

/// The excitation sampled at the surrogate's sample time.
#[derive(Debug, Clone, PartialEq)]
pub struct Excitation {
    /// Sample time, nanoseconds.
    pub sample_time_ns: u64,
    /// Inputs of every step: commands (N) then switches (0/1).
    pub inputs: Vec<InputVec>,
    /// Segment of every step.
    pub segments: Vec<Segment>,
}

/// The paper's eq. 3 at (scaled) time `t`: a point on the unit 4-sphere.
pub fn sphere_signal(t: f64) -> [f64; ENGINE_COUNT] {
    let r = PI * t;
    let theta = PI * (2.0 * (2.0 * t).sin()).sin();
    let phi = PI * (2.0 * t).sin();
    [
        r.cos() * theta.cos() * phi.cos(),
        r.cos() * theta.cos() * phi.sin(),
        r.cos() * theta.sin(),
        r.sin(),
    ]
}

/// One hold's commands: a common level, and with probability 1/2 an independent level
/// per engine instead (the engines' responses then differ). The order of the draws is
/// part of the committed model's provenance: changing it changes the training data.
fn draw_levels(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> [f64; ENGINE_COUNT] {
    let common = rng.gen_range(lo..=hi);
    let split = rng.gen_bool(0.5);
    std::array::from_fn(|_| {
        if split {
            rng.gen_range(lo..=hi)
        } else {
            common
        }
    })
}

impl ExcitationConfig {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), String> {
        let ok = self.thrust_min_n.is_finite()
            && self.thrust_max_n.is_finite()
            && 0.0 < self.thrust_min_n
            && self.thrust_min_n < self.thrust_max_n;
        if !ok {
            return Err("excitation: need 0 < thrust_min_n < thrust_max_n".into());
        }
        for (name, v) in [
            ("amplitude_n", self.amplitude_n),
            ("sphere_duration_s", self.sphere_duration_s),
            ("time_scale", self.time_scale),
            ("step_hold_s", self.step_hold_s),
            ("ramp_duration_s", self.ramp_duration_s),
            ("switch_hold_s", self.switch_hold_s),
            ("burn_s", self.burn_s),
            ("burn_band_n", self.burn_band_n),
            ("start_off_s", self.start_off_s),
            ("start_on_s", self.start_on_s),
        ] {
            if !(0.0..1e6).contains(&v) {
                return Err(format!("excitation.{name} = {v}: need finite, >= 0"));
            }
        }
        if self.levels == 0 || self.cycles == 0 {
            return Err("excitation: levels and cycles must be >= 1".into());
        }
        Ok(())
    }

    /// Total duration, seconds.
    pub fn duration_s(&self) -> f64 {
        self.cycles as f64
            * (self.levels as f64 * self.sphere_duration_s
                + self.steps as f64 * self.step_hold_s
                + self.ramps as f64 * self.ramp_duration_s
                + self.switches as f64 * self.switch_hold_s
                + self.burn_s
                + self.starts as f64 * (self.start_off_s + self.start_on_s))
    }

    /// Generates the excitation at `sample_time_ns`.
    pub fn generate(&self, sample_time_ns: u64) -> Excitation {
        let dt_s = sample_time_ns as f64 * 1e-9;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut ex = Excitation {
            sample_time_ns,
            inputs: Vec::with_capacity((self.duration_s() / dt_s) as usize + 8),
            segments: Vec::new(),
        };
        let steps_of = |d: f64| (d / dt_s).round() as usize;
        let (lo, hi) = (self.thrust_min_n, self.thrust_max_n);
        let clamp = |x: f64| x.clamp(lo, hi);
        let push = |ex: &mut Excitation, cmd: [f64; ENGINE_COUNT], on: [bool; 4], s| {
            let mut v = [0.0; INPUT_DIM];
            for e in 0..ENGINE_COUNT {
                v[e] = if on[e] { clamp(cmd[e]) } else { 0.0 };
                v[ENGINE_COUNT + e] = f64::from(u8::from(on[e]));
            }
            ex.inputs.push(v);
            ex.segments.push(s);
        };
        let all_on = [true; ENGINE_COUNT];
        let mut sphere_t0 = 0.0;
        for _ in 0..self.cycles {
            // Eq. 2 and 4: E_j(t, k) = E_k + A S_j(t).
            for k in 0..self.levels {
                let bias = lo + k as f64 / self.levels as f64 * (hi - lo);
                for i in 0..steps_of(self.sphere_duration_s) {
                    let t = sphere_t0 + self.time_scale * i as f64 * dt_s;
                    let s = sphere_signal(t);
                    push(
                        &mut ex,
                        s.map(|x| bias + self.amplitude_n * x),
                        all_on,
                        Segment::Sphere,
                    );
                }
                sphere_t0 += self.time_scale * self.sphere_duration_s;
            }
            // Step stair: each hold draws a common level, and with probability 1/2 an
            // independent level per engine (the engines' responses then differ).
            for _ in 0..self.steps {
                let cmd = draw_levels(&mut rng, lo, hi);
                for _ in 0..steps_of(self.step_hold_s) {
                    push(&mut ex, cmd, all_on, Segment::Steps);
                }
            }
            // Ramps from one random level to another, per engine.
            for _ in 0..self.ramps {
                let a: [f64; ENGINE_COUNT] = std::array::from_fn(|_| rng.gen_range(lo..=hi));
                let b: [f64; ENGINE_COUNT] = std::array::from_fn(|_| rng.gen_range(lo..=hi));
                let n = steps_of(self.ramp_duration_s).max(1);
                for i in 0..n {
                    let f = i as f64 / n as f64;
                    let cmd = std::array::from_fn(|e| a[e] + (b[e] - a[e]) * f);
                    push(&mut ex, cmd, all_on, Segment::Ramps);
                }
            }
            // On/off switching: each event turns a random subset of engines off (at least
            // two stay on, as in the terminal phase) or everything back on.
            for j in 0..self.switches {
                let on: [bool; ENGINE_COUNT] = if j % 2 == 1 {
                    all_on
                } else {
                    let mut on = all_on;
                    let off = rng.gen_range(1..=ENGINE_COUNT);
                    for _ in 0..off {
                        on[rng.gen_range(0..ENGINE_COUNT)] = false;
                    }
                    on
                };
                let cmd = std::array::from_fn(|_| rng.gen_range(lo..=hi));
                for _ in 0..steps_of(self.switch_hold_s) {
                    push(&mut ex, cmd, on, Segment::Switching);
                }
            }
            // Long burn: propellant use of a descent (drawn last so the earlier segments
            // keep their draws when only the burn changes).
            if self.burn_s > 0.0 {
                let band_lo = (hi - self.burn_band_n).max(lo);
                let cmd: [f64; ENGINE_COUNT] = std::array::from_fn(|_| rng.gen_range(band_lo..=hi));
                for _ in 0..steps_of(self.burn_s) {
                    push(&mut ex, cmd, all_on, Segment::Burn);
                }
            }
            // Cold starts (drawn after the burn, so the earlier segments keep their draws).
            for _ in 0..self.starts {
                let cmd = draw_levels(&mut rng, lo, hi);
                for _ in 0..steps_of(self.start_off_s) {
                    push(&mut ex, cmd, [false; ENGINE_COUNT], Segment::Starts);
                }
                for _ in 0..steps_of(self.start_on_s) {
                    push(&mut ex, cmd, all_on, Segment::Starts);
                }
            }
        }
        ex
    }
}

impl Excitation {
    /// Duration, seconds.
    pub fn duration_s(&self) -> f64 {
        self.inputs.len() as f64 * self.sample_time_ns as f64 * 1e-9
    }

    /// As a thrust-command profile (one row per sample, holding for one sample time).
    pub fn to_profile(&self) -> Result<ThrustProfile, ProfileError> {
        let rows = self
            .inputs
            .iter()
            .enumerate()
            .map(|(k, v)| ProfileRow {
                t_ns: k as i64 * self.sample_time_ns as i64,
                thrust_cmd_n: std::array::from_fn(|e| v[e]),
                on: std::array::from_fn(|e| v[ENGINE_COUNT + e] > 0.5),
            })
            .collect();
        ThrustProfile::from_rows(rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_signal_is_on_the_unit_sphere() {
        for i in 0..1000 {
            let s = sphere_signal(i as f64 * 0.013);
            let r2: f64 = s.iter().map(|x| x * x).sum();
            assert!((r2 - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn deterministic_clamped_and_complete() {
        let cfg = ExcitationConfig::default();
        let a = cfg.generate(10_000_000);
        let b = cfg.generate(10_000_000);
        assert_eq!(a, b);
        let other = ExcitationConfig {
            seed: 8,
            ..cfg.clone()
        }
        .generate(10_000_000);
        assert_ne!(a.inputs, other.inputs);
        assert!((a.duration_s() - cfg.duration_s()).abs() < 0.05);
        let mut saw_off = false;
        let mut saw_top = false;
        for v in &a.inputs {
            for e in 0..ENGINE_COUNT {
                if v[ENGINE_COUNT + e] > 0.5 {
                    assert!((320.0..=800.0).contains(&v[e]), "{v:?}");
                    saw_top |= v[e] == 800.0;
                } else {
                    assert_eq!(v[e], 0.0);
                    saw_off = true;
                }
            }
        }
        assert!(saw_off && saw_top);
        let p = a.to_profile().unwrap();
        assert_eq!(p.rows().len(), a.inputs.len());
        assert_eq!(ThrustProfile::parse(&p.to_csv()).unwrap(), p);
    }

    #[test]
    fn bias_levels_follow_eq_2() {
        // With zero amplitude, the sphere segments are the bias levels themselves.
        let cfg = ExcitationConfig {
            amplitude_n: 0.0,
            levels: 4,
            sphere_duration_s: 0.1,
            steps: 0,
            ramps: 0,
            switches: 0,
            cycles: 1,
            ..Default::default()
        };
        let ex = cfg.generate(10_000_000);
        let firsts: Vec<f64> = ex.inputs.chunks(10).map(|c| c[0][0]).collect();
        assert_eq!(firsts, vec![320.0, 440.0, 560.0, 680.0]);
    }
}
