//! Attitude thrusters at device level: eight on/off thrusters, each at a position and
//! thrusting along a direction in body axes, fired for the on-time the flight software
//! commands per cycle, with a minimum on-time, valve opening and closing delays and a
//! first-order thrust rise and tail. Pure arithmetic on fixed-size arrays: no
//! allocation after construction, no I/O, no clock. See `docs/plant.md`, "Attitude
//! thrusters".
//!
//! # One pulse
//! A command issued for the cycle starting at `t_c` asks thruster `i` for an on-time
//! `T` (ns, at most the cycle). The electrical pulse is `[t_c, t_c + T)`:
//! - `0 < T < T_min` (the minimum on-time, `lander.rcs_min_on_time_s`) is **not fired**:
//!   the valve driver drops a pulse shorter than it can open the valve for, so the
//!   smallest impulse a thruster gives is the minimum impulse bit
//!   `I_min = F (T_min + d_close - d_open)`;
//! - the valve is open over `[t_o, t_f) = [t_c + d_open, t_c + T + d_close)`, with
//!   `d_open`, `d_close` the opening and closing delays;
//! - thrust follows the valve through a first-order lag of time constant `tau`: with
//!   `u(t)` = 1 while the valve is open, 0 otherwise, and `x` the thrust fraction,
//!   `tau dx/dt = u - x`, thrust `F x(t)` along the thruster's direction `d`.
//!
//! Pulses of successive cycles whose electrical pulses touch (an on-time of the whole
//! cycle followed by another pulse) are one pulse: the valve stays open. Valve-open
//! intervals that overlap are their union. A command whose `cycle_start_ns` is not
//! later than the last one latched (a command held over a missed cycle) fires nothing
//! new.
//!
//! # Exact impulse over any interval
//! On a piece `[s, s + h)` of a step where the valve state `u` does not change (the
//! step is split at every `t_o`, `t_f` inside it), starting at thrust fraction `x0`:
//! ```text
//! x(s + h)       = u + (x0 - u) e^(-h/tau)
//! int_s^(s+h) x  = u h + (x0 - u) tau (1 - e^(-h/tau))
//! ```
//! (`tau = 0`: `x = u`, integral `u h`). Summed over the pieces this is the exact
//! integral of the thrust, so impulse and propellant do not depend on how a pulse is cut
//! into plant steps. Over a whole isolated pulse the rise's lag and the tail cancel:
//! ```text
//! rise  [t_o, t_f):  F (D - tau (1 - e^(-D/tau))),   D = t_f - t_o = T + d_close - d_open
//! tail  [t_f, inf):  F tau (1 - e^(-D/tau))
//! total:             I = F D = F (T + d_close - d_open)
//! ```
//! Once the valve is closed with nothing pending and `x` falls below [`TAIL_CUTOFF`],
//! `x` is set to 0 (the impulse lost is below `1e-15 F tau`) and the bank is idle.
//!
//! # What a step gives
//! For the plant step `[t, t + dt]`, with `J_i` thruster `i`'s impulse in it, position
//! `r_i` from the centre of mass and unit direction `d_i` (body axes):
//! ```text
//! mean force   F_body   = sum_i J_i d_i / dt
//! mean torque  tau_body = sum_i r_i x (J_i d_i) / dt
//! propellant   dm       = sum_i J_i / (Isp g0)     (Isp constant over rise and tail)
//! ```
//! The plant holds the mean force and torque over the step, so the step's linear and
//! angular impulse are exact; within a step the pulse's shape is averaged.

use nalgebra::Vector3;
use oils_shared::THRUSTER_COUNT;

use crate::config::LanderConfig;

/// Standard gravity for specific impulse, m/s^2.
const G0_M_S2: f64 = 9.80665;

/// Valve-open pulses kept per thruster at once (pending or still open). Exact while the
/// closing delay spans fewer cycles than this; past that the newest two are merged.
pub const PULSES_PER_THRUSTER: usize = 8;

/// Thrust fraction below which a closed thruster's tail is set to zero.
pub const TAIL_CUTOFF: f64 = 1e-15;

/// What the bank gives for one plant step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrusterStep {
    /// Mean force on the centre of mass over the step, body axes, newtons.
    pub force_body_n: Vector3<f64>,
    /// Mean torque about the centre of mass over the step, body axes, N m.
    pub torque_body_nm: Vector3<f64>,
    /// Each thruster's impulse over the step, N s.
    pub impulse_n_s: [f64; THRUSTER_COUNT],
    /// Propellant used over the step, kilograms.
    pub propellant_kg: f64,
}

