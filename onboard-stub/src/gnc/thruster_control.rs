//! Attitude control with the thrusters: the body torque the attitude loop wants (after
//! the main engines' differential throttle took what it could) turned into on-times of
//! the eight on/off attitude thrusters for the next cycle.
//!
//! **Selection.** At construction, for each signed body axis (+x, -x, +y, -y, +z, -z)
//! the pair of thrusters of the GNC's own layout ([`ThrusterLayout`]) that is a pure
//! couple about that axis (no net force, no torque about the other two axes) with the
//! largest torque. A layout without such a pair for some axis is refused.
//!
//! **Modulation: a torque-error accumulator** (sigma-delta, the discrete cousin of a
//! pulse-width pulse-frequency modulator). The thrusters can only give whole pulses of
//! at least the minimum on-time `T_min`; a pulse of on-time `T` gives the impulse
//! `F (T + d_close - d_open)` (rise and tail cancel). Each cycle the wanted angular
//! impulse `tau Tc` is added to an accumulator `e` (N m s, body axes). Per axis, the
//! couple of the sign of `e_i` is given the effective burn `|e_i| / C_i` (`C_i` its
//! torque with both thrusters on), as an electrical on-time `T = |e_i| / C_i - (d_close
//! - d_open)`:
//! * below half the minimum effective burn (`T_min + d_close - d_open`): nothing fires,
//!   the request stays in `e`;
//! * else at least `T_min`, at most the cycle.
//!
//! The axes are served furthest-behind first; the couples' on-times are summed per
//! thruster (thruster 0 is in both +x and -y) and a couple whose thruster the cycle has
//! no room left for gets what is left (both its thrusters alike: no net force), or
//! waits. Then the angular impulse those on-times deliver (by the same pulse model) is
//! taken off `e`. So the mean torque is right over time: on one axis `e` stays within
//! half a minimum impulse bit, on several within 1.5 (an axis may wait a cycle); the x/y
//! reach is the diamond `|tx| + |ty| <= 2 F arm` (116 N m), not the ideal actuator's
//! box. Small requests are neither dropped (a steady 5 N m would never
//! fire if pulses below `T_min` were dropped) nor over-served (rounding every pulse up
//! to `T_min` would give 116 N m for 5 N m). `e` is clamped to two full cycles per axis
//! so a saturated request cannot wind up. Why not dropping: the reference GNC's
//! attitude loop has no integral term, and a steady small torque (a weak engine's, a
//! centre-of-mass offset's) is exactly what dropping would lose.
//!
//! No allocation: fixed arrays, built in [`ThrusterControl::new`].

use nalgebra::Vector3;
use oils_shared::THRUSTER_COUNT;

/// The attitude thrusters as the GNC knows them. The defaults copy the bench's
/// assumed layout and Chandrayaan-3's 8 x 58 N (see `docs/plant.md`, "Attitude
/// thrusters"); the onboard software never reads the emulator's configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ThrusterLayout {
    /// Thrust of one thruster, newtons (sourced: 8 x 58 N).
    pub thrust_n: f64,
    /// Positions from the centre of mass, body axes, metres (assumed: pods at the
    /// corners of a 2 m square at the centre of mass's height).
    pub positions_body_m: [[f64; 3]; THRUSTER_COUNT],
    /// Unit push directions, body axes (assumed: per pod one along Z, one tangential).
    pub directions_body: [[f64; 3]; THRUSTER_COUNT],
    /// Minimum electrical on-time, seconds (assumed: 10 ms; shorter ones do not fire).
    pub min_on_time_s: f64,
    /// Valve opening delay, seconds (assumed: 5 ms).
    pub open_delay_s: f64,
    /// Valve closing delay, seconds (assumed: 5 ms).
    pub close_delay_s: f64,
}

impl Default for ThrusterLayout {
    fn default() -> Self {
        const H: f64 = std::f64::consts::FRAC_1_SQRT_2;
        Self {
            thrust_n: 58.0,
            positions_body_m: [
                [1.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
                [1.0, -1.0, 0.0],
                [1.0, -1.0, 0.0],
                [-1.0, -1.0, 0.0],
                [-1.0, -1.0, 0.0],
                [-1.0, 1.0, 0.0],
                [-1.0, 1.0, 0.0],
            ],
            directions_body: [
                [0.0, 0.0, 1.0],
                [-H, H, 0.0],
                [0.0, 0.0, -1.0],
                [-H, -H, 0.0],
                [0.0, 0.0, 1.0],
                [H, -H, 0.0],
                [0.0, 0.0, -1.0],
                [H, H, 0.0],
            ],
            min_on_time_s: 0.010,
            open_delay_s: 0.005,
            close_delay_s: 0.005,
        }
    }
}

impl ThrusterLayout {
    /// Torque per newton of thruster `j`, `r_j x d_j`, body axes, metres.
    pub fn torque_arm_m(&self, j: usize) -> Vector3<f64> {
        Vector3::from(self.positions_body_m[j]).cross(&Vector3::from(self.directions_body[j]))
    }

    /// Impulse of one pulse of electrical on-time `on_time_s`, N s: 0 below the minimum
    /// on-time, else `F (T + d_close - d_open)`.
    pub fn pulse_impulse_n_s(&self, on_time_s: f64) -> f64 {
        if on_time_s <= 0.0 || on_time_s < self.min_on_time_s {
            0.0
        } else {
            self.thrust_n * (on_time_s + self.close_delay_s - self.open_delay_s)
        }
    }

    /// The smallest impulse one thruster gives, N s.
    pub fn min_impulse_bit_n_s(&self) -> f64 {
        self.pulse_impulse_n_s(self.min_on_time_s)
    }
}

/// One pure couple: two thrusters and the torque they give together, N m.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Couple {
    thrusters: [usize; 2],
    torque_nm: f64,
}

/// The layout cannot give a pure couple about some signed axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoCoupleError {
    /// 0, 1, 2: x, y, z.
    pub axis: usize,
    /// +1 or -1.
    pub sign: i8,
}

/// Thruster selection and the torque-error accumulator.
#[derive(Debug, Clone)]
pub struct ThrusterControl {
    layout: ThrusterLayout,
    /// Per axis, the couple for a positive and for a negative torque.
    couples: [[Couple; 2]; 3],
    /// Per thruster, `r x d` (m).
    arms_m: [Vector3<f64>; THRUSTER_COUNT],
    /// Angular impulse wanted and not yet delivered, body axes, N m s.
    accumulator_nms: Vector3<f64>,
}

impl ThrusterControl {
    /// Selects the couples of `layout`.
    pub fn new(layout: &ThrusterLayout) -> Result<Self, NoCoupleError> {
        let arms_m: [Vector3<f64>; THRUSTER_COUNT] =
            std::array::from_fn(|j| layout.torque_arm_m(j));
        let dirs: [Vector3<f64>; THRUSTER_COUNT] =
            std::array::from_fn(|j| Vector3::from(layout.directions_body[j]));
        let mut couples = [[Couple {
            thrusters: [0, 0],
            torque_nm: 0.0,
        }; 2]; 3];
        for (axis, pair) in couples.iter_mut().enumerate() {
            for (s, couple) in pair.iter_mut().enumerate() {
                let sign = if s == 0 { 1.0 } else { -1.0 };
                let mut best: Option<Couple> = None;
                for a in 0..THRUSTER_COUNT {
                    for b in a + 1..THRUSTER_COUNT {
                        let force = dirs[a] + dirs[b];
                        let torque = arms_m[a] + arms_m[b];
                        let along = sign * torque[axis];
                        let across = (0..3)
                            .filter(|&i| i != axis)
                            .map(|i| torque[i].abs())
                            .fold(0.0, f64::max);
                        let pure = force.norm() < 1e-9 && across < 1e-9 * along.abs().max(1.0);
                        if pure
                            && along > 1e-9
                            && best.is_none_or(|c| along * layout.thrust_n > c.torque_nm)
                        {
                            best = Some(Couple {
                                thrusters: [a, b],
                                torque_nm: along * layout.thrust_n,
                            });
                        }
                    }
                }
                *couple = best.ok_or(NoCoupleError {
                    axis,
                    sign: if s == 0 { 1 } else { -1 },
                })?;
            }
        }
        Ok(Self {
            layout: layout.clone(),
            couples,
            arms_m,
            accumulator_nms: Vector3::zeros(),
        })
    }