/// Timing of one thruster (the same for all eight).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrusterTiming {
    /// On-times shorter than this (and not zero) are not fired, ns.
    pub min_on_time_ns: i64,
    /// Electrical pulse start to valve open, ns.
    pub open_delay_ns: i64,
    /// Electrical pulse end to valve closed, ns.
    pub close_delay_ns: i64,
    /// Time constant of the thrust's first-order rise and tail, seconds (0: a step).
    pub time_constant_s: f64,
}

impl ThrusterTiming {
    /// From the lander configuration (seconds rounded to whole nanoseconds).
    pub fn from_config(lander: &LanderConfig) -> Self {
        let ns = |s: f64| (s * 1e9).round() as i64;
        Self {
            min_on_time_ns: ns(lander.rcs_min_on_time_s),
            open_delay_ns: ns(lander.rcs_open_delay_s),
            close_delay_ns: ns(lander.rcs_close_delay_s),
            time_constant_s: lander.rcs_time_constant_s,
        }
    }
}

/// An electrical pulse `[start, end)`, ns since the start of the run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct Pulse {
    start_ns: i64,
    end_ns: i64,
}

/// The eight attitude thrusters and their valves.
#[derive(Debug, Clone)]
pub struct ThrusterBank {
    /// Positions from the centre of mass, body axes, metres.
    pos_body_m: [Vector3<f64>; THRUSTER_COUNT],
    /// Unit thrust directions (the force on the vehicle), body axes.
    dir_body: [Vector3<f64>; THRUSTER_COUNT],
    /// Full thrust of one thruster, newtons.
    thrust_n: f64,
    /// Effective exhaust speed, Isp g0, m/s.
    exhaust_m_s: f64,
    timing: ThrusterTiming,
    /// Thrust fraction of each thruster at `time_ns`.
    level: [f64; THRUSTER_COUNT],
    /// Electrical pulses per thruster whose valve has not yet closed by `time_ns`,
    /// oldest first; `count[i]` of them are in use.
    pulses: [[Pulse; PULSES_PER_THRUSTER]; THRUSTER_COUNT],
    count: [usize; THRUSTER_COUNT],
    /// Cycle start of the last command latched.
    last_cycle_start_ns: Option<i64>,
    /// On-times of the last command latched (after the minimum on-time), ns.
    last_on_time_ns: [u64; THRUSTER_COUNT],
    /// End of the last step, ns.
    time_ns: i64,
}

impl ThrusterBank {
    /// A bank of thrusters at `pos_body_m` (from the centre of mass) thrusting along
    /// `dir_body` (normalised here), each `thrust_n` at `isp_s`.
    pub fn new(
        pos_body_m: [Vector3<f64>; THRUSTER_COUNT],
        dir_body: [Vector3<f64>; THRUSTER_COUNT],
        thrust_n: f64,
        isp_s: f64,
        timing: ThrusterTiming,
    ) -> Self {
        Self {
            pos_body_m,
            dir_body: dir_body.map(|d| d.normalize()),
            thrust_n,
            exhaust_m_s: isp_s * G0_M_S2,
            timing,
            level: [0.0; THRUSTER_COUNT],
            pulses: [[Pulse::default(); PULSES_PER_THRUSTER]; THRUSTER_COUNT],
            count: [0; THRUSTER_COUNT],
            last_cycle_start_ns: None,
            last_on_time_ns: [0; THRUSTER_COUNT],
            time_ns: 0,
        }
    }

    /// The configured bank, positions measured from the true centre of mass (the
    /// design one plus `com_offset_body_m`).
    pub fn from_config(lander: &LanderConfig) -> Self {
        let com = Vector3::from(lander.com_offset_body_m);
        Self::new(
            lander.rcs_positions_body_m.map(|p| Vector3::from(p) - com),
            lander.rcs_directions_body.map(Vector3::from),
            lander.rcs_thrust_n,
            lander.rcs_isp_s,
            ThrusterTiming::from_config(lander),
        )
    }

    /// Latches the on-times of a command issued for the cycle starting at
    /// `cycle_start_ns`. A command for a cycle not later than the last one latched (the
    /// same command held over a missed cycle) fires nothing new. On-times below the
    /// minimum on-time are dropped. No allocation.
    pub fn command(&mut self, on_time_ns: &[u64; THRUSTER_COUNT], cycle_start_ns: i64) {
        if self
            .last_cycle_start_ns
            .is_some_and(|last| cycle_start_ns <= last)
        {
            return;
        }
        self.last_cycle_start_ns = Some(cycle_start_ns);
        for (i, &t) in on_time_ns.iter().enumerate() {
            let t = t.min(i64::MAX as u64) as i64;
            if t == 0 || t < self.timing.min_on_time_ns {
                self.last_on_time_ns[i] = 0;
                continue;
            }
            self.last_on_time_ns[i] = t as u64;
            let pulse = Pulse {
                start_ns: cycle_start_ns,
                end_ns: cycle_start_ns.saturating_add(t),
            };
            self.push(i, pulse);
        }
    }

    /// Adds an electrical pulse to thruster `i`: merged with the last one when they
    /// touch, or when no slot is free.
    fn push(&mut self, i: usize, pulse: Pulse) {
        let n = self.count[i];
        if n > 0 {
            let last = &mut self.pulses[i][n - 1];
            if pulse.start_ns <= last.end_ns || n == PULSES_PER_THRUSTER {
                last.end_ns = last.end_ns.max(pulse.end_ns);
                return;
            }
        }
        self.pulses[i][n] = pulse;
        self.count[i] = n + 1;
    }

    /// Whether any thruster is thrusting or has a pulse pending.
    pub fn active(&self) -> bool {
        self.count.iter().any(|&n| n > 0) || self.level.iter().any(|&x| x != 0.0)
    }

    /// Advances over `[t0_ns, t0_ns + dt_ns]` and returns the mean force and torque and
    /// the propellant used. No allocation.
    pub fn step(&mut self, t0_ns: i64, dt_ns: u64) -> ThrusterStep {
        let t1_ns = t0_ns.saturating_add(dt_ns as i64);
        let mut impulse_n_s = [0.0; THRUSTER_COUNT];
        let mut force = Vector3::zeros();
        let mut torque = Vector3::zeros();
        let mut total_n_s = 0.0;
        for (i, impulse) in impulse_n_s.iter_mut().enumerate() {
            if self.count[i] == 0 && self.level[i] == 0.0 {
                continue;
            }
            let j = self.thrust_n * self.integrate(i, t0_ns, t1_ns);
            *impulse = j;
            total_n_s += j;
            let f = self.dir_body[i] * j;
            force += f;
            torque += self.pos_body_m[i].cross(&f);
        }
        self.time_ns = t1_ns;
        let (force_body_n, torque_body_nm) = if dt_ns > 0 {
            let dt_s = dt_ns as f64 * 1e-9;
            (force / dt_s, torque / dt_s)
        } else {
            (Vector3::zeros(), Vector3::zeros())
        };
        ThrusterStep {
            force_body_n,
            torque_body_nm,
            impulse_n_s,
            propellant_kg: total_n_s / self.exhaust_m_s,
        }
    }

    /// Integral of thruster `i`'s thrust fraction over `[t0, t1]` (seconds), advancing
    /// its level and dropping pulses whose valve has closed.
    fn integrate(&mut self, i: usize, t0_ns: i64, t1_ns: i64) -> f64 {
        let (d_open, d_close) = (self.timing.open_delay_ns, self.timing.close_delay_ns);
        let tau = self.timing.time_constant_s;
        let pulses = &self.pulses[i][..self.count[i]];
        let valve = |p: &Pulse| {
            (
                p.start_ns.saturating_add(d_open),
                p.end_ns.saturating_add(d_close),
            )
        };
        let mut x = self.level[i];
        let mut integral = 0.0;
        let mut s = t0_ns;
        while s < t1_ns {
            // Valve state at s, and the next instant it may change.
            let mut open = false;
            let mut next = t1_ns;
            for (o, f) in pulses.iter().map(valve) {
                if o <= s && s < f {
                    open = true;
                }
                if o > s {
                    next = next.min(o);
                }
                if f > s {
                    next = next.min(f);
                }
            }
            let u = if open { 1.0 } else { 0.0 };
            let h = (next - s) as f64 * 1e-9;
            if tau > 0.0 {
                // 1 - e^(-h/tau), without cancellation for short pieces.
                let rise = -(-h / tau).exp_m1();
                integral += u * h + (x - u) * tau * rise;
                x += (u - x) * rise;
            } else {
                integral += u * h;
                x = u;
            }
            s = next;
        }
        // Pulses whose valve closed by t1 are done.
        let mut kept = 0;
        for k in 0..self.count[i] {
            let p = self.pulses[i][k];
            if p.end_ns.saturating_add(d_close) > t1_ns {
                self.pulses[i][kept] = p;
                kept += 1;
            }
        }
        self.count[i] = kept;
        if kept == 0 && x < TAIL_CUTOFF {
            x = 0.0;
        }
        self.level[i] = x;
        integral
    }