    /// The couples' torque per axis for (positive, negative) requests, N m.
    pub fn couple_torque_nm(&self) -> [[f64; 2]; 3] {
        self.couples.map(|p| p.map(|c| c.torque_nm))
    }

    /// The thrusters of the couple about `axis` (0-2) of sign `positive`.
    pub fn couple_thrusters(&self, axis: usize, positive: bool) -> [usize; 2] {
        self.couples[axis][usize::from(!positive)].thrusters
    }

    /// Angular impulse wanted and not yet delivered, body axes, N m s.
    pub fn accumulator_nms(&self) -> Vector3<f64> {
        self.accumulator_nms
    }

    /// Forgets what was not delivered (the thrusters not in use).
    pub fn reset(&mut self) {
        self.accumulator_nms = Vector3::zeros();
    }

    /// Angular impulse that `on_time_ns` deliver by the pulse model, body axes, N m s.
    pub fn angular_impulse_nms(&self, on_time_ns: &[u64; THRUSTER_COUNT]) -> Vector3<f64> {
        let mut h = Vector3::zeros();
        for (j, &t) in on_time_ns.iter().enumerate() {
            h += self.arms_m[j] * self.layout.pulse_impulse_n_s(t as f64 * 1e-9);
        }
        h
    }

    /// On-times for the cycle of `cycle_ns` that starts now, for the wanted body torque
    /// `torque_body_nm` held over it.
    pub fn on_times_ns(
        &mut self,
        torque_body_nm: &Vector3<f64>,
        cycle_ns: u64,
    ) -> [u64; THRUSTER_COUNT] {
        let mut on = [0u64; THRUSTER_COUNT];
        let cycle_s = cycle_ns as f64 * 1e-9;
        if cycle_ns == 0 || !torque_body_nm.iter().all(|t| t.is_finite()) {
            return on;
        }
        let l = &self.layout;
        let lead_s = l.close_delay_s - l.open_delay_s;
        let min_burn_s = l.min_on_time_s + lead_s;
        let min_on_ns = (l.min_on_time_s * 1e9).round() as u64;
        if cycle_ns < min_on_ns {
            // A cycle shorter than the minimum on-time: nothing can fire.
            return on;
        }
        // Per axis: the accumulated request, the couple of its sign and its burn, s.
        let mut burn_s = [0.0; 3];
        let mut couple = [self.couples[0][0]; 3];
        for axis in 0..3 {
            let pair = &self.couples[axis];
            let cap = 2.0 * pair[0].torque_nm.max(pair[1].torque_nm) * (cycle_s + lead_s.max(0.0));
            let e = (self.accumulator_nms[axis] + torque_body_nm[axis] * cycle_s).clamp(-cap, cap);
            self.accumulator_nms[axis] = e;
            couple[axis] = if e >= 0.0 { pair[0] } else { pair[1] };
            burn_s[axis] = e.abs() / couple[axis].torque_nm;
        }
        // The axis furthest behind first; a couple sharing a thruster with one already
        // served gets what is left of the cycle (both its thrusters alike: no net force),
        // or waits in the accumulator if that is less than the minimum on-time.
        let mut order = [0usize, 1, 2];
        order.sort_unstable_by(|&a, &b| burn_s[b].total_cmp(&burn_s[a]));
        for axis in order {
            if burn_s[axis] < 0.5 * min_burn_s {
                continue;
            }
            let want_s = (burn_s[axis] - lead_s).clamp(l.min_on_time_s, cycle_s);
            let [a, b] = couple[axis].thrusters;
            let room_ns = cycle_ns - on[a].max(on[b]);
            let t_ns = ((want_s * 1e9).round() as u64).min(room_ns);
            if t_ns == 0 || t_ns < min_on_ns {
                continue;
            }
            on[a] += t_ns;
            on[b] += t_ns;
        }
        self.accumulator_nms -= self.angular_impulse_nms(&on);
        on
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CYCLE_NS: u64 = 10_000_000;

    fn control() -> ThrusterControl {
        ThrusterControl::new(&ThrusterLayout::default()).unwrap()
    }

    /// Net force of `on` by the pulse model, N s.
    fn linear_impulse(l: &ThrusterLayout, on: &[u64; THRUSTER_COUNT]) -> Vector3<f64> {
        let mut p = Vector3::zeros();
        for (j, &t) in on.iter().enumerate() {
            p += Vector3::from(l.directions_body[j]) * l.pulse_impulse_n_s(t as f64 * 1e-9);
        }
        p
    }

    #[test]
    fn selection_finds_the_documented_couples() {
        let c = control();
        assert_eq!(c.couple_thrusters(0, true), [0, 2]);
        assert_eq!(c.couple_thrusters(0, false), [4, 6]);
        assert_eq!(c.couple_thrusters(1, true), [2, 4]);
        assert_eq!(c.couple_thrusters(1, false), [0, 6]);
        assert_eq!(c.couple_thrusters(2, true), [1, 5]);
        assert_eq!(c.couple_thrusters(2, false), [3, 7]);
        let t = c.couple_torque_nm();
        assert!((t[0][0] - 116.0).abs() < 1e-9 && (t[1][1] - 116.0).abs() < 1e-9);
        assert!((t[2][0] - 2.0 * 58.0 * 2f64.sqrt()).abs() < 1e-9);
        assert!((ThrusterLayout::default().min_impulse_bit_n_s() - 0.58).abs() < 1e-12);
    }

    #[test]
    fn a_layout_without_a_couple_is_refused() {
        let mut l = ThrusterLayout::default();
        // Every tangential thruster turned to +Z: nothing twists about z any more.
        for j in [1, 3, 5, 7] {
            l.directions_body[j] = [0.0, 0.0, 1.0];
        }
        assert_eq!(
            ThrusterControl::new(&l).unwrap_err(),
            NoCoupleError { axis: 2, sign: 1 }
        );
    }

    #[test]
    fn zero_request_fires_nothing() {
        let mut c = control();
        for _ in 0..1000 {
            assert_eq!(
                c.on_times_ns(&Vector3::zeros(), CYCLE_NS),
                [0; THRUSTER_COUNT]
            );
        }
        assert_eq!(c.accumulator_nms(), Vector3::zeros());
        // A request below half a minimum bit stays in the accumulator, unfired.
        let small = Vector3::new(20.0, -20.0, 20.0);
        assert_eq!(c.on_times_ns(&small, CYCLE_NS), [0; THRUSTER_COUNT]);
        assert!((c.accumulator_nms() - small * 0.01).norm() < 1e-15);
    }

    /// Over many cycles of a steady couple request, the delivered angular impulse
    /// (r x F of the on-times) equals the requested one within half a minimum-impulse
    /// quantum per axis, and never a net force; every on-time is 0 or in [T_min, cycle].
    fn check_mean(request: Vector3<f64>, cycle_ns: u64, cycles: usize, bound_quanta: f64) {
        let l = ThrusterLayout::default();
        let mut c = control();
        let quanta = c
            .couple_torque_nm()
            .map(|p| p[0].min(p[1]) * (l.min_on_time_s));
        let mut delivered = Vector3::zeros();
        let mut fired = 0;
        for k in 0..cycles {
            let on = c.on_times_ns(&request, cycle_ns);
            for &t in &on {
                assert!(t == 0 || (10_000_000..=cycle_ns).contains(&t), "{on:?}");
            }
            assert!(linear_impulse(&l, &on).norm() < 1e-9, "net force {on:?}");
            delivered += c.angular_impulse_nms(&on);
            fired += on.iter().filter(|&&t| t > 0).count();
            let wanted = request * (cycle_ns as f64 * 1e-9) * (k + 1) as f64;
            for i in 0..3 {
                assert!(
                    (delivered[i] - wanted[i]).abs() <= bound_quanta * quanta[i] + 1e-9,
                    "cycle {k} axis {i}: delivered {} wanted {}",
                    delivered[i],
                    wanted[i]
                );
            }
        }
        assert_eq!(request == Vector3::zeros(), fired == 0);
    }

    #[test]
    fn pure_couple_requests_are_met_on_average_within_the_quantum() {
        // 10 ms cycle = T_min: each couple is on or off for whole cycles (pulse frequency).
        // One axis: within half a quantum at every cycle.
        check_mean(Vector3::new(5.0, 0.0, 0.0), CYCLE_NS, 2000, 0.5);
        check_mean(Vector3::new(0.0, -37.0, 0.0), CYCLE_NS, 2000, 0.5);
        check_mean(Vector3::new(0.0, 0.0, 3.3), CYCLE_NS, 2000, 0.5);
        check_mean(Vector3::new(0.0, 0.0, -150.0), CYCLE_NS, 2000, 0.5);
        // 40 ms cycle: pulse widths between T_min and the cycle.
        check_mean(Vector3::new(72.0, 0.0, 0.0), 40_000_000, 500, 0.5);
        // Several axes: couples that share a thruster take turns, so an axis may wait a
        // cycle: within 1.5 quanta.
        check_mean(Vector3::new(40.0, 30.0, -10.0), CYCLE_NS, 2000, 1.5);
        check_mean(Vector3::new(60.0, -20.0, 7.0), 40_000_000, 500, 1.5);
        check_mean(Vector3::new(-50.0, 50.0, 0.0), 40_000_000, 500, 1.5);
    }

    #[test]
    fn one_cycle_matches_the_request_within_half_a_quantum() {
        // A 40 ms cycle: 116 N m x 25 ms of +x is one 25 ms couple.
        let mut c = control();
        let on = c.on_times_ns(&Vector3::new(72.5, 0.0, 0.0), 40_000_000);
        assert_eq!(on, [25_000_000, 0, 25_000_000, 0, 0, 0, 0, 0]);
        let h = c.angular_impulse_nms(&on);
        assert!((h - Vector3::new(2.9, 0.0, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn on_times_never_exceed_the_cycle_even_saturated() {
        let mut c = control();
        for k in 0..200 {
            let s = if k % 50 < 25 { 1.0 } else { -1.0 };
            let on = c.on_times_ns(&Vector3::new(500.0 * s, -500.0 * s, 900.0), CYCLE_NS);
            assert!(on.iter().all(|&t| t <= CYCLE_NS), "{on:?}");
            // Saturated: the accumulator is clamped, it does not wind up.
            assert!(c.accumulator_nms().amax() <= 2.0 * 164.1 * 0.01);
        }
        // A cycle shorter than the minimum on-time fires nothing.
        assert_eq!(
            c.on_times_ns(&Vector3::new(100.0, 0.0, 0.0), 5_000_000),
            [0; THRUSTER_COUNT]
        );
        // Not a number fires nothing.
        assert_eq!(
            c.on_times_ns(&Vector3::new(f64::NAN, 0.0, 0.0), CYCLE_NS),
            [0; THRUSTER_COUNT]
        );
    }
}