    /// Force of the thrusters at the end of the last step (the instantaneous value),
    /// body axes, newtons.
    pub fn force_now_body_n(&self) -> Vector3<f64> {
        self.level
            .iter()
            .zip(self.dir_body.iter())
            .map(|(&x, d)| d * (x * self.thrust_n))
            .sum()
    }

    /// Each thruster's thrust at the end of the last step, newtons (for logs).
    pub fn thrust_now_n(&self) -> [f64; THRUSTER_COUNT] {
        self.level.map(|x| x * self.thrust_n)
    }

    /// Whether each thruster's valve is open at the end of the last step (for logs).
    pub fn valve_open_now(&self) -> [bool; THRUSTER_COUNT] {
        let t = self.time_ns;
        let mut open = [false; THRUSTER_COUNT];
        for (i, o) in open.iter_mut().enumerate() {
            *o = self.pulses[i][..self.count[i]].iter().any(|p| {
                p.start_ns.saturating_add(self.timing.open_delay_ns) <= t
                    && t < p.end_ns.saturating_add(self.timing.close_delay_ns)
            });
        }
        open
    }

    /// On-times of the last command latched, after the minimum on-time (0 where a pulse
    /// was dropped), ns (for logs).
    pub fn last_on_time_ns(&self) -> [u64; THRUSTER_COUNT] {
        self.last_on_time_ns
    }

    /// Positions from the centre of mass, body axes, metres.
    pub fn positions_body_m(&self) -> &[Vector3<f64>; THRUSTER_COUNT] {
        &self.pos_body_m
    }

    /// Unit thrust directions, body axes.
    pub fn directions_body(&self) -> &[Vector3<f64>; THRUSTER_COUNT] {
        &self.dir_body
    }

    /// Full thrust of one thruster, newtons.
    pub fn thrust_n(&self) -> f64 {
        self.thrust_n
    }

    /// The timing.
    pub fn timing(&self) -> ThrusterTiming {
        self.timing
    }

    /// Impulse of one isolated pulse of on-time `on_time_ns`, N s: 0 below the minimum
    /// on-time, else `F (T + d_close - d_open)` (the closed form of the module doc).
    pub fn pulse_impulse_n_s(&self, on_time_ns: u64) -> f64 {
        let t = on_time_ns as i64;
        if t == 0 || t < self.timing.min_on_time_ns {
            return 0.0;
        }
        let d = t + self.timing.close_delay_ns - self.timing.open_delay_ns;
        self.thrust_n * d.max(0) as f64 * 1e-9
    }

    /// The minimum impulse bit: the impulse of a pulse of the minimum on-time, N s.
    pub fn minimum_impulse_bit_n_s(&self) -> f64 {
        self.pulse_impulse_n_s(self.timing.min_on_time_ns.max(1) as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: i64 = 1_000_000;

    fn bank(tau_s: f64) -> ThrusterBank {
        ThrusterBank::from_config(&LanderConfig {
            rcs_time_constant_s: tau_s,
            rcs_open_delay_s: 0.005,
            rcs_close_delay_s: 0.003,
            rcs_min_on_time_s: 0.010,
            ..Default::default()
        })
    }

    /// Thrust fraction of an isolated pulse at time t (seconds), written independently
    /// of the stepping code: rise from t_o, tail from t_f.
    fn profile(t: f64, t_o: f64, t_f: f64, tau: f64) -> f64 {
        if t < t_o {
            0.0
        } else if t < t_f {
            1.0 - (-(t - t_o) / tau).exp()
        } else {
            (1.0 - (-(t_f - t_o) / tau).exp()) * (-(t - t_f) / tau).exp()
        }
    }

    #[test]
    fn impulse_over_sub_intervals_matches_quadrature_of_the_profile() {
        let tau = 0.004;
        let mut b = bank(tau);
        let mut on = [0u64; THRUSTER_COUNT];
        on[3] = 12 * MS as u64;
        b.command(&on, 20 * MS);
        // t_o = 25 ms, t_f = 20 + 12 + 3 = 35 ms.
        let (t_o, t_f) = (0.025, 0.035);
        // Uneven steps that cut the open and close instants anywhere.
        let mut t = 0i64;
        for dt in [7 * MS, 11 * MS, 9 * MS, MS, 3 * MS, 13 * MS, 17 * MS] {
            let out = b.step(t, dt as u64);
            let (a, z) = (t as f64 * 1e-9, (t + dt) as f64 * 1e-9);
            // Composite Simpson on a profile smooth inside each piece.
            let mut quad = 0.0;
            let mut cuts = [a, z, t_o, t_f];
            cuts.sort_by(f64::total_cmp);
            for w in cuts.windows(2) {
                let (lo, hi) = (w[0].max(a), w[1].min(z));
                if hi <= lo {
                    continue;
                }
                let n = 2000;
                let h = (hi - lo) / n as f64;
                let mut s = profile(lo, t_o, t_f, tau) + profile(hi - 1e-15, t_o, t_f, tau);
                for k in 1..n {
                    let w = if k % 2 == 1 { 4.0 } else { 2.0 };
                    s += w * profile(lo + h * k as f64, t_o, t_f, tau);
                }
                quad += s * h / 3.0;
            }
            let want = 58.0 * quad;
            assert!(
                (out.impulse_n_s[3] - want).abs() < 1e-9,
                "step at {t}: {} vs {want}",
                out.impulse_n_s[3]
            );
            t += dt;
        }
    }

    #[test]
    fn a_whole_pulse_gives_f_times_on_time_plus_delays_whatever_the_tick() {
        for dt in [MS / 4, MS, 3 * MS, 10 * MS, 16 * MS] {
            let mut b = bank(0.004);
            let mut on = [0u64; THRUSTER_COUNT];
            on[0] = 14 * MS as u64;
            b.command(&on, 0);
            let mut total = 0.0;
            let mut t = 0;
            while t < 400 * MS {
                total += b.step(t, dt as u64).impulse_n_s[0];
                t += dt;
            }
            let want = 58.0 * (0.014 + 0.003 - 0.005);
            assert!((total - want).abs() < 1e-12 * want, "dt {dt}: {total}");
            assert_eq!(want, b.pulse_impulse_n_s(14 * MS as u64));
            assert!(!b.active(), "the tail ends");
        }
    }

    #[test]
    fn below_the_minimum_on_time_nothing_fires_at_it_the_minimum_impulse_bit() {
        let mut b = bank(0.004);
        let mut on = [0u64; THRUSTER_COUNT];
        on[1] = 9_999_999;
        b.command(&on, 0);
        assert!(!b.active());
        assert_eq!(
            b.step(0, 100 * MS as u64).impulse_n_s,
            [0.0; THRUSTER_COUNT]
        );
        on[1] = 10 * MS as u64;
        b.command(&on, 100 * MS);
        let mut total = 0.0;
        for k in 10..60 {
            total += b.step(k * 10 * MS, 10 * MS as u64).impulse_n_s[1];
        }
        let mib = b.minimum_impulse_bit_n_s();
        assert!((mib - 58.0 * 0.008).abs() < 1e-15);
        assert!((total - mib).abs() < 1e-12 * mib, "{total} vs {mib}");
    }

    #[test]
    fn back_to_back_cycles_keep_the_valve_open_and_a_held_command_does_not_refire() {
        let mut b = bank(0.0);
        let mut on = [0u64; THRUSTER_COUNT];
        on[2] = 10 * MS as u64;
        // Two touching pulses: one valve-open interval [5, 23) ms.
        b.command(&on, 0);
        let first = b.step(0, 10 * MS as u64).impulse_n_s[2];
        b.command(&on, 10 * MS);
        // Held over a missed cycle: same cycle start, nothing new.
        let second = b.step(10 * MS, 10 * MS as u64).impulse_n_s[2];
        b.command(&on, 10 * MS);
        let third = b.step(20 * MS, 10 * MS as u64).impulse_n_s[2];
        b.command(&on, 10 * MS);
        let fourth = b.step(30 * MS, 10 * MS as u64).impulse_n_s[2];
        assert!((first - 58.0 * 0.005).abs() < 1e-12);
        assert!((second - 58.0 * 0.010).abs() < 1e-12);
        assert!((third - 58.0 * 0.003).abs() < 1e-12);
        assert_eq!(fourth, 0.0);
        assert!(!b.active());
    }

    #[test]
    fn torque_and_force_follow_r_cross_f_and_propellant_impulse_over_isp_g0() {
        let mut b = bank(0.0);
        let mut on = [0u64; THRUSTER_COUNT];
        on[5] = 20 * MS as u64;
        b.command(&on, 0);
        // Fully open over [10, 20) ms with tau = 0.
        b.step(0, 10 * MS as u64);
        let out = b.step(10 * MS, 10 * MS as u64);
        let f = b.directions_body()[5] * 58.0;
        let want_torque = b.positions_body_m()[5].cross(&f);
        assert!((out.force_body_n - f).norm() < 1e-9);
        assert!((out.torque_body_nm - want_torque).norm() < 1e-9);
        let want_kg = 58.0 * 0.010 / (220.0 * G0_M_S2);
        assert!((out.propellant_kg - want_kg).abs() < 1e-15);
    }
}
